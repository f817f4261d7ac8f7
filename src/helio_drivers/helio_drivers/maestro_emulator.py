"""
Byte-exact Pololu Maestro emulator on a pseudo-terminal (compact protocol).

Each channel's output pulse ramps from where it is to its target on a trapezoidal profile
limited by the channel's speed and acceleration settings (0 = unlimited, as on the device),
following an injected clock (a callable returning seconds, wall or simulated). Targets
outside a channel's [min, max] are clamped as the Maestro clamps them; a target of 0 turns
the pulses off. By default the emulator is a factory-new Maestro: every channel limited to
992..2000 us and sending no pulses at start-up (Get Position answers 0) until its first
target; a configured unit is ``MaestroEmulator(min_pulse_us=500, max_pulse_us=2500,
initial_pulse_us=1500)``. Malformed input sets the serial protocol error bit, which Get
Errors reports and clears. ``joint_positions()`` gives the servo angles through the
configured ``ServoCalibration``s so the simulated world can turn its lens.
"""

from dataclasses import dataclass
import math
import threading
import time

from helio_drivers import maestro_protocol as proto
from helio_drivers.motion_profile import TrapezoidProfile
from helio_drivers.pty_device import PtyDevice


# A new Maestro's channel settings: Min 992 us, Max 2000 us, "Off" at start-up.
FACTORY_MIN_US = 992.0
FACTORY_MAX_US = 2000.0
FACTORY_START_US = 0.0
# A Maestro set up as the drivers' README says: Min 500 us, Max 2500 us, start at 1500 us.
CONFIGURED_SETTINGS = {'min_pulse_us': 500.0, 'max_pulse_us': 2500.0, 'initial_pulse_us': 1500.0}


@dataclass
class _Channel:
    minimum_qus: int = 2000          # 500 us
    maximum_qus: int = 10000         # 2500 us
    speed: int = 0
    acceleration: int = 0
    origin_qus: float = 6000.0
    target_qus: float = 6000.0
    start: float = 0.0
    profile: TrapezoidProfile = None

    def position(self, now):
        if self.profile is None:
            return self.target_qus
        s = self.profile.position(now - self.start)
        return self.origin_qus + (self.target_qus - self.origin_qus) * s

    def moving(self, now):
        return self.profile is not None and now - self.start < self.profile.duration


class MaestroEmulator(PtyDevice):
    """A Maestro servo controller on a pty; see the module docstring."""

    def __init__(self, port_path=None, clock=time.monotonic, channel_count=6,
                 calibrations=(), initial_pulse_us=FACTORY_START_US,
                 min_pulse_us=FACTORY_MIN_US, max_pulse_us=FACTORY_MAX_US, seed=0,
                 line_baudrate=None, device_number=proto.FACTORY_DEVICE_NUMBER):
        """Create `channel_count` channels at `initial_pulse_us` (0: off), limits [us]."""
        self.clock = clock
        self.calibrations = {c.name: c for c in calibrations}
        self._lock = threading.RLock()
        self._channels = [
            _Channel(minimum_qus=round(4 * min_pulse_us), maximum_qus=round(4 * max_pulse_us),
                     origin_qus=4.0 * initial_pulse_us, target_qus=4.0 * initial_pulse_us)
            for _ in range(channel_count)]
        self._errors = 0
        self._parser = proto.CommandParser(device_number)     # compact and Pololu protocols
        self.commands_received = 0
        super().__init__(port_path=port_path, seed=seed, name='maestro',
                         line_baudrate=line_baudrate)

    # ---- in-process accessors ---------------------------------------------------------------

    def pulse_widths_us(self):
        """Return the output pulse width of every channel now [us] (0 = off)."""
        now = self.clock()
        with self._lock:
            return [channel.position(now) / 4.0 for channel in self._channels]

    def target_pulse_widths_us(self):
        """Return the pulse width every channel is heading for [us] (0 = off)."""
        with self._lock:
            return [channel.target_qus / 4.0 for channel in self._channels]

    def motion_limits(self):
        """Return every channel's (speed [us/s], acceleration [us/s^2]); inf = unlimited."""
        with self._lock:
            return [(c.speed * proto.SPEED_UNIT_US_PER_S if c.speed else math.inf,
                     c.acceleration * proto.ACCELERATION_UNIT_US_PER_S2 if c.acceleration
                     else math.inf) for c in self._channels]

    def joint_positions(self):
        """Return the angle [rad] of every calibrated joint now, by name."""
        pulses = self.pulse_widths_us()
        return {name: calibration.angle(pulses[calibration.channel])
                for name, calibration in self.calibrations.items()}

    def is_moving(self):
        """Whether any channel is still ramping towards its target."""
        now = self.clock()
        with self._lock:
            return any(channel.moving(now) for channel in self._channels)

    @property
    def errors(self):
        """Error bits that Get Errors would report now (without clearing them)."""
        with self._lock:
            return self._errors

    # ---- protocol ---------------------------------------------------------------------------

    def handle_input(self, data):
        """Parse compact-protocol bytes, act, and return the replies."""
        with self._lock:
            errors_before = self._parser.protocol_errors
            commands = self._parser.feed(data)
            if self._parser.protocol_errors != errors_before:
                self._errors |= proto.SERIAL_PROTOCOL_ERROR
            replies = []
            for command in commands:
                self.commands_received += 1
                reply = self.handle_command(command)
                if reply:
                    replies.append(reply)
            return replies

    def handle_command(self, command):
        """Apply one parsed command; return its reply bytes (b'' if none)."""
        now = self.clock()
        with self._lock:
            if command.code == proto.GET_MOVING_STATE:
                return bytes([int(any(c.moving(now) for c in self._channels))])
            if command.code == proto.GET_ERRORS:
                errors, self._errors = self._errors, 0
                return proto.encode_u16(errors)
            if command.code == proto.GO_HOME:
                for channel in self._channels:
                    channel.target_qus, channel.profile = 0.0, None
                return b''
            if command.channel >= len(self._channels):
                self._errors |= proto.SERIAL_PROTOCOL_ERROR
                return b''
            channel = self._channels[command.channel]
            if command.code == proto.GET_POSITION:
                return proto.encode_u16(int(round(channel.position(now))))
            if command.code == proto.SET_SPEED:
                channel.speed = command.value
            elif command.code == proto.SET_ACCELERATION:
                channel.acceleration = min(command.value, 255)
            elif command.code == proto.SET_TARGET:
                self._set_target(channel, command.value, now)
            return b''

    @staticmethod
    def _set_target(channel, value, now):
        if value == 0:
            channel.target_qus, channel.origin_qus, channel.profile = 0.0, 0.0, None
            return
        target = float(min(max(value, channel.minimum_qus), channel.maximum_qus))
        origin = channel.position(now)
        if origin == 0.0:          # pulses were off: the servo jumps to the first target
            channel.origin_qus = channel.target_qus = target
            channel.profile = None
            return
        distance_us = abs(target - origin) / 4.0
        channel.origin_qus, channel.target_qus, channel.start = origin, target, now
        if distance_us == 0.0:
            channel.profile = None
            return
        velocity = (channel.speed * proto.SPEED_UNIT_US_PER_S if channel.speed else math.inf)
        acceleration = (channel.acceleration * proto.ACCELERATION_UNIT_US_PER_S2
                        if channel.acceleration else math.inf)
        channel.profile = TrapezoidProfile(velocity / distance_us, acceleration / distance_us)
