"""
Node painter: Algorithm 1 of the paper as the ``paint`` action (helio_msgs/PaintPattern).

The procedures are not here (``helio_control.procedures``, no rclpy): a goal is a
``painting_run.PaintingRun`` (check, calibrate, estimate the sun, plan or resume, the dots
in order, the result), each dot a ``dot_procedure.DotProcedure`` (Algorithm 1 lines 6-14,
clouds, the fire-safety watchdog, the camera's check). They talk to the rig through a
``painter_port.PainterRigPort``, which this node implements over ROS:

- moves are goals of the lens planner's actions (``focus``, ``calibrate_world``,
  ``calibrate_rig``, ``sweep_sun``) and, for the escapes, of the drivers' (``move_wrist``,
  ``move_arm``). Every goal must be accepted within ``goal_accept_timeout`` of wall time (a
  killed server stays discovered for seconds and never answers); a retreat within
  ``retreat_accept_timeout``, or the procedure turns to the next way at once (a goal
  accepted late is then cancelled);
- observations: ``thermal/stats`` (stale after ``thermal_stale`` of the node clock or
  ``thermal_stale_wall`` of wall time), ``spot``, ``rgb/image_raw`` (decoded only when a
  check waits for a frame), ``joint_states``, ``sun/estimate`` (used when its larger angle
  sigma is at most ``sun_max_sigma``), ``calibration/focus`` (the heating distance);
- what stops a painting: a cancel, Ctrl-C or SIGTERM (``on_interrupt``: the painting's
  retreat first, at most ``interrupt_timeout``), the emergency stop, a device fault or alarm
  (``dobot/status``, ``servo/status``), a driver whose joint states stopped for
  ``device_silence`` (wall clock, the painter's own pauses not counted): each wakes the
  heating at once.

It beats ``painter/heartbeat`` (the lens planner's focus lease, ``node_kit.focus_lease``) on
the node clock and on the wall clock, and publishes the N_p window on ``thermal/window``.
Parameters: ``painter_parameters``.
"""

from dataclasses import asdict
import math
import time

from geometry_msgs.msg import PointStamped
from helio_control.dot_size_calibration import dot_size_for_painting
from helio_control.driver_silence import device_of, DriverSilence
from helio_control.painter_parameters import declare_painter_parameters, DYNAMIC
from helio_control.procedures.painter_port import PainterRigPort, PaintFailed
from helio_control.procedures.painting_run import PaintingRun
from helio_msgs.action import CalibrateRig, CalibrateWorld, FocusLens, MoveArm, MoveWrist
from helio_msgs.action import PaintPattern
from helio_msgs.action import SweepSun
from helio_msgs.msg import DeviceStatus, FocalCalibration, SpotObservation, SunEstimate
from helio_msgs.msg import ThermalStats
from helio_optics.node_kit import emergency_stop
from helio_optics.node_kit import topics
from helio_optics.node_kit.awaitables import cancel_if_accepted, discovered, FirstOf, GoalTrouble
from helio_optics.node_kit.awaitables import NextTurn, results_unless, sleep, within
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


def _message(message_type, fields):
    """Return a `message_type` of a dataclass' `fields`, each of its field's Python type."""
    blank = message_type()
    return message_type(**{name: type(getattr(blank, name))(value)
                           for name, value in asdict(fields).items()})


def _focus_goal(target, d_lp, travel_d_lp=0.0):
    """Return the FocusLens goal of world `target` (x, y) at `d_lp` [m]."""
    goal = FocusLens.Goal(d_lp=float(d_lp), travel_d_lp=float(travel_d_lp))
    goal.target.header.frame_id = 'world'
    goal.target.point.x, goal.target.point.y = float(target[0]), float(target[1])
    return goal


class PainterNode(Node, PainterRigPort):
    """See the module docstring."""

    def __init__(self, **kwargs):
        """Declare parameters and open the interfaces."""
        super().__init__('painter', **kwargs)
        self.rig, rig_file = declare_rig(self)
        follow_world_calibration(self, self.rig)
        self.settings = settings = declare_painter_parameters(self)
        settings.rig_file = rig_file
        self.interrupt_timeout = settings.interrupt_timeout     # run_node reads it [s wall]
        self.add_post_set_parameters_callback(self._on_parameters_set)
        self.painting = PaintingRun(self, settings)
        self._rgb_camera = None
        self._rgb_info_key = None
        self._frame_waiters = []       # (since [s], FirstOf) of the verifications waiting
        self.create_subscription(CameraInfo, topics.RGB_CAMERA_INFO, self._on_rgb_info,
                                 qos_profile_sensor_data)
        # subscribed only while a verification waits for a frame (``next_rgb_image``): every
        # RGB frame taken is a megabyte copied out of DDS, 30 a second beside a world at 6x,
        # and the painter took a tenth of a core doing so while it heated
        self._frames = None
        self.sun = None
        self.faults = {}
        self._stats_waiters = []
        self._live_stats_stamp = None   # the stamp of the last thermal frame not frozen [s]
        self._spot_waiters = []
        self._next_turn = NextTurn(self)
        self._busy = False
        self._goal_handle = None           # the paint goal running
        self._cancel_requested = False
        self._stop_signal = ''             # why the node stops mid-painting ('' while not)
        self.create_subscription(ThermalStats, topics.THERMAL_STATS, self._on_stats, RELIABLE)
        self.create_subscription(SunEstimate, topics.SUN_ESTIMATE, self._on_sun, LATCHED)
        self.create_subscription(FocalCalibration, topics.FOCUS_CALIBRATION, self._on_focus_cal,
                                 LATCHED)
        self.create_subscription(SpotObservation, topics.SPOT, self._on_spot, RELIABLE)
        for device in ('dobot', 'servo'):
            self.create_subscription(DeviceStatus, topics.device_status(device), self._on_status,
                                     LATCHED)
        # the drivers' joint states on the wall clock, the painter's own pauses not counted
        pause = min(LONGEST_RUN_GAP, 0.5 * settings.device_silence)
        self.drivers = DriverSilence(settings.device_silence, pause)
        self._silent_seen = set()          # the drivers silent at the last watch
        self.create_timer(pause / 5.0, self._watch_drivers,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.joints_now = {}               # every joint's latest position, by name [rad]
        self.create_subscription(JointState, topics.JOINT_STATES, self._on_joints, 20)
        self.window_publisher = self.create_publisher(PointStamped, topics.THERMAL_WINDOW, LATCHED)
        # the lens planner's focus lease (helio_optics.node_kit.focus_lease): while this heartbeat
        # lives, a lens left at the heating distance is the painter's to watch; a painter
        # killed outright stops it, and the lens planner retreats the lens
        # (issue 31) It beats on both clocks: on the node clock the simulated world holds at
        # most its lockstep lead ahead of the newest beat, so a painter starved of the CPU
        # does not leave the lens on the wood for simulated seconds while it cannot watch
        # (and the lease then does not expire for a painter that is merely slow); on the wall
        # clock it goes on while /clock pauses.
        self.heartbeat_publisher = self.create_publisher(Header, topics.PAINTER_HEARTBEAT, 10)
        self.create_timer(settings.heartbeat_period, self._beat)
        self.create_timer(settings.heartbeat_period, self._beat,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.focus_client = ActionClient(self, FocusLens, 'focus')
        self.world = ActionClient(self, CalibrateWorld, 'calibrate_world')
        self.rig_calibration = ActionClient(self, CalibrateRig, 'calibrate_rig')
        self.sweep = ActionClient(self, SweepSun, 'sweep_sun')
        self.wrist = ActionClient(self, MoveWrist, 'move_wrist')
        self.arm = ActionClient(self, MoveArm, 'move_arm')   # the lift when the wrist is down
        self.emergency = EmergencyStopListener(self, self._on_emergency_stop)
        ActionServer(self, PaintPattern, 'paint', self._execute,
                     goal_callback=lambda goal: GoalResponse.ACCEPT,
                     cancel_callback=self._on_cancel)
        self.get_logger().info(f'painter: heating {settings.heating_distance * 100:.1f} cm, '
                               f'retreat {settings.retreat_offset * 100:.1f} cm, cooling rule '
                               f'{settings.cooling}, runs in {settings.runs_dir}')
        self._say_dot_size_calibration()

    def _say_dot_size_calibration(self):
        """Log the dot-size calibration a painting will use (read again at each goal)."""
        settings = self.settings
        calibration, note = dot_size_for_painting(settings.calibration_dir, settings.rig_file)
        if note:
            self.get_logger().warning(note)
        elif calibration is None:
            self.get_logger().info(f'no dot-size calibration in {settings.calibration_dir}: '
                                   "dots are sized by the goal's N_p target")
        else:
            self.get_logger().info(f'dot-size calibration read back from '
                                   f'{settings.calibration_dir}: {calibration.summary()[0]}')

    # ---- inputs ---------------------------------------------------------------------------

    def _on_stats(self, message):
        if not message.frozen:
            self._live_stats_stamp = stamp_to_seconds(message.header.stamp)
        for waiter in list(self._stats_waiters):
            waiter.offer(message)

    def _on_sun(self, message):
        # sun/estimate also carries the sweep's acquisition (4 spots, sigma about 0.3 deg,
        # 0.6 mm at the heating distance): a painting waits for an estimate this precise,
        # and sweeps for one if it has none
        sigma = math.degrees(math.sqrt(max(message.covariance[0], message.covariance[3])))
        if message.converged and sigma <= self.settings.sun_max_sigma:
            self.sun = message

    def _on_focus_cal(self, message):
        if math.isfinite(message.heating_distance) and message.heating_distance > 0.0:
            self.settings.heating_distance = message.heating_distance
            self.get_logger().info(f'heating distance from the focal calibration: '
                                   f'{message.heating_distance * 100:.2f} cm')

    def _on_spot(self, message):
        for waiter in list(self._spot_waiters):
            waiter(message)

    def _on_joints(self, message):
        device = device_of(message.name)
        if device:
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
        """Take the parameters set at run time (``DYNAMIC``: from the next use on)."""
        for parameter in parameters:
            if parameter.name in DYNAMIC:
                name = DYNAMIC[parameter.name]
                setattr(self.settings, name,
                        type(getattr(self.settings, name))(parameter.value))

    def _on_rgb_info(self, message):
        key = (tuple(message.k), tuple(message.d), message.width, message.height)
        if key != self._rgb_info_key:
            try:
                self._rgb_camera = camera_from_info(message)
            except ValueError:
                self._rgb_camera = None
            self._rgb_info_key = key

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
        return self._cancel_requested

    def client_canceled(self):
        return self._goal_handle is not None and self._goal_handle.is_cancel_requested

    def stop_signal(self):
        return self._stop_signal

    def emergency_engaged(self):
        return self.emergency.engaged

    def device_faults(self):
        """Return [(device, why)]: the devices' faults and alarms, then the silent drivers."""
        silent = self.drivers.silent(time.monotonic())
        return list(self.faults.items()) + [
            (device, f'{device} silent for {seconds:.1f} s (no joint states: driver '
                     'stopped?)') for device, seconds in silent.items()]

    async def focus(self, target, d_lp, travel_d_lp=0.0, urgent=False):
        return await self._run_action(self.focus_client, 'focus',
                                      _focus_goal(target, d_lp, travel_d_lp), urgent,
                                      devices=('dobot', 'servo'))

    async def escape_wrist(self, yaw, pitch):
        return await self._run_action(self.wrist, 'move_wrist',
                                      MoveWrist.Goal(yaw=yaw, pitch=pitch, escape=True),
                                      urgent=True, last=True, devices=('servo',))

    async def lift_arm(self, joints):
        goal = MoveArm.Goal(mode=MoveArm.Goal.MOVJ_ANGLE, target=list(joints))
        return await self._run_action(self.arm, 'move_arm', goal, urgent=True, last=True,
                                      devices=('dobot',))

    async def calibrate_rig(self):
        return await self._run_action(self.rig_calibration, 'calibrate_rig',
                                      CalibrateRig.Goal(apply=True))

    async def calibrate_world(self):
        return await self._run_action(self.world, 'calibrate_world',
                                      CalibrateWorld.Goal(apply=True))

    async def sweep_sun(self):
        return await self._run_action(self.sweep, 'sweep_sun', SweepSun.Goal())

    async def next_stats(self, stale_after=None):
        """
        Return the next thermal statistics, or None when they are stale (watchdog).

        Stale after ``thermal_stale`` of the node clock, or `stale_after` [s] if sooner (the
        rest of a frozen camera's ``thermal_freeze_max``), or ``thermal_stale_wall``.
        """
        settings = self.settings
        waiter = FirstOf()
        # stale on the node clock only once the statistics queued meanwhile were taken
        node_timer = self.create_timer(
            settings.thermal_stale if stale_after is None else min(settings.thermal_stale,
                                                                   stale_after),
            lambda: self._next_turn.call(lambda: waiter.offer(None)))
        wall_timer = self.create_timer(settings.thermal_stale_wall, lambda: waiter.offer(None),
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))
        return await self._offered(waiter, self._stats_waiters, waiter, node_timer, wall_timer)

    def live_stats_stamp(self):
        return self._live_stats_stamp

    async def wait_for_spots(self, back, timeout):
        """Offer each spot's validity to `back` until True; False on `timeout` or cancel."""
        done = FirstOf()

        def on_spot(message):
            if back(message.valid):
                done.offer(True)
        timer = self.create_timer(timeout, lambda: done.offer(False))
        cancel = self.create_timer(0.2, lambda: self._cancel_requested and done.offer(False))
        return await self._offered(done, self._spot_waiters, on_spot, timer, cancel)

    def rgb_camera(self):
        return self._rgb_camera

    async def next_rgb_image(self, since, timeout):
        """Return the first RGB image stamped from `since` [s] on, or None after `timeout`."""
        waiter = FirstOf()
        if self._frames is None:
            # raw: a frame is decoded only when a verification waits for it
            self._frames = self.create_subscription(Image, topics.RGB_IMAGE, self._on_frame,
                                                    qos_profile_sensor_data, raw=True)
        timer = self.create_timer(timeout, lambda: waiter.offer(None),
                                  clock=Clock(clock_type=ClockType.STEADY_TIME))
        try:
            frame = await self._offered(waiter, self._frame_waiters, (since, waiter), timer)
        finally:
            if not self._frame_waiters and self._frames is not None:
                self.destroy_subscription(self._frames)
                self._frames = None
        return None if frame is None else image_to_numpy(frame)

    async def _offered(self, waiter, waiters, entry, *timers):
        """Return what `waiter` gets while `entry` is in `waiters`; then end it and `timers`."""
        waiters.append(entry)
        try:
            return await waiter
        finally:
            waiters.remove(entry)
            for timer in timers:
                self.destroy_timer(timer)

    def publish_feedback(self, feedback):
        """Publish the running goal's feedback (painter_port.PaintFeedback)."""
        self._goal_handle.publish_feedback(_message(PaintPattern.Feedback, feedback))

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

    async def _run_action(self, client, name, goal, urgent=False, last=False, devices=()):
        """
        Send a goal and return its result (PaintFailed when refused).

        Every goal must be accepted within ``goal_accept_timeout`` of wall time (a killed
        server stays discovered for seconds and never answers; a lens left at the heating
        distance then goes to the procedure's retreat). `urgent` (the retreat): no wait for a
        server that is not there, and ``retreat_accept_timeout`` instead: the retreat then
        turns to the next way at once, and a goal accepted after that is cancelled. The
        `last` way (the wrist's escape, the arm's lift) has no next: it gets
        ``goal_accept_timeout``, and a late acceptance is better than none (a killed node can
        stall the others' DDS writes for a second: the wrist's driver then goes silent and
        the arm's accepts late). A fault of one of the `devices` the goal moves (a driver
        fallen silent: killed mid-move, its result never comes) ends the wait for the
        result: the goal is canceled, and PaintFailed sends the painting to its retreat.
        """
        settings = self.settings
        if not urgent:
            try:
                await discovered(self, client.server_is_ready, settings.server_timeout,
                                 f'{name} (is the lens_planner running?)')
            except TimeoutError as error:
                raise PaintFailed(str(error)) from None
        elif not client.server_is_ready():
            raise PaintFailed(f'no {name} server (its node is gone)')
        limit = settings.retreat_accept_timeout if urgent and not last \
            else settings.goal_accept_timeout
        sent = client.send_goal_async(goal)
        if not await within(self, sent, limit, wall=True):
            if urgent and not last:
                # accepted after all, late (a loaded machine): cancelled, so that it does not
                # move the lens against the next way the painter takes
                sent.add_done_callback(cancel_if_accepted)
            raise PaintFailed(f'{name} did not accept the goal within {limit:g} s (is its node '
                              'running?)')
        handle = sent.result()
        if not handle.accepted:
            raise PaintFailed(f'{name} refused the goal')

        def device_fault():
            return '; '.join(why for device, why in self.device_faults() if device in devices)
        try:
            reply, = await results_unless(self, [handle], device_fault)
        except GoalTrouble as trouble:
            raise PaintFailed(f'{name} given up: {trouble}') from None
        return reply.result

    async def _execute(self, goal_handle):
        if self._busy or self.emergency.engaged:
            goal_handle.abort()
            return PaintPattern.Result(
                message=emergency_stop.refusal('paint goal') if self.emergency.engaged
                else 'busy: another painting runs')
        self._busy, self._cancel_requested, self._stop_signal = True, False, ''
        self._goal_handle = goal_handle
        try:
            result, ending = await self.painting.execute(goal_handle.request)
        finally:
            self._busy = False
        getattr(goal_handle, ending)()
        if result.success:
            self.get_logger().info(f'paint: {result.message}')
        else:
            self.get_logger().warning(f'paint: {result.message}')
        return _message(PaintPattern.Result, result)

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
        if self.painting.dot.at_heating is not None:
            target, d_lp = self.painting.dot.at_heating
            if self.focus_client.server_is_ready():
                self.focus_client.send_goal_async(
                    _focus_goal(target, d_lp + self.settings.retreat_offset))
                self.get_logger().warning('stopping while heating: retreat sent')
        return super().destroy_node()


def main(args=None):
    """Run the painter node."""
    run_node(PainterNode, args)


if __name__ == '__main__':
    main()
