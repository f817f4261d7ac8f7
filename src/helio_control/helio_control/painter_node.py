"""
Node painter: Algorithm 1 of the paper as the ``paint`` action (helio_msgs/PaintPattern).

The procedures are not here: a goal is a ``procedures.painting_run.PaintingRun``, each dot a
``procedures.dot_procedure.DotProcedure`` (no rclpy). They talk to the rig through a
``painter_port.PainterRigPort``, which this node implements over ROS:

- moves: goals of the lens planner's actions (``focus`` at its heating or retreat distance,
  which it owns, issue 32; ``calibrate_world``, ``calibrate_rig``, ``sweep_sun``) and, for
  the escapes, of the drivers' (``move_wrist``, ``move_arm``), sent by ``goal_sending``:
  accepted within ``goal_accept_timeout`` of wall time, a retreat within
  ``retreat_accept_timeout`` or the procedure turns to the next way at once;
- observations (``stream_waits``): ``thermal/stats`` (stale after ``thermal_stale`` of the
  node clock or ``thermal_stale_wall`` of wall time), ``spot``, ``rgb/image_raw`` (decoded
  only while a check waits for a frame), ``joint_states``, ``sun/estimate`` (used when its
  larger angle sigma is at most ``sun_max_sigma``), ``focus/distances`` (the lens planner's
  heating and retreat distances, which the plan checks reach at and times moves with);
- what stops a painting (``painter_port.GoalStops``, ``driver_silence.DeviceFaults``): a
  cancel, Ctrl-C or SIGTERM (``on_interrupt``: the retreat first, at most
  ``interrupt_timeout``), the emergency stop, a device fault or alarm (``dobot/status``,
  ``servo/status``), a driver silent for ``device_silence`` (wall clock, the painter's own
  pauses not counted): each wakes the heating at once.

It beats ``painter/heartbeat`` (the lens planner's focus lease) on the node clock and on the
wall clock, and publishes the N_p window on ``thermal/window``. Parameters:
``painter_parameters``.
"""

import math
import time

from geometry_msgs.msg import PointStamped
from helio_control.dot_size_calibration import painting_note
from helio_control.driver_silence import DeviceFaults
from helio_control.goal_sending import GoalNotRun, run_goal
from helio_control.painter_parameters import declare_painter_parameters, DYNAMIC
from helio_control.procedures.painter_port import as_message, GoalStops, HEAT, PainterRigPort
from helio_control.procedures.painter_port import PaintFailed, RETREAT
from helio_control.procedures.painting_run import PaintingRun
from helio_control.stream_waits import CameraModel, ThermalWaits, Waits
from helio_msgs.action import CalibrateRig, CalibrateWorld, FocusLens, MoveArm, MoveWrist
from helio_msgs.action import PaintPattern
from helio_msgs.action import SweepSun
from helio_msgs.msg import DeviceStatus, FocusDistances, SpotObservation, SunEstimate
from helio_msgs.msg import ThermalStats
from helio_optics.node_kit import emergency_stop
from helio_optics.node_kit import topics
from helio_optics.node_kit.awaitables import discovered, FirstOf, NextTurn, sleep
from helio_optics.node_kit.conversions import camera_from_info, image_to_numpy
from helio_optics.node_kit.conversions import point_to_array, stamp_to_seconds
from helio_optics.node_kit.deployment import declare_rig, follow_world_calibration
from helio_optics.node_kit.emergency_stop import EmergencyStopListener
from helio_optics.node_kit.qos import LATCHED, reliable
from helio_optics.node_kit.runner import run_node
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Header

RELIABLE = reliable(20)
# A steady tick this late says the painter itself did not run (DriverSilence): at most this,
# and at most half device_silence [s wall].
LONGEST_RUN_GAP = 0.5
# the lens planner's distance (FocusLens.Goal.distance) a PainterRigPort.focus asks for
FOCUS_AT = {HEAT: FocusLens.Goal.HEATING, RETREAT: FocusLens.Goal.RETREAT}


def _focus_goal(target, at, travel_offset=0.0):
    """Return the FocusLens goal of world `target` (x, y) `at` HEAT or RETREAT."""
    goal = FocusLens.Goal(distance=FOCUS_AT[at], travel_offset=float(travel_offset))
    goal.target.header.frame_id = 'world'
    goal.target.point.x, goal.target.point.y = float(target[0]), float(target[1])
    return goal


class PainterNode(Node, PainterRigPort):
    """See the module docstring."""

    def __init__(self, **kwargs):
        """Declare parameters and open the interfaces."""
        super().__init__('painter', **kwargs)
        self.wall_clock = Clock(clock_type=ClockType.STEADY_TIME)   # the wall-time timers'
        self.rig, rig_file = declare_rig(self)
        follow_world_calibration(self, self.rig)
        self.settings = settings = declare_painter_parameters(self)
        settings.rig_file = rig_file
        self.interrupt_timeout = settings.interrupt_timeout     # run_node reads it [s wall]
        self.add_post_set_parameters_callback(self._on_parameters_set)
        self.painting = PaintingRun(self, settings)
        self.rgb = CameraModel(camera_from_info)
        self.create_subscription(CameraInfo, topics.RGB_CAMERA_INFO, self.rgb.take,
                                 qos_profile_sensor_data)
        # subscribed only while a verification waits for a frame (``next_rgb_image``): every
        # RGB frame taken is a megabyte copied out of DDS, 30 a second beside a world at 6x,
        # and the painter took a tenth of a core doing so while it heated
        self._frames = None
        self.frames, self.stats, self.spots = Waits(), ThermalWaits(), Waits()
        self.sun = None
        self.distances = None              # the lens planner's (heating, retreat) [m]
        self._next_turn = NextTurn(self)
        self.stops = GoalStops(self.stats.wake)
        self.create_subscription(ThermalStats, topics.THERMAL_STATS, self._on_stats, RELIABLE)
        self.create_subscription(SunEstimate, topics.SUN_ESTIMATE, self._on_sun, LATCHED)
        self.create_subscription(FocusDistances, topics.FOCUS_DISTANCES, self._on_distances,
                                 LATCHED)
        self.create_subscription(SpotObservation, topics.SPOT, self.spots.offer, RELIABLE)
        # the drivers' joint states on the wall clock, the painter's own pauses not counted; a
        # new fault wakes the heating loop at once (issue 30): it may wait on thermal
        # statistics that a world holding for a silent driver's joint states never sends
        pause = min(LONGEST_RUN_GAP, 0.5 * settings.device_silence)
        self.faults = DeviceFaults(settings.device_silence, pause, self.stats.wake)
        self.create_timer(pause / 5.0, self._watch_drivers, clock=self.wall_clock)
        for device in ('dobot', 'servo'):
            self.create_subscription(DeviceStatus, topics.device_status(device), lambda m: (
                self.faults.status(m.device, m.connected, m.message, m.alarms)), LATCHED)
        self.joints_now = {}               # every joint's latest position, by name [rad]
        self.create_subscription(JointState, topics.JOINT_STATES, self._on_joints, 20)
        self.window_publisher = self.create_publisher(PointStamped, topics.THERMAL_WINDOW, LATCHED)
        # the lens planner's focus lease (node_kit.focus_lease): a painter killed outright
        # stops beating, and the lens planner retreats a lens left at the heating distance.
        # On both clocks (issue 31): the simulated world holds at most its lockstep lead
        # ahead of the newest beat on the node clock; the wall clock goes on while /clock
        # pauses.
        self.heartbeat_publisher = self.create_publisher(Header, topics.PAINTER_HEARTBEAT, 10)
        self.create_timer(settings.heartbeat_period, self._beat)
        self.create_timer(settings.heartbeat_period, self._beat, clock=self.wall_clock)
        # the lens planner's actions, and the drivers' for the escapes (the wrist's turn, the
        # arm's lift when the wrist is down)
        self.actions = {name: ActionClient(self, action, name) for action, name in (
            (FocusLens, 'focus'), (CalibrateWorld, 'calibrate_world'),
            (CalibrateRig, 'calibrate_rig'), (SweepSun, 'sweep_sun'),
            (MoveWrist, 'move_wrist'), (MoveArm, 'move_arm'))}
        # engaged: a running painting ends at once (the drivers take the focus off the wood)
        self.emergency = EmergencyStopListener(
            self, lambda engaged: engaged and self.stops.stop('the EMERGENCY STOP'))
        ActionServer(self, PaintPattern, 'paint', self._execute,
                     goal_callback=lambda goal: GoalResponse.ACCEPT,
                     cancel_callback=self._on_cancel)
        self.get_logger().info(f'painter: cooling rule {settings.cooling}, runs in '
                               f'{settings.runs_dir}; heating and retreat distances from the '
                               'lens planner (focus/distances)')
        note, warning = painting_note(settings.calibration_dir, rig_file)   # read at each goal
        if warning:
            self.get_logger().warning(note)
        else:
            self.get_logger().info(note)

    # ---- inputs ---------------------------------------------------------------------------

    def _on_sun(self, message):
        # sun/estimate also carries the sweep's acquisition (4 spots, sigma about 0.3 deg,
        # 0.6 mm at the heating distance): a painting waits for an estimate this precise,
        # and sweeps for one if it has none
        sigma = math.degrees(math.sqrt(max(message.covariance[0], message.covariance[3])))
        if message.converged and sigma <= self.settings.sun_max_sigma:
            self.sun = message

    def _on_stats(self, message):
        self.stats.take(message, stamp_to_seconds(message.header.stamp))

    def _on_distances(self, message):
        self.distances = (message.heating_distance, message.retreat_distance)
        self.get_logger().info(
            f"the lens planner's distances: heating {message.heating_distance * 100:.2f} cm "
            f'({"focal calibration" if message.calibrated else "its parameter"}), retreat '
            f'{message.retreat_distance * 100:.2f} cm')

    def _on_joints(self, message):
        self.faults.joint_states(message.name, time.monotonic())
        self.joints_now.update(zip(message.name, message.position))

    def _watch_drivers(self):
        pause = self.faults.watch(time.monotonic())
        if pause:
            self.get_logger().warning(
                f'the painter did not run for {pause:.2f} s (a starved or paused process): '
                "the drivers' silence is counted again from now")

    def _beat(self):
        beat = Header()
        beat.stamp = self.get_clock().now().to_msg()
        self.heartbeat_publisher.publish(beat)

    def _on_cancel(self, _goal_handle):
        self.stops.cancel()
        return CancelResponse.ACCEPT

    def _on_frame(self, raw):
        """Take a raw RGB frame: decoded only when a verification waits for it."""
        if self.frames:
            message = deserialize_message(raw, Image)
            self.frames.offer(message, stamp_to_seconds(message.header.stamp))

    def _on_parameters_set(self, parameters):
        """Take the parameters set at run time (``DYNAMIC``: from the next use on)."""
        for parameter in parameters:
            if parameter.name in DYNAMIC:
                name = DYNAMIC[parameter.name]
                setattr(self.settings, name,
                        type(getattr(self.settings, name))(parameter.value))

    # ---- the port: painter_port.PainterRigPort says what each method does ----------------

    def now(self):
        return self.get_clock().now().nanoseconds * 1e-9

    def wall_now(self):
        return time.monotonic()

    def unix_now(self):
        return time.time()

    async def pause(self, seconds):
        """Wait `seconds` of wall time."""
        await sleep(self, seconds, wall=True)

    def running(self):
        """Return whether the node's ROS context is up."""
        return self.context.ok()

    async def wait_until(self, ready, what):
        await discovered(self, ready, self.settings.server_timeout, what)

    def joints(self):
        return self.joints_now

    def sun_ray(self):
        if self.sun is None:
            return None
        return point_to_array(self.sun.direction), stamp_to_seconds(self.sun.header.stamp)

    def use_sun_estimate(self, estimate):
        self.sun = estimate

    def cancel_requested(self):
        return self.stops.requested

    def client_canceled(self):
        return self.stops.client_canceled()

    def stop_signal(self):
        return self.stops.signal

    def emergency_engaged(self):
        return self.emergency.engaged

    def device_faults(self):
        return self.faults.faults(time.monotonic())

    def focus_distances(self):
        return self.distances

    async def focus(self, target, at, travel_offset=0.0, urgent=False):
        return await self._run_action('focus', _focus_goal(target, at, travel_offset), urgent,
                                      devices=('dobot', 'servo'))

    async def escape_wrist(self, yaw, pitch):
        return await self._run_action('move_wrist',
                                      MoveWrist.Goal(yaw=yaw, pitch=pitch, escape=True),
                                      urgent=True, last=True, devices=('servo',))

    async def lift_arm(self, joints):
        goal = MoveArm.Goal(mode=MoveArm.Goal.MOVJ_ANGLE, target=list(joints))
        return await self._run_action('move_arm', goal, urgent=True, last=True,
                                      devices=('dobot',))

    async def calibrate_rig(self):
        return await self._run_action('calibrate_rig', CalibrateRig.Goal(apply=True))

    async def calibrate_world(self):
        return await self._run_action('calibrate_world', CalibrateWorld.Goal(apply=True))

    async def sweep_sun(self):
        return await self._run_action('sweep_sun', SweepSun.Goal())

    async def next_stats(self, stale_after=None):
        """Return the next thermal statistics, or None when stale (``next_stats`` of the port)."""
        settings = self.settings
        waiter = FirstOf()
        # stale on the node clock only once the statistics queued meanwhile were taken
        node_timer = self.create_timer(
            settings.thermal_stale if stale_after is None else min(settings.thermal_stale,
                                                                   stale_after),
            lambda: self._next_turn.call(lambda: waiter.offer(None)))
        wall_timer = self.create_timer(settings.thermal_stale_wall, lambda: waiter.offer(None),
                                       clock=self.wall_clock)
        return await self._offered(waiter, self.stats, waiter.offer, node_timer, wall_timer)

    def live_stats_stamp(self):
        return self.stats.live_stamp

    async def wait_for_spots(self, back, timeout):
        """Offer each spot's validity to `back` until True; False on `timeout` or cancel."""
        done = FirstOf()

        def on_spot(message):
            if back(message.valid):
                done.offer(True)
        timer = self.create_timer(timeout, lambda: done.offer(False))
        cancel = self.create_timer(0.2, lambda: self.stops.requested and done.offer(False))
        return await self._offered(done, self.spots, on_spot, timer, cancel)

    def rgb_camera(self):
        return self.rgb.model

    async def next_rgb_image(self, since, timeout):
        """Return the first RGB image stamped from `since` [s] on, or None after `timeout`."""
        waiter = FirstOf()
        if self._frames is None:
            # raw: a frame is decoded only when a verification waits for it
            self._frames = self.create_subscription(Image, topics.RGB_IMAGE, self._on_frame,
                                                    qos_profile_sensor_data, raw=True)
        timer = self.create_timer(timeout, lambda: waiter.offer(None), clock=self.wall_clock)
        try:
            frame = await self._offered(waiter, self.frames, waiter.offer, timer, since=since)
        finally:
            if not self.frames and self._frames is not None:
                self.destroy_subscription(self._frames)
                self._frames = None
        return None if frame is None else image_to_numpy(frame)

    async def _offered(self, waiter, waits, take, *timers, since=None):
        """Return what `waiter` gets while `take` waits on `waits`; then end it and `timers`."""
        with waits.waiting(take, since):
            try:
                return await waiter
            finally:
                for timer in timers:
                    self.destroy_timer(timer)

    def publish_feedback(self, feedback):
        """Publish the running goal's feedback (painter_port.PaintFeedback)."""
        self.stops.goal.publish_feedback(as_message(feedback, PaintPattern.Feedback))

    def set_window(self, target):
        """Publish the N_p window at world `target` (``window_radius``); None: no window."""
        message = PointStamped()
        message.header.stamp = self.get_clock().now().to_msg()
        message.header.frame_id = 'world'
        if target is None:
            message.point.x = message.point.y = message.point.z = math.nan
        else:
            message.point.x, message.point.y = float(target[0]), float(target[1])
            message.point.z = float(self.settings.window_radius)    # the radius rides in z
        self.window_publisher.publish(message)

    # ---- goals ----------------------------------------------------------------------------

    async def _run_action(self, name, goal, urgent=False, last=False, devices=()):
        """
        Send a goal (``goal_sending.run_goal``); return its result, PaintFailed if not run.

        Accepted within ``goal_accept_timeout`` (wall). `urgent` (a retreat): no wait for a
        server that is not there, and ``retreat_accept_timeout``: the retreat turns to the
        next way at once, and a goal accepted later is cancelled. The `last` way (the
        wrist's escape, the arm's lift) has no next: a late acceptance is better than none.
        A fault of one of the `devices` the goal moves ends the wait for its result.
        """
        settings = self.settings
        next_way = urgent and not last
        try:
            return await run_goal(
                self, self.actions[name], name, goal,
                settings.retreat_accept_timeout if next_way else settings.goal_accept_timeout,
                lambda: self.faults.sentence(time.monotonic(), devices),
                None if urgent else settings.server_timeout, cancel_late=next_way,
                server_hint='is the lens_planner running?')
        except GoalNotRun as failure:
            raise PaintFailed(str(failure)) from None

    async def _execute(self, goal_handle):
        if self.stops.busy or self.emergency.engaged:
            goal_handle.abort()
            return PaintPattern.Result(
                message=emergency_stop.refusal('paint goal') if self.emergency.engaged
                else 'busy: another painting runs')
        self.stops.begin(goal_handle)
        try:
            result, ending = await self.painting.execute(goal_handle.request)
        finally:
            self.stops.busy = False
        getattr(goal_handle, ending)()
        # (rclpy's logger refuses two severities from one line of code)
        if result.success:
            self.get_logger().info(f'paint: {result.message}')
        else:
            self.get_logger().warning(f'paint: {result.message}')
        return as_message(result, PaintPattern.Result)

    async def on_interrupt(self):
        """
        Ctrl-C or SIGTERM: end a running painting as a cancel does (its retreat), then stop.

        ``run_node`` runs this first, for at most ``interrupt_timeout`` [s wall] (issue 30:
        the graph signals the painter before the lens planner, which carries the retreat out).
        """
        self.stops.stop('a stop signal')
        while self.stops.busy:
            await sleep(self, 0.02, wall=True)

    def destroy_node(self):
        """Leave the lens off the wood if a painting is cut short (best effort)."""
        target = self.painting.dot.at_heating
        if target is not None and self.actions['focus'].server_is_ready():
            self.actions['focus'].send_goal_async(_focus_goal(target, RETREAT))
            self.get_logger().warning('stopping while heating: retreat sent')
        return super().destroy_node()


def main(args=None):
    """Run the painter node."""
    run_node(PainterNode, args)


if __name__ == '__main__':
    main()
