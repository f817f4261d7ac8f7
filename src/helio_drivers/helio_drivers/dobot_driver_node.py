"""
Node dobot_driver: the Dobot Magician on a serial port (real arm or the emulator's pty).

- action ``move_arm`` (helio_msgs/MoveArm): MOVJ_XYZ / MOVL_XYZ (x, y, z [m], r [rad],
  robot frame) or MOVJ_ANGLE (j1..j4 [rad]). Targets beyond the joint limits are refused
  before anything moves, naming the joint. The goal succeeds when the device's executed
  queue index reaches the move's index; feedback carries the current pose, the result the
  achieved pose. Cancel force-stops the arm and clears the queue. Limit alarms raised by the
  device during the move abort the goal with their description.
- ``joint_states`` (sensor_msgs/JointState): dobot_j1..dobot_j4 [rad] at joint_state_rate_hz.
- ``dobot/status`` (helio_msgs/DeviceStatus): link state, reconnect attempts, active alarms.

A lost port (unplugged, or the device stops answering) is reopened with exponential backoff;
meanwhile goals abort at once with a clear message, and a goal in progress aborts as soon as
the link fails. On shutdown the queue is force-stopped and cleared.
"""

import threading
import time

from helio_drivers import dobot_protocol as proto
from helio_drivers.dobot_client import (
    check_target, DobotClient, LIMIT_ALARMS, pose_to_si)
from helio_drivers.node_support import device_status
from helio_drivers.serial_link import DeviceError, LinkError, ReconnectBackoff
from helio_msgs.action import MoveArm
from helio_msgs.msg import DeviceStatus
from helio_optics.arm_kinematics import UnreachableError
from helio_optics.node_parameters import declare
import rclpy
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

MODES = {MoveArm.Goal.MOVJ_XYZ: 'MOVJ_XYZ', MoveArm.Goal.MOVL_XYZ: 'MOVL_XYZ',
         MoveArm.Goal.MOVJ_ANGLE: 'MOVJ_ANGLE'}


class DobotDriverNode(Node):
    """Serial driver of the Dobot Magician; see the module docstring."""

    def __init__(self, **kwargs):
        """Declare parameters, create the interfaces and try to connect."""
        super().__init__('dobot_driver', **kwargs)
        self.port = declare(self, 'port', '/dev/ttyUSB0',
                            'Serial port of the Dobot (device path or the emulator link).')
        baudrate = declare(self, 'baudrate', 115200, 'Serial baud rate [bit/s].', 1200, 4000000)
        timeout = declare(self, 'timeout_s', 0.2, 'Reply timeout per attempt [s].', 0.005, 10.0)
        retries = declare(self, 'retries', 2, 'Extra attempts after a bad or missing reply.',
                          0, 10)
        rate = declare(self, 'joint_state_rate_hz', 20.0,
                       'Rate of pose polling and /joint_states [Hz].', 0.1, 200.0)
        status_period = declare(self, 'status_period_s', 1.0,
                                'Period of dobot/status and alarm polling [s].', 0.05, 60.0)
        initial = declare(self, 'reconnect_initial_s', 0.2,
                          'First delay before reopening a lost port [s].', 0.01, 60.0)
        maximum = declare(self, 'reconnect_max_s', 5.0,
                          'Longest delay between reconnect attempts [s].', 0.01, 600.0)
        self.poll_period = declare(self, 'poll_period_s', 0.02,
                                   'Period of executed-index polling during a move [s].',
                                   0.001, 1.0)
        self.move_timeout = declare(self, 'move_timeout_s', 60.0,
                                    'Longest time a move may take before it is stopped [s].',
                                    0.1, 3600.0)
        self.joint_params = proto.PtpJointParams(
            tuple(declare(self, 'joint_velocity_dps', [100.0] * 4,
                          'PTP joint velocities j1..j4 [deg/s].')),
            tuple(declare(self, 'joint_acceleration_dps2', [100.0] * 4,
                          'PTP joint accelerations j1..j4 [deg/s^2].')))
        self.coordinate_params = proto.PtpCoordinateParams(
            declare(self, 'xyz_velocity_mmps', 100.0, 'PTP Cartesian velocity [mm/s].',
                    1.0, 1000.0),
            declare(self, 'r_velocity_dps', 100.0, 'PTP end rotation velocity [deg/s].',
                    1.0, 1000.0),
            declare(self, 'xyz_acceleration_mmps2', 100.0,
                    'PTP Cartesian acceleration [mm/s^2].', 1.0, 10000.0),
            declare(self, 'r_acceleration_dps2', 100.0,
                    'PTP end rotation acceleration [deg/s^2].', 1.0, 10000.0))
        self.common_params = proto.PtpCommonParams(
            declare(self, 'velocity_ratio_percent', 100.0,
                    'PTP velocity ratio applied to every move [%].', 1.0, 100.0),
            declare(self, 'acceleration_ratio_percent', 100.0,
                    'PTP acceleration ratio applied to every move [%].', 1.0, 100.0))
        self.home_on_connect = declare(self, 'home_on_connect', False,
                                       'Run the homing procedure after (re)connecting.')
        self.joint_names = list(declare(
            self, 'joint_names', ['dobot_j1', 'dobot_j2', 'dobot_j3', 'dobot_j4'],
            'Names of j1..j4 on /joint_states.'))
        if len(self.joint_names) != 4:
            raise ValueError(f'joint_names needs 4 names, got {self.joint_names}')
        if len(self.joint_params.velocity) != 4 or len(self.joint_params.acceleration) != 4:
            raise ValueError('joint_velocity_dps and joint_acceleration_dps2 need 4 values')

        self.client = DobotClient(self.port, baudrate, timeout, retries)
        self.backoff = ReconnectBackoff(initial, maximum)
        self._message = ''
        self._alarms = []
        self._goal_lock = threading.Lock()
        self._active_goal = None
        self._wake = threading.Event()

        self.joint_publisher = self.create_publisher(JointState, 'joint_states', 10)
        self.status_publisher = self.create_publisher(
            DeviceStatus, 'dobot/status',
            QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL))
        link_group = MutuallyExclusiveCallbackGroup()
        self.create_timer(1.0 / rate, self._poll, callback_group=link_group)
        self.create_timer(status_period, self._poll_status, callback_group=link_group)
        self.action_server = ActionServer(
            self, MoveArm, 'move_arm', self._execute, goal_callback=self._accept_goal,
            cancel_callback=self._accept_cancel, callback_group=ReentrantCallbackGroup())
        self._connect()

    # ---- link -------------------------------------------------------------------------------

    def _connect(self):
        try:
            self.client.connect()
            self.client.get_pose()            # the device answers, not just the port opens
            self.client.set_ptp_joint_params(self.joint_params)
            self.client.set_ptp_coordinate_params(self.coordinate_params)
            self.client.set_ptp_common_params(self.common_params)
            self.client.queue_start()
            if self.home_on_connect:
                self.client.home()
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

    def _poll(self):
        if not self.client.connected:
            if self.backoff.due(time.monotonic()):
                self._connect()
            return
        try:
            pose = self.client.get_pose()
        except DeviceError as error:     # unplugged, or no answer after every retry
            self._link_lost(error)
            return
        self._publish_joints(pose)

    def _poll_status(self):
        if self.client.connected:
            try:
                self._alarms = [proto.alarm_description(a) for a in self.client.get_alarms()]
            except DeviceError as error:
                self._link_lost(error)
                return
        self._publish_status()

    def _publish_joints(self, pose):
        _, joints = pose_to_si(pose)
        message = JointState()
        message.header.stamp = self.get_clock().now().to_msg()
        message.name = list(self.joint_names)
        message.position = [float(j) for j in joints]
        self.joint_publisher.publish(message)

    def _publish_status(self):
        self.status_publisher.publish(device_status(
            self.get_clock().now(), 'dobot', self.port, self.client.connected,
            self.backoff.attempts, self._alarms, self._message))

    # ---- action -----------------------------------------------------------------------------

    def _accept_goal(self, goal):
        with self._goal_lock:
            if self._active_goal is not None:
                self.get_logger().warning('move_arm goal rejected: another move is running')
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

    def _finish(self, goal_handle, outcome, message, pose=None):
        result = MoveArm.Result()
        result.success = outcome == 'succeed'
        result.message = message
        if pose is not None:
            cartesian, joints = pose_to_si(pose)
            result.achieved_cartesian = [float(v) for v in cartesian]
            result.achieved_joints = [float(v) for v in joints]
        getattr(goal_handle, outcome)()
        if result.success:
            self.get_logger().info(f'move_arm {outcome}: {message}')
        else:
            self.get_logger().warning(f'move_arm {outcome}: {message}')
        return result

    def _run_goal(self, goal_handle):
        goal = goal_handle.request
        mode = goal.mode
        if mode not in MODES:
            return self._finish(goal_handle, 'abort',
                                f'mode {mode} is not MOVJ_XYZ (1), MOVL_XYZ (2) or MOVJ_ANGLE (4)')
        if not self.client.connected:
            return self._finish(goal_handle, 'abort',
                                f'dobot not connected on {self.port} ({self._message}); '
                                'reconnecting in the background')
        target = list(goal.target)
        try:
            check_target(self.client.arm, mode, target)
        except (UnreachableError, ValueError) as error:
            return self._finish(goal_handle, 'abort', f'{MODES[mode]} target refused: {error}')
        self._wake.clear()
        try:
            if self.client.get_alarms():
                self.client.clear_alarms()    # so alarms seen after the move are this move's
            index = self.client.move(mode, target)
            deadline = time.monotonic() + self.move_timeout
            while True:
                if goal_handle.is_cancel_requested:
                    self.client.stop_and_clear()
                    return self._finish(goal_handle, 'canceled',
                                        'canceled: arm force-stopped and queue cleared',
                                        self.client.get_pose())
                if self.client.executed_index() >= index:
                    break
                if time.monotonic() > deadline:
                    self.client.stop_and_clear()
                    return self._finish(goal_handle, 'abort',
                                        f'move not finished within {self.move_timeout:.1f} s; '
                                        'arm stopped', self.client.get_pose())
                pose = self.client.get_pose()
                feedback = MoveArm.Feedback()
                cartesian, joints = pose_to_si(pose)
                feedback.current_cartesian = [float(v) for v in cartesian]
                feedback.current_joints = [float(v) for v in joints]
                goal_handle.publish_feedback(feedback)
                if not self.client.connected:
                    raise LinkError('link lost during the move')
                self._wake.wait(self.poll_period)
            alarms = [a for a in self.client.get_alarms() if a in LIMIT_ALARMS]
            pose = self.client.get_pose()
            if alarms:
                return self._finish(goal_handle, 'abort', 'device refused the move: ' + '; '.join(
                    proto.alarm_description(a) for a in alarms), pose)
            return self._finish(goal_handle, 'succeed', f'{MODES[mode]} done (index {index})',
                                pose)
        except LinkError as error:
            self._link_lost(error)
            return self._finish(goal_handle, 'abort', f'link lost, move aborted: {error}')
        except DeviceError as error:
            return self._finish(goal_handle, 'abort', f'device error, move aborted: {error}')

    # ---- shutdown ---------------------------------------------------------------------------

    def stop_device(self):
        """Leave the arm stopped: force-stop and clear the queue (best effort)."""
        if self.client.connected:
            try:
                self.client.queue_force_stop()
                self.client.queue_clear()
            except DeviceError as error:
                self.get_logger().warning(f'could not stop the arm on shutdown: {error}')
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
        node = DobotDriverNode()
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
