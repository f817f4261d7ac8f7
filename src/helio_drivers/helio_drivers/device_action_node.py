"""
The base both serial driver nodes share: one device thread, one goal at a time, reconnect.

A ``DeviceActionNode`` owns a serial client (``serial_link.SerialClient``) and one thread that
alone talks to it: it reopens a lost port with exponential backoff, polls the joints
(``joint_states`` at ``joint_state_rate_hz``) and the alarms (``<device>/status``,
helio_msgs/DeviceStatus, every ``status_period_s``), and runs the one accepted goal of the
node's action. No ROS callback ever waits on the device: the action's execute callback is a
coroutine that awaits the device thread's answer, and a guard condition wakes the executor
when the answer is there. The nodes therefore run in a plain ``rclpy.spin`` (single-threaded
executor).

Why (the unplug stall): rclpy Jazzy's MultiThreadedExecutor (7.1.6, installed here)
yields a task again while it still waits in the thread pool's queue (ros2/rclpy#1452,
fixed upstream by #1547). With blocking callbacks in the pool, the spinning thread loops on
those tasks holding the GIL and starves the callbacks that talk to the device: measured, the
spin thread stayed runnable for 0.6 s while every other thread waited on the GIL, and the
executor yielded the same three tasks 150-550 times per 50 ms. A node whose callbacks do not
block needs no thread pool.

Time: a move is limited by ``move_timeout_s`` on the node's clock (simulated seconds under
``use_sim_time``) and by ``move_wall_timeout_s`` of wall time (a stopped /clock cannot hold
a goal); the device is polled every ``poll_period_s`` of wall time (see
``node_support.MoveDeadline``).

Subclasses declare their own parameters, then call ``start_device()``, and implement the
device hooks: ``configure_device``, ``read_joints``, ``read_alarms``, ``plan_move``,
``start_move``, ``poll_move``, ``stop_move``, ``stop_device``.
"""

from dataclasses import dataclass
import threading
import time

from helio_drivers.node_support import device_status, MoveDeadline
from helio_drivers.serial_link import DeviceError, LinkError, ReconnectBackoff
from helio_msgs.msg import DeviceStatus
from helio_optics.node_parameters import declare
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
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
    port: str                    # default serial port
    baudrate_max: int            # [bit/s]
    timeout_s: float             # default reply timeout per attempt [s]
    move_timeout_s: float        # default move limit on the node clock [s]
    move_timeout_max_s: float    # its upper bound [s]


@dataclass
class MoveProgress:
    """What one poll of a running move found: feedback, or the outcome once finished."""

    feedback: object = None      # the action's Feedback message while the move runs
    done: bool = False
    success: bool = False
    message: str = ''
    result: object = None        # the action's Result (achieved pose) once done


class _GoalRun:
    """One accepted goal, handed from the executor to the device thread."""

    def __init__(self, handle):
        self.handle = handle
        self.answer = Future()       # (outcome, Result), set by the device thread
        self.move = None             # the subclass's state of the started move
        self.deadline = None


class DeviceActionNode(Node):
    """Serial device + action server plumbing; see the module docstring."""

    def __init__(self, node_name, spec, action_type, client_class, **kwargs):
        """Declare the link parameters and create the client, interfaces and guard."""
        super().__init__(node_name, **kwargs)
        self.spec = spec
        self.action_type = action_type
        self.port = declare(self, 'port', spec.port,
                            f'Serial port of the {spec.label} (device path or emulator link).')
        baudrate = declare(self, 'baudrate', 115200, 'Serial baud rate [bit/s].', 1200,
                           spec.baudrate_max)
        timeout = declare(self, 'timeout_s', spec.timeout_s, 'Reply timeout per attempt [s].',
                          0.005, 10.0)
        retries = declare(self, 'retries', 2, 'Extra attempts after a bad or missing reply.',
                          0, 10)
        rate = declare(self, 'joint_state_rate_hz', 20.0,
                       'Rate of joint polling and /joint_states [Hz].', 0.1, 200.0)
        self.joint_period = 1.0 / rate
        self.status_period = declare(self, 'status_period_s', 1.0,
                                     f'Period of {spec.device}/status and alarm polling [s].',
                                     0.05, 60.0)
        initial = declare(self, 'reconnect_initial_s', 0.2,
                          'First delay before reopening a lost port [s].', 0.01, 60.0)
        maximum = declare(self, 'reconnect_max_s', 5.0,
                          'Longest delay between reconnect attempts [s].', 0.01, 600.0)
        self.poll_period = declare(self, 'poll_period_s', 0.02,
                                   'Wall-clock period of device polling during a move [s].',
                                   0.001, 1.0)
        self.move_timeout = declare(
            self, 'move_timeout_s', spec.move_timeout_s,
            'Longest time a move may take on the node clock (simulated seconds under '
            'use_sim_time) before it is stopped and aborted [s].', 0.1, spec.move_timeout_max_s)
        self.move_wall_timeout = declare(
            self, 'move_wall_timeout_s', 10.0 * spec.move_timeout_s,
            'Longest wall-clock time a move may take whatever the node clock says, so that a '
            'stopped /clock cannot hold a goal [s].', 0.1, 10.0 * spec.move_timeout_max_s)

        self.client = client_class(self.port, baudrate, timeout, retries)
        self.backoff = ReconnectBackoff(initial, maximum)
        self._message = ''
        self._alarms = []
        self._goal_lock = threading.Lock()
        self._busy = False           # a goal is accepted and not yet finished
        self._run = None             # the _GoalRun the device thread works on
        self._wake = threading.Event()
        self._stopping = threading.Event()
        self._thread = None

        self.joint_publisher = self.create_publisher(JointState, 'joint_states', 10)
        self.status_publisher = self.create_publisher(
            DeviceStatus, f'{spec.device}/status',
            QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL))
        # Triggered by the device thread when a goal's answer is ready: wakes the executor,
        # which then resumes the waiting execute coroutine.
        self._answer_ready = self.create_guard_condition(lambda: None)
        self.action_server = ActionServer(
            self, action_type, spec.action_name, self._execute,
            goal_callback=self._accept_goal, cancel_callback=self._accept_cancel)

    def start_device(self):
        """Connect once now, then start the device thread (end of the subclass __init__)."""
        self._connect()
        self._thread = threading.Thread(target=self._device_loop, daemon=True,
                                        name=f'{self.spec.device}-device')
        self._thread.start()

    # ---- device hooks (subclasses) ----------------------------------------------------------

    def configure_device(self):
        """Set up the device after its port opened; raise DeviceError if it does not answer."""
        raise NotImplementedError

    def read_joints(self):
        """Return (joint names, positions [rad]) read from the device."""
        raise NotImplementedError

    def read_alarms(self):
        """Return the device's active alarms or errors, human-readable."""
        raise NotImplementedError

    def plan_move(self, goal):
        """Check a goal and return what start_move needs; GoalRefused before anything moves."""
        raise NotImplementedError

    def start_move(self, plan):
        """Send the move to the device; return the state poll_move and stop_move use."""
        raise NotImplementedError

    def poll_move(self, move):
        """Return the MoveProgress of a started move."""
        raise NotImplementedError

    def stop_move(self, move):
        """Stop the device mid-move; return (Result with the pose it stopped at, what done)."""
        raise NotImplementedError

    def stop_device(self):
        """Leave the device stopped on shutdown (best effort; the port is open)."""
        raise NotImplementedError

    # ---- link -------------------------------------------------------------------------------

    def _connect(self):
        try:
            self.client.connect()
            self.configure_device()
        except DeviceError as error:
            self.client.close()
            delay = self.backoff.failed(time.monotonic())
            self._message = f'{error}; retrying in {delay:.2f} s'
            self.get_logger().warning(self._message, throttle_duration_sec=5.0)
            self._publish_status()
            return False
        attempts = self.backoff.attempts
        self.backoff.succeeded()
        self._message = f'connected to {self.port}' + (
            f' after {attempts} attempts' if attempts else '')
        self.get_logger().info(self._message)
        self._publish_status()
        return True

    def _link_lost(self, error):
        self.client.close()
        if self.backoff.attempts == 0:
            self.backoff.failed(time.monotonic())
        self._message = f'link lost: {error}'
        self.get_logger().error(self._message)
        self._publish_status()

    def _publish_status(self):
        self.status_publisher.publish(device_status(
            self.get_clock().now(), self.spec.device, self.port, self.client.connected,
            self.backoff.attempts, self._alarms, self._message))

    def _publish_joints(self):
        names, positions = self.read_joints()
        message = JointState()
        message.header.stamp = self.get_clock().now().to_msg()
        message.name = list(names)
        message.position = [float(p) for p in positions]
        self.joint_publisher.publish(message)

    # ---- device thread ----------------------------------------------------------------------

    def _device_loop(self):
        schedule = {'joints': time.monotonic(), 'status': time.monotonic()}
        while not self._stopping.is_set():
            self._wake.clear()           # before looking: a wake from now on is not lost
            try:
                self._device_cycle(schedule)
            except Exception as error:   # a bug must not end the thread and strand a goal
                self._driver_error(error)
            wake_at = min(schedule.values())
            if not self.client.connected:
                wake_at = min(wake_at, self.backoff.next_attempt_at)
            if self._run is not None:
                wake_at = min(wake_at, time.monotonic() + self.poll_period)
            self._wake.wait(max(0.0, wake_at - time.monotonic()))

    def _driver_error(self, error):
        """Log an unexpected error; stop and abort the goal it hit (best effort)."""
        self.get_logger().error(f'{self.spec.device} device thread: {type(error).__name__}: '
                                f'{error}', throttle_duration_sec=5.0)
        run = self._run
        if run is None:
            return
        if run.move is not None and self.client.connected:
            try:
                self.stop_move(run.move)
            except Exception:            # best effort: the goal is aborted either way
                pass
        self._answer(run, 'abort', f'driver error, move aborted: {error}')

    def _device_cycle(self, schedule):
        """Reconnect when due, advance the goal, poll joints and status when due."""
        now = time.monotonic()
        if not self.client.connected and self.backoff.due(now):
            self._connect()
        run = self._run
        if run is not None:
            self._step_goal(run)
        if self.client.connected and now >= schedule['joints']:
            schedule['joints'] = now + self.joint_period
            try:
                self._publish_joints()
            except DeviceError as error:     # unplugged, or no answer after every retry
                self._link_lost(error)
        if now >= schedule['status']:
            schedule['status'] = now + self.status_period
            if self.client.connected:
                try:
                    self._alarms = self.read_alarms()
                except DeviceError as error:
                    self._link_lost(error)
            self._publish_status()

    def _node_now_s(self):
        return self.get_clock().now().nanoseconds * 1e-9

    def _step_goal(self, run):
        """Advance the goal by one poll; answer it when it ends."""
        label = self.spec.label
        try:
            if run.move is None:
                if run.handle.is_cancel_requested:
                    return self._answer(run, 'canceled', 'canceled before the move started')
                if not self.client.connected:
                    return self._answer(run, 'abort',
                                        f'{label} not connected on {self.port} '
                                        f'({self._message}); reconnecting in the background')
                try:
                    plan = self.plan_move(run.handle.request)
                except GoalRefused as error:
                    return self._answer(run, 'abort', str(error))
                run.move = self.start_move(plan)
                run.deadline = MoveDeadline(self.move_timeout, self.move_wall_timeout,
                                            self._node_now_s(), time.monotonic())
            if run.handle.is_cancel_requested:
                result, stopped = self.stop_move(run.move)
                return self._answer(run, 'canceled', f'canceled: {stopped}', result)
            progress = self.poll_move(run.move)
            if progress.done:
                return self._answer(run, 'succeed' if progress.success else 'abort',
                                    progress.message, progress.result)
            overdue = run.deadline.exceeded(self._node_now_s(), time.monotonic())
            if overdue is not None:
                result, stopped = self.stop_move(run.move)
                return self._answer(run, 'abort', f'{overdue}; {stopped}', result)
            if progress.feedback is not None:
                run.handle.publish_feedback(progress.feedback)
        except LinkError as error:
            self._link_lost(error)
            self._answer(run, 'abort', f'link lost, move aborted: {error}')
        except DeviceError as error:
            self._answer(run, 'abort', f'device error, move aborted: {error}')

    def _answer(self, run, outcome, message, result=None):
        """Hand the goal's outcome to the execute coroutine and wake the executor."""
        result = self.action_type.Result() if result is None else result
        result.success = outcome == 'succeed'
        result.message = message
        self._run = None
        run.answer.set_result((outcome, result))
        self._answer_ready.trigger()

    # ---- action (executor thread: never waits on the device) --------------------------------

    def _accept_goal(self, goal):
        with self._goal_lock:
            if self._busy:
                self.get_logger().warning(
                    f'{self.spec.action_name} goal rejected: another move is running')
                return GoalResponse.REJECT
            self._busy = True
        return GoalResponse.ACCEPT

    def _accept_cancel(self, goal_handle):
        self._wake.set()
        return CancelResponse.ACCEPT

    async def _execute(self, goal_handle):
        run = _GoalRun(goal_handle)
        try:
            if self._stopping.is_set():
                self._answer(run, 'abort', f'{self.spec.label} driver is shutting down')
            else:
                self._run = run
                self._wake.set()
            outcome, result = await run.answer
            getattr(goal_handle, outcome)()
            said = f'{self.spec.action_name} {outcome}: {result.message}'
            if result.success:
                self.get_logger().info(said)
            else:
                self.get_logger().warning(said)
            return result
        finally:
            with self._goal_lock:
                self._busy = False

    # ---- shutdown ---------------------------------------------------------------------------

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
                self.stop_device()
            except DeviceError as error:
                self.get_logger().warning(f'could not stop the {self.spec.label} on '
                                          f'shutdown: {error}')
        self.client.close()
        self.action_server.destroy()
        return super().destroy_node()
