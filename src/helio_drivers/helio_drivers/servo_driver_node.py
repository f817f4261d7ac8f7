"""
Node servo_driver: the two wrist servos (lens yaw, lens pitch) on a Pololu Maestro.

- action ``move_wrist`` (helio_msgs/MoveWrist): yaw and pitch [rad] are converted to pulse
  widths with each channel's calibration (``yaw.*``, ``pitch.*`` parameters, see
  config/servo_driver.yaml); an angle outside a channel's pulse range is refused naming the
  joint. The goal succeeds when both reported positions are within
  ``position_tolerance_us`` of their targets; feedback carries the current angles. Cancel
  holds both servos where they are, and so does a move longer than ``move_timeout_s`` on the
  node clock (or ``move_wall_timeout_s`` of wall time), which is aborted.
- ``joint_states``: lens_yaw, lens_pitch [rad] at ``joint_state_rate_hz``.
- ``servo/status`` (helio_msgs/DeviceStatus): link state, reconnect attempts, Maestro errors.

A lost port is reopened with exponential backoff while goals abort at once; on shutdown
both servos are held at their current positions. The link, the device thread and the
action plumbing are ``device_action_node.DeviceActionNode``'s.
"""

from helio_drivers import maestro_protocol as proto
from helio_drivers.device_action_node import (
    DeviceActionNode, DeviceSpec, GoalRefused, MoveProgress)
from helio_drivers.maestro_client import MaestroClient
from helio_msgs.action import MoveWrist
from helio_optics.node_parameters import declare
from helio_optics.node_runner import run_node

AXES = ('yaw', 'pitch')

SPEC = DeviceSpec(device='servo', label='servo controller', action_name='move_wrist',
                  port='/dev/ttyACM0', baudrate_max=250000, timeout_s=0.1,
                  move_timeout_s=10.0, move_timeout_max_s=600.0)


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


class ServoDriverNode(DeviceActionNode):
    """Serial driver of the lens wrist servos; see the module docstring."""

    def __init__(self, **kwargs):
        """Declare parameters, create the interfaces and start the device thread."""
        super().__init__('servo_driver', SPEC, MoveWrist, MaestroClient, **kwargs)
        self.tolerance_qus = 4.0 * declare(
            self, 'position_tolerance_us', 1.0,
            'A servo has arrived when within this pulse width of its target [us].', 0.25, 100.0)
        self.axes = {}
        for axis, joint, channel in (('yaw', 'lens_yaw', 0), ('pitch', 'lens_pitch', 1)):
            self.axes[axis] = declare_calibration(self, axis, joint, channel)
        channels = [c.channel for c, _, _ in self.axes.values()]
        if len(set(channels)) != len(channels):
            raise ValueError(f'yaw and pitch need different channels, got {channels}')
        self.start_device()

    def _positions_qus(self):
        return {axis: self.client.get_position(c.channel)
                for axis, (c, _, _) in self.axes.items()}

    def _angles(self, positions_qus):
        return {axis: self.axes[axis][0].angle(q / 4.0) for axis, q in positions_qus.items()}

    def _result(self, positions_qus):
        angles = self._angles(positions_qus)
        return MoveWrist.Result(achieved_yaw=angles['yaw'], achieved_pitch=angles['pitch'])

    def _hold(self):
        """Stop both servos where they are (target = current position); return positions."""
        positions = self._positions_qus()
        for axis, (calibration, _, _) in self.axes.items():
            self.client.set_target(calibration.channel, positions[axis])
        # Set Target has no reply: a query answered after it proves the device has it.
        return self._positions_qus()

    # ---- device hooks -----------------------------------------------------------------------

    def configure_device(self):
        """Set each channel's speed and acceleration limits; check the Maestro answers."""
        for calibration, speed, acceleration in self.axes.values():
            self.client.set_speed(calibration.channel, speed)
            self.client.set_acceleration(calibration.channel, acceleration)
        self.client.get_errors()          # the device answers (and stale errors go)

    def read_joints(self):
        """Return the joint names and the yaw, pitch angles [rad]."""
        angles = self._angles(self._positions_qus())
        return [self.axes[axis][0].name for axis in AXES], [angles[axis] for axis in AXES]

    def read_alarms(self):
        """Return (and clear) the Maestro's error bits by name, logging any."""
        errors = proto.error_descriptions(self.client.get_errors())
        if errors:
            self.get_logger().warning(f'Maestro errors: {", ".join(errors)}')
        return errors

    def plan_move(self, goal):
        """Return each axis's target [quarter-us]; an angle out of range names the joint."""
        try:
            return {axis: self.axes[axis][0].quarter_us(getattr(goal, axis)) for axis in AXES}
        except ValueError as error:
            raise GoalRefused(f'wrist target refused: {error}') from error

    def start_move(self, plan):
        """Set both targets."""
        for axis, target in plan.items():
            self.client.set_target(self.axes[axis][0].channel, target)
        return plan

    def poll_move(self, move):
        """Done when both read-back positions are within the tolerance of their targets."""
        positions = self._positions_qus()
        if all(abs(positions[a] - move[a]) <= self.tolerance_qus for a in move):
            return MoveProgress(done=True, success=True, message='wrist at target',
                                result=self._result(positions))
        angles = self._angles(positions)
        return MoveProgress(feedback=MoveWrist.Feedback(current_yaw=angles['yaw'],
                                                        current_pitch=angles['pitch']))

    def stop_move(self, move):
        """Hold both servos where they are; return where that is."""
        return self._result(self._hold()), 'servos held where they were'

    def stop_device(self):
        """Leave the servos stopped: hold them at their current positions."""
        self._hold()


def main(args=None):
    """Run the node until shutdown."""
    run_node(ServoDriverNode, args)


if __name__ == '__main__':
    main()
