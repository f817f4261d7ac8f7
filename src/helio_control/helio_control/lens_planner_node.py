"""
Node lens_planner: place the lens so the focus lands on a point, and calibrate the rig.

Actions (one goal at a time across all five; a second is aborted with "busy"), each a
procedure of ``helio_control.procedures`` run against this node's side of their port
(``node_lens_rig.NodeLensRig``, a ``LensRigPort``):

- ``focus`` (helio_msgs/FocusLens, paper Eqs 14-15): ``procedures.focus``; the lens pose
  from the sun estimate (``sun/estimate``, kept current by Eq 18) reached in legs that keep
  the focus off the wood while it travels.
- ``calibrate_world`` (CalibrateWorld, Sec. II-B): ``procedures.world_calibration_run``;
  T_robot_world published on ``calibration/world_pose`` (transient local) and saved.
- ``calibrate_rig`` (CalibrateRig, issue 28): ``procedures.rig_calibration_run``; the rig as
  built published on ``calibration/rig`` (transient local) and saved.
- ``sweep_sun`` (SweepSun, Sec. V-B): ``procedures.sun_sweep_run``; acquire the spot, sweep,
  call ``estimate_sun`` on the sweep's spots.
- ``calibrate_focus`` (CalibrateFocus, Sec. V-A): ``procedures.focal_calibration_run``; the
  heating distance published on ``calibration/focus`` (transient local) and saved.

It alone owns the heating distance and the retreat distance (``procedures.focus``: issue
32), latched on ``focus/distances`` at the start and after each focal calibration.

Every goal is checked first: no sun estimate, a non-finite or unreachable target (which
joint, by how much), no joint states: the goal is aborted at once with the reason. A cancel
cancels the driver goals (the drivers stop the arm and hold the servos) and ends the goal.
The node keeps the parameters (the procedures' in ``lens_planner_parameters``), the
subscriptions, the action wiring, the calibrations read back at start, and the focus lease:
a lens left at the heating distance is retreated when its client falls silent or the node
is stopped, and beats on ``lens/heating`` while it is there.

Execute callbacks are coroutines that await the driver actions, the estimator service, the
spot stream and node-clock timers; nothing blocks, and the node runs in a plain
``rclpy.spin`` (one thread).
"""
import math
import time

from geometry_msgs.msg import PoseStamped
from helio_control.calibration_store import CalibrationRefused, load_calibration
from helio_control.calibration_store import rig_description, save_calibration
from helio_control.driver_silence import DriverSilence
from helio_control.lens_planner_parameters import declare_heating_distance, declare_settings
from helio_control.node_lens_rig import goal_runner, NodeLensRig, UNATTENDED
from helio_control.procedures import focus
from helio_control.procedures.focal_calibration_run import calibrate_focus, scaled_lens
from helio_control.procedures.lens_rig_port import GoalCanceled, GoalFailed
from helio_control.procedures.rig_calibration_run import calibrate_rig
from helio_control.procedures.sun_sweep_run import sweep_sun
from helio_control.procedures.world_calibration_run import calibrate_world
from helio_msgs.action import (CalibrateFocus, CalibrateRig, CalibrateWorld, FocusLens,
                               MoveArm, MoveWrist, SweepSun)
from helio_msgs.msg import FocalCalibration, FocusDistances, SpotObservation
from helio_msgs.msg import SunEstimate
from helio_msgs.srv import EstimateSun
from helio_optics.focus_targeting import FocusTargeting
from helio_optics.node_kit import topics
from helio_optics.node_kit.awaitables import FirstOf, sleep
from helio_optics.node_kit.conversions import camera_from_info, matrix_to_pose
from helio_optics.node_kit.conversions import point_to_array
from helio_optics.node_kit.deployment import declare_calibration_dir, declare_lens, declare_rig
from helio_optics.node_kit.deployment import declare_site
from helio_optics.node_kit.deployment import follow_world_calibration, RIG_CALIBRATION_TOPIC
from helio_optics.node_kit.emergency_stop import EmergencyStopListener
from helio_optics.node_kit.focus_lease import CLEAR, declare_lease, HEATING, HEATING_TOPIC
from helio_optics.node_kit.joint_states import JointStateBuffer
from helio_optics.node_kit.parameters import declare
from helio_optics.node_kit.qos import LATCHED, reliable
from helio_optics.node_kit.runner import run_node
from helio_optics.spot import SpotModel
import numpy as np
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, JointState
from std_msgs.msg import Header, String
import yaml

RELIABLE = reliable(50)


class LensPlannerNode(Node):
    """See the module docstring."""

    def __init__(self, **kwargs):
        """Declare parameters, load the rig and lens models, open the interfaces."""
        super().__init__('lens_planner', **kwargs)
        self.rig, rig_file = declare_rig(self)
        self.lens, lens_file = declare_lens(self)
        self.site, _ = declare_site(self)
        self.heating_distance = declare_heating_distance(self)
        self.focus_calibrated = False       # heating_distance a focal calibration's
        self.settings = declare_settings(self)
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
        self.started = time.monotonic()
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
        self.observe_timeout = declare(self, 'observe_timeout', 10.0,
                                       'Longest wait for them (node clock) [s].', 0.1, 600.0)
        self.settle_time = declare(self, 'settle_time', 0.3,
                                   'Wait after a move before observing (node clock) [s].',
                                   0.0, 10.0)
        self.calibration_dir = declare_calibration_dir(
            self, 'the robot-world, rig-build and focal calibrations are saved there and read '
            'back at start')
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
        self.camera_seen = FirstOf()        # done at the first rgb/camera_info
        self.busy = False
        self.at_heating = False             # a focus left the lens at the heating distance
        self.interrupt_timeout = declare(
            self, 'interrupt_timeout', 5.0,
            'On Ctrl-C or SIGTERM, how long a retreat of a lens left at the heating distance '
            'may take before the node stops [s wall].', 0.0, 60.0)
        self.driver_goals = []              # handles of the driver goals in flight
        self.goal_accept_timeout = declare(
            self, 'goal_accept_timeout', 5.0,
            "A driver's move goal must be accepted within this much wall time, else the move "
            'fails (a killed driver stays discovered for seconds and answers nothing) [s].',
            0.1, 60.0)
        # a driver killed mid-move never sends its result: its joint states stop (wall clock,
        # this node's own pauses not counted), and the move is given up (issue 31)
        # longer than the painter's 1 s, its heating watchdog's: a driver merely starved of
        # the CPU must not fail a calibration's move, and a painter watches its own moves
        device_silence = declare(
            self, 'device_silence', 2.0,
            "A move whose driver's joint states stop this long is given up and its goals "
            'canceled [s wall].', 0.1, 60.0)
        self.drivers = DriverSilence(device_silence, 0.5 * device_silence)
        self.create_timer(0.1 * device_silence, lambda: self.drivers.tick(time.monotonic()),
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.spot_waiters = []
        self.create_subscription(JointState, topics.JOINT_STATES, self._on_joint_state, 50)
        self.create_subscription(SunEstimate, topics.SUN_ESTIMATE, self._on_sun, LATCHED)
        self.create_subscription(SpotObservation, topics.SPOT, self._on_spot, RELIABLE)
        self.create_subscription(CameraInfo, topics.RGB_CAMERA_INFO, self._on_camera_info,
                                 qos_profile_sensor_data)
        self.world_publisher = self.create_publisher(PoseStamped, 'calibration/world_pose',
                                                     LATCHED)
        self.focus_publisher = self.create_publisher(FocalCalibration, topics.FOCUS_CALIBRATION,
                                                     LATCHED)
        self.distances_publisher = self.create_publisher(FocusDistances, topics.FOCUS_DISTANCES,
                                                         LATCHED)
        self.rig_publisher = self.create_publisher(String, RIG_CALIBRATION_TOPIC, LATCHED)
        self.lease = declare_lease(
            self, 'lease', topics.PAINTER_HEARTBEAT,
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
                (FocusLens, 'focus', focus.focus),
                (CalibrateWorld, 'calibrate_world', calibrate_world),
                (CalibrateRig, 'calibrate_rig', calibrate_rig),
                (SweepSun, 'sweep_sun', sweep_sun),
                (CalibrateFocus, 'calibrate_focus', calibrate_focus)):
            ActionServer(self, action_type, name, goal_runner(self, action_type, execute),
                         goal_callback=lambda goal: GoalResponse.ACCEPT,
                         cancel_callback=self._on_cancel)
        if load_calibrations:
            self._load_calibrations()
        heating, retreat = self.publish_distances()   # (calibrated or not)
        self.get_logger().info(f'lens_planner: rig from {rig_file}, lens from {lens_file}; '
                               f'heating {heating * 100:.1f} cm, retreat and travel '
                               f'{retreat * 100:.1f} cm')

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
        self.publish_rig(values['rig'], values.get('calibration_id', 'saved'))
        return f'the rig as built: {", ".join(sorted(values["rig"]))}'

    def publish_rig(self, flat, identity):
        """Use a rig calibration's values and publish them on calibration/rig (latched)."""
        self.rig.apply_calibration(flat, identity)
        self.world_calibrated = True
        self.rig_publisher.publish(String(data=yaml.safe_dump(
            {**flat, 'calibration_id': identity}, sort_keys=True)))
        self.publish_world(self.rig.parameters.world_in_robot, self.rig.parameters.world_yaw)

    def _use_saved_world(self, values):
        rig = values['rig']
        self.publish_world(rig['world_in_robot'], rig['world_yaw'])
        return (f'marker at {np.round(np.asarray(rig["world_in_robot"]) * 1000, 2).tolist()} '
                f'mm, yaw {math.degrees(rig["world_yaw"]):.3f} deg')

    def _use_saved_focus(self, values):
        distance = float(values['heating_distance'])
        if not (math.isfinite(distance) and distance > 0.0):
            raise ValueError(f'heating_distance {distance} m')
        self.publish_focus(distance, float(values.get('min_area', math.nan)),
                           float(values.get('fit_rms_relative', math.nan)),
                           int(values.get('samples', 0)))
        return f'heating distance {distance * 100:.2f} cm'

    def publish_focus(self, heating_distance, min_area, fit_rms_relative, samples):
        """Use a measured heating distance (the lens model scaled to it); publish it."""
        self.lens = scaled_lens(self.lens, heating_distance, self.heating_distance)
        self.spot_model = SpotModel(self.lens)      # the rig calibration's, of this lens
        self.targeting = FocusTargeting(self.rig, self.lens, rays=self.focus_rays)
        self.heating_distance = heating_distance
        message = FocalCalibration(heating_distance=heating_distance, min_area=min_area,
                                   fit_rms_relative=fit_rms_relative, samples=samples)
        message.header.stamp = self.get_clock().now().to_msg()
        self.focus_publisher.publish(message)
        self.focus_calibrated = True
        self.publish_distances()

    def publish_distances(self):
        """Publish the heating and retreat distances on focus/distances; return them [m]."""
        heating, retreat = focus.distances(self)
        message = FocusDistances(heating_distance=heating, retreat_distance=retreat,
                                 calibrated=self.focus_calibrated)
        message.header.stamp = self.get_clock().now().to_msg()
        self.distances_publisher.publish(message)
        return heating, retreat

    def save(self, name, tree, notes=None):
        """Save a calibration under `name` in calibration_dir; return its path."""
        return save_calibration(self.calibration_dir, name, tree, self.rig_description,
                                'lens_planner', notes)

    def publish_world(self, world_in_robot, world_yaw):
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
        self.drivers.heard_joints(message.name, time.monotonic())
        if problem:
            self.get_logger().warning(problem, throttle_duration_sec=5.0)

    def _on_heartbeat(self, _message):
        self.lease.heard(self.now(), time.monotonic())

    def _beat_heating(self):
        """Beat on lens/heating while the lens is at the heating distance; say 'clear' once."""
        heating = bool(self.at_heating)
        if heating or self._heating_said is not False:
            self.heating_publisher.publish(Header(
                stamp=self.get_clock().now().to_msg(), frame_id=HEATING if heating else CLEAR))
            self._heating_said = heating

    def _check_lease(self):
        """Retreat a lens left at the heating distance by a client that went silent."""
        now, wall_now = self.now(), time.monotonic()
        if self.busy or not self.lease.expired(now, wall_now):
            return
        silence, wall_silence = self.lease.silence(now, wall_now)
        self.lease.disarm()
        self.busy = True
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
        while self.busy:
            await sleep(self, 0.02, wall=True)
        if not self.at_heating:
            return
        self.lease.disarm()
        self.busy = True
        self.get_logger().warning('stopping with the lens at the heating distance: retreating')
        await self._lease_retreat()

    async def _lease_retreat(self):
        """Move the lens along the sun ray to the travel distance over where it focuses."""
        try:
            await focus.retreat(NodeLensRig(self, UNATTENDED))
            self.at_heating = False
            self.get_logger().warning('lens retreated to the travel distance')
        except (GoalFailed, GoalCanceled) as error:
            self.get_logger().error(f'the lens could not be retreated: {error}')
        finally:
            self.busy = False

    def _on_sun(self, message):
        if message.converged:
            self.sun = message

    def _on_spot(self, message):
        for waiter in list(self.spot_waiters):
            waiter.offer(message)

    def _on_camera_info(self, message):
        try:
            self.camera = camera_from_info(message)
            self.camera_seen.offer(True)
        except ValueError as error:
            self.get_logger().warning(f'rgb/camera_info ignored: {error}',
                                      throttle_duration_sec=10.0)

    def _on_cancel(self, _goal_handle):
        for handle in list(self.driver_goals):
            handle.cancel_goal_async()     # the drivers stop the arm and hold the servos
        return CancelResponse.ACCEPT

    # ---- shared pieces ----------------------------------------------------------------------

    def now(self):
        """Return the node clock [s]."""
        return self.get_clock().now().nanoseconds * 1e-9

    def sun_ray(self):
        """Return the sun estimate's ray s0 (robot frame); GoalFailed when none came."""
        if self.sun is None:
            raise GoalFailed("no sun estimate yet: run sweep_sun (or sun_estimator's "
                             'estimate_sun) first')
        return point_to_array(self.sun.direction)

    def inputs_heard(self):
        """Tell whether a sun estimate and the present joints are known."""
        return self.sun is not None and bool(self._present_lookup())

    def _present_lookup(self):
        """Return the JointLookup of the present joints (fresh on either clock)."""
        return self.joints.latest(self.now(), self.joint_state_max_age, time.monotonic(),
                                  self.joint_state_max_wall_age)

    def present_joints(self):
        """Return the present joints (5,); GoalFailed when none are fresh."""
        lookup = self._present_lookup()
        if not lookup:
            raise GoalFailed(f'the present joints are unknown: {lookup.reason}')
        return lookup.positions


def main(args=None):
    """Run the lens_planner node."""
    run_node(LensPlannerNode, args)


if __name__ == '__main__':
    main()
