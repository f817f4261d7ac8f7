"""
Node dobot_driver: the Dobot Magician on a serial port (real arm or the emulator's pty).

- action ``move_arm`` (helio_msgs/MoveArm): MOVJ_XYZ / MOVL_XYZ (x, y, z [m], r [rad],
  robot frame) or MOVJ_ANGLE (j1..j4 [rad]). Targets beyond the joint limits are refused
  before anything moves, naming the joint; so is every goal while the arm has an active
  alarm. The goal succeeds when the device's executed queue index reaches the move's index
  AND the arm is at the target (within ``joint_tolerance`` / ``position_tolerance``), so
  a misattributed index cannot report a move done early; feedback carries the current pose,
  the result the achieved pose. An alarm raised during the move aborts it with its
  description. Cancel, a move past ``move_timeout`` (node clock) or ``move_wall_timeout``
  (wall clock), and every device error force-stop the arm, clear the queue and confirm the
  arm stands still before the goal ends (``stop_timeout``).
- services ``dobot/home`` (std_srvs/Trigger): run the homing procedure (the base has an
  incremental encoder), answered when the arm is home (``home_timeout``);
  ``dobot/clear_alarms`` (std_srvs/Trigger): clear the device's alarms, answered with
  what was cleared and what is still active.
- ``joint_states`` (sensor_msgs/JointState): dobot_j1..dobot_j4 [rad] at joint_state_rate.
- ``dobot/status`` (helio_msgs/DeviceStatus): link state, reconnect attempts, active alarms
  (published at once when they change).

The action server and the services exist only while the node has held its device once; a
port held by another process makes the node refuse to start. ``port: auto`` finds the arm
by the USB id of its USB-serial adapter (``usb_ids``). A lost port is reopened with
exponential backoff; meanwhile goals abort at once with a clear message. Every connection
force-stops the arm and clears its queue first. On shutdown the arm is stopped the same
way. The link, the device thread and the action plumbing are
``device_action_node.DeviceActionNode``'s.
"""

import math

from helio_drivers import dobot_protocol as proto
from helio_drivers.device_action_node import (
    DeviceActionNode, DeviceSpec, GoalRefused, MoveProgress)
from helio_drivers.dobot_client import check_target, DobotClient, pose_to_si
from helio_drivers.serial_link import DeviceError
from helio_msgs.action import MoveArm
from helio_optics.arm_kinematics import DobotArm, UnreachableError
from helio_optics.node_kit.deployment import declare_rig
from helio_optics.node_kit.parameters import declare
from helio_optics.node_kit.runner import run_node
from std_srvs.srv import Trigger

MODES = {MoveArm.Goal.MOVJ_XYZ: 'MOVJ_XYZ', MoveArm.Goal.MOVL_XYZ: 'MOVL_XYZ',
         MoveArm.Goal.MOVJ_ANGLE: 'MOVJ_ANGLE'}

# The Magician's USB-serial adapter: Silicon Labs CP210x, on some units a WCH CH340.
DOBOT_USB_IDS = ('10c4:ea60', '1a86:7523', '1a86:55d4')

SPEC = DeviceSpec(device='dobot', label='dobot', action_name='move_arm', port='auto',
                  usb_ids=DOBOT_USB_IDS, baudrate_max=4000000, timeout=0.2,
                  move_timeout=60.0, move_timeout_max=3600.0)

STILL_DEG = 0.01        # joints moving less than this between two polls stand still [deg]


def pose_result(pose):
    """Return a MoveArm.Result holding a GetPose reply as the achieved pose (SI)."""
    cartesian, joints = pose_to_si(pose)
    return MoveArm.Result(achieved_cartesian=[float(v) for v in cartesian],
                          achieved_joints=[float(v) for v in joints])


# The arrays' ranges (a descriptor's range covers scalars only): what the Magician's
# firmware accepts for j1..j4 is not documented; these bound a typing error, not the arm.
JOINT_VELOCITY_MAX_DPS = 1000.0
JOINT_ACCELERATION_MAX_DPS2 = 10000.0


def joint_limits_problem(values, highest):
    """Return what is wrong with four PTP joint limits (each in (0, highest]), or ''."""
    if len(values) != 4:
        return f'needs 4 values (j1..j4), got {len(values)}'
    bad = [f'j{i + 1} {v:g}' for i, v in enumerate(values)
           if not (math.isfinite(v) and 0.0 < v <= highest)]
    return f'{", ".join(bad)} outside (0, {highest:g}]' if bad else ''


class DobotDriverNode(DeviceActionNode):
    """Serial driver of the Dobot Magician; see the module docstring."""

    _dropped_said = 0      # impossible pose replies the status note last said (device thread)

    def __init__(self, **kwargs):
        """Declare parameters, create the interfaces and start the device thread."""
        super().__init__('dobot_driver', SPEC, MoveArm, DobotClient, **kwargs)
        self.joint_params = proto.PtpJointParams(
            tuple(declare(self, 'joint_velocity_dps', [100.0] * 4,
                          f'PTP joint velocities j1..j4 [deg/s], each in (0, '
                          f'{JOINT_VELOCITY_MAX_DPS:g}].')),
            tuple(declare(self, 'joint_acceleration_dps2', [100.0] * 4,
                          f'PTP joint accelerations j1..j4 [deg/s^2], each in (0, '
                          f'{JOINT_ACCELERATION_MAX_DPS2:g}].')))
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
        self.home_timeout = declare(
            self, 'home_timeout', 60.0,
            'Longest time the homing procedure may take on the node clock [s].', 1.0, 600.0)
        self.joint_tolerance = declare(
            self, 'joint_tolerance', 0.0005,
            'A MOVJ_ANGLE move has arrived when every joint is within this of its target '
            '[rad].', 1e-5, 0.1)
        self.position_tolerance = declare(
            self, 'position_tolerance', 0.0002,
            'A Cartesian move has arrived when the flange is within this of its target [m].',
            1e-6, 0.01)
        self.joint_names = list(declare(
            self, 'joint_names', ['dobot_j1', 'dobot_j2', 'dobot_j3', 'dobot_j4'],
            'Names of j1..j4 on /joint_states.'))
        if len(self.joint_names) != 4:
            raise ValueError(f'joint_names needs 4 names, got {self.joint_names}')
        for name, values, highest in (
                ('joint_velocity_dps', self.joint_params.velocity, JOINT_VELOCITY_MAX_DPS),
                ('joint_acceleration_dps2', self.joint_params.acceleration,
                 JOINT_ACCELERATION_MAX_DPS2)):
            problem = joint_limits_problem(values, highest)
            if problem:
                raise ValueError(f'parameter {name}: {problem}')
        rig, _ = declare_rig(self)      # link lengths and joint limits of this arm
        self.client.arm = DobotArm(rig.parameters.arm)
        self.start_device()

    # ---- device hooks -----------------------------------------------------------------------

    def configure_device(self):
        """Stop whatever the arm was doing, set the PTP parameters, start the queue (home)."""
        self.client.get_pose()            # the device answers, not just the port opens
        _, done = self.stop_device()
        self.get_logger().info(f'on connect: {done}')
        self.client.set_ptp_joint_params(self.joint_params)
        self.client.set_ptp_coordinate_params(self.coordinate_params)
        self.client.set_ptp_common_params(self.common_params)
        self.client.queue_start()
        if self.home_on_connect:
            self.client.home()

    def advertise_services(self):
        """Create dobot/home and dobot/clear_alarms."""
        for name, callback in (('dobot/home', self._home),
                               ('dobot/clear_alarms', self._clear_alarms)):
            self.create_device_service(Trigger, name, callback)

    def read_joints(self):
        """Return the joint names and j1..j4 [rad]; impossible poses are said on dobot/status."""
        _, joints = pose_to_si(self.client.get_pose())
        dropped = self.client.impossible_replies
        if dropped != self._dropped_said:       # a new note only when the count changed
            self._dropped_said = dropped
            self.setup_notes['replies'] = (
                f'dropped {dropped} pose replies no Dobot can send (values out of range '
                'behind a valid checksum): noise on the line?')
        return self.joint_names, joints

    def read_alarms(self):
        """Return the names of the active alarms."""
        return [proto.alarm_description(a) for a in self.client.get_alarms()]

    def _refuse_while_alarmed(self, what):
        alarms = self._poll_alarms()
        if alarms:
            raise GoalRefused(
                f'{what} refused: the dobot has active alarms ({"; ".join(alarms)}); remove '
                'the cause, then call the dobot/clear_alarms service (std_srvs/srv/Trigger)')

    def goal_problem(self, goal):
        """Return why a goal is no move: an unknown mode, a non-finite or unreachable target."""
        mode = goal.mode
        if mode not in MODES:
            return f'mode {mode} is not MOVJ_XYZ (1), MOVL_XYZ (2) or MOVJ_ANGLE (4)'
        try:
            check_target(self.client.arm, mode, list(goal.target))
        except (UnreachableError, ValueError) as error:
            return f'{MODES[mode]} target refused: {error}'
        return ''

    def plan_move(self, goal):
        """Return (mode, SI target) of a checked goal (``goal_problem``); refuse an alarm."""
        self._refuse_while_alarmed(f'{MODES[goal.mode]} goal')
        return goal.mode, list(goal.target)

    def start_move(self, plan):
        """Queue the move; return (mode, target, queue index)."""
        mode, target = plan
        return mode, target, self.client.move(mode, target)

    def _arrival_error(self, mode, target, pose):
        """Return how far the arm is from an SI target, or '' when it is there."""
        cartesian, joints = pose_to_si(pose)
        if mode == MoveArm.Goal.MOVJ_ANGLE:
            worst = max(range(4), key=lambda j: abs(joints[j] - target[j]))
            if abs(joints[worst] - target[worst]) <= self.joint_tolerance:
                return ''
            return f'j{worst + 1} is {math.degrees(joints[worst] - target[worst]):+.2f} deg ' \
                   'from its target'
        distance = math.dist(cartesian[:3], target[:3])
        r_error = math.remainder(cartesian[3] - target[3], 2.0 * math.pi)
        if distance <= self.position_tolerance and abs(r_error) <= self.joint_tolerance:
            return ''
        return f'the flange is {distance * 1000.0:.2f} mm and r {math.degrees(r_error):+.2f} ' \
               'deg from the target'

    def poll_move(self, move):
        """Done when the index is executed and the arm is at the target; alarms fail it."""
        mode, target, index = move
        alarms = self.client.get_alarms()
        pose = self.client.get_pose()
        result = pose_result(pose)
        if alarms:
            return MoveProgress(done=True, result=result, message=(
                'device refused the move: '
                + '; '.join(proto.alarm_description(a) for a in alarms)))
        if self.client.executed_index() >= index:
            # the pose above was read before the index: the arm may have moved on to the
            # target since (a CI run reported joints 4e-6 rad short of it); read it again
            pose = self.client.get_pose()
            result = pose_result(pose)
            far = self._arrival_error(mode, target, pose)
            if not far:
                return MoveProgress(done=True, success=True, result=result,
                                    message=f'{MODES[mode]} done (index {index})')
            # Index reached but the arm is not there: the index was not this move's (or it
            # has not settled yet); keep polling until it arrives or the time limit.
        return MoveProgress(feedback=MoveArm.Feedback(
            current_cartesian=result.achieved_cartesian,
            current_joints=result.achieved_joints))

    def stop_device(self):
        """Force-stop, clear and restart the queue; confirm the joints stand still."""
        self.client.stop_and_clear()
        before = self.client.get_pose()
        self._stopping.wait(self.poll_period)       # pacing the two samples
        after = self.client.get_pose()
        moved = max(abs(a - b) for a, b in zip(after.joints, before.joints))
        if moved > STILL_DEG:
            raise DeviceError(f'the arm still moves after force-stop ({moved:.3f} deg in '
                              f'{self.poll_period * 1000.0:.0f} ms)')
        return pose_result(after), 'arm force-stopped and queue cleared (confirmed still)'

    # ---- services ---------------------------------------------------------------------------

    def _start_home(self, plan):
        return 'home', None, self.client.home()

    def _poll_home(self, move):
        _, _, index = move
        alarms = self.client.get_alarms()
        if alarms:
            return MoveProgress(done=True, message='homing failed: ' + '; '.join(
                proto.alarm_description(a) for a in alarms))
        if self.client.executed_index() >= index:
            _, joints = pose_to_si(self.client.get_pose())
            return MoveProgress(done=True, success=True, message='homed: joints ' + ', '.join(
                f'{math.degrees(j):.2f}' for j in joints) + ' deg')
        return MoveProgress()

    async def _home(self, request, response):
        response.success, response.message, _ = await self.run_job(
            'homing', lambda: self._refuse_while_alarmed('homing'), self._start_home,
            self._poll_home, self.home_timeout)
        return response

    def _clear_alarms_now(self):
        if not self.client.connected:
            return False, f'dobot not connected on {self.port} ({self._message})'
        before = self.read_alarms()
        self.client.clear_alarms()
        after = self._poll_alarms()
        self._publish_status()
        if after:
            return False, 'alarms still active after clearing: ' + '; '.join(after)
        return True, ('cleared: ' + '; '.join(before)) if before else 'no alarm was active'

    async def _clear_alarms(self, request, response):
        try:
            response.success, response.message = await self.run_call(self._clear_alarms_now)
        except DeviceError as error:
            response.success, response.message = False, f'clearing alarms failed: {error}'
        self.get_logger().info(f'clear_alarms: {response.message}')
        return response


def main(args=None):
    """Run the node until shutdown."""
    run_node(DobotDriverNode, args)


if __name__ == '__main__':
    main()
