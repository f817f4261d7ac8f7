"""
Node painter: Algorithm 1 of the paper as the ``paint`` action (helio_msgs/PaintPattern).

Per goal (paper Sec. IV-B and IV-C, Algorithm 1):

1. the rig calibration (``calibrate_rig`` of the lens planner, issue 28: the build's
   errors measured from the marker and the spot) when asked by ``calibrate_rig``
   (``missing``: no calibration of the rig as built has come on ``calibration/rig``;
   ``always``; ``never``, the default until it places as well as the paper), else the
   robot-world calibration (``calibrate_world``; once per node, or every goal, by
   parameter); without a sun estimate, the sun sweep (``sweep_sun``);
2. the plan (``helio_control.plan``): the picture (or the goal's points) to ordered world
   dots with per-dot N_p targets, checked against the rig's reach for the estimated sun;
3. per dot: ``focus`` at the heating distance (the focal calibration's, ``calibration/focus``,
   else the parameter); hold while N_p < the dot's target (``dot_cycle``); retreat by delta
   d_lp; with the paper's cooling rule wait until N_p is back to 0, with the ``window``
   rule count N_p only within ``window_radius`` of the dot (``thermal/window``: the previous
   dot's afterglow does not count) and go on at once (the move to the next dot is one
   ``focus`` goal that starts with the retreat, so the arm does not stop in between);
   the sun estimate follows the sun by Eq 18 (``sun_estimator`` republishes it).

Beyond the paper:

- **clouds**: a loss of sun while heating (``dot_cycle``: N_p or T_max falling, or no light
  spot) retreats the lens and waits for the sun (the spot seen again in a row of frames, at
  most ``cloud_timeout``), then heats the same dot again with its full target;
- **fire-safety watchdog**: the lens never rests at the heating distance without fresh thermal
  data. Thermal statistics older than ``thermal_stale`` (node clock, or ``thermal_stale_wall``
  of wall time), a dot held past ``max_heating``, a device fault or alarm (``dobot/status``,
  ``servo/status``), a cancel, or the node stopping: the lens retreats at once (``focus`` at
  the retreat distance; if the arm cannot move, the wrist turns the lens off the sun: a
  ``move_wrist`` escape goal, at the servos' own speed; if the wrist cannot move (its driver
  silent or faulted), the arm alone lifts the lens straight up by ``arm_escape_lift``, a
  ``move_arm`` goal (``escape_lift``); a retreat goal not accepted within
  ``retreat_accept_timeout`` of wall time, as a killed lens planner's never is, goes to the
  wrist at once (the lens planner's goal, accepted late, is cancelled); the last way, the
  wrist's escape or the arm's lift, waits ``goal_accept_timeout``, and any other goal not
  accepted within that fails the painting).
  A stale stream then gets ``thermal_back_timeout`` to come back (the dot is heated again from
  the start, and the result counts it); everything else ends the goal saying why. A window-rule
  frame without a camera pose is fresh data without a window reading: heat on while the image's
  N_p is below the target (the window lies in the image), else it counts towards
  ``thermal_stale``. A frozen frame (``ThermalStats.frozen``: a Lepton's flat-field
  correction repeats its last frame for 0.3-1 s every few minutes) is no fresh reading either:
  the dot heats on blind for at most ``thermal_freeze_max``, then it is a stale stream; a
  stream that stops is stale after ``thermal_stale`` as before (issue 29);
- **resume**: every finished dot is appended (and flushed) to the run's ``journal.jsonl``;
  the same goal sent again continues an unfinished run at its first unburnt dot, with the
  same plan, none lost and none doubled (``fresh`` starts over; ``start_index`` skips the
  dots before it);
- **dry run**: the whole painting with the lens at the retreat distance: reach and timing
  without burning;
- **tones**: each dot's own N_p target (the plan's, Fig. 8d);
- **the sky** (``helio_control.sky``, ``helio sky``): a goal the sun cannot serve is refused
  before its first dot: without a sun estimate, a sun lower than the sweep estimates
  (``sky.min_sweep_elevation_deg``, at the ``site_file``'s site: before the sweep); with
  one, none of the goal's points (its dots, or a grid over its canvas) within reach of it.
  The reason names ``helio sky`` (with the robot heading the estimate implies) and when the
  sun serves next at the site.

The run directory (``run_dir`` of the goal, else ``runs_dir``/<UTC time>) holds
``plan.json``, ``journal.jsonl`` (``helio_control.run_journal``) and ``resume.json``.
"""

from dataclasses import replace
import datetime
import glob
import hashlib
import json
import math
import os
import time
import traceback

from geometry_msgs.msg import PointStamped
from helio_control import sky
from helio_control.dot_check import expected_dot
from helio_control.dot_cycle import CycleSettings, Decision, DotCycle
from helio_control.dot_size_calibration import dot_size_for_painting, options_for_dot_size
from helio_control.driver_silence import DriverSilence
from helio_control.picture_input import picture_from_image_msg, PictureError
from helio_control.plan import options_from_goal, Plan, plan_dots, plan_picture
from helio_control.plan import PlanError, PlanOptionsError
from helio_control.run_journal import goal_to_dict, JournalError, JournalWriter, read_journal
from helio_msgs.action import CalibrateRig, CalibrateWorld, FocusLens, MoveArm, MoveWrist
from helio_msgs.action import PaintPattern
from helio_msgs.action import SweepSun
from helio_msgs.msg import DeviceStatus, FocalCalibration, SpotObservation, SunEstimate
from helio_msgs.msg import ThermalStats
from helio_optics.geometry import invert_transform
from helio_optics.node_kit import emergency_stop
from helio_optics.node_kit.awaitables import discovered, FirstOf, NextTurn, sleep, within
from helio_optics.node_kit.conversions import camera_from_info, image_to_numpy
from helio_optics.node_kit.conversions import ImageConversionError
from helio_optics.node_kit.conversions import point_to_array, stamp_to_seconds
from helio_optics.node_kit.deployment import declare_rig, declare_site
from helio_optics.node_kit.deployment import follow_world_calibration
from helio_optics.node_kit.emergency_stop import EmergencyStopListener
from helio_optics.node_kit.parameters import declare
from helio_optics.node_kit.qos import LATCHED, reliable
from helio_optics.node_kit.runner import run_node
from helio_optics.rig_kinematics import escape_lift, escape_pitch, JOINT_NAMES
from helio_optics.rig_kinematics import UnreachableError
from helio_perception.char_dots import CharSettings, measure_in_image
from helio_perception.ground_plane import RESPONSES
import numpy as np
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Header

RELIABLE = reliable(20)
COOLING_RULES = ('paper', 'window')
# how a retreat that found no way to take the focus off the wood begins its account
RETREAT_FAILED = 'RETREAT FAILED'
# Goal fields that do not change what is painted (a resumed goal may differ in them).
NOT_THE_PICTURE = ('run_dir', 'fresh', 'start_index', 'dry_run')
# A steady tick this late says the painter itself did not run (DriverSilence): at most this,
# and at most half device_silence [s wall].
LONGEST_RUN_GAP = 0.5


class PaintFailed(Exception):
    """The painting cannot go on; the message is the goal's result message."""


class PaintCanceled(Exception):
    """The goal was canceled."""


def goal_key(goal):
    """
    Return a key naming what a goal paints.

    The goal's fields but NOT_THE_PICTURE, and the picture's content (an edited file is a
    new painting).
    """
    fields = {k: v for k, v in goal_to_dict(goal).items() if k not in NOT_THE_PICTURE}
    if goal.image_path and os.path.isfile(goal.image_path):
        with open(goal.image_path, 'rb') as stream:
            fields['image_sha256'] = hashlib.sha256(stream.read()).hexdigest()
    if goal.image.width:
        fields['image_sha256'] = hashlib.sha256(bytes(goal.image.data)).hexdigest()
    return hashlib.sha256(json.dumps(fields, sort_keys=True).encode()).hexdigest()[:16]


def unfinished_run(runs_dir, key):
    """
    Return (run dir, burnt indices) of the newest unfinished run of the goal `key`, or None.

    A run is unfinished when its journal has no result line or an unsuccessful one. The
    burnt dots are those of its journal and of the runs it resumed (``resume.json``).
    """
    candidates = []
    for resume in glob.glob(os.path.join(runs_dir, '*', 'resume.json')):
        try:
            with open(resume) as stream:
                state = json.load(stream)
        except (OSError, ValueError):
            continue
        if state.get('goal_key') == key:
            candidates.append((os.path.getmtime(resume), os.path.dirname(resume), state))
    for _, run_dir, state in sorted(candidates, reverse=True):
        journal_path = os.path.join(run_dir, 'journal.jsonl')
        try:
            journal = read_journal(journal_path)
        except (OSError, JournalError):
            continue
        if journal.result is not None and journal.result.success:
            return None              # the newest run of this goal finished: start over
        burnt = set(state.get('burnt_before', []))
        burnt.update(dot.index for dot in journal.dots if dot.outcome == 'burnt')
        return run_dir, burnt
    return None


def _cancel_if_accepted(sent):
    """Cancel the goal of a send future that completed after the painter gave up on it."""
    handle = sent.result() if sent.done() and sent.exception() is None else None
    if handle is not None and handle.accepted:
        handle.cancel_goal_async()


class PainterNode(Node):
    """See the module docstring."""

    def __init__(self, **kwargs):
        """Declare parameters and open the interfaces."""
        super().__init__('painter', **kwargs)
        self.rig, self.rig_file = declare_rig(self)
        follow_world_calibration(self, self.rig)
        self.site, _ = declare_site(self)
        self.sky_min_elevation = declare(
            self, 'sky.min_sweep_elevation_deg', 30.0,
            'Without a sun estimate, a goal is refused while the sun stands lower than this '
            'at the site (the simulated sweep estimated a 31 deg sun, not a 26.5 deg one; '
            'helio sky uses the same figure) [deg].', 0.0, 89.0)
        self.sky_spacing = declare(
            self, 'sky.reach_spacing', 0.01,
            "Spacing of the grid over a picture goal's canvas that must have a point within "
            'reach of the sun estimate, or the goal is refused [m].', 0.001, 0.1)
        self.heating_distance = declare(
            self, 'heating_distance', 0.082,
            'd_lp of a dot until a focal calibration arrives on calibration/focus (paper: '
            '8.2 cm) [m].', 0.02, 0.3)
        self.retreat_offset = declare(self, 'retreat_offset', 0.03,
                                      "Retreat delta d_lp after a dot (the paper's 3 cm) [m].",
                                      0.005, 0.2)
        self.cooling = declare(self, 'cooling', 'paper',
                               "Before the next dot: 'paper' waits until N_p is 0; 'window' "
                               'counts N_p only near the dot and goes on at once.',
                               choices=COOLING_RULES)
        self.window_radius = declare(self, 'window_radius', 0.004,
                                     'Radius of the N_p window around the dot (world) [m].',
                                     0.0005, 0.05)
        self.window_separation = declare(
            self, 'window_separation', 0.0075,
            'Window rule: dots burnt one after the other lie at least this far apart where the '
            "plan can (the last dot's hot region, about 2 mm around it, and a thermal pixel "
            "outside the next one's window); a next dot closer than this waits for N_p = 0 as "
            "the paper's rule does [m].", 0.0, 0.1)
        self.window_travel_offset = declare(
            self, 'window_travel_offset', 0.015,
            'Window rule: between dots the focus moves sideways this far beyond the heating '
            "distance instead of at the lens planner's travel_distance (the paper's retreat, "
            "which the window rule does not wait at); 1.5 cm puts 9 % of the heating peak's "
            'irradiance on the wood (simulated lens) [m].', 0.0, 0.2)
        self.max_heating = declare(self, 'max_heating', 90.0,
                                   'A dot held longer than this is given up (set at run time: '
                                   'from the next dot on) [s].', 1.0, 3600.0, dynamic=True)
        self.max_cooling = declare(self, 'max_cooling', 60.0,
                                   "Longest wait for N_p = 0 (paper's rule) [s].", 1.0, 3600.0)
        self.thermal_stale = declare(
            self, 'thermal_stale', 0.5,
            'Thermal statistics older than this (node clock) while the lens is at the heating '
            'distance: retreat, wait for them, heat the dot again [s].', 0.05, 10.0)
        self.thermal_stale_wall = declare(
            self, 'thermal_stale_wall', 2.0,
            'The same on the wall clock, so a stopped /clock cannot hold the lens [s].',
            0.1, 60.0)
        self.thermal_freeze_max = declare(
            self, 'thermal_freeze_max', 1.5,
            'Frozen thermal frames (a flat-field correction: the last frame again) are no '
            'fresh reading; heat on blind for at most this long (node clock), then treat the '
            "stream as stale [s] (a Lepton's freezes last 0.3-1 s).", 0.0, 10.0)
        self.thermal_back_timeout = declare(
            self, 'thermal_back_timeout', 30.0,
            'After a stale thermal stream, wait at most this long (wall clock) for it to come '
            'back before the painting stops [s].', 0.0, 3600.0)
        self.cloud_timeout = declare(self, 'cloud_timeout', 600.0,
                                     'Longest wait for the sun after a cloud [s].',
                                     1.0, 86400.0)
        self.sun_back_frames = declare(self, 'sun_back_frames', 5,
                                       'Valid spot observations in a row that say the sun is '
                                       'back [-].', 1, 100)
        self.calibrate_world = declare(self, 'calibrate_world', 'once',
                                       "Robot-world calibration before a painting: 'once' per "
                                       "node, 'always', or 'never'.",
                                       choices=('once', 'always', 'never'))
        self.calibrate_rig = declare(self, 'calibrate_rig', 'never',
                                     "Rig calibration before a painting: 'missing' (when no "
                                     'calibration of the rig as built has come on '
                                     "calibration/rig), 'always', or 'never' (the rig file "
                                     'and the robot-world calibration only).',
                                     choices=('missing', 'always', 'never'))
        self.server_timeout = declare(self, 'server_timeout', 60.0,
                                      'Wait at most this long for the lens planner (wall) [s].',
                                      0.1, 3600.0)
        self.runs_dir = os.path.abspath(os.path.expanduser(declare(
            self, 'runs_dir', 'runs', 'Where runs are written (a relative path is taken from '
            'the working directory).')))
        self.device_silence = declare(
            self, 'device_silence', 1.0,
            'A driver whose joint states stopped this long (wall clock, not counting time in '
            'which the painter itself did not run) is a device fault while heating [s].',
            0.1, 60.0)
        self.goal_accept_timeout = declare(
            self, 'goal_accept_timeout', 5.0,
            'A focus or wrist goal not accepted within this (wall clock) fails the painting, '
            'which then retreats: a killed server stays discovered for seconds and never '
            'answers [s].', 0.1, 600.0)
        self.retreat_retry_time = declare(
            self, 'retreat_retry_time', 10.0,
            'A retreat that failed every way (both devices at fault) is tried again for this '
            'long (wall clock), until one way works [s].', 0.0, 600.0)
        self.retreat_retry_period = declare(
            self, 'retreat_retry_period', 0.2,
            'Between those tries (wall clock) [s].', 0.01, 10.0)
        self.retreat_accept_timeout = declare(
            self, 'retreat_accept_timeout', 0.25,
            'A retreat goal not accepted within this (wall clock) goes to the next way of '
            'taking the focus off the wood: the lens planner, then the wrist; it counts '
            'against the 0.5 s in which the focus must be off [s].', 0.05, 10.0)
        self.wrist_turn = declare(self, 'wrist_escape_pitch', 0.6,
                                  'If the arm cannot retreat, turn the lens pitch by this to '
                                  'put the focus off the wood [rad].', 0.05, 1.5)
        self.arm_lift = declare(self, 'arm_escape_lift', 0.06,
                                'If the wrist cannot move, lift the lens straight up by this '
                                'with the arm alone (halved while a joint limit is in the '
                                'way): 3 cm leaves a quarter of the peak irradiance, 6 cm '
                                'about a tenth [m].', 0.005, 0.2)
        self.verify_dots = declare(
            self, 'verify_dots', True,
            'After each dot, with the lens retreated, the RGB camera checks that a dot of the '
            'expected size charred at the target (helio_perception.char_dots); the window '
            "rule's dots are verified only where it retreats.")
        self.verify_reheats = declare(
            self, 'verify_reheats', 1,
            'A dot the camera finds not charred is heated again at most this often, then '
            'counted as failed [-].', 0, 5)
        self.verify_timeout = declare(
            self, 'verify_timeout', 5.0,
            'Wait at most this long (wall clock) for an RGB frame after a dot, the camera '
            'subscribed to from then on; without one the dot is recorded as not verified '
            '[s].', 0.1, 60.0)
        self.char_settings = CharSettings(
            dark_ratio=declare(self, 'verify.dark_ratio', 0.6,
                               "Char: darker than this share of the bare wood's light around "
                               'the target [-].', 0.05, 0.95),
            min_diameter_ratio=declare(
                self, 'verify.min_diameter_ratio', 0.5,
                'A dot is charred when its char is at least this share of the expected '
                "diameter (the plan's dot pitch at the paper's N_p 30, scaled by the square "
                "root of the dot's N_p target over 30; set at run time: from the next look "
                'on) [-].',
                0.05, 2.0, dynamic=True),
            response=declare(self, 'verify.camera_response', 'srgb',
                             "The RGB camera's tone curve, undone before char is measured.",
                             choices=RESPONSES))
        self.calibration_dir = declare(
            self, 'calibration_dir', '', 'Where calibrations are read (empty: ~/.helio/'
            'calibration); its dots.yaml (helio calibrate dots) is read at each goal.') or \
            '~/.helio/calibration'
        self.add_post_set_parameters_callback(self._on_parameters_set)
        self.rgb_camera = None
        self._rgb_info_key = None
        self._frame_waiters = []       # (since [s], FirstOf) of the verifications waiting
        self.verified_dots = []
        self.create_subscription(CameraInfo, 'rgb/camera_info', self._on_rgb_info,
                                 qos_profile_sensor_data)
        # subscribed only while a verification waits for a frame (``_verify``): every RGB
        # frame taken is a megabyte copied out of DDS, 30 a second beside a world at 6x, and
        # the painter took a tenth of a core doing so while it heated
        self._frames = None

        self.sun_max_sigma = declare(
            self, 'sun_max_sigma', 0.2,
            'A sun estimate on sun/estimate is used when the larger standard deviation of '
            'its angles is at most this (the sweep gives 0.04-0.09 deg, its acquisition '
            'about 0.3 deg); otherwise the painting sweeps first [deg].', 0.0, 90.0)
        self.sun = None
        self.stats = None
        self.stats_wall = 0.0
        self.world_calibrated = False
        self.faults = {}
        self._stats_waiters = []
        self._live_stats_stamp = None   # the stamp of the last thermal frame not frozen [s]
        self._spot_waiters = []
        self._next_turn = NextTurn(self)
        self._busy = False
        self._thermal_interruptions = 0   # heatings broken off by a stale stream (this goal)
        self._cancel_requested = False
        self._stop_signal = ''             # why the node stops mid-painting ('' while not)
        self.interrupt_timeout = declare(
            self, 'interrupt_timeout', 5.0,
            'On Ctrl-C or SIGTERM, how long the running painting may take to put the focus '
            'off the wood before the node stops [s wall].', 0.0, 60.0)
        self._at_heating = None            # (target, d_lp) while the lens is focused on wood
        self.create_subscription(ThermalStats, 'thermal/stats', self._on_stats, RELIABLE)
        self.create_subscription(SunEstimate, 'sun/estimate', self._on_sun, LATCHED)
        self.create_subscription(FocalCalibration, 'calibration/focus', self._on_focus_cal,
                                 LATCHED)
        self.create_subscription(SpotObservation, 'spot', self._on_spot, RELIABLE)
        for device in ('dobot', 'servo'):
            self.create_subscription(DeviceStatus, f'{device}/status', self._on_status, LATCHED)
        # the drivers' joint states on the wall clock, the painter's own pauses not counted
        pause = min(LONGEST_RUN_GAP, 0.5 * self.device_silence)
        self.drivers = DriverSilence(self.device_silence, pause)
        self._silent_seen = set()          # the drivers silent at the last watch
        self.create_timer(pause / 5.0, self._watch_drivers,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.joints_now = {}               # every joint's latest position, by name [rad]
        self.create_subscription(JointState, 'joint_states', self._on_joints, 20)
        self.window_publisher = self.create_publisher(PointStamped, 'thermal/window', LATCHED)
        # the lens planner's focus lease (helio_optics.node_kit.focus_lease): while this heartbeat
        # lives, a lens left at the heating distance is the painter's to watch; a painter
        # killed outright stops it, and the lens planner retreats the lens
        # (issue 31) It beats on both clocks: on the node clock the simulated world holds at
        # most its lockstep lead ahead of the newest beat, so a painter starved of the CPU
        # does not leave the lens on the wood for simulated seconds while it cannot watch
        # (and the lease then does not expire for a painter that is merely slow); on the wall
        # clock it goes on while /clock pauses.
        self.heartbeat_publisher = self.create_publisher(Header, 'painter/heartbeat', 10)
        heartbeat_period = declare(
            self, 'heartbeat_period', 0.05,
            "Period of painter/heartbeat, the lens planner's focus lease, on the node clock "
            'and on the wall clock [s].', 0.01, 1.0)
        self.create_timer(heartbeat_period, self._beat)
        self.create_timer(heartbeat_period, self._beat,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.focus = ActionClient(self, FocusLens, 'focus')
        self.world = ActionClient(self, CalibrateWorld, 'calibrate_world')
        self.rig_calibration = ActionClient(self, CalibrateRig, 'calibrate_rig')
        self.sweep = ActionClient(self, SweepSun, 'sweep_sun')
        self.wrist = ActionClient(self, MoveWrist, 'move_wrist')
        self.arm = ActionClient(self, MoveArm, 'move_arm')   # the lift when the wrist is down
        self._focus_handles = []
        self.emergency = EmergencyStopListener(self, self._on_emergency_stop)
        ActionServer(self, PaintPattern, 'paint', self._execute,
                     goal_callback=lambda goal: GoalResponse.ACCEPT,
                     cancel_callback=self._on_cancel)
        self.get_logger().info(f'painter: heating {self.heating_distance * 100:.1f} cm, '
                               f'retreat {self.retreat_offset * 100:.1f} cm, cooling rule '
                               f'{self.cooling}, runs in {self.runs_dir}')

    # ---- inputs ---------------------------------------------------------------------------

    def _now(self):
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_stats(self, message):
        self.stats, self.stats_wall = message, time.monotonic()
        if not message.frozen:
            self._live_stats_stamp = stamp_to_seconds(message.header.stamp)
        for waiter in list(self._stats_waiters):
            waiter.offer(message)

    def _on_sun(self, message):
        # sun/estimate also carries the sweep's acquisition (4 spots, sigma about 0.3 deg,
        # 0.6 mm at the heating distance): a painting waits for an estimate this precise,
        # and sweeps for one if it has none
        sigma = math.degrees(math.sqrt(max(message.covariance[0], message.covariance[3])))
        if message.converged and sigma <= self.sun_max_sigma:
            self.sun = message

    def _on_focus_cal(self, message):
        if math.isfinite(message.heating_distance) and message.heating_distance > 0.0:
            self.heating_distance = message.heating_distance
            self.get_logger().info(f'heating distance from the focal calibration: '
                                   f'{self.heating_distance * 100:.2f} cm')

    def _on_spot(self, message):
        for waiter in list(self._spot_waiters):
            waiter(message)

    def _on_joints(self, message):
        device = 'servo' if 'lens_pitch' in message.name else 'dobot'
        self.drivers.heard(device, time.monotonic())
        self.joints_now.update(zip(message.name, message.position))

    def _watch_drivers(self):
        now = time.monotonic()
        pause = self.drivers.tick(now)
        if pause:
            self.get_logger().warning(
                f'the painter did not run for {pause:.2f} s (a starved or paused process): '
                "the drivers' silence is counted again from now")
        # a driver fallen silent wakes the heating loop at once (issue 30): it may wait on
        # thermal statistics that a world holding for that driver's joint states never sends
        silent = set(self.drivers.silent(now))
        if silent - self._silent_seen:
            self._wake_heating()
        self._silent_seen = silent

    def _silent_devices(self):
        """Return {device: sentence} of the drivers whose joint states stopped (wall clock)."""
        return {device: f'{device} silent for {seconds:.1f} s (no joint states: driver '
                        'stopped?)'
                for device, seconds in self.drivers.silent(time.monotonic()).items()}

    def _wake_heating(self):
        """Wake the heating loop's wait for thermal statistics: it checks and retreats."""
        for waiter in list(self._stats_waiters):
            waiter.offer(None)

    def _on_status(self, message):
        problem = ''
        if not message.connected:
            problem = f'{message.device} not connected ({message.message})'
        elif message.alarms:
            problem = f'{message.device} alarm: {", ".join(message.alarms)}'
        if problem:
            new = message.device not in self.faults
            self.faults[message.device] = problem
            if new:
                self._wake_heating()
        else:
            self.faults.pop(message.device, None)

    def _beat(self):
        beat = Header()
        beat.stamp = self.get_clock().now().to_msg()
        self.heartbeat_publisher.publish(beat)

    def _on_emergency_stop(self, engaged):
        """Engaged: end a running painting at once; the drivers take the focus off the wood."""
        if engaged and self._busy:
            self._stop_signal = 'the EMERGENCY STOP'
            self._cancel_requested = True
            self._wake_heating()

    def _on_cancel(self, _goal_handle):
        self._cancel_requested = True
        self._wake_heating()
        return CancelResponse.ACCEPT

    # ---- waits and moves ------------------------------------------------------------------

    async def _next_stats(self, stale_after=None):
        """
        Return the next thermal statistics, or None when they are stale (watchdog).

        Stale after ``thermal_stale`` of the node clock, or `stale_after` [s] if sooner (the
        rest of a frozen camera's ``thermal_freeze_max``), or ``thermal_stale_wall``.
        """
        waiter = FirstOf()
        self._stats_waiters.append(waiter)
        # stale on the node clock only once the statistics queued meanwhile were taken
        node_timer = self.create_timer(
            self.thermal_stale if stale_after is None else min(self.thermal_stale,
                                                               stale_after),
            lambda: self._next_turn.call(lambda: waiter.offer(None)))
        wall_timer = self.create_timer(self.thermal_stale_wall, lambda: waiter.offer(None),
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))
        try:
            return await waiter
        finally:
            self._stats_waiters.remove(waiter)
            self.destroy_timer(node_timer)
            self.destroy_timer(wall_timer)

    async def _server(self, client, name):
        try:
            await discovered(self, client.server_is_ready, self.server_timeout,
                             f'{name} (is the lens_planner running?)')
        except TimeoutError as error:
            raise PaintFailed(str(error)) from None

    async def _run_action(self, client, name, goal, urgent=False, last=False):
        """
        Send a goal and return its result (PaintFailed when refused).

        Every goal must be accepted within ``goal_accept_timeout`` of wall time (a killed
        server stays discovered for seconds and never answers; a lens left at the heating
        distance then goes to ``_retreat``). `urgent` (``_retreat``): no wait for a server
        that is not there, and ``retreat_accept_timeout`` instead: the retreat then turns to
        the next way at once, and a goal accepted after that is cancelled. The `last` way
        (the wrist's escape, the arm's lift) has no next: it gets ``goal_accept_timeout``, and
        a late acceptance is better than none (a killed node can stall the others' DDS
        writes for a second: the wrist's driver then goes silent and the arm's accepts late).
        """
        if not urgent:
            await self._server(client, name)
        elif not client.server_is_ready():
            raise PaintFailed(f'no {name} server (its node is gone)')
        # a killed server stays discovered for seconds and never answers: every goal must be
        # accepted within a bound, or the painting fails (and retreats) instead of waiting
        limit = self.retreat_accept_timeout if urgent and not last else self.goal_accept_timeout
        sent = client.send_goal_async(goal)
        if not await within(self, sent, limit, wall=True):
            if urgent and not last:
                # accepted after all, late (a loaded machine): cancelled, so that it does not
                # move the lens against the next way the painter takes
                sent.add_done_callback(_cancel_if_accepted)
            raise PaintFailed(f'{name} did not accept the goal within {limit:g} s (is its node '
                              'running?)')
        handle = sent.result()
        if not handle.accepted:
            raise PaintFailed(f'{name} refused the goal')
        self._focus_handles.append(handle)
        try:
            return (await handle.get_result_async()).result
        finally:
            self._focus_handles.remove(handle)

    async def _focus(self, target, d_lp, travel_d_lp=0.0, urgent=False):
        goal = FocusLens.Goal(d_lp=float(d_lp), travel_d_lp=float(travel_d_lp))
        goal.target.header.frame_id = 'world'
        goal.target.point.x, goal.target.point.y = float(target[0]), float(target[1])
        result = await self._run_action(self.focus, 'focus', goal, urgent)
        return result

    async def _retreat(self, why):
        """
        Put the focus off the wood; return what was done (never raises).

        A retreat that failed every way (``_retreat_once``: both devices at fault at that
        moment, e.g. the Dobot's link reset while the servo driver is dead) is tried again
        every ``retreat_retry_period`` of wall time, with the devices as they are then, for
        up to ``retreat_retry_time``: a lens is never left focused on the wood while a way
        may come back (a driver reconnects within a second of a link reset). Not under the
        emergency stop, whose drivers refuse every goal and turn the lens away themselves.
        """
        deadline = time.monotonic() + self.retreat_retry_time
        done = await self._retreat_once(why)
        first, tries = done, 1
        # not under the emergency stop: the drivers refuse every goal and take the focus off
        # the wood themselves
        while done.startswith(RETREAT_FAILED) and time.monotonic() < deadline \
                and self.context.ok() and not self.emergency.engaged:
            self.get_logger().warning(f'{done}: trying again', throttle_duration_sec=2.0)
            await sleep(self, self.retreat_retry_period, wall=True)
            done = await self._retreat_once(why)
            tries += 1
        return done if tries == 1 else f'{done} (at the try {tries}; the first: {first})'

    async def _retreat_once(self, why):
        """Put the focus off the wood the first way that works; say what was done."""
        if self._at_heating is None:
            return 'the lens was not at the heating distance'
        target, d_lp = self._at_heating
        arm_fault = self.faults.get('dobot') or self._silent_devices().get('dobot')
        wrist_fault = self.faults.get('servo') or self._silent_devices().get('servo')
        if wrist_fault and arm_fault:      # nothing can move the lens now: tried again
            return f'{RETREAT_FAILED}: {arm_fault}; {wrist_fault}'
        if wrist_fault:                    # the wrist cannot move: the arm lifts the lens
            return await self._lift(wrist_fault)
        if arm_fault:                     # the arm cannot move: straight to the wrist
            failure = arm_fault
        else:
            try:
                result = await self._focus(target, d_lp + self.retreat_offset, urgent=True)
                if result.success:
                    self._at_heating = None
                    return f'retreated ({why})'
                failure = result.message
            except PaintFailed as error:
                failure = str(error)
        # the arm cannot move: tilt the lens off the sun with the wrist, from where it is,
        # away from the pitch servo's nearer end (the lens axis leaves the sun ray)
        try:
            yaw = float(self.joints_now.get('lens_yaw', 0.0))
            pitch = escape_pitch(float(self.joints_now.get('lens_pitch', 0.0)), self.wrist_turn)
            result = await self._run_action(self.wrist, 'move_wrist',
                                            MoveWrist.Goal(yaw=yaw, pitch=pitch,
                                                           escape=True), urgent=True,
                                            last=True)
            if result.success:
                self._at_heating = None
                return f'the arm could not retreat ({failure}); the wrist turned the lens away'
            return f'{RETREAT_FAILED}: {failure}; the wrist: {result.message}'
        except PaintFailed as error:
            return f'{RETREAT_FAILED}: {failure}; the wrist: {error}'

    async def _lift(self, wrist_fault):
        """
        Lift the lens straight up (``arm_escape_lift``) with the arm alone; say what was done.

        The focus retreat of the lens planner moves the wrist too, and the wrist's driver is
        down: j1 kept and the flange level, the lens keeps its orientation and the focus
        rises off the wood (``rig_kinematics.escape_lift``).
        """
        names = ('dobot_j1', 'dobot_j2', 'dobot_j3')
        try:
            if not all(name in self.joints_now for name in names):
                raise UnreachableError('no Dobot joint states heard yet', joint='')
            joints = escape_lift(self.rig.arm, [self.joints_now[n] for n in names],
                                 self.arm_lift)
            goal = MoveArm.Goal(mode=MoveArm.Goal.MOVJ_ANGLE, target=[
                *(float(v) for v in joints), float(self.joints_now.get('dobot_j4', 0.0))])
            result = await self._run_action(self.arm, 'move_arm', goal, urgent=True, last=True)
        except (UnreachableError, PaintFailed) as error:
            return f'{RETREAT_FAILED}: {wrist_fault}; the arm could not lift the lens: {error}'
        if not result.success:
            return (f'{RETREAT_FAILED}: {wrist_fault}; the arm could not lift the lens: '
                    f'{result.message}')
        self._at_heating = None
        return f'the wrist could not move ({wrist_fault}); the arm lifted the lens'

    def _set_window(self, target):
        message = PointStamped()
        message.header.stamp = self.get_clock().now().to_msg()
        message.header.frame_id = 'world'
        if target is None:
            message.point.x = message.point.y = message.point.z = math.nan
        else:
            message.point.x, message.point.y = float(target[0]), float(target[1])
            message.point.z = float(self.window_radius)    # the radius rides in z [m]
        self.window_publisher.publish(message)

    async def _wait_for_sun(self, goal_handle, feedback):
        """Wait until the spot is seen in `sun_back_frames` frames in a row; return seconds."""
        started = self._now()
        seen = {'run': 0}
        back = FirstOf()

        def on_spot(message):
            seen['run'] = seen['run'] + 1 if message.valid else 0
            if seen['run'] >= self.sun_back_frames:
                back.offer(True)
        self._spot_waiters.append(on_spot)
        timer = self.create_timer(self.cloud_timeout, lambda: back.offer(False))
        cancel = self.create_timer(0.2, lambda: self._cancel_requested and back.offer(False))
        feedback.phase = 'waiting_for_sun'
        goal_handle.publish_feedback(feedback)
        try:
            returned = await back
        finally:
            self._spot_waiters.remove(on_spot)
            self.destroy_timer(timer)
            self.destroy_timer(cancel)
        if self._cancel_requested:
            raise PaintCanceled()
        if not returned:
            raise PaintFailed(f'the sun did not come back within {self.cloud_timeout:g} s')
        return self._now() - started

    # ---- the painting ---------------------------------------------------------------------

    async def _execute(self, goal_handle):
        result = PaintPattern.Result()
        if self._busy or self.emergency.engaged:
            result.message = (emergency_stop.refusal('paint goal') if self.emergency.engaged
                              else 'busy: another painting runs')
            goal_handle.abort()
            return result
        self._busy, self._cancel_requested, self._stop_signal = True, False, ''
        self._thermal_interruptions = 0
        self.verified_dots = []          # (index, DotMeasure) of every look of the camera
        wall_started = time.time()
        try:
            # under use_sim_time the clock reads 0 until the first /clock arrives: every
            # duration of the run would be counted from 1970
            await discovered(self, lambda: self._now() > 0.0, self.server_timeout,
                             'the clock (/clock, with use_sim_time)')
        except TimeoutError as error:
            self._busy = False
            result.message = str(error)
            goal_handle.abort()
            return result
        started = self._now()
        try:
            await self._paint(goal_handle, result)
            if result.success:
                goal_handle.succeed()
            else:
                goal_handle.abort()
        except (PaintCanceled, PaintFailed) as ended:
            if self.emergency.engaged:
                # no retreat: the drivers refuse every move now; they stopped the arm and the
                # servo driver turned the lens off the sun (node_kit.emergency_stop)
                self._at_heating = None
                result.message = 'stopped by the EMERGENCY STOP: the drivers stopped the ' \
                    'arm and turned the lens off the sun' + (f' ({ended})' if str(ended) else '')
                goal_handle.abort()
            elif isinstance(ended, PaintFailed):
                result.message = f'{ended}; {await self._retreat(str(ended))}'
                goal_handle.abort()
            elif self._stop_signal and not goal_handle.is_cancel_requested:
                # the node stopped (Ctrl-C, SIGTERM), not the client: the goal aborts
                result.message = (f'stopped by {self._stop_signal}: '
                                  + await self._retreat(self._stop_signal))
                goal_handle.abort()
            else:
                result.message = 'canceled: ' + await self._retreat('cancel')
                goal_handle.canceled()
        except Exception as error:           # a bug: retreat, then say what happened
            self.get_logger().error(traceback.format_exc())
            result.message = (f'internal error: {type(error).__name__}: {error}; '
                              f'{await self._retreat("internal error")}')
            goal_handle.abort()
        finally:
            self._set_window(None)
            self._busy = False
            result.duration = self._now() - started
            writer = getattr(self, '_journal', None)
            if writer is not None:
                writer.result(success=bool(result.success), dots_burnt=int(result.dots_burnt),
                              dots_skipped=int(result.dots_skipped),
                              duration=float(result.duration),
                              wall_duration=time.time() - wall_started, message=result.message)
                writer.close()
                self._journal = None
        if result.success:
            self.get_logger().info(f'paint: {result.message}')
        else:
            self.get_logger().warning(f'paint: {result.message}')
        return result

    def _check(self):
        if self._cancel_requested:
            raise PaintCanceled()
        faults = list(self.faults.values()) + list(self._silent_devices().values())
        if faults:
            raise PaintFailed('device fault: ' + '; '.join(faults))

    async def _prepare(self, goal_handle, feedback):
        """Calibrate the rig or the world, estimate the sun when needed (Alg. 1 lines 1-2)."""
        if self.calibrate_rig == 'always' or (self.calibrate_rig == 'missing'
                                              and not self.rig.calibrations_applied):
            feedback.phase = 'calibrating'
            goal_handle.publish_feedback(feedback)
            taken = self.rig.calibrations_applied
            rig = await self._run_action(self.rig_calibration, 'calibrate_rig',
                                         CalibrateRig.Goal(apply=True))
            if not rig.success:
                raise PaintFailed(f'rig calibration failed: {rig.message}')
            # planned with the calibrated rig only: its calibration/rig message may come
            # after the result
            await discovered(self, lambda: self.rig.calibrations_applied > taken,
                             self.server_timeout, 'the rig calibration on calibration/rig')
            self.world_calibrated = True
            if rig.estimate.converged and not rig.estimate.ambiguous:
                self.sun = rig.estimate
        elif self.calibrate_world == 'always' or (self.calibrate_world == 'once'
                                                  and not self.world_calibrated):
            feedback.phase = 'calibrating'
            goal_handle.publish_feedback(feedback)
            world = await self._run_action(self.world, 'calibrate_world',
                                           CalibrateWorld.Goal(apply=True))
            if not world.success:
                raise PaintFailed(f'robot-world calibration failed: {world.message}')
            self.world_calibrated = True
        self._check()
        if self.sun is None:
            feedback.phase = 'estimating_sun'
            goal_handle.publish_feedback(feedback)
            sweep = await self._run_action(self.sweep, 'sweep_sun', SweepSun.Goal())
            if not sweep.success:
                raise PaintFailed(f'sun estimation failed: {sweep.message}')
            self.sun = sweep.estimate
        self._check()

    def _refuse_what_the_sun_cannot_serve(self, goal):
        """Raise PaintFailed when the sun cannot serve `goal` now (see the module: the sky)."""
        now = datetime.datetime.fromtimestamp(self._now(), datetime.timezone.utc)
        if self.sun is None:
            refusal = sky.sweep_refusal(self.site, now, self.sky_min_elevation)
        else:
            options = options_from_goal(goal)
            points = [[p.x, p.y] for p in goal.points] if goal.points else sky.canvas_points(
                options.offset_x, options.offset_y, options.canvas_size, self.sky_spacing)
            estimated = stamp_to_seconds(self.sun.header.stamp)
            refusal = sky.reach_refusal(
                self.rig, points, point_to_array(self.sun.direction), self.heating_distance,
                self.retreat_offset, self.site, now, self.sky_min_elevation,
                ray_time=datetime.datetime.fromtimestamp(estimated, datetime.timezone.utc)
                if estimated > 0.0 else None)
        if refusal is not None:
            raise PaintFailed(f'refused: {refusal}')

    def _make_plan(self, goal):
        try:
            dot_size, note = dot_size_for_painting(self.calibration_dir, self.rig_file)
            if note:
                self.get_logger().warning(note)
            options = options_for_dot_size(options_from_goal(goal), dot_size, goal.n_p_target > 0)
            options.d_lp, options.retreat = self.heating_distance, self.retreat_offset
            if (goal.cooling or self.cooling) == 'window':
                options.min_separation = self.window_separation     # no hot neighbour next
                options.cooling_wait = False                        # and no wait
            sun = point_to_array(self.sun.direction)
            if goal.points:
                points = np.array([[p.x, p.y] for p in goal.points], dtype=float)
                return plan_dots(points, options, self.rig, sun, dot_size=dot_size)
            picture = goal.image_path if goal.image_path else \
                picture_from_image_msg(goal.image)
            return plan_picture(picture, options, self.rig, sun, dot_size=dot_size)
        except (PictureError, PlanError, PlanOptionsError, ValueError) as error:
            raise PaintFailed(f'cannot plan the painting: {error}') from None

    async def _paint(self, goal_handle, result):
        goal = goal_handle.request
        feedback = PaintPattern.Feedback(phase='planning')
        began = self._now()
        # check the goal before anything moves
        sources = [bool(goal.image_path), goal.image.width > 0, len(goal.points) > 0]
        if sum(sources) != 1:
            raise PaintFailed('give exactly one source of dots: image_path, image or points '
                              f'(got {sum(sources)})')
        if goal.image_path and not goal.image_path.startswith('sample:') \
                and not os.path.isfile(goal.image_path):
            raise PaintFailed(f"image_path {goal.image_path!r}: no such file on the painter's "
                              'machine (or sample:NAME for a picture the project makes)')
        if goal.cooling and goal.cooling not in COOLING_RULES:
            raise PaintFailed(f'cooling must be one of {COOLING_RULES} or empty, got '
                              f'{goal.cooling!r}')
        try:
            options_from_goal(goal).validate()
        except PlanOptionsError as error:
            raise PaintFailed(f'bad goal: {error}') from None
        key = goal_key(goal)
        self._refuse_what_the_sun_cannot_serve(goal)      # no sweep for a sun too low
        await self._prepare(goal_handle, feedback)
        self._refuse_what_the_sun_cannot_serve(goal)      # nor a canvas out of its reach
        resumed = None if goal.fresh else unfinished_run(self.runs_dir, key)
        if resumed is not None:
            try:
                with open(os.path.join(resumed[0], 'plan.json')) as stream:
                    plan = Plan.from_json(stream.read())
            except (OSError, ValueError, KeyError) as error:
                raise PaintFailed(f'cannot resume {resumed[0]}: {error}') from None
            burnt = resumed[1]
        else:
            plan = self._make_plan(goal)
            burnt = set()
        run_dir = os.path.abspath(goal.run_dir) if goal.run_dir else os.path.join(
            self.runs_dir, datetime.datetime.now(datetime.timezone.utc).strftime(
                '%Y%m%dT%H%M%SZ'))
        os.makedirs(run_dir, exist_ok=True)
        with open(os.path.join(run_dir, 'plan.json'), 'w') as stream:
            stream.write(plan.to_json())
        with open(os.path.join(run_dir, 'resume.json'), 'w') as stream:
            json.dump({'goal_key': key, 'burnt_before': sorted(burnt),
                       'resumed_from': resumed[0] if resumed else ''}, stream)
        self._journal = JournalWriter(os.path.join(run_dir, 'journal.jsonl'))
        self._journal.run(goal, began, time.time())
        result.run_dir = run_dir
        result.dots_planned = len(plan.dots)
        result.dots_resumed = len(burnt)
        if not len(plan.dots):
            raise PaintFailed('the plan has no dot: ' + '; '.join(
                f'{reason}' for _, reason in plan.rejected[:3]) if plan.rejected else
                'the plan has no dot')
        cooling = goal.cooling or self.cooling
        per_dot = plan.time_estimate.get('per_dot_s', 0.0)
        todo = [i for i in range(len(plan.dots)) if i not in burnt and i >= goal.start_index]
        result.time_estimated = per_dot * len(todo)
        result.dots_skipped = len(plan.dots) - len(todo) - len(burnt)
        feedback.total = len(plan.dots)
        cycles = []
        failed = 0
        for i in range(len(plan.dots)):
            if i not in todo:
                continue
            self._check()
            target = plan.dots[i]
            n_p_target = int(plan.n_p_targets[i])
            remaining = len(todo) - todo.index(i)
            mean = float(np.mean(cycles)) if cycles else per_dot
            feedback.index = i
            feedback.elapsed = self._now() - began
            feedback.eta = mean * remaining
            # the window rule goes on at once, but not into this dot's hot region
            later = [j for j in todo if j > i]
            hot_next = cooling == 'window' and bool(later) and float(np.hypot(
                *(plan.dots[later[0]] - target))) < self.window_separation
            expected, neighbours = expected_dot(plan, i)
            outcome = await self._paint_dot(goal_handle, feedback, i, target, n_p_target,
                                            cooling, goal.dry_run, result, hot_next,
                                            expected, neighbours)
            cycles.append(outcome['end'] - outcome['start'])
            self._journal.dot(**outcome)
            if outcome['outcome'] == 'burnt':
                result.dots_burnt += 1
            elif outcome['outcome'] == 'failed':
                failed += 1
            else:
                result.dots_skipped += 1
        if self._at_heating is not None:              # the window rule's last dot
            retreated = await self._retreat('the painting is done')
            if not retreated.startswith('retreated'):
                raise PaintFailed(f'after the last dot: {retreated}')
        feedback.phase, feedback.index = 'done', len(plan.dots)
        goal_handle.publish_feedback(feedback)
        if goal.dry_run:
            result.success = failed == 0
            result.message = (f'dry run: {len(todo) - failed} of {len(todo)} dots reached at '
                              'the retreat distance')
        else:
            result.success = failed == 0
            result.message = f'{result.dots_burnt} dots burnt'
        result.message += (f' in {self._now() - began:.0f} s (the plan estimated '
                           f'{result.time_estimated:.0f} s); {result.dots_resumed} burnt '
                           f'before, {result.dots_skipped} skipped, {failed} failed, of '
                           f'{len(plan.dots)}; waited {result.cloud_wait:.0f} s for the '
                           f'sun; run in {run_dir}')
        if plan.rejected:
            result.message += f'; {len(plan.rejected)} picture dots left out by the plan'
        if self._thermal_interruptions:
            result.message += (f'; {self._thermal_interruptions} heating(s) broken off by a '
                               'stale thermal stream and done again')
        if self.verify_dots and not goal.dry_run:
            seen = sum(measure.charred for _, measure in self.verified_dots)
            result.message += (f'; {seen} dots verified by the camera, '
                               f'{len(self.verified_dots) - seen} looks found no dot')

    async def _paint_dot(self, goal_handle, feedback, index, target, n_p_target, cooling,
                         dry_run, result, hot_next=False, expected=0.0, neighbours=()):
        """
        Burn one dot and verify it with the RGB camera; return its journal record's fields.

        The dot is heated (``_heat_dot``); once the lens is retreated (the paper's cooling
        rule, or a window-rule dot whose next one lies in its hot region) the camera's
        verdict (``_verify``) is recorded, a dot given up too; a dot burnt that it finds not
        charred (nothing dark of at least ``verify.min_diameter_ratio`` of `expected` [m] at
        the target) is heated again, at most ``verify_reheats`` times, then counted as
        failed. The lens is retreated
        through all of it: a failed verification leaves it where the heating left it, off
        the wood.
        """
        record = await self._heat_dot(goal_handle, feedback, index, target, n_p_target,
                                      cooling, dry_run, result, hot_next)
        record.update(verdict='', verdict_reason='', measured_diameter=0.0, reheats=0)
        if dry_run or not self.verify_dots or not record['dwell'] > 0.0:
            return record             # nothing heated: nothing to see
        while True:
            if self._at_heating is not None:
                record['verdict_reason'] = 'not verified: the lens is not retreated'
                return record
            feedback.phase = 'verifying'
            goal_handle.publish_feedback(feedback)
            began, wall = self._now(), time.monotonic()
            measure, why = await self._verify(target, expected, neighbours)
            self.get_logger().info(
                f'dot {index}: the camera looked in {self._now() - began:.2f} s '
                f'({time.monotonic() - wall:.2f} s wall): '
                + (why if measure is None else
                   f'{measure.diameter * 1e3:.2f} mm, {measure.reason or "charred"}'))
            if measure is None:
                self.get_logger().warning(f'dot {index} not verified: {why}')
                record['verdict_reason'] = f'not verified: {why}'
                return record
            self.verified_dots.append((index, measure))
            record.update(verdict='charred' if measure.charred else 'not charred',
                          verdict_reason=measure.reason,
                          measured_diameter=float(measure.diameter))
            if measure.charred or record['outcome'] != 'burnt':
                return record         # a dot given up (max_heating) is not heated again
            if record['reheats'] >= self.verify_reheats:
                record.update(outcome='failed', reason=(
                    f'the RGB camera sees no dot at the target ({measure.reason}) after '
                    f"{record['reheats'] + 1} heating(s)"))
                return record
            self.get_logger().warning(f'dot {index}: the RGB camera sees no dot '
                                      f'({measure.reason}): heated again')
            again = await self._heat_dot(goal_handle, feedback, index, target, n_p_target,
                                         cooling, dry_run, result, hot_next)
            record.update(reheats=record['reheats'] + 1, end=again['end'],
                          dwell=record['dwell'] + again['dwell'],
                          restarts=record['restarts'] + again['restarts'],
                          peak_n_p=max(record['peak_n_p'], again['peak_n_p']),
                          t_max=max(record['t_max'], again['t_max']))
            if again['outcome'] != 'burnt':
                record.update(outcome=again['outcome'], reason=again['reason'])
                return record

    async def _verify(self, target, expected, neighbours):
        """
        Measure the dot at `target` in the first RGB frame taken from now on.

        Return (``char_dots.DotMeasure``, '') or (None, why not: no camera_info, no frame
        within ``verify_timeout`` of wall time, no joint states). The frame's camera pose is
        the joints' (at rest, retreated) through the rig and the robot-world calibration.
        """
        if self.rgb_camera is None:
            return None, 'no rgb/camera_info'
        names = JOINT_NAMES
        if not all(name in self.joints_now for name in names):
            return None, 'no joint states'
        since = self._now()
        waiter = FirstOf()
        if self._frames is None:
            # raw: a frame is decoded only when a verification waits for it
            self._frames = self.create_subscription(Image, 'rgb/image_raw', self._on_frame,
                                                    qos_profile_sensor_data, raw=True)
        self._frame_waiters.append((since, waiter))
        timer = self.create_timer(self.verify_timeout, lambda: waiter.offer(None),
                                  clock=Clock(clock_type=ClockType.STEADY_TIME))
        try:
            frame = await waiter
        finally:
            self._frame_waiters.remove((since, waiter))
            self.destroy_timer(timer)
            if not self._frame_waiters and self._frames is not None:
                self.destroy_subscription(self._frames)
                self._frames = None
        self._check()
        if frame is None:
            return None, f'no RGB frame within {self.verify_timeout:g} s'
        pose = self.rig.forward(np.array([self.joints_now[name] for name in names]))
        T_world_rgb = invert_transform(self.rig.parameters.T_robot_world) @ pose.T_robot_rgb
        try:
            return measure_in_image(image_to_numpy(frame), self.rgb_camera, T_world_rgb,
                                    target, expected, neighbours, self.char_settings), ''
        except (ImageConversionError, ValueError) as error:
            return None, f'the frame cannot be measured: {error}'

    def _on_frame(self, raw):
        """Take a raw RGB frame: decoded only when a verification waits for it."""
        if not self._frame_waiters:
            return
        message = deserialize_message(raw, Image)
        stamp = stamp_to_seconds(message.header.stamp)
        for since, waiter in list(self._frame_waiters):
            if stamp >= since:
                waiter.offer(message)

    def _on_parameters_set(self, parameters):
        """Take the parameters set at run time (``max_heating``, ``verify.*``)."""
        for parameter in parameters:
            if parameter.name == 'max_heating':
                self.max_heating = float(parameter.value)
            elif parameter.name == 'verify.min_diameter_ratio':
                self.char_settings = replace(self.char_settings,
                                             min_diameter_ratio=float(parameter.value))

    def _on_rgb_info(self, message):
        key = (tuple(message.k), tuple(message.d), message.width, message.height)
        if key != self._rgb_info_key:
            try:
                self.rgb_camera = camera_from_info(message)
            except ValueError:
                self.rgb_camera = None
            self._rgb_info_key = key

    async def _heat_dot(self, goal_handle, feedback, index, target, n_p_target, cooling,
                        dry_run, result, hot_next=False):
        """
        Burn one dot (Algorithm 1 lines 6-14); return its journal record's fields.

        `hot_next`: with the window rule, the next dot lies in this one's hot region, so
        this dot retreats and waits for N_p = 0 in its window before the next begins.
        """
        start = self._now()
        record = {'index': int(index), 'target': [float(target[0]), float(target[1])],
                  'n_p_target': n_p_target, 'start': start, 'end': start, 'dwell': 0.0,
                  'peak_n_p': 0, 't_max': -273.15, 'outcome': 'burnt', 'reason': '',
                  'restarts': 0}
        d_heat = self.heating_distance
        if dry_run:
            feedback.phase = 'moving'
            goal_handle.publish_feedback(feedback)
            moved = await self._focus(target, d_heat + self.retreat_offset)
            record.update(end=self._now(), outcome='skipped' if moved.success else 'failed',
                          reason='dry run' if moved.success else moved.message)
            return record
        settings = CycleSettings(n_p_target=n_p_target, max_heating=self.max_heating,
                                 max_cooling=self.max_cooling,
                                 wait_for_zero=(cooling == 'paper' or hot_next))
        cycle = DotCycle(settings)
        window = cooling == 'window'
        self._set_window(target if window else None)
        while True:                                   # again after a cloud
            feedback.phase = 'moving'
            goal_handle.publish_feedback(feedback)
            moved = await self._focus(target, d_heat, (d_heat + self.window_travel_offset)
                                      if window and self.window_travel_offset > 0.0 else 0.0)
            if not moved.success:
                if self._at_heating is not None:      # the last dot's heating pose
                    self.get_logger().warning(await self._retreat('the move failed'))
                record.update(end=self._now(), outcome='failed', reason=moved.message)
                return record
            self._at_heating = (target, d_heat)
            cycle.start_heating(self._now())
            feedback.phase = 'heating'
            decision = Decision.HEAT
            stale = ''                 # why the watchdog retreated, if it did
            blind_since = None         # window rule: since when the window had no figures
            frozen = False             # the camera repeats its last frame
            n_p, t_max = 0, 0.0        # the last reading (none yet)
            while decision is Decision.HEAT:
                # a frozen camera (flat-field correction) holds its output: no reading, and
                # no reason to fail the dot; blind for at most thermal_freeze_max from the
                # last live frame, then a stale stream
                budget = None
                if frozen:
                    live = self._live_stats_stamp
                    budget = -1.0 if live is None else \
                        live + self.thermal_freeze_max - self._now()
                stats = None if budget is not None and budget <= 0.0 else \
                    await self._next_stats(budget)
                self._check()
                if stats is None:
                    # the watchdog: off the wood, below
                    stale = (f'the thermal camera frozen for more than '
                             f'{self.thermal_freeze_max:g} s' if frozen
                             else 'no thermal statistics')
                    break
                frozen = stats.frozen
                if frozen:
                    decision = cycle.update_unread(self._now())      # max_heating only
                    continue
                if window and not stats.window_valid:
                    # no thermal camera pose for this image (joint states too far from its
                    # stamp): no window reading. The image is fresh, and the window lies in
                    # it, so the dot cannot be done while the whole image's N_p is below its
                    # target: heat on. Otherwise the image's N_p (the last dot's afterglow
                    # too) says nothing, and no reading for longer than thermal_stale is a
                    # stale stream (watchdog)
                    n_p, t_max = _readings(stats, window)          # the image's
                    record['t_max'] = max(record['t_max'], float(t_max))
                    if n_p < n_p_target:
                        blind_since = None
                        decision = cycle.update_unread(self._now())   # max_heating only
                        continue
                    blind_since = self._now() if blind_since is None else blind_since
                    if self._now() - blind_since > self.thermal_stale:
                        stale = 'no window reading (thermal camera pose unknown)'
                        break
                    continue
                blind_since = None
                n_p, t_max = _readings(stats, window)
                feedback.n_p, feedback.t_max = int(n_p), float(t_max)
                goal_handle.publish_feedback(feedback)
                record['t_max'] = max(record['t_max'], float(t_max))
                decision = cycle.update(self._now(), n_p, t_max, stats.camera_cap)
            if window and not hot_next and decision is Decision.RETREAT:
                # the window rule moves on at once: the move to the next dot begins with
                # the retreat along the sun ray (lens_moves), so no separate retreat here;
                # after the last dot, or when anything stops the painting, _paint retreats
                decision = cycle.update(self._now(), n_p, t_max, stats.camera_cap)
                break
            retreat = await self._focus(target, d_heat + self.retreat_offset)
            if not retreat.success:
                raise PaintFailed(f'the retreat after dot {index} failed: {retreat.message}')
            self._at_heating = None
            if stale:
                self.get_logger().error(
                    f'dot {index}: thermal statistics stale for more than '
                    f'{self.thermal_stale:g} s while heating ({stale}): retreated; waiting '
                    'for them')
                await self._wait_for_thermal(index)
                self._thermal_interruptions += 1
                record['restarts'] += 1
                cycle.restart()
                continue
            if decision is Decision.CLOUD:
                self.get_logger().warning(f'dot {index}: sun lost ({cycle.cloud_reason}); '
                                          'waiting for it')
                result.cloud_wait += await self._wait_for_sun(goal_handle, feedback)
                record['restarts'] += 1
                cycle.restart()
                continue
            break
        record.update(dwell=float(cycle.heating_time), peak_n_p=int(cycle.peak_n_p))
        if cycle.outcome != 'charred':
            record.update(outcome='failed', reason=f'N_p reached only {cycle.peak_n_p} of '
                          f'{n_p_target} in {self.max_heating:g} s (max_heating)')
        feedback.phase = 'cooling'
        goal_handle.publish_feedback(feedback)
        while decision is not Decision.NEXT:
            stats = await self._next_stats()
            self._check()
            if stats is None:
                break                  # retreated already: a stale stream ends the wait
            if stats.frozen:
                continue               # no reading (flat-field correction)
            n_p, t_max = _readings(stats, window)
            feedback.n_p, feedback.t_max = int(n_p), float(t_max)
            goal_handle.publish_feedback(feedback)
            decision = cycle.update(self._now(), n_p, t_max, stats.camera_cap)
        record['end'] = self._now()
        return record

    async def _wait_for_thermal(self, index):
        """Wait (lens retreated) for fresh thermal statistics; PaintFailed after the timeout."""
        deadline = time.monotonic() + self.thermal_back_timeout
        while time.monotonic() < deadline:
            stats = await self._next_stats()
            self._check()
            if stats is not None and not stats.frozen:
                return
        raise PaintFailed(f'thermal statistics stale for more than {self.thermal_stale:g} s '
                          f'while heating dot {index}, and not back within '
                          f'{self.thermal_back_timeout:g} s')

    async def on_interrupt(self):
        """
        Ctrl-C or SIGTERM of this node: end a running painting as a cancel does, then stop.

        ``run_node`` runs this before the node goes (issue 30: a stop signal used to end the
        node at once, the lens left heating; the graph's stop signals the painter first and
        the lens planner, which carries the retreat out, after it). The painting's retreat
        is awaited for at most ``interrupt_timeout`` [s wall].
        """
        if not self._busy:
            return
        self._stop_signal = 'a stop signal'
        self._cancel_requested = True
        self._wake_heating()
        while self._busy:
            await sleep(self, 0.02, wall=True)

    def destroy_node(self):
        """Leave the lens off the wood if a painting is cut short (best effort)."""
        if self._at_heating is not None:
            target, d_lp = self._at_heating
            goal = FocusLens.Goal(d_lp=float(d_lp + self.retreat_offset))
            goal.target.header.frame_id = 'world'
            goal.target.point.x, goal.target.point.y = float(target[0]), float(target[1])
            if self.focus.server_is_ready():
                self.focus.send_goal_async(goal)
                self.get_logger().warning('stopping while heating: retreat sent')
        return super().destroy_node()


def _readings(stats, window):
    """Return (N_p, T_max) of the window when it is used and valid, else of the image."""
    if window and stats.window_valid:
        return stats.window_n_p, stats.window_t_max
    return stats.n_p, stats.t_max


def main(args=None):
    """Run the painter node."""
    run_node(PainterNode, args)


if __name__ == '__main__':
    main()
