"""
Node servo_driver: the two wrist servos (lens yaw, lens pitch) on a Pololu Maestro.

- action ``move_wrist`` (helio_msgs/MoveWrist): yaw and pitch [rad] are converted to pulse widths
  with each channel's calibration (``yaw.*``, ``pitch.*`` parameters, see
  config/servo_driver.yaml); an angle outside a channel's pulse range is refused naming the joint,
  and so is one beyond a limit the Maestro itself was found to impose. The goal succeeds when both
  reported positions are within ``position_tolerance_us`` of their targets; feedback carries the
  current angles. A goal with ``escape`` (a retreat: the painter turning the lens off the sun when
  the arm cannot move) runs at ``escape_speed_us_per_s`` and ``escape_acceleration_us_per_s2`` on
  both channels instead of the per-axis limits; every move sets its channel limits before its
  targets. When the Maestro stops a servo short of its target (its own channel range is narrower
  than the configured one: a factory-new Maestro allows 992..2000 us), the goal aborts at once
  saying so, and the limit is remembered. Cancel, a move longer than ``move_timeout`` on the node
  clock (or ``move_wall_timeout`` of wall time) and every device error hold both servos where they
  are, confirmed by reading them back, before the goal ends.
- ``joint_states``: lens_yaw, lens_pitch [rad] at ``joint_state_rate``; a channel that sends
  no pulses (a factory Maestro's start-up state: the servo is limp and its angle unknown) is
  left out until its first move, never published as a bogus angle.
- ``servo/status`` (helio_msgs/DeviceStatus): link state, reconnect attempts, Maestro errors,
  and what is wrong with the device's set-up (pulses off, limits found).

The emergency stop (``helio_optics.node_kit.emergency_stop``) is this node's: it serves
``emergency_stop`` and ``emergency_stop_reset`` (std_srvs/Trigger; from the start, with or
without the Maestro) and publishes the latched ``emergency_stop`` state that every actor of
the graph follows. Engaged, it aborts a running move, holds the servos and turns the lens
pitch ``emergency_turn`` off its axis at the escape speed (the focus spreads off the wood),
and refuses goals until the reset.

The heating guard (issue 30): the lens planner beats on ``lens/heating`` (std_msgs/Header,
frame_id ``heating``) while a lens it placed is at the heating distance, and says ``clear``
when the lens leaves it. Beats that stop without a ``clear`` for ``heating_guard_timeout``
(node clock) and ``heating_guard_timeout_wall`` (both must pass: the
``helio_optics.node_kit.focus_lease`` rule) mean the lens planner died there, or its retreat
failed: this node then stops any move and turns the lens pitch ``emergency_turn`` off the
sun by itself, as for an emergency stop but without refusing later goals.

The action server exists only while the node has held its device once; a port held by
another process makes the node refuse to start. A lost port is reopened with exponential
backoff while goals abort at once; every connection and the shutdown hold both servos at
their current positions. The link, the device thread and the action plumbing are
``device_action_node.DeviceActionNode``'s.
"""

import math
import time

from helio_drivers import maestro_protocol as proto
from helio_drivers.device_action_node import (
    DeviceActionNode, DeviceSpec, GoalRefused, MoveProgress)
from helio_drivers.maestro_client import MaestroClient
from helio_drivers.serial_link import DeviceError
from helio_msgs.action import MoveWrist
from helio_optics.node_kit import emergency_stop
from helio_optics.node_kit.focus_lease import CLEAR, declare_lease, HEATING, HEATING_TOPIC
from helio_optics.node_kit.parameters import declare
from helio_optics.node_kit.runner import run_node
from helio_optics.rig_kinematics import escape_pitch
from std_msgs.msg import Bool
from std_srvs.srv import Trigger

AXES = ('yaw', 'pitch')

# Pololu Maestro 6, 12, 18 and 24 channels (each shows two ports: the first is the
# command port)
MAESTRO_USB_IDS = ('1ffb:0089', '1ffb:008a', '1ffb:008b', '1ffb:008c')

SPEC = DeviceSpec(device='servo', label='servo controller', action_name='move_wrist',
                  port='/dev/ttyACM0', usb_ids=MAESTRO_USB_IDS, baudrate_max=250000,
                  timeout=0.1, move_timeout=10.0, move_timeout_max=600.0)

FACTORY_RANGE_US = (992.0, 2000.0)      # a new Maestro's channel limits (Min, Max)
# Two readings of a channel agree when this close [quarter-us]: 10 us, what a servo at the
# default 1000 us/s covers in the 10 ms between two queries.
AGREEING_READINGS_QUS = 40


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
        zero_offset=declare(node, prefix + 'zero_offset', 0.0,
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
        self.escape_limits = (
            proto.speed_units(declare(
                self, 'escape_speed_us_per_s', 4000.0,
                'Pulse-width speed of an escape move [us/s] (0 = unlimited): about a '
                "standard servo's own no-load speed (0.16 s per 60 deg).", 0.0, 400000.0)),
            proto.acceleration_units(declare(
                self, 'escape_acceleration_us_per_s2', 0.0,
                'Pulse-width acceleration of an escape move [us/s^2] (0 = unlimited: the '
                "servo's torque limits it).", 0.0, 80000.0)))
        self.emergency_turn = declare(
            self, 'emergency_turn', 0.6,
            'On an emergency stop, turn the lens pitch by this off its axis, away from the '
            "pitch servo's nearer end, at the escape speed: the focus spreads off the wood "
            '[rad].', 0.05, 1.5)
        self.emergency_publisher = self.create_publisher(Bool, emergency_stop.TOPIC,
                                                         emergency_stop.QOS)
        self.emergency_publisher.publish(Bool(data=False))
        self.create_service(Trigger, emergency_stop.SERVICE, self._engage_emergency_stop)
        self.create_service(Trigger, emergency_stop.RESET_SERVICE, self._reset_emergency_stop)
        self.heating_guard = declare_lease(
            self, 'heating_guard', HEATING_TOPIC,
            "the lens planner while a lens is at the heating distance (frame_id 'heating', "
            "then 'clear')", 'the lens is turned off the sun', self._on_heating_beat,
            self._check_heating_guard)
        self.device_limits_qus = {}     # axis -> (low, high) the Maestro was seen to clamp to
        self.envelopes = {axis: proto.PositionEnvelope(self.tolerance_qus) for axis in AXES}
        self.readings_dropped = 0       # possible values that no move explains (line noise)
        self._limits_sent = {}          # axis -> (speed, acceleration) units last sent
        self.start_device()

    # ---- heating guard ----------------------------------------------------------------------

    def _node_and_wall_now(self):
        return self.get_clock().now().nanoseconds * 1e-9, time.monotonic()

    def _on_heating_beat(self, message):
        now, wall_now = self._node_and_wall_now()
        if message.frame_id == HEATING:
            self.heating_guard.heard(now, wall_now)
            self.heating_guard.placed(at_heating=True, alive_when_asked=True)
        elif message.frame_id == CLEAR:
            self.heating_guard.disarm()

    def _check_heating_guard(self):
        """Turn the lens off the sun when the lens planner fell silent with the lens heating."""
        now, wall_now = self._node_and_wall_now()
        if not self.heating_guard.expired(now, wall_now):
            return
        silence, wall_silence = self.heating_guard.silence(now, wall_now)
        self.heating_guard.disarm()
        self.request_escape(
            f'HEATING GUARD: the lens planner fell silent with the lens at the heating '
            f'distance ({silence:.2f} s node clock, {wall_silence:.2f} s wall)',
            spare=lambda job: job.handle is not None and job.handle.request.escape)

    # ---- emergency stop ---------------------------------------------------------------------

    def _engage_emergency_stop(self, _request, response):
        """Service emergency_stop: publish the latched state; every actor acts on it."""
        was = self.emergency.engaged
        self.emergency_publisher.publish(Bool(data=True))
        response.success = True
        response.message = (('already engaged' if was else 'EMERGENCY STOP engaged') +
                            ': the drivers stop, the wrist turns the lens off the sun, every '
                            'goal ends and new ones are refused until the reset (helio reset)')
        self.get_logger().error(f'emergency_stop called: {response.message}')
        return response

    def _reset_emergency_stop(self, _request, response):
        """Service emergency_stop_reset: release the stop; goals are taken again."""
        was = self.emergency.engaged
        self.emergency_publisher.publish(Bool(data=False))
        response.success = True
        response.message = ('emergency stop reset: goals are taken again' if was
                            else 'the emergency stop was not engaged')
        self.get_logger().warning(f'emergency_stop_reset called: {response.message}')
        return response

    def emergency_move(self):
        """Turn the lens pitch ``emergency_turn`` off its axis at the escape speed."""
        calibration = self.axes['pitch'][0]
        position = self._read_position('pitch')
        if not position:
            return f'{calibration.name} sends no pulses: the lens was not turned'
        pitch = escape_pitch(calibration.angle(position / 4.0), self.emergency_turn)
        try:
            target = calibration.quarter_us(pitch)
        except ValueError as error:
            return f'the lens was not turned ({error})'
        low, high = self.device_limits_qus.get('pitch', (0, 1 << 14))
        target = min(max(target, low), high)
        self._send_limits(escape=True)
        self._set_target('pitch', target)
        return (f'the lens turned to pitch {calibration.angle(target / 4.0):.2f} rad, off the '
                'sun')

    def _positions_qus(self):
        return {axis: self._read_position(axis) for axis in self.axes}

    def _read_position(self, axis):
        """
        Return a channel's pulse [quarter-us] that the device really reported (issue 35).

        The compact protocol has no checksum: noise on the line can be read as a reply. The
        client drops values no Maestro can send; here a possible value is taken when it lies
        where the pulse can be (``PositionEnvelope``: between the last reading and the
        targets sent since), or else when a second reading agrees with it (a move nobody
        here sent, or no span known yet after a connection). A reading that is neither is
        dropped and counted (``servo/status``); three in a row fail the read.
        """
        channel = self.axes[axis][0].channel
        envelope = self.envelopes[axis]
        reading = self.client.get_position(channel)
        if envelope.known() and envelope.consistent(reading):
            envelope.accepted(reading)
            return reading
        for _ in range(2):
            again = self.client.get_position(channel)
            if envelope.known() and envelope.consistent(again) or \
                    abs(again - reading) <= AGREEING_READINGS_QUS:
                if envelope.known() and not envelope.consistent(reading):
                    self._reading_dropped(axis, reading)
                envelope.accepted(again)
                return again
            self._reading_dropped(axis, reading)
            reading = again
        raise DeviceError(f'{self.axes[axis][0].name}: three position readings that neither '
                          f'agree nor fit the moves sent (the last {reading / 4.0:.1f} us): '
                          'noise on the line?')

    def _reading_dropped(self, axis, reading):
        """Count a dropped reading; say so on servo/status (and in the log, sparingly)."""
        self.readings_dropped += 1
        count = self.readings_dropped
        self.setup_notes['readings'] = (
            f'{count} position reading{"s" if count > 1 else ""} dropped as not the '
            f"device's (the last: {self.axes[axis][0].name} {reading / 4.0:.1f} us); "
            f'{self.client.impossible_replies} impossible replies: noise on the line?')
        if count & (count - 1) == 0:         # 1, 2, 4, 8, ...
            self.get_logger().warning(self.setup_notes['readings'])

    def _set_target(self, axis, target_qus):
        """Send a channel's target, and let its envelope expect the pulse to go there."""
        self.envelopes[axis].targeted(target_qus)
        self.client.set_target(self.axes[axis][0].channel, target_qus)

    def _angles(self, positions_qus):
        """Return the angle [rad] of each axis whose channel sends pulses (None if not)."""
        return {axis: (self.axes[axis][0].angle(q / 4.0) if q else None)
                for axis, q in positions_qus.items()}

    def _result(self, positions_qus):
        angles = self._known(self._angles(positions_qus))
        return MoveWrist.Result(achieved_yaw=angles['yaw'], achieved_pitch=angles['pitch'])

    @staticmethod
    def _known(angles):
        """Angles for a message: NaN (unknown, never a made-up value) for a limp servo."""
        return {axis: math.nan if angle is None else angle for axis, angle in angles.items()}

    def _note(self, axis, text):
        """Record (and log once) a problem with the device's set-up for one axis."""
        if self.setup_notes.get(axis) != text:
            self.setup_notes[axis] = text
            self.get_logger().warning(text)

    # ---- device hooks -----------------------------------------------------------------------

    def configure_device(self):
        """Hold the servos, set speed and acceleration limits, check the Maestro's state."""
        self.client.get_errors()          # the device answers (and stale errors go)
        for envelope in self.envelopes.values():
            envelope.forget()               # the servos may have moved while unconnected
        _, done = self.stop_device()
        self.get_logger().info(f'on connect: {done}')
        self._limits_sent.clear()
        self._send_limits(escape=False)
        for axis, position in self._positions_qus().items():
            calibration = self.axes[axis][0]
            if position == 0:
                self._note(axis, (
                    f'{calibration.name} (Maestro channel {calibration.channel}) sends no '
                    'pulses: the servo is limp and its angle unknown until its first move '
                    '(a factory-new Maestro starts so; see the README, "Setting up the '
                    'Maestro")'))
            elif not calibration.min_pulse_us <= position / 4.0 <= calibration.max_pulse_us:
                self._note(axis, (
                    f'{calibration.name} starts at {position / 4.0:.1f} us, outside its '
                    f'configured {calibration.min_pulse_us:.0f}..'
                    f'{calibration.max_pulse_us:.0f} us'))
            else:
                self.setup_notes.pop(axis, None)

    def _send_limits(self, escape):
        """Set each channel's speed and acceleration for a move (unless already set)."""
        for axis, (calibration, speed, acceleration) in self.axes.items():
            limits = self.escape_limits if escape else (speed, acceleration)
            if self._limits_sent.get(axis) != limits:
                self.client.set_speed(calibration.channel, limits[0])
                self.client.set_acceleration(calibration.channel, limits[1])
                self._limits_sent[axis] = limits

    def read_joints(self):
        """Return the names and angles [rad] of the servos whose position is known."""
        angles = self._angles(self._positions_qus())
        known = [axis for axis in AXES if angles[axis] is not None]
        return [self.axes[axis][0].name for axis in known], [angles[axis] for axis in known]

    def read_alarms(self):
        """Return (and clear) the Maestro's error bits by name, logging any."""
        errors = proto.error_descriptions(self.client.get_errors())
        if errors:
            self.get_logger().warning(f'Maestro errors: {", ".join(errors)}')
        return errors

    def goal_problem(self, goal):
        """Return why a goal is no move: an angle not finite or beyond its calibration."""
        for axis in AXES:
            try:
                self.axes[axis][0].quarter_us(getattr(goal, axis))
            except ValueError as error:
                return f'wrist target refused: {error}'
        return ''

    def plan_move(self, goal):
        """Return (each axis's target [quarter-us], escape); refuse what the Maestro limits."""
        plan = {}
        for axis in AXES:
            calibration = self.axes[axis][0]
            target = calibration.quarter_us(getattr(goal, axis))   # checked: goal_problem
            low, high = self.device_limits_qus.get(axis, (0, 1 << 14))
            if not low <= target <= high:
                raise GoalRefused(
                    f'wrist target refused: {calibration.name} needs {target / 4.0:.1f} us, '
                    f'beyond the {low / 4.0:.1f}..{high / 4.0:.1f} us the Maestro allows on '
                    f'channel {calibration.channel} ({self.setup_notes.get(axis, "")})')
            plan[axis] = target
        return plan, bool(goal.escape)

    def start_move(self, plan):
        """Set the move's speed and acceleration limits, then both targets."""
        targets, escape = plan
        self._send_limits(escape)
        for axis, target in targets.items():
            self._set_target(axis, target)
        return targets

    def poll_move(self, move):
        """
        Done when both read-back positions are within the tolerance of their targets.

        A Maestro that has stopped (Get Moving State 0) short of a target clamped it to its
        own channel range: the move fails at once, naming the limit, which is remembered.
        The moving state is read before the positions: a servo that stopped before the
        positions were read cannot have moved since (read after, a servo arriving between
        the two reads would look stopped short of its target).
        """
        moving = self.client.moving()
        positions = self._positions_qus()
        short = [a for a in move if abs(positions[a] - move[a]) > self.tolerance_qus]
        if not short:
            return MoveProgress(done=True, success=True, message='wrist at target',
                                result=self._result(positions))
        if not moving:
            return MoveProgress(done=True, result=self._result(positions),
                                message='; '.join(self._clamped(a, positions[a], move[a])
                                                  for a in short))
        angles = self._known(self._angles(positions))
        return MoveProgress(feedback=MoveWrist.Feedback(current_yaw=angles['yaw'],
                                                        current_pitch=angles['pitch']))

    def _clamped(self, axis, position, target):
        """Remember the device limit a servo stopped at; return the explanation."""
        calibration = self.axes[axis][0]
        low, high = self.device_limits_qus.get(axis, (0, 1 << 14))
        if target > position:
            high = min(high, position)
        else:
            low = max(low, position)
        self.device_limits_qus[axis] = (low, high)
        factory = ' (a factory-new Maestro allows {:.0f}..{:.0f} us)'.format(*FACTORY_RANGE_US)
        text = (f'{calibration.name}: the Maestro stopped at {position / 4.0:.1f} us, short of '
                f'the target {target / 4.0:.1f} us: its channel {calibration.channel} range is '
                f'narrower than the configured {calibration.min_pulse_us:.0f}..'
                f'{calibration.max_pulse_us:.0f} us{factory}; set the channel' "'s Min and Max in "
                'the Maestro Control Center (README, "Setting up the Maestro") or narrow '
                f'{axis}.min_pulse_us / {axis}.max_pulse_us')
        self._note(axis, text)
        return text

    def stop_device(self):
        """Hold both servos where they are (target = current position), confirmed."""
        positions = self._positions_qus()
        for axis in self.axes:
            self._set_target(axis, positions[axis])
        # Set Target has no reply: reading the positions back proves the device has it.
        held = self._positions_qus()
        drift = {a: abs(held[a] - positions[a]) for a in held}
        if any(d > self.tolerance_qus for d in drift.values()):
            raise DeviceError('servos still move after the hold: ' + ', '.join(
                f'{self.axes[a][0].name} {d / 4.0:.2f} us' for a, d in drift.items()))
        return self._result(held), 'servos held where they were (confirmed)'


def main(args=None):
    """Run the node until shutdown."""
    run_node(ServoDriverNode, args)


if __name__ == '__main__':
    main()
