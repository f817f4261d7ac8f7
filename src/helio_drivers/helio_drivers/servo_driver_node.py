"""
Node servo_driver: the two wrist servos (lens yaw, lens pitch) on a Pololu Maestro.

- action ``move_wrist`` (helio_msgs/MoveWrist): yaw and pitch [rad] are converted to pulse
  widths with each channel's calibration (``yaw.*``, ``pitch.*`` parameters, see
  config/servo_driver.yaml); an angle outside a channel's pulse range is refused naming the
  joint. The goal succeeds when both reported positions are within
  ``position_tolerance_us`` of their targets; feedback carries the current angles. Cancel
  holds both servos where they are.
- ``joint_states``: lens_yaw, lens_pitch [rad] at ``joint_state_rate_hz``.
- ``servo/status`` (helio_msgs/DeviceStatus): link state, reconnect attempts, Maestro errors.

A lost port is reopened with exponential backoff while goals abort at once; on shutdown
both servos are held at their current positions.
"""

import threading
import time

from helio_drivers import maestro_protocol as proto
from helio_drivers.maestro_client import MaestroClient
from helio_drivers.node_support import device_status
from helio_drivers.serial_link import DeviceError, LinkError, ReconnectBackoff
from helio_msgs.action import MoveWrist
from helio_msgs.msg import DeviceStatus
from helio_optics.node_parameters import declare
import rclpy
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

AXES = ('yaw', 'pitch')


def declare_calibration(node, axis, joint_name, channel):
    """Declare one servo's calibration parameters (prefix `axis.`) and build it."""
    prefix = f'{axis}.'
    calibration = proto.ServoCalibration(
        name=declare(node, prefix + 'joint_name', joint_name,
                     f'Name of the {axis} servo on /joint_states.'),
        channel=declare(node, prefix + 'channel', channel, 'Maestro channel.', 0, 23),
        min_pulse_us=declare(node, prefix + 'min_pulse_us', 500.0,
                             'Lowest pulse width allowed [us].', 100.0, 4000.0),
        max_pulse_us=declare(node, prefix + 'max_pulse_us', 2500.0,
                             'Highest pulse width allowed [us].', 100.0, 4000.0),
        centre_pulse_us=declare(node, prefix + 'centre_pulse_us', 1500.0,
                                'Pulse width at the zero-offset angle [us].', 100.0, 4000.0),
        us_per_rad=declare(node, prefix + 'us_per_rad', 636.6197723675814,
                           'Pulse width change per radian [us/rad].', 1.0, 10000.0),
        direction=declare(node, prefix + 'direction', 1,
                          'Sign between angle and pulse width (+1 or -1).', -1, 1),
        zero_offset_rad=declare(node, prefix + 'zero_offset_rad', 0.0,
                                'Joint angle at the centre pulse [rad].', -3.2, 3.2))
    speed = declare(node, prefix + 'speed_us_per_s', 1000.0,
                    'Pulse-width speed limit [us/s] (0 = unlimited).', 0.0, 400000.0)
    acceleration = declare(node, prefix + 'acceleration_us_per_s2', 5000.0,
                           'Pulse-width acceleration limit [us/s^2] (0 = unlimited).',
                           0.0, 80000.0)
    return calibration, proto.speed_units(speed), proto.acceleration_units(acceleration)


class ServoDriverNode(Node):
    """Serial driver of the lens wrist servos; see the module docstring."""

    def __init__(self, **kwargs):
        """Declare parameters, create the interfaces and try to connect."""
        super().__init__('servo_driver', **kwargs)
        self.port = declare(self, 'port', '/dev/ttyACM0',
                            'Serial port of the Maestro (command port or the emulator link).')
        baudrate = declare(self, 'baudrate', 115200, 'Serial baud rate [bit/s].', 1200, 250000)
        timeout = declare(self, 'timeout_s', 0.1, 'Reply timeout per attempt [s].', 0.005, 10.0)
        retries = declare(self, 'retries', 2, 'Extra attempts after a missing reply.', 0, 10)
        rate = declare(self, 'joint_state_rate_hz', 20.0,
                       'Rate of position polling and /joint_states [Hz].', 0.1, 200.0)
        status_period = declare(self, 'status_period_s', 1.0,
                                'Period of servo/status and error polling [s].', 0.05, 60.0)
        initial = declare(self, 'reconnect_initial_s', 0.2,
                          'First delay before reopening a lost port [s].', 0.01, 60.0)
        maximum = declare(self, 'reconnect_max_s', 5.0,
                          'Longest delay between reconnect attempts [s].', 0.01, 600.0)
        self.poll_period = declare(self, 'poll_period_s', 0.02,
                                   'Period of position polling during a move [s].', 0.001, 1.0)
        self.move_timeout = declare(self, 'move_timeout_s', 10.0,
                                    'Longest time a wrist move may take [s].', 0.1, 600.0)
        self.tolerance_qus = 4.0 * declare(
            self, 'position_tolerance_us', 1.0,
            'A servo has arrived when within this pulse width of its target [us].', 0.25, 100.0)
        self.axes = {}
        for axis, joint, channel in (('yaw', 'lens_yaw', 0), ('pitch', 'lens_pitch', 1)):
            self.axes[axis] = declare_calibration(self, axis, joint, channel)
        channels = [c.channel for c, _, _ in self.axes.values()]
        if len(set(channels)) != len(channels):
            raise ValueError(f'yaw and pitch need different channels, got {channels}')

        self.client = MaestroClient(self.port, baudrate, timeout, retries)
        self.backoff = ReconnectBackoff(initial, maximum)
        self._message = ''
        self._errors = []
        self._goal_lock = threading.Lock()
        self._active_goal = None
        self._wake = threading.Event()

        self.joint_publisher = self.create_publisher(JointState, 'joint_states', 10)
        self.status_publisher = self.create_publisher(
            DeviceStatus, 'servo/status',
            QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL))
        link_group = MutuallyExclusiveCallbackGroup()
        self.create_timer(1.0 / rate, self._poll, callback_group=link_group)
        self.create_timer(status_period, self._poll_status, callback_group=link_group)
        self.action_server = ActionServer(
            self, MoveWrist, 'move_wrist', self._execute, goal_callback=self._accept_goal,
            cancel_callback=self._accept_cancel, callback_group=ReentrantCallbackGroup())
        self._connect()

    # ---- link -------------------------------------------------------------------------------

    def _connect(self):
        try:
            self.client.connect()
            for calibration, speed, acceleration in self.axes.values():
                self.client.set_speed(calibration.channel, speed)
                self.client.set_acceleration(calibration.channel, acceleration)
            self.client.get_errors()          # the device answers (and stale errors go)
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
        self._wake.set()
        self._publish_status()

    def _positions_qus(self):
        return {axis: self.client.get_position(c.channel)
                for axis, (c, _, _) in self.axes.items()}

    def _angles(self, positions_qus):
        return {axis: self.axes[axis][0].angle(q / 4.0) for axis, q in positions_qus.items()}

    def _poll(self):
        if not self.client.connected:
            if self.backoff.due(time.monotonic()):
                self._connect()
            return
        try:
            angles = self._angles(self._positions_qus())
        except DeviceError as error:
            self._link_lost(error)
            return
        message = JointState()
        message.header.stamp = self.get_clock().now().to_msg()
        message.name = [self.axes[axis][0].name for axis in AXES]
        message.position = [float(angles[axis]) for axis in AXES]
        self.joint_publisher.publish(message)

    def _poll_status(self):
        if self.client.connected:
            try:
                errors = self.client.get_errors()
            except DeviceError as error:
                self._link_lost(error)
                return
            self._errors = proto.error_descriptions(errors)
            if errors:
                self.get_logger().warning(f'Maestro errors: {", ".join(self._errors)}')
        self._publish_status()

    def _publish_status(self):
        self.status_publisher.publish(device_status(
            self.get_clock().now(), 'servo', self.port, self.client.connected,
            self.backoff.attempts, self._errors, self._message))

    # ---- action -----------------------------------------------------------------------------

    def _accept_goal(self, goal):
        with self._goal_lock:
            if self._active_goal is not None:
                self.get_logger().warning('move_wrist goal rejected: another move is running')
                return GoalResponse.REJECT
            self._active_goal = goal
        return GoalResponse.ACCEPT

    def _accept_cancel(self, goal_handle):
        self._wake.set()
        return CancelResponse.ACCEPT

    def _execute(self, goal_handle):
        try:
            return self._run_goal(goal_handle)
        finally:
            with self._goal_lock:
                self._active_goal = None

    def _finish(self, goal_handle, outcome, message, positions_qus=None):
        result = MoveWrist.Result()
        result.success = outcome == 'succeed'
        result.message = message
        if positions_qus is not None:
            angles = self._angles(positions_qus)
            result.achieved_yaw, result.achieved_pitch = angles['yaw'], angles['pitch']
        getattr(goal_handle, outcome)()
        if result.success:
            self.get_logger().info(f'move_wrist {outcome}: {message}')
        else:
            self.get_logger().warning(f'move_wrist {outcome}: {message}')
        return result

    def _hold(self):
        """Stop both servos where they are (target = current position); return positions."""
        positions = self._positions_qus()
        for axis, (calibration, _, _) in self.axes.items():
            self.client.set_target(calibration.channel, positions[axis])
        # Set Target has no reply: a query answered after it proves the device has it.
        return self._positions_qus()

    def _run_goal(self, goal_handle):
        goal = goal_handle.request
        if not self.client.connected:
            return self._finish(goal_handle, 'abort',
                                f'servo controller not connected on {self.port} '
                                f'({self._message}); reconnecting in the background')
        try:
            targets = {'yaw': self.axes['yaw'][0].quarter_us(goal.yaw),
                       'pitch': self.axes['pitch'][0].quarter_us(goal.pitch)}
        except ValueError as error:
            return self._finish(goal_handle, 'abort', f'wrist target refused: {error}')
        self._wake.clear()
        try:
            for axis, target in targets.items():
                self.client.set_target(self.axes[axis][0].channel, target)
            deadline = time.monotonic() + self.move_timeout
            while True:
                if goal_handle.is_cancel_requested:
                    positions = self._hold()
                    return self._finish(goal_handle, 'canceled',
                                        'canceled: servos held where they were', positions)
                positions = self._positions_qus()
                if all(abs(positions[a] - targets[a]) <= self.tolerance_qus for a in targets):
                    return self._finish(goal_handle, 'succeed', 'wrist at target', positions)
                if time.monotonic() > deadline:
                    positions = self._hold()
                    return self._finish(goal_handle, 'abort',
                                        f'servos not at target within {self.move_timeout:.1f} '
                                        's; held where they were', positions)
                angles = self._angles(positions)
                goal_handle.publish_feedback(MoveWrist.Feedback(
                    current_yaw=angles['yaw'], current_pitch=angles['pitch']))
                if not self.client.connected:
                    raise LinkError('link lost during the move')
                self._wake.wait(self.poll_period)
        except LinkError as error:
            self._link_lost(error)
            return self._finish(goal_handle, 'abort', f'link lost, move aborted: {error}')
        except DeviceError as error:
            return self._finish(goal_handle, 'abort', f'device error, move aborted: {error}')

    # ---- shutdown ---------------------------------------------------------------------------

    def stop_device(self):
        """Leave the servos stopped: hold them at their current positions (best effort)."""
        if self.client.connected:
            try:
                self._hold()
            except DeviceError as error:
                self.get_logger().warning(f'could not stop the servos on shutdown: {error}')
        self.client.close()

    def destroy_node(self):
        """Stop the device, then destroy the node."""
        self.stop_device()
        self.action_server.destroy()
        return super().destroy_node()


def main(args=None):
    """Run the node until shutdown."""
    rclpy.init(args=args)
    node = None
    try:
        node = ServoDriverNode()
        executor = MultiThreadedExecutor(num_threads=3)
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
