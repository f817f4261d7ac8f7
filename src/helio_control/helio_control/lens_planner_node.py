"""
Node lens_planner: place the lens so the focus lands on a point, and calibrate the rig.

Actions (one goal at a time across all four; a second is aborted with "busy"):

- ``focus`` (helio_msgs/FocusLens, paper Eqs 14-15): world target + d_lp -> the lens pose
  from the sun estimate (``sun/estimate``, kept current by Eq 18), corrected so the spot's
  power centre (not only the lens axis) lands on the target (``FocusTargeting``) -> the five
  joints by the rig's inverse kinematics -> ``move_arm`` and ``move_wrist`` together, in legs
  that keep the focus off the wood while it travels (``lens_moves``: retreat, travel at the
  travel distance, approach). The result holds the pose reached (forward kinematics of the
  joints the drivers report) and its distance from the commanded one.
- ``calibrate_world`` (CalibrateWorld, Sec. II-B): poses from which the RGB camera sees the
  marker; each marker pose with the kinematic camera pose gives T_robot_world
  (``world_calibration``); published on ``calibration/world_pose`` (transient local), saved,
  and used from then on by this node (and every node that follows the topic).
- ``sweep_sun`` (SweepSun, Sec. V-B): acquire the spot when there is no estimate (the
  ephemeris' elevation, a ring of azimuth guesses; the first spot seen gives a coarse sun,
  its pose's lens model solved for it: ``sun_sweep.coarse_sun``), sweep poses that change
  the geometry (``sun_sweep``), call ``estimate_sun`` on the sweep's spots.
- ``calibrate_focus`` (CalibrateFocus, Sec. V-A): lens aligned with the estimated sun, d_lp
  swept, A_c from the spot detector, fit (``helio_optics.focal_calibration``); the heating
  distance published on ``calibration/focus`` (transient local) and saved; the lens model's
  focal length is scaled so its focus falls where the sweep found it.

Every goal is checked first: no sun estimate, a non-finite or unreachable target (which
joint, by how much), no joint states: the goal is aborted at once with the reason. A cancel
cancels the driver goals (the drivers stop the arm and hold the servos) and ends the goal.

Execute callbacks are coroutines that await the driver actions, the estimator service, the
spot stream and node-clock timers; nothing blocks, and the node runs in a plain
``rclpy.spin`` (one thread).
"""

from dataclasses import dataclass, replace
import datetime
import math
import os
import time
import traceback

from action_msgs.msg import GoalStatus
from geometry_msgs.msg import PoseStamped
from helio_control import lens_moves, rig_calibration, sun_sweep
from helio_control.calibration_store import CalibrationRefused, load_calibration
from helio_control.calibration_store import rig_description, save_calibration
from helio_control.world_calibration import estimate_world_in_robot, marker_poses
from helio_msgs.action import (CalibrateFocus, CalibrateRig, CalibrateWorld, FocusLens,
                               MoveArm, MoveWrist, SweepSun)
from helio_msgs.msg import FocalCalibration, LensPose, SpotObservation, SunEstimate
from helio_msgs.srv import EstimateSun
from helio_optics.ephemeris import angle_offsets, sun_position
from helio_optics.focal_calibration import calibrate_focus
from helio_optics.focus_targeting import FocusTargeting
from helio_optics.geometry import transform_points
from helio_optics.node_kit import emergency_stop
from helio_optics.node_kit.awaitables import discovered, FirstOf, in_thread, sleep, within
from helio_optics.node_kit.conversions import array_to_point, camera_from_info
from helio_optics.node_kit.conversions import matrix_to_pose, point_to_array, pose_to_matrix
from helio_optics.node_kit.conversions import stamp_from_seconds, stamp_to_seconds
from helio_optics.node_kit.deployment import declare_lens, declare_rig, declare_site
from helio_optics.node_kit.deployment import follow_world_calibration, RIG_CALIBRATION_TOPIC
from helio_optics.node_kit.emergency_stop import EmergencyStopListener
from helio_optics.node_kit.focus_lease import CLEAR, declare_lease, HEATING, HEATING_TOPIC
from helio_optics.node_kit.joint_states import JointStateBuffer
from helio_optics.node_kit.parameters import declare
from helio_optics.node_kit.qos import LATCHED, reliable
from helio_optics.node_kit.runner import run_node
from helio_optics.rig_kinematics import Rig
from helio_optics.spot import spot_area_at, SpotModel
import numpy as np
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, JointState
from std_msgs.msg import Header, String
import yaml

RELIABLE = reliable(50)


class GoalFailed(Exception):
    """A procedure cannot go on; the message is the goal's result message."""


class GoalCanceled(Exception):
    """The goal was canceled while it ran."""


class _Unattended:
    """The goal handle of a move no client asked for (the lease's retreat): never canceled."""

    is_cancel_requested = False


UNATTENDED = _Unattended()


class SpotWaiter:
    """Collects the spot observations stamped after `after` until `count` arrived."""

    def __init__(self, after, count, accept):
        self.after, self.count, self.accept = after, count, accept
        self.messages = []
        self.refused = {}              # reason -> count, for the log
        self.future = FirstOf()

    def offer(self, message):
        """Take a spot observation; complete the future when enough were taken."""
        if self.future.done() or stamp_to_seconds(message.header.stamp) <= self.after:
            return
        if self.accept(message):
            self.messages.append(message)
        else:
            reason = message.reason or 'not accepted'
            self.refused[reason] = self.refused.get(reason, 0) + 1
        if len(self.messages) >= self.count:
            self.future.offer(self.messages)


class LensPlannerNode(Node):
    """See the module docstring."""

    def __init__(self, **kwargs):
        """Declare parameters, load the rig and lens models, open the interfaces."""
        super().__init__('lens_planner', **kwargs)
        self.rig, rig_file = declare_rig(self)
        self.lens, lens_file = declare_lens(self)
        self.site, _ = declare_site(self)
        self.heating_distance = declare(
            self, 'heating_distance', 0.082,
            'd_lp at which a dot is heated until the focal calibration says otherwise '
            '(paper: 8.2 cm) [m].', 0.02, 0.3)
        self.travel_distance = declare(
            self, 'travel_distance', 0.112,
            "d_lp at which the lens travels between points (heating distance + the paper's "
            'retreat of 3 cm), so the focus never sweeps the wood [m].', 0.02, 0.4)
        self.safe_margin = declare(
            self, 'safe_margin', 0.015,
            'The focus moves sideways only this far or farther from the heating distance '
            '(where the retreat distance is out of reach, such a distance is taken) [m].',
            0.002, 0.1)
        self.same_point = declare(self, 'same_point', 0.001,
                                  'Moves that shift the focus less than this on the panel go '
                                  'straight along the sun ray [m].', 0.0, 0.05)
        self.server_timeout = declare(
            self, 'server_timeout', 30.0,
            'Wait at most this long for the driver actions and estimate_sun to be discovered '
            '(wall clock) [s].', 0.1, 600.0)
        self.startup_wait = declare(
            self, 'startup_wait', 5.0,
            'For this long after the start, a focus goal waits for the sun estimate and the '
            "joint states (a lens planner started again after the sweep: the sun estimator's "
            "latched estimate and the drivers' joint states come once the nodes have "
            'discovered each other) (wall clock) [s].', 0.0, 60.0)
        self._started = time.monotonic()
        self.joint_state_max_age = declare(
            self, 'joint_state_max_age', 5.0,
            'The present joints must be younger than this (node clock) [s], unless their '
            'message came within joint_state_max_wall_age.', 0.01, 60.0)
        self.joint_state_max_wall_age = declare(
            self, 'joint_state_max_wall_age', 1.0,
            'Joints older than joint_state_max_age are still present while their driver was '
            'heard within this much wall time [s]: the drivers publish at a wall-clock rate, '
            'beside a simulated world that may run far faster.', 0.01, 60.0)
        self.joint_state_tolerance = declare(
            self, 'joint_state_tolerance', 0.3,
            'Largest gap between an image stamp and the joint state used with it (node '
            'clock) [s].', 0.001, 10.0)
        self.focus_rays = declare(self, 'focus_rays', 3000,
                                  'Rays per spectral band of the focus model [-].', 100, 100000)
        self.marker_side = declare(self, 'marker_side', 0.04,
                                   "Side of the ArUco marker's black square [m].", 0.001, 1.0)
        self.view_margin = declare(self, 'view_margin', 30.0,
                                   'Marker and spot must lie this far inside the image '
                                   '[px].', 0.0, 500.0)
        self.observe_frames = declare(self, 'observe_frames', 4,
                                      'Spot observations collected per pose [-].', 1, 100)
        self.observe_timeout = declare(self, 'observe_timeout', 10.0,
                                       'Longest wait for them (node clock) [s].', 0.1, 600.0)
        self.settle_time = declare(self, 'settle_time', 0.3,
                                   'Wait after a move before observing (node clock) [s].',
                                   0.0, 10.0)
        self.view_points = sun_sweep.view_points(
            declare(self, 'panel_extent', [-0.04, 0.16, -0.04, 0.16],
                    'The wood panel around the marker: x_min, x_max, y_min, y_max, world '
                    'frame [m]; the calibrations aim at points of it.'),
            declare(self, 'view_spacing', 0.02,
                    'Spacing of the grid of panel points the calibrations aim near [m].',
                    0.002, 0.1),
            declare(self, 'marker_clearance', 0.05,
                    "Aim no closer than this to the marker's centre (the spot must miss the "
                    'marker) [m].', 0.0, 0.5))
        self.world_poses = declare(self, 'world_calibration.poses', 8,
                                   'Arm poses of the robot-world calibration [-].', 3, 100)
        self.world_distance = declare(self, 'world_calibration.distance', 0.11,
                                      'Lens height over the panel while the marker is '
                                      'observed (the focus spread out) [m].', 0.05, 0.4)
        self.rig_poses = declare(self, 'rig_calibration.poses', 48,
                                 'Marker views of the rig calibration [-].', 12, 400)
        self.rig_spot_poses = declare(self, 'rig_calibration.spot_poses', 16,
                                      'Sweep poses whose spots fit the lens centre [-].', 4,
                                      200)
        self.rig_spot_tilts = declare(
            self, 'rig_calibration.spot_tilts_deg', [0.0, 5.0, 10.0],
            "Tilts of the lens axis off the sun in the rig calibration's sweep (0, 8, 16 "
            'placed dots 0.7 mm worse than these in the simulated 3D-printed build: the lens '
            "model's spot drifts from the detector's with the tilt) [deg].")
        self.rig_max_residual = (
            declare(self, 'rig_calibration.max_residual_position', 0.001,
                    'Refuse a rig calibration whose marker views miss the camera chain by '
                    'more than this, rms [m].', 1e-5, 0.05),
            declare(self, 'rig_calibration.max_residual_angle', math.radians(0.5),
                    'The same for the camera orientation, rms [rad].', 1e-5, 0.5),
            declare(self, 'rig_calibration.max_spot_residual', 0.0005,
                    'Refuse it when the spots miss the lens-centre fit by more than this, rms '
                    '[m].', 1e-5, 0.05))
        self.sweep_count = declare(self, 'sweep.poses', 6, 'Poses of the sun sweep [-].', 2,
                                   100)
        self.sweep_tilts = declare(self, 'sweep.tilts_deg', [0.0, 5.0, 10.0],
                                   'Tilts of the lens axis off the sun in the sweep [deg].')
        self.sweep_distances = declare(
            self, 'sweep.distances', [0.076, 0.082, 0.088],
            'Lens-panel distances of the sweep, near the focus where the spot model holds '
            '[m].')
        self.acquire_step = declare(self, 'sweep.acquire_azimuth_step_deg', 30.0,
                                    'Azimuth step of the search for the spot [deg].', 1.0, 180.0)
        self.focus_sweep = (declare(self, 'focal_calibration.d_min', 0.064,
                                    'First d_lp of the focal sweep (paper 6.4 cm) [m].',
                                    0.02, 0.3),
                            declare(self, 'focal_calibration.d_max', 0.098,
                                    'Last d_lp of the focal sweep (paper 9.8 cm) [m].',
                                    0.02, 0.3),
                            declare(self, 'focal_calibration.step', 0.001,
                                    'Step of the focal sweep (paper 0.1 cm) [m].', 1e-4, 0.05))
        calibration_dir = declare(self, 'calibration_dir', '',
                                  'Where calibrations are saved (empty: ~/.helio/'
                                  'calibration).')
        self.calibration_dir = os.path.expanduser(calibration_dir or '~/.helio/calibration')
        self.rig_description = rig_description(rig_file)
        load_calibrations = declare(
            self, 'load_calibrations', True,
            'At start, read back the robot-world and focal calibrations saved in '
            'calibration_dir for this rig description, publish and use them.')

        self.nominal_rig = self.rig.parameters      # the rig file's: a calibration's priors
        self.spot_model = SpotModel(self.lens)
        self.targeting = FocusTargeting(self.rig, self.lens, rays=self.focus_rays)
        self.world_calibrated = False      # T_robot_world measured: no marker needed
        follow_world_calibration(self, self.rig, self._calibrated)
        self.joints = JointStateBuffer()
        self.sun = None                      # latest trustworthy SunEstimate
        self.camera = None
        self._camera_seen = FirstOf()        # done at the first rgb/camera_info
        self._busy = False
        self._at_heating = False             # a focus left the lens at the heating distance
        self.interrupt_timeout = declare(
            self, 'interrupt_timeout', 5.0,
            'On Ctrl-C or SIGTERM, how long a retreat of a lens left at the heating distance '
            'may take before the node stops [s wall].', 0.0, 60.0)
        self._driver_goals = []              # handles of the driver goals in flight
        self._spot_waiters = []
        self.create_subscription(JointState, 'joint_states', self._on_joint_state, 50)
        self.create_subscription(SunEstimate, 'sun/estimate', self._on_sun, LATCHED)
        self.create_subscription(SpotObservation, 'spot', self._on_spot, RELIABLE)
        self.create_subscription(CameraInfo, 'rgb/camera_info', self._on_camera_info,
                                 qos_profile_sensor_data)
        self.world_publisher = self.create_publisher(PoseStamped, 'calibration/world_pose',
                                                     LATCHED)
        self.focus_publisher = self.create_publisher(FocalCalibration, 'calibration/focus',
                                                     LATCHED)
        self.rig_publisher = self.create_publisher(String, RIG_CALIBRATION_TOPIC, LATCHED)
        self.lease = declare_lease(
            self, 'lease', 'painter/heartbeat',
            'the client a focus at the heating distance is held for (the painter)',
            'a lens left at the heating distance is retreated', self._on_heartbeat,
            self._check_lease)
        # the servo driver's heating guard (issue 30): beats while a lens this node placed is at
        # the heating distance, 'clear' once it leaves; on both clocks, as the painter's
        self.heating_publisher = self.create_publisher(Header, HEATING_TOPIC, 10)
        self._heating_said = None
        heating_beat = declare(
            self, 'heating_beat_period', 0.05,
            'Period of the lens/heating beats while the lens is at the heating distance, on '
            "the node clock and on the wall clock (the servo driver's heating guard) [s].",
            0.01, 1.0)
        self.create_timer(heating_beat, self._beat_heating)
        self.create_timer(heating_beat, self._beat_heating,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.arm = ActionClient(self, MoveArm, 'move_arm')
        self.wrist = ActionClient(self, MoveWrist, 'move_wrist')
        self.estimator = self.create_client(EstimateSun, 'estimate_sun')
        # the emergency stop (node_kit.emergency_stop): goals refused until the reset; one
        # that runs ends when the drivers abort its moves
        self.emergency = EmergencyStopListener(self)
        for action_type, name, execute in (
                (FocusLens, 'focus', self._execute_focus),
                (CalibrateWorld, 'calibrate_world', self._execute_calibrate_world),
                (CalibrateRig, 'calibrate_rig', self._execute_calibrate_rig),
                (SweepSun, 'sweep_sun', self._execute_sweep_sun),
                (CalibrateFocus, 'calibrate_focus', self._execute_calibrate_focus)):
            ActionServer(self, action_type, name, self._guarded(action_type, execute),
                         goal_callback=lambda goal: GoalResponse.ACCEPT,
                         cancel_callback=self._on_cancel)
        if load_calibrations:
            self._load_calibrations()
        self.get_logger().info(f'lens_planner: rig from {rig_file}, lens from {lens_file}; '
                               f'heating {self.heating_distance * 100:.1f} cm, travel '
                               f'{self.travel_distance * 100:.1f} cm')

    # ---- inputs -----------------------------------------------------------------------------

    def _calibrated(self, _rig):
        self.world_calibrated = True

    def _load_calibrations(self):
        """Read back, publish and use the calibrations saved for this rig (issue 30)."""
        for name, use in (('rig_build.yaml', self._use_saved_rig),
                          ('robot_world.yaml', self._use_saved_world),
                          ('focus.yaml', self._use_saved_focus)):
            try:
                saved = load_calibration(self.calibration_dir, name, self.rig_description)
            except CalibrationRefused as error:
                self.get_logger().warning(f'calibration not used: {error}')
                continue
            if saved is None:
                continue
            values, record = saved
            try:
                what = use(values)
            except (KeyError, TypeError, ValueError) as error:
                self.get_logger().warning(f'calibration not used: {name}: {error!r}')
                continue
            self.get_logger().info(f'calibration read back from {self.calibration_dir}/{name} '
                                   f'(saved {record.get("saved_at")}): {what}')

    def _use_saved_rig(self, values):
        self._publish_rig(values['rig'], values.get('calibration_id', 'saved'))
        return f'the rig as built: {", ".join(sorted(values["rig"]))}'

    def _publish_rig(self, flat, identity):
        """Use a rig calibration's values and publish them on calibration/rig (latched)."""
        self.rig.apply_calibration(flat, identity)
        self.world_calibrated = True
        self.rig_publisher.publish(String(data=yaml.safe_dump(
            {**flat, 'calibration_id': identity}, sort_keys=True)))
        self._publish_world(self.rig.parameters.world_in_robot, self.rig.parameters.world_yaw)

    def _use_saved_world(self, values):
        rig = values['rig']
        self._publish_world(rig['world_in_robot'], rig['world_yaw'])
        return (f'marker at {np.round(np.asarray(rig["world_in_robot"]) * 1000, 2).tolist()} '
                f'mm, yaw {math.degrees(rig["world_yaw"]):.3f} deg')

    def _use_saved_focus(self, values):
        distance = float(values['heating_distance'])
        if not (math.isfinite(distance) and distance > 0.0):
            raise ValueError(f'heating_distance {distance} m')
        self._apply_focus(distance)
        message = FocalCalibration(heating_distance=distance,
                                   min_area=float(values.get('min_area', math.nan)),
                                   fit_rms_relative=float(values.get('fit_rms_relative',
                                                                     math.nan)),
                                   samples=int(values.get('samples', 0)))
        message.header.stamp = self.get_clock().now().to_msg()
        self.focus_publisher.publish(message)
        return f'heating distance {distance * 100:.2f} cm'

    def _publish_world(self, world_in_robot, world_yaw):
        """Use T_robot_world and publish it on calibration/world_pose (latched)."""
        self.rig.set_world(world_in_robot, world_yaw)
        self.world_calibrated = True
        message = PoseStamped()
        message.header.stamp = self.get_clock().now().to_msg()
        message.header.frame_id = 'robot'
        message.pose = matrix_to_pose(self.rig.parameters.T_robot_world)
        self.world_publisher.publish(message)

    def _on_joint_state(self, message):
        problem = self.joints.add_message(message, received=time.monotonic())
        if problem:
            self.get_logger().warning(problem, throttle_duration_sec=5.0)

    def _on_heartbeat(self, _message):
        self.lease.heard(self._now(), time.monotonic())

    def _beat_heating(self):
        """Beat on lens/heating while the lens is at the heating distance; say 'clear' once."""
        heating = bool(self._at_heating)
        if heating or self._heating_said is not False:
            self.heating_publisher.publish(Header(
                stamp=self.get_clock().now().to_msg(), frame_id=HEATING if heating else CLEAR))
            self._heating_said = heating

    def _check_lease(self):
        """Retreat a lens left at the heating distance by a client that went silent."""
        now, wall_now = self._now(), time.monotonic()
        if self._busy or not self.lease.expired(now, wall_now):
            return
        silence, wall_silence = self.lease.silence(now, wall_now)
        self.lease.disarm()
        self._busy = True
        self.get_logger().error(
            f'the heartbeat of the client the lens is focused for is silent ({silence:.2f} s '
            f'node clock, {wall_silence:.2f} s wall): retreating the lens')
        self.executor.create_task(self._lease_retreat())

    async def on_interrupt(self):
        """
        Ctrl-C or SIGTERM of this node: a lens left at the heating distance is retreated first.

        ``run_node`` runs this before the node goes (issue 30). A goal in progress (the
        painter's own retreat, signalled before this node) is let end first; then, if a focus
        left the lens at the heating distance, the lens is moved to the travel distance as
        when a client's lease expires. At most ``interrupt_timeout`` [s wall] in all.
        """
        while self._busy:
            await sleep(self, 0.02, wall=True)
        if not self._at_heating:
            return
        self.lease.disarm()
        self._busy = True
        self.get_logger().warning('stopping with the lens at the heating distance: retreating')
        await self._lease_retreat()

    async def _lease_retreat(self):
        """Move the lens along the sun ray to the travel distance over where it focuses."""
        try:
            x_now = self._present_joints()
            here, _ = lens_moves.focus_point(self.rig, x_now, self._sun_ray(),
                                             self.rig.parameters.T_robot_world)
            if here is None:
                raise GoalFailed('the lens does not face the panel: nothing to retreat')
            legs, _ = self._plan_focus(here, self.travel_distance)
            for leg in legs:
                await self._move(UNATTENDED, leg.x)
            self._at_heating = False
            self.get_logger().warning('lens retreated to the travel distance')
        except (GoalFailed, GoalCanceled) as error:
            self.get_logger().error(f'the lens could not be retreated: {error}')
        finally:
            self._busy = False

    def _on_sun(self, message):
        if message.converged:
            self.sun = message

    def _on_spot(self, message):
        for waiter in list(self._spot_waiters):
            waiter.offer(message)

    def _on_camera_info(self, message):
        try:
            self.camera = camera_from_info(message)
            self._camera_seen.offer(True)
        except ValueError as error:
            self.get_logger().warning(f'rgb/camera_info ignored: {error}',
                                      throttle_duration_sec=10.0)

    def _on_cancel(self, _goal_handle):
        for handle in list(self._driver_goals):
            handle.cancel_goal_async()     # the drivers stop the arm and hold the servos
        return CancelResponse.ACCEPT

    # ---- shared pieces ----------------------------------------------------------------------

    def _now(self):
        return self.get_clock().now().nanoseconds * 1e-9

    def _guarded(self, action_type, execute):
        """Wrap a procedure: one goal at a time, failures and cancels become results."""
        async def run(goal_handle):
            result = action_type.Result()
            if self._busy or self.emergency.engaged:
                result.success = False
                result.message = (emergency_stop.refusal(f'{action_type.__name__} goal')
                                  if self.emergency.engaged
                                  else 'busy: another lens_planner goal runs')
                goal_handle.abort()
                return result
            self._busy = True
            if action_type is not FocusLens:
                self.lease.disarm()       # its own procedure: no client's focus to guard
                self._at_heating = False
            try:
                await execute(goal_handle, result)
                result.success = True
                goal_handle.succeed()
            except GoalCanceled:
                result.success, result.message = False, 'canceled; the devices were stopped'
                goal_handle.canceled()
            except GoalFailed as failure:
                result.success, result.message = False, str(failure)
                goal_handle.abort()
            except Exception as error:      # a bug: end the goal with what happened
                result.success = False
                result.message = f'internal error: {type(error).__name__}: {error}'
                self.get_logger().error(traceback.format_exc())
                goal_handle.abort()
            finally:
                self._busy = False
            if result.success:
                self.get_logger().info(f'{action_type.__name__}: {result.message}')
            else:
                self.get_logger().warning(f'{action_type.__name__}: {result.message}')
            return result
        return run

    def _check_cancel(self, goal_handle):
        if goal_handle.is_cancel_requested:
            raise GoalCanceled()

    def _sun_ray(self):
        if self.sun is None:
            raise GoalFailed("no sun estimate yet: run sweep_sun (or sun_estimator's "
                             'estimate_sun) first')
        return point_to_array(self.sun.direction)

    def _inputs_heard(self):
        """Tell whether a sun estimate and the present joints are known."""
        return self.sun is not None and bool(self._present_lookup())

    def _present_lookup(self):
        """Return the JointLookup of the present joints (fresh on either clock)."""
        return self.joints.latest(self._now(), self.joint_state_max_age, time.monotonic(),
                                  self.joint_state_max_wall_age)

    def _present_joints(self):
        lookup = self._present_lookup()
        if not lookup:
            raise GoalFailed(f'the present joints are unknown: {lookup.reason}')
        return lookup.positions

    async def _discovered(self, ready, what):
        """Wait until `ready()` (a server discovered), at most server_timeout of wall time."""
        try:
            await discovered(self, ready, self.server_timeout, what)
        except TimeoutError as error:
            raise GoalFailed(str(error)) from None

    async def _move(self, goal_handle, x):
        """Move arm and wrist to joints x together; return the joints the drivers reached."""
        self._check_cancel(goal_handle)
        await self._discovered(lambda: self.arm.server_is_ready()
                               and self.wrist.server_is_ready(),
                               'move_arm or move_wrist (are dobot_driver and servo_driver '
                               'running and connected?)')
        arm_goal = MoveArm.Goal(mode=MoveArm.Goal.MOVJ_ANGLE,
                                target=[float(v) for v in x[:3]] + [0.0])
        wrist_goal = MoveWrist.Goal(yaw=float(x[3]), pitch=float(x[4]))
        handles = []
        for client, goal, name in ((self.arm, arm_goal, 'move_arm'),
                                   (self.wrist, wrist_goal, 'move_wrist')):
            handle = await client.send_goal_async(goal)
            if not handle.accepted:
                for other in handles:
                    other.cancel_goal_async()
                raise GoalFailed(f'{name} refused the goal (another move running?)')
            handles.append(handle)
            self._driver_goals.append(handle)
        # both results are asked for at once: a result asked for only after the other move
        # ended can find the goal expired (a driver that accepted it before its first /clock
        # stamped it 0, so once done it is 'older' than any result timeout) and comes back
        # as an empty failure with status UNKNOWN
        replies = [handle.get_result_async() for handle in handles]
        try:
            arm_reply, wrist_reply = await replies[0], await replies[1]
        finally:
            for handle in handles:
                self._driver_goals.remove(handle)
        self._check_cancel(goal_handle)
        for reply, name in ((arm_reply, 'move_arm'), (wrist_reply, 'move_wrist')):
            if reply.status == GoalStatus.STATUS_UNKNOWN:
                raise GoalFailed(f'{name} no longer knew the goal when its result was asked '
                                 'for (expired on the driver)')
            if not reply.result.success:
                raise GoalFailed(f'{name} failed: {reply.result.message}')
        arm_result, wrist_result = arm_reply.result, wrist_reply.result
        return np.array([*arm_result.achieved_joints[:3], wrist_result.achieved_yaw,
                         wrist_result.achieved_pitch])

    async def _observe(self, goal_handle, count, accept=lambda message: message.valid):
        """Return `count` spot observations imaged after now (after the settle time)."""
        await sleep(self, self.settle_time)
        waiter = SpotWaiter(self._now(), count, accept)
        self._spot_waiters.append(waiter)
        timer = self.create_timer(self.observe_timeout,
                                  lambda: waiter.future.offer(list(waiter.messages)))
        try:
            messages = await waiter.future
        finally:
            self._spot_waiters.remove(waiter)
            self.destroy_timer(timer)
        if len(messages) < count:
            self.get_logger().warning(
                f'{len(messages)} of {count} spot observations accepted in '
                f'{self.observe_timeout:g} s; refused: {waiter.refused or "none arrived"}')
        self._check_cancel(goal_handle)
        return messages

    def _lens_pose(self, x, d_lp):
        pose = self.rig.forward(x)
        message = LensPose()
        message.header.stamp = self.get_clock().now().to_msg()
        message.header.frame_id = 'robot'
        message.position = array_to_point(pose.T_robot_lens[:3, 3])
        message.yaw, message.pitch, message.d_lp = pose.yaw, pose.pitch, float(d_lp)
        message.joints = [float(v) for v in x]
        return message

    # ---- focus ------------------------------------------------------------------------------

    async def _execute_focus(self, goal_handle, result):
        goal = goal_handle.request
        frame = goal.target.header.frame_id or 'world'
        if frame != 'world':
            raise GoalFailed(f"target frame '{frame}': give the target in 'world' (the "
                             'marker frame, z = 0 on the panel)')
        target = point_to_array(goal.target.point)
        if not np.all(np.isfinite(target)):
            raise GoalFailed(f'the target {target.tolist()} is not finite')
        if abs(target[2]) > 1e-6:
            raise GoalFailed(f'the target lies {target[2] * 1000:.1f} mm off the panel (z must '
                             'be 0 in the world frame)')
        d_lp = goal.d_lp if goal.d_lp != 0.0 else self.heating_distance
        if not (math.isfinite(d_lp) and d_lp > 0.0):
            raise GoalFailed(f'd_lp must be a finite distance > 0 m, got {goal.d_lp}')
        travel = goal.travel_d_lp if goal.travel_d_lp != 0.0 else self.travel_distance
        if not (math.isfinite(travel) and lens_moves.safe_to_travel_at(
                travel, self.heating_distance, self.safe_margin)):
            raise GoalFailed(f'travel_d_lp {goal.travel_d_lp} m: the focus may move sideways '
                             f'only {self.safe_margin * 100:.1f} cm or more from the heating '
                             f'distance {self.heating_distance * 100:.1f} cm (safe_margin)')
        waited = time.monotonic() - self._started
        if waited < self.startup_wait and not self._inputs_heard():
            try:            # just started: the sun estimate and joints may be on their way
                await discovered(self, self._inputs_heard, self.startup_wait - waited,
                                 'the sun estimate and the joint states')
            except TimeoutError:
                pass        # _sun_ray and _present_joints say why
        alive = self.lease.alive(self._now(), time.monotonic())   # a client to outlive?
        legs, x_now = self._plan_focus(target, d_lp, travel)
        solution = self.targeting.aim(target, self._sun_ray(), d_lp,
                                      self.rig.parameters.T_robot_world)
        feedback = FocusLens.Feedback()
        feedback.commanded = self._lens_pose(legs[-1].x, d_lp)
        reached = x_now
        for leg in legs:
            feedback.joints = [float(v) for v in reached]
            feedback.distance_remaining = float(np.linalg.norm(
                self.rig.forward(legs[-1].x).T_robot_lens[:3, 3]
                - self.rig.forward(reached).T_robot_lens[:3, 3]))
            goal_handle.publish_feedback(feedback)
            reached = await self._move(goal_handle, leg.x)
        self._at_heating = not lens_moves.safe_to_travel_at(d_lp, self.heating_distance,
                                                            self.safe_margin)
        self.lease.placed(self._at_heating, alive)
        commanded = self.rig.forward(legs[-1].x).T_robot_lens[:3, 3]
        achieved = self.rig.forward(reached).T_robot_lens[:3, 3]
        result.achieved = self._lens_pose(reached, d_lp)
        result.position_error = float(np.linalg.norm(achieved - commanded))
        correction = np.hypot(*solution.correction[:2])
        result.message = (f'focused on ({target[0] * 100:.2f}, {target[1] * 100:.2f}) cm at '
                          f'd_lp {d_lp * 100:.2f} cm in {len(legs)} leg(s) '
                          f'({", ".join(leg.name for leg in legs)}); aim corrected by '
                          f'{correction * 1e3:.3f} mm; lens within '
                          f'{result.position_error * 1e3:.3f} mm of the command')

    def _plan_focus(self, target, d_lp, travel=None):
        """
        Return (legs, present joints) that bring the focus to `target` at `d_lp`.

        The focus moves sideways at `travel` (default ``travel_distance``), else at the first
        reachable distance a safe margin from the heating distance.
        """
        sun = self._sun_ray()
        x_now = self._present_joints()
        try:
            legs = lens_moves.plan_focus_moves(
                self.targeting, x_now, target, d_lp, sun,
                self.rig.parameters.T_robot_world, self.heating_distance,
                (travel or self.travel_distance, self.heating_distance + self.safe_margin,
                 self.heating_distance - self.safe_margin), self.safe_margin, self.same_point)
        except (lens_moves.MovePlanningError, ValueError) as error:
            raise GoalFailed(str(error)) from None
        return legs, x_now

    # ---- robot-world calibration --------------------------------------------------------

    async def _need_camera(self):
        if self.camera is None and not await within(self, self._camera_seen,
                                                    self.observe_timeout):
            raise GoalFailed(f'no rgb/camera_info within {self.observe_timeout:g} s: is the '
                             'RGB camera running?')
        return self.camera

    async def _execute_calibrate_world(self, goal_handle, result):
        camera = await self._need_camera()
        total = goal_handle.request.poses or self.world_poses
        poses = self._marker_poses(camera, total)
        if len(poses) < 3:
            raise GoalFailed(f'only {len(poses)} poses show the whole marker to the camera '
                             'according to the rig file: check world_in_robot in the rig file '
                             'and the panel_extent parameter')
        feedback = CalibrateWorld.Feedback(total=len(poses))
        joints, world_rgb, _ = await self._marker_views(goal_handle, poses, feedback)
        robot_rgb = [self.rig.forward(x).T_robot_rgb for x in joints]
        try:
            estimate = estimate_world_in_robot(robot_rgb, world_rgb)
        except ValueError as error:
            raise GoalFailed(f'robot-world calibration failed: {error}') from None
        before = self.rig.parameters
        result.world_in_robot = matrix_to_pose(estimate.T_robot_world)
        result.world_yaw = estimate.world_yaw
        result.residual_position = estimate.residual_position
        result.residual_angle = estimate.residual_angle
        result.tilt = estimate.tilt
        result.poses_used = estimate.used
        result.shift_from_rig_file = float(np.linalg.norm(
            estimate.world_in_robot - np.asarray(before.world_in_robot)))
        result.turn_from_rig_file = float(math.remainder(estimate.world_yaw - before.world_yaw,
                                                         2.0 * math.pi))
        if goal_handle.request.apply:
            self._publish_world(estimate.world_in_robot, estimate.world_yaw)
            result.saved_to = self._save('robot_world.yaml', {'rig': {
                'world_in_robot': [float(v) for v in estimate.world_in_robot],
                'world_yaw': float(estimate.world_yaw)}}, {
                'residual_position_m': float(estimate.residual_position),
                'residual_angle_rad': float(estimate.residual_angle),
                'poses_used': int(estimate.used)})
        result.message = (
            f'T_robot_world from {estimate.used} poses ({len(estimate.rejected)} left out): '
            f'marker at {np.round(estimate.world_in_robot * 1000, 2).tolist()} mm, yaw '
            f'{math.degrees(estimate.world_yaw):.3f} deg; spread '
            f'{estimate.residual_position * 1000:.2f} mm, '
            f'{math.degrees(estimate.residual_angle):.3f} deg; tilt '
            f'{math.degrees(estimate.tilt):.2f} deg; moved '
            f'{result.shift_from_rig_file * 1000:.2f} mm and '
            f'{math.degrees(result.turn_from_rig_file):.3f} deg from the rig file'
            + ('' if goal_handle.request.apply else ' (not applied)'))

    async def _marker_views(self, goal_handle, poses, feedback):
        """
        Visit `poses`; return (reported joints, T_world_rgb, pose index) of each marker pose.

        Each frame's marker pose is paired with the joints when its image was taken (the
        detector reuses a pose while the joints stay within its tolerance), not those the
        move reported on arrival: a servo arrives within 1 us (about 0.1 deg, i.e. 0.25 mm
        on a marker 15 cm away) and settles after. `feedback` (with index, phase and,
        where it has it, poses_used) is published as it goes.
        """
        joints, world_rgb, indices = [], [], []
        for index, x in enumerate(poses):
            feedback.index, feedback.phase = index, 'moving'
            goal_handle.publish_feedback(feedback)
            await self._move(goal_handle, x)
            feedback.phase = 'observing'
            goal_handle.publish_feedback(feedback)
            seen = await self._observe(goal_handle, self.observe_frames,
                                       accept=_has_marker_pose)
            if not seen:
                self.get_logger().warning(f'pose {index}: no marker pose seen')
                continue
            for message in seen:     # every frame's marker pose: their noise averages out
                taken = stamp_to_seconds(message.header.stamp) - message.marker_pose_age
                lookup = self.joints.at(taken, self.joint_state_tolerance)
                if not lookup:
                    self.get_logger().warning(f'pose {index}: a marker pose skipped: '
                                              f'{lookup.reason}')
                    continue
                joints.append(np.asarray(lookup.positions, dtype=float))
                world_rgb.append(pose_to_matrix(message.camera_pose))
                indices.append(index)
            if hasattr(feedback, 'poses_used'):
                feedback.poses_used = len(joints)
            goal_handle.publish_feedback(feedback)
        return joints, world_rgb, indices

    # ---- rig calibration (issue 28) ------------------------------------------------------

    async def _execute_calibrate_rig(self, goal_handle, result):
        request = goal_handle.request
        started = self._now()
        camera = await self._need_camera()
        feedback = CalibrateRig.Feedback()
        # the rig file is the prior; T_robot_world the best one known (a saved calibration)
        world = (self.rig.parameters.world_in_robot, self.rig.parameters.world_yaw)
        belief = Rig(replace(self.nominal_rig, world_in_robot=world[0], world_yaw=world[1]))
        # over the marker and the panel points near it, the focus spread out (the lens at
        # least the robot-world calibration's height over the panel)
        points = [(0.0, 0.0)] + [p for p in self.view_points if math.hypot(*p) <= 0.08]
        poses = rig_calibration.marker_view_poses(
            belief, camera, self.marker_side, points, request.poses or self.rig_poses,
            distances=(self.world_distance, self.world_distance + 0.03),
            margin=self.view_margin)
        if len(poses) < 12:
            raise GoalFailed(f'only {len(poses)} poses show the whole marker to the camera '
                             'according to the rig file (12 needed): check world_in_robot in '
                             'the rig file and the panel_extent parameter')
        feedback.total = len(poses)
        joints, world_rgb, indices = await self._marker_views(goal_handle, poses, feedback)
        feedback.phase = 'fitting the camera chain'
        goal_handle.publish_feedback(feedback)
        try:
            if len(joints) < 3:
                raise ValueError(f'{len(joints)} marker views: at least 3 are needed')
            joints, world_rgb = rig_calibration.mean_views(joints, world_rgb, indices)
            chain = await in_thread(self, lambda: rig_calibration.fit_camera_chain(
                self.nominal_rig, joints, world_rgb, world_guess=world))
        except ValueError as error:
            raise GoalFailed(f'rig calibration failed: {error}') from None
        result.views_used = chain.used
        result.residual_position, result.residual_angle = (chain.residual_position,
                                                           chain.residual_angle)
        max_position, max_angle, max_spot = self.rig_max_residual
        if chain.residual_position > max_position or chain.residual_angle > max_angle:
            raise GoalFailed(
                f'rig calibration refused: the marker views miss the camera chain by '
                f'{chain.residual_position * 1000:.2f} mm and '
                f'{math.degrees(chain.residual_angle):.2f} deg rms (bounds '
                f'{max_position * 1000:.2f} mm, {math.degrees(max_angle):.2f} deg): the '
                'marker moved, or the build is off beyond what the model holds')
        before = self.rig.parameters
        self.rig.set_parameters(chain.parameters)      # the sweep plans with the chain
        try:
            feedback.phase = 'spot sweep'
            sweep = await self._sweep(goal_handle, feedback, '', self.rig_spot_poses,
                                      self.rig_spot_tilts)
            if len(sweep.spots) < 4:
                raise GoalFailed(f'rig calibration failed: {len(sweep.spots)} still spots in '
                                 'the sweep, 4 needed (clouds? the marker out of view?)')
            feedback.phase = 'fitting the lens centre'
            goal_handle.publish_feedback(feedback)
            lens = await self._fit_lens_centre(chain.parameters, sweep)
        except BaseException:
            self.rig.set_parameters(before)
            raise
        result.spots_used = lens.used
        result.spot_residual = lens.residual_position
        if lens.residual_position > max_spot:
            self.rig.set_parameters(before)
            raise GoalFailed(f'rig calibration refused: the spots miss the lens-centre fit by '
                             f'{lens.residual_position * 1000:.2f} mm rms (bound '
                             f'{max_spot * 1000:.2f} mm)')
        estimates = chain.estimates + lens.estimates
        result.names = [e.name for e in estimates]
        result.values = [e.value for e in estimates]
        result.rig_file = [e.prior for e in estimates]
        result.sigmas = [e.std for e in estimates]
        unobserved = {**chain.unobserved, **lens.unobserved}
        result.unobserved = [f'{name}: {why}' for name, why in sorted(unobserved.items())]
        flat = rig_calibration.build_terms(lens.parameters)
        if request.apply:
            identity = f'{self._now():.3f}'
            self._publish_rig(flat, identity)
            result.saved_to = self._save('rig_build.yaml', {'rig': flat,
                                                            'calibration_id': identity}, {
                'residual_position_m': chain.residual_position,
                'residual_angle_rad': chain.residual_angle,
                'spot_residual_m': lens.residual_position,
                'views_used': chain.used, 'spots_used': lens.used,
                'unobserved': result.unobserved})
            # the sun again, from the same spots with the calibrated rig, once the estimator
            # has it (its response names the rig calibration its lens poses came from)
            deadline = time.monotonic() + self.server_timeout
            response = await self._estimate('', sweep.start)
            while response.rig_calibration != identity and time.monotonic() < deadline:
                await sleep(self, 0.1, wall=True)
                response = await self._estimate('', sweep.start)
            if response.rig_calibration != identity:
                raise GoalFailed('rig calibration applied, but the sun estimator did not take '
                                 f'it within {self.server_timeout:g} s: its estimate used the '
                                 f'rig calibration {response.rig_calibration!r}')
            if response.success:
                self.sun = response.estimate
            result.estimate = response.estimate
        else:
            self.rig.set_parameters(before)
        result.rig_time = self._now() - started
        result.message = (
            f'rig calibrated from {chain.used} marker views and {lens.used} spots in '
            f'{result.rig_time:.0f} s: camera chain rms {chain.residual_position * 1000:.2f} '
            f'mm, {math.degrees(chain.residual_angle):.2f} deg; spots rms '
            f'{lens.residual_position * 1000:.2f} mm; {len(unobserved)} terms not observed'
            + ('' if request.apply else ' (not applied)'))
        self.get_logger().info(result.message + '\n  ' + '\n  '.join(
            chain.table() + lens.table()))

    async def _fit_lens_centre(self, parameters, sweep):
        """Fit the lens centre to a sweep's still spots (Eq 18 offsets from its middle)."""
        times = [spot[0] for spot in sweep.spots]
        middle = 0.5 * (min(times) + max(times))
        anchor = sun_position(self.site, _utc(middle))
        offsets = [angle_offsets(anchor, sun_position(self.site, _utc(t))) for t in times]
        guess = point_to_array(sweep.response.estimate.direction)
        if not (np.all(np.isfinite(guess)) and guess[2] < 0.0):
            raise GoalFailed('rig calibration failed: the sweep gave no sun to start from: '
                             f'{sweep.response.message}')

        def spot_model(rays, T_robot_lens, T_robot_world):
            count = len(rays)
            centres = self.spot_model.centres(
                rays, T_robot_lens, np.repeat(T_robot_world[None, :3, 3], count, axis=0),
                np.repeat(T_robot_world[None, :3, 2], count, axis=0))
            return transform_points(np.linalg.inv(T_robot_world), centres)[:, :2]

        def fit():
            return rig_calibration.fit_lens_centre(
                parameters, [spot[1] for spot in sweep.spots], [spot[2] for spot in sweep.spots],
                guess, offsets, spot_model=spot_model)

        try:
            return await in_thread(self, fit)
        except ValueError as error:
            raise GoalFailed(f'rig calibration failed: {error}') from None

    def _marker_poses(self, camera, count):
        """Poses high over the canvas from which the camera sees the marker (rig file)."""
        return marker_poses(self.rig, camera, self.marker_side, self.view_points,
                            self.world_distance, count, self.view_margin)

    def _save(self, name, tree, notes=None):
        return save_calibration(self.calibration_dir, name, tree, self.rig_description,
                                'lens_planner', notes)

    # ---- sun sweep -------------------------------------------------------------------------

    async def _estimate(self, method, since):
        """
        Call estimate_sun on the spots imaged since `since` [s, node clock].

        The estimator keeps only the spots imaged with the lens still (its ``still_only``):
        those of the holds since then, not those of the moves between them, nor an earlier
        sweep's.
        """
        await self._discovered(self.estimator.service_is_ready,
                               'estimate_sun (is sun_estimator running?)')
        return await self.estimator.call_async(EstimateSun.Request(
            method=method, since=stamp_from_seconds(since)))

    async def _execute_sweep_sun(self, goal_handle, result):
        request = goal_handle.request
        sweep = await self._sweep(goal_handle, SweepSun.Feedback(), request.method,
                                  request.poses or self.sweep_count)
        result.estimate = sweep.response.estimate
        result.poses_used, result.observations = sweep.used, sweep.observations
        if not sweep.response.success:
            raise GoalFailed(f'estimate_sun after the sweep: {sweep.response.message}')
        self.sun = sweep.response.estimate
        result.message = (f'{sweep.used} of {sweep.planned} sweep poses saw the spot, '
                          f'{sweep.observations} observations: {sweep.response.message}')

    async def _sweep(self, goal_handle, feedback, method, count, tilts=None):
        """
        Find the spot when there is no sun estimate, sweep `count` poses, estimate the sun.

        `tilts` [deg] of the lens axis off the sun (default the ``sweep.tilts_deg``).

        Return a ``_Sweep``: the estimate_sun response, the poses planned and used, the
        observations, the still valid spots of the sweep's holds (image time, reported
        joints, world centre) and when the sweep began (node clock).
        """
        camera = await self._need_camera()
        T_robot_world = self.rig.parameters.T_robot_world
        observations = 0
        sun = None if self.sun is None else point_to_array(self.sun.direction)

        def report(**fields):
            for name, value in fields.items():
                if hasattr(feedback, name):
                    setattr(feedback, name, value)
            goal_handle.publish_feedback(feedback)

        if sun is None:
            elevation = sun_position(self.site, _utc(self._now())).elevation
            if elevation <= math.radians(5.0):
                raise GoalFailed(f'the sun stands {math.degrees(elevation):.1f} deg above the '
                                 'horizon at this site and time: too low to paint')
            candidates = sun_sweep.acquisition_poses(
                self.rig, T_robot_world, elevation, camera, self.marker_side,
                self.view_points, math.radians(self.acquire_step),
                (self.heating_distance - 0.016, self.heating_distance - 0.022,
                 self.heating_distance + 0.03), margin=self.view_margin,
                need_marker=not self.world_calibrated)
            if not candidates:
                raise GoalFailed('no pose to look for the spot: the view points are out of '
                                 'reach or out of the camera view for this sun elevation')
            for index, (azimuth, x) in enumerate(candidates):
                report(phase='acquiring', total=len(candidates), index=index)
                await self._move(goal_handle, x)
                seen = [m for m in await self._observe(goal_handle, self.observe_frames)
                        if m.header.frame_id in ('', 'world')]
                observations += len(seen)
                report(observations=observations)
                if seen:
                    # a coarse sun is enough to choose the sweep: this pose's spot solved for
                    # the sun by the lens model (not the estimator's fit, whose reach leaves
                    # out a lens facing a guessed sun; a twin sun is settled by the sweep)
                    centres = transform_points(T_robot_world, [point_to_array(m.center)
                                                               for m in seen])
                    try:
                        sun = sun_sweep.coarse_sun(
                            self.spot_model, self.rig.forward(x).T_robot_lens, centres,
                            T_robot_world[:3, 3], T_robot_world[:3, 2])
                    except ValueError as error:
                        self.get_logger().warning(f'azimuth guess {math.degrees(azimuth):.0f} '
                                                  f'deg: {error}')
                        continue
                    up, around = (math.degrees(a) for a in sun_sweep.sun_angles(sun))
                    self.get_logger().info(
                        f'spot found with the azimuth guess {math.degrees(azimuth):.0f} deg: '
                        f'a coarse sun {up:.2f} deg up, azimuth {around:.2f} deg (robot frame)')
                    break
            if sun is None:
                raise GoalFailed(f'the spot was not found at any of {len(candidates)} azimuth '
                                 'guesses (clouds? the camera? the marker?)')
        poses = sun_sweep.sweep_poses(self.rig, T_robot_world, sun, camera, self.marker_side,
                                      self.view_points, count,
                                      tuple(self.sweep_tilts if tilts is None else tilts),
                                      tuple(self.sweep_distances), self.view_margin,
                                      need_marker=not self.world_calibrated)
        if len(poses) < 2:
            raise GoalFailed(f'only {len(poses)} sweep poses show the marker and the spot')
        used, spots = 0, []
        for index, x in enumerate(poses):
            report(phase='sweeping', total=len(poses), index=index)
            await self._move(goal_handle, x)
            if index == 0:
                # the estimate is of the sweep's holds only: an acquisition pose far from the
                # focus casts a large spot whose centre the model misses by 2.5 mm at a 31 deg
                # sun (0.33 deg off the world's sun with it in the fit, 0.14-0.18 without)
                sweep_start = self._now()
            seen = await self._observe(goal_handle, self.observe_frames)
            observations += len(seen)
            used += bool(seen)
            for message in seen:
                taken = stamp_to_seconds(message.header.stamp)
                lookup = self.joints.at(taken, self.joint_state_tolerance)
                if lookup and message.quality == SpotObservation.FULL and \
                        message.header.frame_id in ('', 'world'):
                    spots.append((taken, np.asarray(lookup.positions, dtype=float),
                                  point_to_array(message.center)[:2]))
            report(observations=observations)
        report(phase='estimating')
        response = await self._estimate(method, sweep_start)
        return _Sweep(response, len(poses), used, observations, spots, sweep_start)

    # ---- focal calibration ------------------------------------------------------------------

    async def _execute_calibrate_focus(self, goal_handle, result):
        request = goal_handle.request
        d_min = request.d_min or self.focus_sweep[0]
        d_max = request.d_max or self.focus_sweep[1]
        step = request.step or self.focus_sweep[2]
        target = point_to_array(request.target)
        if not all(math.isfinite(v) for v in (d_min, d_max, step, *target)):
            raise GoalFailed(f'bad sweep: every number must be finite: d_min {d_min}, d_max '
                             f'{d_max}, step {step} m, target {target.tolist()}')
        if not (0.0 < d_min < d_max and step > 0.0 and (d_max - d_min) / step < 1000):
            raise GoalFailed(f'bad sweep: d_min {d_min}, d_max {d_max}, step {step} m')
        distances = np.round(np.arange(d_min, d_max + 0.5 * step, step), 6)
        sun = self._sun_ray()
        camera = await self._need_camera()
        T_robot_world = self.rig.parameters.T_robot_world
        if not np.any(target):
            target = self._focus_target(sun, camera, distances)
        feedback = CalibrateFocus.Feedback(total=len(distances))
        areas = []
        for index, d_lp in enumerate(distances):
            lens = self.rig.lens_pose_for_target(transform_points(T_robot_world, target), sun,
                                                 float(d_lp))
            if lens.x is None:
                raise GoalFailed(f'd_lp {d_lp * 100:.1f} cm over {target[:2].tolist()} is '
                                 f'unreachable: {lens.reason}')
            await self._move(goal_handle, lens.x)
            seen = await self._observe(goal_handle, self.observe_frames)
            area = float(np.median([m.area for m in seen])) if seen else math.nan
            areas.append(area)
            feedback.index, feedback.d_lp, feedback.area = index, float(d_lp), area
            goal_handle.publish_feedback(feedback)
        result.d_lp = [float(d) for d in distances]
        result.areas = [float(a) for a in areas]
        measured = np.isfinite(areas)
        try:
            fit = calibrate_focus(distances[measured], np.asarray(areas)[measured])
        except ValueError as error:
            raise GoalFailed(f'focal calibration: {error} ({np.count_nonzero(measured)} of '
                             f'{len(distances)} distances gave a spot)') from None
        result.heating_distance = fit.best_d_lp
        result.sample_best_d_lp = fit.sample_best_d_lp
        result.min_area = fit.min_area
        result.fit_rms_relative = fit.fit.rms_relative
        if request.apply:
            self._apply_focus(fit.best_d_lp)
            message = FocalCalibration(heating_distance=fit.best_d_lp, min_area=fit.min_area,
                                       fit_rms_relative=fit.fit.rms_relative,
                                       samples=int(np.count_nonzero(measured)))
            message.header.stamp = self.get_clock().now().to_msg()
            self.focus_publisher.publish(message)
            result.saved_to = self._save('focus.yaml', {
                'heating_distance': float(fit.best_d_lp),
                'min_area': float(fit.min_area),
                'fit_rms_relative': float(fit.fit.rms_relative),
                'samples': int(message.samples)})
        result.message = (f'smallest spot at d_lp {fit.best_d_lp * 100:.2f} cm (fit), '
                          f'{fit.sample_best_d_lp * 100:.1f} cm (samples), '
                          f'{fit.min_area * 1e6:.2f} mm^2; fit rms '
                          f'{fit.fit.rms_relative * 100:.1f} %'
                          + ('' if request.apply else ' (not applied)'))

    def _focus_target(self, sun, camera, distances):
        """
        Return the panel point from which most of the sweep shows the marker and the spot.

        The distances around the heating distance (where the minimum should be) must all be
        seen; at least 60% of the whole sweep.
        """
        T_robot_world = self.rig.parameters.T_robot_world
        best, best_count = None, -1
        probe = distances[::max(1, len(distances) // 12)]
        near = [d for d in distances if abs(d - self.heating_distance) <= 0.004]
        for point in self.view_points:
            target = np.array([point[0], point[1], 0.0])

            def seen(d_lp):
                x = self.rig.lens_pose_for_target(transform_points(T_robot_world, target), sun,
                                                  float(d_lp)).x
                return x is not None and sun_sweep.sees_marker_and_spot(
                    self.rig, x, sun, camera, T_robot_world, self.marker_side,
                    self.view_margin, need_marker=not self.world_calibrated)
            if not all(seen(d) for d in near):
                continue
            count = sum(seen(d) for d in probe)
            if count > best_count:
                best, best_count = target, count
        if best is None or best_count < 0.6 * len(probe):
            raise GoalFailed('no panel point shows the marker and the spot over most of the '
                             'sweep for this sun; give the goal a target')
        return best

    def _apply_focus(self, heating_distance):
        """Use a measured heating distance; scale the lens model's focus to match it."""
        model_best = _model_best_distance(self.lens, self.heating_distance)
        scale = heating_distance / model_best if model_best > 0 else 1.0
        self.lens = type(self.lens)(**{**self.lens.__dict__,
                                       'focal_length': self.lens.focal_length * scale})
        self.spot_model = SpotModel(self.lens)      # the rig calibration's, of this lens
        self.targeting = FocusTargeting(self.rig, self.lens, rays=self.focus_rays)
        self.heating_distance = heating_distance


@dataclass
class _Sweep:
    """What a sun sweep gave (``LensPlannerNode._sweep``)."""

    response: object        # EstimateSun.Response
    planned: int
    used: int
    observations: int
    spots: list             # (image time [s], reported joints (5,), world centre (2,))
    start: float            # node clock [s]


def _model_best_distance(lens, around):
    """Return the d_lp of the lens model's smallest spot near `around` [m]."""
    distances = np.linspace(around - 0.01, around + 0.01, 41)
    areas = [spot_area_at(lens, d) for d in distances]
    return float(distances[int(np.argmin(areas))])


def _has_marker_pose(message):
    """
    Return whether a spot observation carries a camera pose from the marker (Eqs 7-9).

    Observed after the arm stopped, it was detected after the move: the spot detector
    detects the marker again whenever the joints change, and reuses it while they are still.
    A pose from the kinematics (no marker in view) would calibrate the rig with itself.
    """
    return message.camera_pose_source == 'marker'


def _utc(seconds):
    return datetime.datetime.fromtimestamp(seconds, tz=datetime.timezone.utc)


def main(args=None):
    """Run the lens_planner node."""
    run_node(LensPlannerNode, args)


if __name__ == '__main__':
    main()
