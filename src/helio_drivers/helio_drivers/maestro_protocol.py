"""
Pololu Maestro compact serial protocol and per-channel servo calibration.

Commands (a command byte with bit 7 set, then 7-bit data bytes):

- Set Target ``0x84 ch lo7 hi7``: pulse width in quarter-microseconds (0 = pulses off);
- Set Speed ``0x87 ch lo7 hi7``: limit in 0.25 us per 10 ms (0 = unlimited);
- Set Acceleration ``0x89 ch lo7 hi7``: limit in 0.25 us per 10 ms per 80 ms (0 = unlimited);
- Get Position ``0x90 ch``: reply 2 bytes little-endian, quarter-microseconds;
- Get Moving State ``0x93``: reply 1 byte, 1 while any servo is still moving;
- Get Errors ``0xA1``: reply 2 bytes little-endian error bits (reading clears them);
- Go Home ``0xA2``: every channel to its home setting (here: pulses off).

The compact protocol has no checksum and no reply framing: a client must flush its input
before every query so a late reply is never taken for the next one.

The Pololu protocol, which public clients use to address one Maestro of several on a
line, carries the same commands as ``0xAA device command&0x7F data...``: a device acts on
(and answers) only the commands with its own device number (12 from the factory).

``ServoCalibration`` maps a joint angle [rad] to a pulse width [us] and back
(Eq-free, linear): ``pulse = centre + direction * us_per_rad * (angle - zero_offset)``,
refusing angles whose pulse would leave [min_pulse, max_pulse].
"""

from dataclasses import dataclass
import math

SET_TARGET = 0x84
SET_SPEED = 0x87
SET_ACCELERATION = 0x89
GET_POSITION = 0x90
GET_MOVING_STATE = 0x93
GET_ERRORS = 0xA1
GO_HOME = 0xA2

DATA_BYTES = {SET_TARGET: 3, SET_SPEED: 3, SET_ACCELERATION: 3, GET_POSITION: 1,
              GET_MOVING_STATE: 0, GET_ERRORS: 0, GO_HOME: 0}
REPLY_BYTES = {GET_POSITION: 2, GET_MOVING_STATE: 1, GET_ERRORS: 2}
POLOLU_START = 0xAA                 # the Pololu protocol's first byte
FACTORY_DEVICE_NUMBER = 12          # a new Maestro's device number

ERROR_BITS = {
    0: 'serial signal error',
    1: 'serial overrun error',
    2: 'serial buffer full',
    3: 'serial CRC error',
    4: 'serial protocol error',
    5: 'serial timeout',
    6: 'script stack error',
    7: 'script call stack error',
    8: 'script program counter error',
}
SERIAL_PROTOCOL_ERROR = 1 << 4

# The widest a channel's Min and Max can be set (Maestro Control Center): a Get Position
# reply is 0 (no pulses) or within this, anything else is line noise read as a reply.
PULSE_RANGE_US = (64.0, 4080.0)

SPEED_UNIT_US_PER_S = 0.25 / 0.010                  # one Set Speed unit [us/s]
ACCELERATION_UNIT_US_PER_S2 = 0.25 / 0.010 / 0.080  # one Set Acceleration unit [us/s^2]


class MaestroProtocolError(ValueError):
    """A value that does not fit the protocol."""


def _fourteen_bits(value, what):
    value = int(value)
    if not 0 <= value < 1 << 14:
        raise MaestroProtocolError(f'{what} {value} outside 0..16383')
    return bytes([value & 0x7F, (value >> 7) & 0x7F])


def _channel(channel):
    if not 0 <= int(channel) < 128:
        raise MaestroProtocolError(f'channel {channel} outside 0..127')
    return int(channel)


def set_target(channel, quarter_us):
    """Set Target bytes (pulse width in quarter-microseconds, 0 = off)."""
    return bytes([SET_TARGET, _channel(channel)]) + _fourteen_bits(quarter_us, 'target')


def set_speed(channel, speed_units):
    """Set Speed bytes (0.25 us / 10 ms units, 0 = unlimited)."""
    return bytes([SET_SPEED, _channel(channel)]) + _fourteen_bits(speed_units, 'speed')


def set_acceleration(channel, acceleration_units):
    """Set Acceleration bytes (0.25 us / 10 ms / 80 ms units, 0 = unlimited)."""
    if not 0 <= int(acceleration_units) <= 255:
        raise MaestroProtocolError(f'acceleration {acceleration_units} outside 0..255')
    return bytes([SET_ACCELERATION, _channel(channel)]) + _fourteen_bits(
        acceleration_units, 'acceleration')


def get_position(channel):
    """Get Position bytes."""
    return bytes([GET_POSITION, _channel(channel)])


def get_moving_state():
    """Get Moving State bytes."""
    return bytes([GET_MOVING_STATE])


def get_errors():
    """Get Errors bytes."""
    return bytes([GET_ERRORS])


def go_home():
    """Go Home bytes."""
    return bytes([GO_HOME])


def decode_u16(reply):
    """Little-endian 16-bit value of a 2-byte reply (position or errors)."""
    if len(reply) != 2:
        raise MaestroProtocolError(f'expected a 2-byte reply, got {len(reply)} bytes')
    return reply[0] | (reply[1] << 8)


def possible_position(quarter_us):
    """Whether a Get Position value can come from a Maestro (0: no pulses)."""
    return quarter_us == 0 or 4.0 * PULSE_RANGE_US[0] <= quarter_us <= 4.0 * PULSE_RANGE_US[1]


class PositionEnvelope:
    """
    Where a channel's pulse can be at its next reading, from its last reading and targets.

    A Maestro moves a channel's pulse monotonically from where it is towards its target (at
    the speed limit, or at once when unlimited), so between two readings the pulse stays
    within the span of the last reading and every target sent since it. A reading outside
    that span (beyond `tolerance_qus`) cannot be the device's; until a reading has been
    accepted and a target sent (after a (re)connection) the span is unknown and every
    possible value is consistent.
    """

    def __init__(self, tolerance_qus):
        """Allow readings `tolerance_qus` [quarter-us] beyond the span."""
        self.tolerance_qus = tolerance_qus
        self._span = None               # (low, high) [quarter-us], None: unknown
        self._target = None             # the last target sent [quarter-us]

    def forget(self):
        """Know nothing: the device may have moved unseen (a (re)connection)."""
        self._span = self._target = None

    def known(self):
        """Whether the span is known."""
        return self._span is not None

    def targeted(self, target_qus):
        """Let the pulse travel towards a target just sent."""
        self._target = target_qus
        if self._span is not None:
            self._span = (min(self._span[0], target_qus), max(self._span[1], target_qus))

    def consistent(self, reading_qus):
        """Whether a reading lies within the span (always, while the span is unknown)."""
        if self._span is None:
            return True
        low, high = self._span
        return low - self.tolerance_qus <= reading_qus <= high + self.tolerance_qus

    def accepted(self, reading_qus):
        """Take a reading as the device's: the span restarts from it."""
        if self._target is None:
            return                      # no target sent yet: where it goes is unknown
        self._span = (min(reading_qus, self._target), max(reading_qus, self._target))


def encode_u16(value):
    """2-byte little-endian reply."""
    return bytes([value & 0xFF, (value >> 8) & 0xFF])


def error_descriptions(bits):
    """Names of the error bits set in a Get Errors value."""
    return [name for bit, name in ERROR_BITS.items() if bits & (1 << bit)] + [
        f'error bit {bit}' for bit in range(9, 16) if bits & (1 << bit)]


def speed_units(us_per_s):
    """Set Speed value for a pulse-width rate [us/s] (0 or inf = unlimited)."""
    if us_per_s <= 0.0 or math.isinf(us_per_s):
        return 0
    return max(1, min(16383, round(us_per_s / SPEED_UNIT_US_PER_S)))


def acceleration_units(us_per_s2):
    """Set Acceleration value for a pulse-width acceleration [us/s^2] (0 or inf = unlimited)."""
    if us_per_s2 <= 0.0 or math.isinf(us_per_s2):
        return 0
    return max(1, min(255, round(us_per_s2 / ACCELERATION_UNIT_US_PER_S2)))


@dataclass
class Command:
    """A parsed compact-protocol command: code, channel (or None) and 14-bit value (or None)."""

    code: int
    channel: int = None
    value: int = None


class CommandParser:
    """
    Incremental parser of the compact and Pololu protocols (as the Maestro firmware reads).

    A data byte with bit 7 set where data was expected, or an unknown command byte, is a
    protocol error: it is counted and parsing restarts at the next command byte. A Pololu
    command (``0xAA device command&0x7F data...``) for another device number is read and
    dropped (another device on the line acts on it).
    """

    def __init__(self, device_number=FACTORY_DEVICE_NUMBER):
        """Start between commands; answer Pololu commands addressed to `device_number`."""
        self.device_number = device_number
        self._pending = []
        self._addressed = None          # None: compact; else the Pololu device number
        self._pololu = ''               # '', 'device' or 'command': the next byte expected
        self.protocol_errors = 0

    def feed(self, data):
        """Return the complete commands found in `data` that are for this device."""
        commands = []
        for byte in data:
            if byte & 0x80:
                if self._pending or self._pololu:
                    self.protocol_errors += 1     # previous command cut short
                self._pending, self._addressed = [], None
                self._pololu = 'device' if byte == POLOLU_START else ''
                if self._pololu:
                    continue
                if byte not in DATA_BYTES:
                    self.protocol_errors += 1
                    continue
                self._pending = [byte]
            elif self._pololu == 'device':
                self._addressed, self._pololu = byte, 'command'
                continue
            elif self._pololu == 'command':
                self._pololu = ''
                if byte | 0x80 not in DATA_BYTES:
                    self.protocol_errors += 1
                    self._addressed = None
                    continue
                self._pending = [byte | 0x80]
            elif not self._pending:
                self.protocol_errors += 1         # stray data byte
                continue
            else:
                self._pending.append(byte)
            if len(self._pending) == 1 + DATA_BYTES[self._pending[0]]:
                if self._addressed in (None, self.device_number):
                    commands.append(self._command(self._pending))
                self._pending, self._addressed = [], None
        return commands

    @staticmethod
    def _command(raw):
        code = raw[0]
        if len(raw) == 1:
            return Command(code)
        if len(raw) == 2:
            return Command(code, raw[1])
        return Command(code, raw[1], raw[2] | (raw[3] << 7))


def encode_pololu(command, device_number=FACTORY_DEVICE_NUMBER):
    """Bytes of a Command in the Pololu protocol, for the Maestro `device_number`."""
    if not 0 <= device_number < 0x80:
        raise MaestroProtocolError(f'device number must be 0..127, got {device_number}')
    compact = encode_command(command)
    return bytes([POLOLU_START, device_number, compact[0] & 0x7F]) + compact[1:]


def encode_command(command):
    """Bytes of a parsed Command in the compact protocol (the inverse of CommandParser)."""
    if command.code not in DATA_BYTES:
        raise MaestroProtocolError(f'unknown command byte 0x{command.code:02X}')
    count = DATA_BYTES[command.code]
    data = bytes([command.code])
    if count >= 1:
        data += bytes([_channel(command.channel)])
    if count == 3:
        data += _fourteen_bits(command.value, 'value')
    return data


@dataclass(frozen=True)
class ServoCalibration:
    """Angle <-> pulse width of one servo channel (see the module docstring)."""

    name: str
    channel: int
    min_pulse_us: float = 500.0
    max_pulse_us: float = 2500.0
    centre_pulse_us: float = 1500.0
    us_per_rad: float = 2000.0 / math.pi     # 180 deg over 500..2500 us
    direction: int = 1                       # +1 or -1
    zero_offset: float = 0.0             # joint angle at the centre pulse [rad]

    def __post_init__(self):
        """Check the calibration is usable."""
        if self.direction not in (1, -1):
            raise ValueError(f'{self.name}: direction must be 1 or -1, got {self.direction}')
        if not self.min_pulse_us < self.max_pulse_us:
            raise ValueError(f'{self.name}: min_pulse_us {self.min_pulse_us} must be below '
                             f'max_pulse_us {self.max_pulse_us}')
        if not self.us_per_rad > 0.0:
            raise ValueError(f'{self.name}: us_per_rad must be positive')

    def pulse_us(self, angle):
        """Pulse width [us] for a joint angle [rad]; ValueError naming the joint if outside."""
        if not math.isfinite(angle):
            raise ValueError(f'{self.name} = {angle}: not a finite angle')
        pulse = self.centre_pulse_us + self.direction * self.us_per_rad * (
            angle - self.zero_offset)
        if not self.min_pulse_us - 1e-6 <= pulse <= self.max_pulse_us + 1e-6:
            low, high = sorted((self.angle(self.min_pulse_us), self.angle(self.max_pulse_us)))
            raise ValueError(
                f'{self.name}: {math.degrees(angle):.2f} deg is outside its range '
                f'[{math.degrees(low):.2f}, {math.degrees(high):.2f}] deg '
                f'(pulse {pulse:.1f} us, allowed {self.min_pulse_us:.0f}..'
                f'{self.max_pulse_us:.0f} us)')
        return pulse

    def angle(self, pulse_us):
        """Joint angle [rad] for a pulse width [us]."""
        return self.zero_offset + self.direction * (
            pulse_us - self.centre_pulse_us) / self.us_per_rad

    def angle_range(self):
        """(lowest, highest) reachable joint angle [rad]."""
        return tuple(sorted((self.angle(self.min_pulse_us), self.angle(self.max_pulse_us))))

    def quarter_us(self, angle):
        """Set Target value (quarter-microseconds) for a joint angle [rad]."""
        return round(4.0 * self.pulse_us(angle))
