"""
The base both serial driver nodes share: one device thread, one job at a time, reconnect.

A ``DeviceActionNode`` owns a serial client (``serial_link.SerialClient``) and one thread that
alone talks to it: it reopens a lost port with exponential backoff, polls the joints
(``joint_states`` at ``joint_state_rate``) and the alarms (``<device>/status``,
helio_msgs/DeviceStatus, every ``status_period``), and runs the one accepted job: a goal of
the node's action, or a service of the device (homing, clearing alarms). No ROS callback
ever waits on the device: the action's execute callback and the service callbacks are
coroutines that await the device thread's answer, and a guard condition wakes the executor
when the answer is there. The nodes therefore run in a plain ``rclpy.spin``
(single-threaded executor).

Why (the unplug stall): rclpy Jazzy's MultiThreadedExecutor (7.1.6, installed here)
yields a task again while it still waits in the thread pool's queue (ros2/rclpy#1452,
fixed upstream by #1547). With blocking callbacks in the pool, the spinning thread loops on
those tasks holding the GIL and starves the callbacks that talk to the device: measured, the
spin thread stayed runnable for 0.6 s while every other thread waited on the GIL, and the
executor yielded the same three tasks 150-550 times per 50 ms. A node whose callbacks do not
block needs no thread pool.

No server without the device: the action server and the device's services are created
only once the node has opened its port and the device answered, so a driver that does not
hold its device (it waits for it to be plugged in) never answers for it; a port held by
another process (a second driver for the same device) is refused at start-up with the
holder named (``PortBusyError``: the node does not start). After a link loss the server
stays (the node still owns the device's port) and goals abort at once saying why.

Stopping: every path on which a started job does not succeed (cancel, time limit, device
error, device refusal, unexpected error, shutdown) calls ``stop_device`` until it confirms
the device stands still, for up to ``stop_timeout``; the result says whether the stop was
confirmed. Every (re)connection stops the device first too (``configure_device``), so a
move the driver lost track of while the link was down does not go on. One exception: a
device that fell silent (no reply after every retry) is not asked to stop before the goal
ends, as each try would cost as long again; the link is reset, the goal ends at once saying
the stop is not confirmed, and the reconnection stops the device as soon as it answers. A
silent device so ends its goal within (retries + 1) reply timeouts (the Maestro client also
drains the line for a timeout after each) plus one poll period: 0.6 s with either driver's
defaults; ``silence_timeout`` caps that wait whatever the attempts: the simulated graph
gives its emulators 0.5 s a reply (a busy machine) and 1.0 s in all, so a frozen world ends
a move within 1.1 s.

Time (issue 31): beside a simulated world the driver is clocked by ``/clock``. The joints are
read and published every ``1/joint_state_rate`` of the node clock (simulated seconds under
``use_sim_time``), stamped on it, and every such period of wall time as well, whichever comes
first (``device_support.TwoClockSchedule``): the world steps the emulated devices on simulated
time, and nodes match images to joints within tolerances of simulated time, so the joint
states must be as dense in simulated time on a busy machine as on an idle one; the wall side
keeps them flowing while /clock pauses. Every /clock tick wakes the device thread (a jump
callback of the node clock), so a running move is also polled once per simulated step, not
only every ``poll_period`` of wall time. A move is limited by ``move_timeout`` on the node's
clock and by ``move_wall_timeout`` of wall time (a stopped /clock cannot hold a goal; see
``device_support.MoveDeadline``). The serial link's reply ``timeout`` and the reconnect
backoff stay on the wall clock: they are about the device, which answers in wall time. On a
real rig the node clock is the system clock and all of this is a plain wall-clock period.

Subclasses declare their own parameters, then call ``start_device()``, and implement the
device hooks: ``configure_device``, ``read_joints``, ``read_alarms``, ``plan_move``,
``start_move``, ``poll_move``, ``stop_device``, and optionally ``advertise_services``.
"""

from dataclasses import dataclass
import threading
import time

from helio_drivers.device_support import device_status, MoveDeadline, TwoClockSchedule
from helio_drivers.serial_link import (
    AUTO_PORT, DeviceError, DeviceTimeoutError, find_port, LinkError, parse_usb_id,
    PortBusyError, ReconnectBackoff)
from helio_msgs.msg import DeviceStatus
from helio_optics.node_kit import emergency_stop
from helio_optics.node_kit import topics
from helio_optics.node_kit.awaitables import sleep
from helio_optics.node_kit.emergency_stop import EmergencyStopListener
from helio_optics.node_kit.parameters import declare
from helio_optics.node_kit.qos import latched
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.clock import JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.task import Future
from sensor_msgs.msg import JointState


class GoalRefused(ValueError):
    """A goal the device must not be asked to do; the message says why."""


@dataclass(frozen=True)
class DeviceSpec:
    """What differs between the devices in the shared parameters and messages."""

    device: str                  # DeviceStatus.device and the status topic's namespace
    label: str                   # how messages name the device
    action_name: str             # e.g. 'move_arm'
    port: str                    # default serial port ('auto': found by USB id)
    usb_ids: tuple               # default USB ids ('vvvv:pppp') that `port: auto` looks for
    baudrate_max: int            # [bit/s]
    timeout: float               # default reply timeout per attempt [s]
    move_timeout: float          # default move limit on the node clock [s]
    move_timeout_max: float      # its upper bound [s]


@dataclass
class MoveProgress:
    """What one poll of a running move found: feedback, or the outcome once finished."""

    feedback: object = None      # the action's Feedback message while the move runs
    done: bool = False
    success: bool = False
    message: str = ''
    result: object = None        # the action's Result (achieved pose) once done


class DeviceJob:
    """
    One job for the device thread: plan, start, poll until done, within time limits.

    `handle` is the goal handle of an action goal (None for a service's job); `plan()`
    returns what `start(plan)` needs (GoalRefused before anything moves); `start` returns
    the move that `poll(move)` follows (MoveProgress).
    """

    def __init__(self, what, plan, start, poll, limit_s, wall_limit_s, handle=None):
        """Describe the job; `what` names it in messages."""
        self.what = what
        self.plan, self.start, self.poll = plan, start, poll
        self.limit_s, self.wall_limit_s = limit_s, wall_limit_s
        self.handle = handle
        self.answer = Future()       # (outcome, message, result), set by the device thread
        self.move = None
        self.started = False         # a command that may move the device was (being) sent
        self.deadline = None

    @property
    def cancel_requested(self):
        """Whether the goal's client asked to cancel it."""
        return self.handle is not None and self.handle.is_cancel_requested


class DeviceActionNode(Node):
    """Serial device + action server plumbing; see the module docstring."""

    def __init__(self, node_name, spec, action_type, client_class, **kwargs):
        """Declare the link parameters and create the client, publishers and guards."""
        super().__init__(node_name, **kwargs)
        self.spec = spec
        self.action_type = action_type
        self.port_setting = declare(
            self, 'port', spec.port,
            f'Serial port of the {spec.label} (device path or emulator link), or "auto": the '
            'one port whose USB id is in usb_ids.')
        self.usb_ids = list(declare(
            self, 'usb_ids', list(spec.usb_ids),
            f'USB ids (vvvv:pppp or vvvv, hexadecimal) of the {spec.label} for port "auto".'))
        for usb_id in self.usb_ids:
            parse_usb_id(usb_id)
        baudrate = declare(self, 'baudrate', 115200, 'Serial baud rate [bit/s].', 1200,
                           spec.baudrate_max)
        timeout = declare(self, 'timeout', spec.timeout, 'Reply timeout per attempt [s].',
                          0.005, 10.0)
        retries = declare(self, 'retries', 2, 'Extra attempts after a bad or missing reply.',
                          0, 10)
        silence_timeout = declare(
            self, 'silence_timeout', 0.0,
            'A request left without a valid reply this long in all (its attempts and the '
            'waits for late replies together) fails at once: the device is silent, the goal '
            'ends (0: no such limit, (retries + 1) timeouts, and the Maestro waits a timeout '
            'for a late reply after each) [s].', 0.0, 60.0)
        rate = declare(self, 'joint_state_rate', 20.0,
                       'Rate of joint polling and /joint_states, on the node clock (simulated '
                       'time under use_sim_time) and on the wall clock, whichever is first '
                       '[Hz].', 0.1, 200.0)
        self.joint_period = 1.0 / rate
        self.status_period = declare(self, 'status_period', 1.0,
                                     f'Period of {spec.device}/status and alarm polling [s].',
                                     0.05, 60.0)
        initial = declare(self, 'reconnect_initial', 0.2,
                          'First delay before reopening a lost port [s].', 0.01, 60.0)
        maximum = declare(self, 'reconnect_max', 5.0,
                          'Longest delay between reconnect attempts [s].', 0.01, 600.0)
        self.poll_period = declare(self, 'poll_period', 0.02,
                                   'Wall-clock period of device polling during a move [s].',
                                   0.001, 1.0)
        self.move_timeout = declare(
            self, 'move_timeout', spec.move_timeout,
            'Longest time a move may take on the node clock (simulated seconds under '
            'use_sim_time) before it is stopped and aborted [s].', 0.1, spec.move_timeout_max)
        self.move_wall_timeout = declare(
            self, 'move_wall_timeout', 10.0 * spec.move_timeout,
            'Longest wall-clock time a move may take whatever the node clock says, so that a '
            'stopped /clock cannot hold a goal [s].', 0.1, 10.0 * spec.move_timeout_max)
        self.shutdown_grace = declare(
            self, 'shutdown_grace', 0.5,
            'On Ctrl-C or SIGTERM the driver goes on serving goals until none has run for '
            'this long (at most interrupt_timeout): ros2 launch signals every node at once, '
            'and the painter and the lens planner then still take the focus off the wood '
            'through it (0: stop at once) [s].', 0.0, 10.0)
        self.interrupt_timeout = declare(
            self, 'interrupt_timeout', 5.0,
            'Ctrl-C or SIGTERM: the longest the driver goes on serving goals before it stops '
            'the device and exits (a second signal: at once) [s].', 0.1, 60.0)
        self.stop_timeout = declare(
            self, 'stop_timeout', 2.0,
            f'How long to keep trying to stop the {spec.label} and confirm it stands still '
            'after a failed, cancelled or timed-out job [s].', 0.05, 60.0)

        port = '' if self.port_setting == AUTO_PORT else self.port_setting
        self.client = client_class(port, baudrate, timeout, retries)
        self.client.silence_timeout = silence_timeout
        self.backoff = ReconnectBackoff(initial, maximum)
        self._message = ''
        self._alarms = []
        self.setup_notes = {}        # what is wrong with the device's set-up, by topic
        self._goal_lock = threading.Lock()
        self._busy = False           # a job is accepted and not yet finished
        self._run = None             # the DeviceJob the device thread works on
        self._calls = []             # one-shot functions for the device thread (services)
        self._wake = threading.Event()
        self._stopping = threading.Event()
        self._thread = None
        self.action_server = None
        self.device_services = []
        # A service callback awaits the device thread's answer. In the node's default
        # (mutually exclusive) group that await would hold the whole group: the executor
        # then leaves every other entity of it out of its wait set, /clock, the timers and
        # the guard condition that brings the answer included, and waits for ever (a
        # dobot/clear_alarms call in its own process never answered). The services share
        # a group of their own: one call at a time, the rest of the node unaffected.
        self.service_group = MutuallyExclusiveCallbackGroup()

        self.joint_publisher = self.create_publisher(JointState, topics.JOINT_STATES, 10)
        self.status_publisher = self.create_publisher(
            DeviceStatus, topics.device_status(spec.device),
            latched(5))
        # Every /clock tick wakes the device thread: joint states and move polls follow
        # simulated time (no effect on a clock that is not driven by /clock)
        self._clock_tick = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=Duration(nanoseconds=1), min_backward=None,
                          on_clock_change=False),
            post_callback=lambda _jump: self._wake.set())
        # Triggered by the device thread when a job's answer is ready: wakes the executor,
        # which then resumes the waiting coroutine.
        self._answer_ready = self.create_guard_condition(lambda: None)
        # Triggered by the device thread once it holds the device: the executor creates the
        # action server and the services (entities are made on the executor's thread).
        self._device_held = self.create_guard_condition(self._advertise)
        # The emergency stop (issue 30): engaged, the device thread aborts the job, stops the
        # device and makes the device's own emergency move (``emergency_move``) once; goals
        # and device services are refused until the reset.
        self._emergency_done = False
        self.emergency = EmergencyStopListener(self, lambda _engaged: self._wake.set())

    def start_device(self):
        """
        Connect once now, then start the device thread (end of the subclass __init__).

        A port held by another process is refused at once: PortBusyError, the node does not
        start (a second driver must not answer for a device that another one holds).
        """
        try:
            connected = self._connect(refuse_busy=True)
        except PortBusyError as error:
            self.get_logger().fatal(f'refusing to start: {error}')
            raise
        if connected:
            self._advertise()
        self._thread = threading.Thread(target=self._device_loop, daemon=True,
                                        name=f'{self.spec.device}-device')
        self._thread.start()

    @property
    def port(self):
        """Return the port in use (resolved when the parameter is "auto")."""
        if self.port_setting == AUTO_PORT:
            return f'auto ({self.client.port or "not found"})'
        return self.client.port

    # ---- device hooks (subclasses) ----------------------------------------------------------

    def configure_device(self):
        """
        Make the device ready after its port opened; raise DeviceError if it does not answer.

        It must leave the device stopped (stop_device) before anything else: a move started
        before the link was lost must not go on unobserved.
        """
        raise NotImplementedError

    def read_joints(self):
        """Return (joint names, positions [rad]) read from the device (known joints only)."""
        raise NotImplementedError

    def read_alarms(self):
        """Return the device's active alarms or errors, human-readable."""
        raise NotImplementedError

    def plan_move(self, goal):
        """Check a goal and return what start_move needs; GoalRefused before anything moves."""
        raise NotImplementedError

    def start_move(self, plan):
        """Send the move to the device; return the state poll_move uses."""
        raise NotImplementedError

    def poll_move(self, move):
        """Return the MoveProgress of a started move."""
        raise NotImplementedError

    def stop_device(self):
        """
        Stop the device now and confirm it stands still; return (Result or None, what done).

        Raise DeviceError when the stop could not be confirmed (it is then tried again).
        """
        raise NotImplementedError

    def advertise_services(self):
        """Create the device's services (called once, when the device is first held)."""

    def create_device_service(self, service_type, name, callback):
        """Create a service answered on the device thread (`run_call`), in its own group."""
        service = self.create_service(service_type, name, callback,
                                      callback_group=self.service_group)
        self.device_services.append(service)
        return service

    # ---- link -------------------------------------------------------------------------------

    def _resolve_port(self):
        """Find the port for `port: auto` (at every attempt: a replug may rename it)."""
        if self.port_setting == AUTO_PORT:
            self.client.port = ''
            self.client.port = find_port(self.usb_ids, f'the {self.spec.label}')

    def _connect(self, refuse_busy=False):
        try:
            self._resolve_port()
            self.client.connect()
            self.configure_device()
        except DeviceError as error:
            self.client.close()
            if refuse_busy and isinstance(error, PortBusyError):
                raise
            delay = self.backoff.failed(time.monotonic())
            self._message = f'{error}; retrying in {delay:.2f} s'
            if isinstance(error, PortBusyError):
                self.get_logger().error(self._message, throttle_duration_sec=5.0)
            else:
                self.get_logger().warning(self._message, throttle_duration_sec=5.0)
            self._publish_status()
            return False
        attempts = self.backoff.attempts
        self.backoff.succeeded()
        self._message = f'connected to {self.port}' + (
            f' after {attempts} attempts' if attempts else '')
        self.get_logger().info(self._message)
        self._publish_status()
        if self.action_server is None:
            self._device_held.trigger()
        return True

    def _advertise(self):
        """Create the action server and the services once (executor thread or constructor)."""
        if self.action_server is not None:
            return
        self.action_server = ActionServer(
            self, self.action_type, self.spec.action_name, self._execute,
            goal_callback=self._accept_goal, cancel_callback=self._accept_cancel)
        self.advertise_services()
        self.get_logger().info(
            f'{self.spec.action_name} ready' + ''.join(
                f', {service.srv_name}' for service in self.device_services))

    def _link_lost(self, error):
        self.client.close()
        if self.backoff.attempts == 0:
            self.backoff.failed(time.monotonic())
        self._message = f'link lost: {error}'
        self.get_logger().error(self._message)
        self._publish_status()

    def _publish_status(self):
        if not self.context.ok():
            return          # shutting down (Ctrl-C): nothing can be published any more
        message = '; '.join([self._message, *self.setup_notes.values()]).strip('; ')
        self.status_publisher.publish(device_status(
            self.get_clock().now(), self.spec.device, self.port, self.client.connected,
            self.backoff.attempts, self._alarms, message))

    def _publish_joints(self):
        names, positions = self.read_joints()
        if not names or not self.context.ok():
            return          # no joint known (e.g. servos sending no pulses), or shutting down
        message = JointState()
        message.header.stamp = self.get_clock().now().to_msg()
        message.name = list(names)
        message.position = [float(p) for p in positions]
        self.joint_publisher.publish(message)

    def _poll_alarms(self):
        alarms = self.read_alarms()
        if alarms != self._alarms:
            if alarms:
                self.get_logger().error(f'{self.spec.label} alarms: {"; ".join(alarms)}')
            self._alarms = alarms
            self._publish_status()
        return alarms

    # ---- device thread ----------------------------------------------------------------------

    def _device_loop(self):
        schedule = {'joints': TwoClockSchedule(self.joint_period), 'status': time.monotonic()}
        while not self._stopping.is_set():
            self._wake.clear()           # before looking: a wake from now on is not lost
            try:
                self._device_cycle(schedule)
            except Exception as error:   # a bug must not end the thread and strand a job
                self._driver_error(error)
            # the node clock's side of the joints is woken by /clock (_clock_tick)
            wake_at = min(schedule['joints'].wall_due_at(), schedule['status'])
            if not self.client.connected:
                wake_at = min(wake_at, self.backoff.next_attempt_at)
            if self._run is not None:
                wake_at = min(wake_at, time.monotonic() + self.poll_period)
            self._wake.wait(max(0.0, wake_at - time.monotonic()))

    def _driver_error(self, error):
        """Log an unexpected error; stop the device and abort the job it hit."""
        self.get_logger().error(f'{self.spec.device} device thread: {type(error).__name__}: '
                                f'{error}', throttle_duration_sec=5.0)
        run = self._run
        if run is None:
            return
        message = f'driver error, {run.what} aborted: {error}'
        result = None
        if run.started:
            result, stopped = self._stop_confirmed()
            message += f'; {stopped}'
        self._answer(run, 'abort', message, result)

    def _device_cycle(self, schedule):
        """Reconnect when due, run calls, advance the job, poll joints and status when due."""
        now = time.monotonic()
        if not self.client.connected and self.backoff.due(now):
            self._connect()
        if self.emergency.engaged != self._emergency_done:
            self._follow_emergency_stop()
        while self._calls:
            self._calls.pop(0)()
        run = self._run
        if run is not None:
            self._step_job(run)
        if self.client.connected and schedule['joints'].due(self._node_now_s(), now):
            try:
                self._publish_joints()
            except DeviceError as error:     # unplugged, or no answer after every retry
                self._poll_failed(error)
        if now >= schedule['status']:
            schedule['status'] = now + self.status_period
            if self.client.connected:
                try:
                    self._poll_alarms()
                except DeviceError as error:
                    self._poll_failed(error)
            self._publish_status()

    def _follow_emergency_stop(self):
        """
        Engaged: abort the job (stopping the device), stop it anyway, make the emergency move.

        Reset: say so. Runs on the device thread; once per change of the state.
        """
        engaged = self.emergency.engaged
        self._emergency_done = engaged
        if not engaged:
            self.setup_notes.pop('emergency', None)
            self.get_logger().warning('emergency stop reset: goals are taken again')
            self._publish_status()
            return
        done = self._stop_and_escape('EMERGENCY STOP')
        self.setup_notes['emergency'] = (
            f'EMERGENCY STOP engaged ({"; ".join(d for d in done if d)}); '
            + emergency_stop.HOW_TO_RESET)
        self.get_logger().error(self.setup_notes['emergency'])
        self._publish_status()

    def request_escape(self, why, spare=lambda job: False):
        """
        From any thread: stop the running job and the device, then make the emergency move.

        Done once on the device thread, as for an emergency stop but not latched: goals are
        taken again at once. `why` heads the aborted job's message and the log line. A
        running job for which `spare(job)` is true is let run, and nothing else is done (it
        is an escape already: aborting it would only stop the lens on its way off the sun).
        """
        def escape():
            run = self._run
            if run is not None and spare(run):
                self.get_logger().error(f'{why}: an escape move already runs ({run.what})')
                return
            done = self._stop_and_escape(why)
            self.get_logger().error(f'{why}: {"; ".join(d for d in done if d)}')
            self._publish_status()
        self._calls.append(escape)
        self._wake.set()

    def _stop_and_escape(self, why):
        """Abort the job (stopping the device), stop it anyway, make the emergency move."""
        done = []
        run = self._run
        stopped_already = False
        if run is not None:
            # a job that may have moved the device is stopped (and the stop confirmed) here
            stopped_already = run.started
            self._stop_and_answer(run, 'abort', f'{why}: {run.what} aborted')
            done.append(f'{run.what} aborted')
        if self.client.connected:
            try:
                if not stopped_already:         # one stop, not two, before the escape
                    _, stopped = self.stop_device()
                    done.append(stopped)
                done.append(self.emergency_move())
            except DeviceError as error:
                done.append(f'the {self.spec.label} could NOT be stopped: {error}')
        else:
            done.append(f'the {self.spec.label} is not connected ({self._message})')
        return done

    def emergency_move(self):
        """
        Make the device's own move of an emergency stop (device thread); return what it did.

        The device stands still when this runs. None by default (the arm stays stopped); the
        servo driver turns the lens off the sun.
        """
        return ''

    def _poll_failed(self, error):
        """Handle a failed joint or alarm poll: the running job fails, else the link is lost."""
        run = self._run
        if run is not None and run.started:
            self._job_failed(run, error)
        else:
            self._link_lost(error)

    def _node_now_s(self):
        return self.get_clock().now().nanoseconds * 1e-9

    def _step_job(self, run):
        """Advance the job by one poll; answer it when it ends (stopping the device)."""
        try:
            if run.move is None:
                if run.cancel_requested:
                    return self._answer(run, 'canceled', 'canceled before the move started')
                if not self.client.connected:
                    return self._answer(run, 'abort',
                                        f'{self.spec.label} not connected on {self.port} '
                                        f'({self._message}); reconnecting in the background')
                plan = run.plan()
                run.started = True           # from here on the device may move
                run.move = run.start(plan)
                run.deadline = MoveDeadline(run.limit_s, run.wall_limit_s, self._node_now_s(),
                                            time.monotonic())
            if run.cancel_requested:
                return self._stop_and_answer(run, 'canceled', 'canceled')
            progress = run.poll(run.move)
            if progress.done:
                if progress.success:
                    return self._answer(run, 'succeed', progress.message, progress.result)
                return self._stop_and_answer(run, 'abort', progress.message, progress.result)
            overdue = run.deadline.exceeded(self._node_now_s(), time.monotonic())
            if overdue is not None:
                return self._stop_and_answer(run, 'abort', overdue)
            if progress.feedback is not None and run.handle is not None:
                run.handle.publish_feedback(progress.feedback)
        except GoalRefused as error:
            self._answer(run, 'abort', str(error))
        except DeviceError as error:
            self._job_failed(run, error)

    def _job_failed(self, run, error):
        """
        Abort a job on a device error, stopping the device first.

        A device that fell silent (no reply after every retry: ``DeviceTimeoutError``) is not
        asked to stop before the goal ends: each try costs as long as the silence was found
        in, and the goal's client (the painter) must hear at once that its device does not
        answer, to take the focus off the wood with what can still move (issue 35: a silent
        Dobot's goal ended after 3.0 s). The link is reset instead; the next connection stops
        the device first (``configure_device``), as soon as it answers again.
        """
        if isinstance(error, DeviceTimeoutError):
            self._link_lost(error)
            label = self.spec.label
            self._answer(run, 'abort', f'{label} silent, {run.what} aborted: {error}; the '
                         f'{label} could NOT be stopped (it does not answer): the link is '
                         'reset and it is stopped as soon as it answers again')
        elif isinstance(error, LinkError):
            self._link_lost(error)
            self._stop_and_answer(run, 'abort', f'link lost, {run.what} aborted: {error}')
        else:
            self._stop_and_answer(run, 'abort', f'device error, {run.what} aborted: {error}')

    def _stop_and_answer(self, run, outcome, message, result=None):
        """Stop the device if the job may have moved it, then answer with what was done."""
        if run.started:
            stopped_result, stopped = self._stop_confirmed()
            message = f'{message}; {stopped}'
            result = stopped_result if stopped_result is not None else result
        self._answer(run, outcome, message, result)

    def _stop_confirmed(self):
        """
        Stop the device and confirm it stands still, retrying for up to ``stop_timeout``.

        A port closed after a timeout is reopened for it. Return (Result or None, what was
        done). When the port is gone, or the stop cannot be confirmed in time, the link is
        closed: the next connection stops the device first (``configure_device``), and the
        text says that the stop is NOT confirmed.
        """
        label = self.spec.label
        deadline = time.monotonic() + self.stop_timeout
        attempts = 0
        while True:
            if not self.client.connected:
                try:
                    self.client.connect()           # closed after a timeout: reopen
                    self.backoff.succeeded()
                except LinkError as error:
                    return None, (f'the {label} could NOT be stopped (its port is gone: '
                                  f'{error}): it is stopped as soon as the link is back')
            attempts += 1
            try:
                result, done = self.stop_device()
                return result, done + (f' after {attempts} attempts' if attempts > 1 else '')
            except LinkError as error:
                self._link_lost(error)
            except DeviceError as error:
                if time.monotonic() >= deadline or self._stopping.is_set():
                    self._link_lost(DeviceError(f'stop not confirmed: {error}'))
                    return None, (f'the {label} could NOT be confirmed stopped within '
                                  f'{self.stop_timeout:.2f} s ({error}); the link is reset '
                                  'and the device is stopped when it answers again')

    def _answer(self, run, outcome, message, result=None):
        """Hand the job's outcome to the waiting coroutine and wake the executor."""
        self._run = None
        run.answer.set_result((outcome, message, result))
        self._answer_ready.trigger()

    # ---- jobs from ROS callbacks (executor thread: never waits on the device) ---------------

    def _claim(self):
        with self._goal_lock:
            if self._busy:
                return False
            self._busy = True
            return True

    def _release(self):
        with self._goal_lock:
            self._busy = False

    def _submit(self, run):
        """Give `run` to the device thread (or answer it at once when shutting down)."""
        if self._stopping.is_set():
            self._answer(run, 'abort', f'{self.spec.label} driver is shutting down')
        else:
            self._run = run
            self._wake.set()
        return run.answer

    async def run_job(self, what, plan, start, poll, limit_s):
        """
        Run a device job from a service callback; return (success, message, result).

        Refused at once (success False) while another job or goal runs.
        """
        if self.emergency.engaged:
            return False, emergency_stop.refusal(what), None
        if not self._claim():
            return False, f'{what} refused: the {self.spec.label} is busy with another job', None
        try:
            run = DeviceJob(what, plan, start, poll, limit_s, 10.0 * limit_s)
            outcome, message, result = await self._submit(run)
            if outcome == 'succeed':
                self.get_logger().info(f'{what} {outcome}: {message}')
            else:
                self.get_logger().warning(f'{what} {outcome}: {message}')
            return outcome == 'succeed', message, result
        finally:
            self._release()

    async def run_call(self, function):
        """Run `function()` once on the device thread; return its value (or raise its error)."""
        answer = Future()

        def call():
            try:
                answer.set_result(('value', function()))
            except Exception as error:   # handed to the awaiting callback
                answer.set_result(('error', error))
            self._answer_ready.trigger()
        self._calls.append(call)
        self._wake.set()
        kind, value = await answer
        if kind == 'error':
            raise value
        return value

    def _accept_goal(self, goal):
        if not self._claim():
            self.get_logger().warning(
                f'{self.spec.action_name} goal rejected: the {self.spec.label} is busy')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _accept_cancel(self, goal_handle):
        self._wake.set()
        return CancelResponse.ACCEPT

    def goal_problem(self, goal):
        """
        Return why a goal's values cannot be a move ('' when they can); no device state.

        Called in the executor before the goal reaches the device thread: a subclass refuses
        non-finite numbers, unknown modes and targets beyond the kinematic limits here, so
        that no bad value is ever handed to the device's client (issue 35).
        """
        return ''

    async def _execute(self, goal_handle):
        try:
            problem = self.goal_problem(goal_handle.request)
            if self.emergency.engaged:
                problem = emergency_stop.refusal(f'{self.spec.action_name} goal')
            if problem:
                result = self.action_type.Result()
                result.success, result.message = False, problem
                goal_handle.abort()
                self.get_logger().warning(f'{self.spec.action_name} refused: {problem}')
                return result
            run = DeviceJob('move', lambda: self.plan_move(goal_handle.request),
                            self.start_move, self.poll_move, self.move_timeout,
                            self.move_wall_timeout, handle=goal_handle)
            outcome, message, result = await self._submit(run)
            result = self.action_type.Result() if result is None else result
            result.success = outcome == 'succeed'
            result.message = message
            getattr(goal_handle, outcome)()
            said = f'{self.spec.action_name} {outcome}: {message}'
            if result.success:
                self.get_logger().info(said)
            else:
                self.get_logger().warning(said)
            return result
        finally:
            self._release()

    # ---- shutdown ---------------------------------------------------------------------------

    async def on_interrupt(self):
        """
        Ctrl-C or SIGTERM: go on serving goals until none has run for ``shutdown_grace``.

        ``run_node`` runs this with the node still up, for at most ``interrupt_timeout``
        (issue 30). ``ros2 launch`` signals every node at once: the lens planner, stopping
        too, retreats a lens left at the heating distance through the drivers, which must
        still answer; ``helio sim`` and ``helio rig`` signal the drivers last, when no goal
        comes any more, and they then stop after the grace.
        """
        quiet_since = time.monotonic()
        while True:
            now = time.monotonic()
            if self._busy:
                quiet_since = now
            elif now - quiet_since >= self.shutdown_grace:
                return
            await sleep(self, 0.02, wall=True)

    def destroy_node(self):
        """Stop the device thread, leave the device stopped, then destroy the node."""
        self._stopping.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=10.0)
        run = self._run
        if run is not None and not run.answer.done():
            self._answer(run, 'abort', f'{self.spec.label} driver shut down mid-move')
        if self.client.connected:
            try:
                result, done = self._stop_confirmed()
            except Exception as error:      # destroy_node must not raise: shutdown goes on
                result, done = None, f'{type(error).__name__}: {error}'
            if result is None:      # (after Ctrl-C the log cannot reach /rosout: no INFO)
                self.get_logger().warning(f'shutdown: {done}')
        self.client.close()
        if self.action_server is not None:
            self.action_server.destroy()
        self._clock_tick.unregister()
        return super().destroy_node()
