"""
Node dobot_driver: the Dobot Magician on a serial port (real arm or the emulator's pty).

- action ``move_arm`` (helio_msgs/MoveArm): MOVJ_XYZ / MOVL_XYZ (x, y, z [m], r [rad],
  robot frame) or MOVJ_ANGLE (j1..j4 [rad]). Targets beyond the joint limits are refused
  before anything moves, naming the joint. The goal succeeds when the device's executed
  queue index reaches the move's index; feedback carries the current pose, the result the
  achieved pose. Cancel force-stops the arm and clears the queue. Limit alarms raised by the
  device during the move abort the goal with their description. A move longer than
  ``move_timeout_s`` on the node clock (or ``move_wall_timeout_s`` of wall time) is stopped
  and aborted.
- ``joint_states`` (sensor_msgs/JointState): dobot_j1..dobot_j4 [rad] at joint_state_rate_hz.
- ``dobot/status`` (helio_msgs/DeviceStatus): link state, reconnect attempts, active alarms.

A lost port (unplugged, or the device stops answering) is reopened with exponential backoff;
meanwhile goals abort at once with a clear message, and a goal in progress aborts as soon as
the link fails. On shutdown the queue is force-stopped and cleared. The link, the device
thread and the action plumbing are ``device_action_node.DeviceActionNode``'s.
"""

from helio_drivers import dobot_protocol as proto
from helio_drivers.device_action_node import (
    DeviceActionNode, DeviceSpec, GoalRefused, MoveProgress)
from helio_drivers.dobot_client import (
    check_target, DobotClient, LIMIT_ALARMS, pose_to_si)
from helio_msgs.action import MoveArm
from helio_optics.arm_kinematics import UnreachableError
from helio_optics.node_parameters import declare
from helio_optics.node_runner import run_node

MODES = {MoveArm.Goal.MOVJ_XYZ: 'MOVJ_XYZ', MoveArm.Goal.MOVL_XYZ: 'MOVL_XYZ',
         MoveArm.Goal.MOVJ_ANGLE: 'MOVJ_ANGLE'}

SPEC = DeviceSpec(device='dobot', label='dobot', action_name='move_arm', port='/dev/ttyUSB0',
                  baudrate_max=4000000, timeout_s=0.2, move_timeout_s=60.0,
                  move_timeout_max_s=3600.0)


def pose_result(pose):
    """Return a MoveArm.Result holding a GetPose reply as the achieved pose (SI)."""
    cartesian, joints = pose_to_si(pose)
    return MoveArm.Result(achieved_cartesian=[float(v) for v in cartesian],
                          achieved_joints=[float(v) for v in joints])


class DobotDriverNode(DeviceActionNode):
    """Serial driver of the Dobot Magician; see the module docstring."""

    def __init__(self, **kwargs):
        """Declare parameters, create the interfaces and start the device thread."""
        super().__init__('dobot_driver', SPEC, MoveArm, DobotClient, **kwargs)
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
        self.start_device()

    # ---- device hooks -----------------------------------------------------------------------

    def configure_device(self):
        """Check the arm answers, set the PTP parameters, start the queue (and home)."""
        self.client.get_pose()            # the device answers, not just the port opens
        self.client.set_ptp_joint_params(self.joint_params)
        self.client.set_ptp_coordinate_params(self.coordinate_params)
        self.client.set_ptp_common_params(self.common_params)
        self.client.queue_start()
        if self.home_on_connect:
            self.client.home()

    def read_joints(self):
        """Return the joint names and j1..j4 [rad]."""
        _, joints = pose_to_si(self.client.get_pose())
        return self.joint_names, joints

    def read_alarms(self):
        """Return the names of the active alarms."""
        return [proto.alarm_description(a) for a in self.client.get_alarms()]

    def plan_move(self, goal):
        """Return (mode, SI target), refusing a bad mode or a target beyond a joint limit."""
        mode = goal.mode
        if mode not in MODES:
            raise GoalRefused(f'mode {mode} is not MOVJ_XYZ (1), MOVL_XYZ (2) or MOVJ_ANGLE (4)')
        target = list(goal.target)
        try:
            check_target(self.client.arm, mode, target)
        except (UnreachableError, ValueError) as error:
            raise GoalRefused(f'{MODES[mode]} target refused: {error}') from error
        return mode, target

    def start_move(self, plan):
        """Clear old alarms (so alarms after the move are its own), queue the move."""
        mode, target = plan
        if self.client.get_alarms():
            self.client.clear_alarms()
        return mode, self.client.move(mode, target)

    def poll_move(self, move):
        """Done when the executed index reaches the move's; limit alarms make it a failure."""
        mode, index = move
        if self.client.executed_index() >= index:
            alarms = [a for a in self.client.get_alarms() if a in LIMIT_ALARMS]
            result = pose_result(self.client.get_pose())
            if alarms:
                return MoveProgress(done=True, result=result, message=(
                    'device refused the move: '
                    + '; '.join(proto.alarm_description(a) for a in alarms)))
            return MoveProgress(done=True, success=True, result=result,
                                message=f'{MODES[mode]} done (index {index})')
        pose = pose_result(self.client.get_pose())
        return MoveProgress(feedback=MoveArm.Feedback(
            current_cartesian=pose.achieved_cartesian, current_joints=pose.achieved_joints))

    def stop_move(self, move):
        """Force-stop the arm, clear and restart the queue; return where it stopped."""
        self.client.stop_and_clear()
        return pose_result(self.client.get_pose()), 'arm force-stopped and queue cleared'

    def stop_device(self):
        """Leave the arm stopped: force-stop and clear the queue."""
        self.client.queue_force_stop()
        self.client.queue_clear()


def main(args=None):
    """Run the node until shutdown."""
    run_node(DobotDriverNode, args)


if __name__ == '__main__':
    main()
