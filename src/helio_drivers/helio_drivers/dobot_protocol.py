"""
Dobot Magician serial protocol: framing, checksum, typed commands and a resynchronising reader.

A frame is ``AA AA | len | id | ctrl | params | checksum`` with ``len = 2 + len(params)``,
``ctrl`` bit 0 = write (rw), bit 1 = queued (isQueued), and
``checksum = (256 - (id + ctrl + sum(params)) % 256) % 256``. Numbers are little-endian;
positions are float32 millimetres and degrees on the wire (the driver converts to SI).
A queued write is answered with the u64 index the device gave it in its command queue; the
move is done when the executed index (command 246) reaches it, not when the reply arrives.

This module has no I/O: the pyserial client (``dobot_client``) and the emulator
(``dobot_emulator``) both build on it, so the bytes they exchange are defined once.
"""

from dataclasses import dataclass
import enum
import struct

HEADER = b'\xaa\xaa'
HEADER_BYTE = 0xAA
CTRL_WRITE = 0x01
CTRL_QUEUED = 0x02
MAX_PARAMS = 253          # len is one byte and counts id and ctrl as well
FRAME_OVERHEAD = 6        # header (2) + len + id + ctrl + checksum


class ProtocolError(ValueError):
    """A frame or a reply that does not follow the protocol."""


class CommandId(enum.IntEnum):
    """Command ids of the Magician protocol that helio sends or the emulator models."""

    DEVICE_SN = 0
    DEVICE_NAME = 1
    DEVICE_VERSION = 2
    DEVICE_TIME = 4
    GET_POSE = 10
    RESET_POSE = 11
    ALARMS = 20               # read: get alarms state; write: clear all alarms
    HOME_PARAMS = 30
    HOME = 31
    ARM_ORIENTATION = 50
    END_EFFECTOR_PARAMS = 60
    END_EFFECTOR_LASER = 61
    END_EFFECTOR_SUCTION_CUP = 62
    END_EFFECTOR_GRIPPER = 63
    JOG_JOINT_PARAMS = 70
    JOG_COORDINATE_PARAMS = 71
    JOG_COMMON_PARAMS = 72
    JOG = 73
    PTP_JOINT_PARAMS = 80
    PTP_COORDINATE_PARAMS = 81
    PTP_JUMP_PARAMS = 82
    PTP_COMMON_PARAMS = 83
    PTP = 84
    CP_PARAMS = 90
    CP = 91
    ARC_PARAMS = 100
    WAIT = 110
    IO_MULTIPLEXING = 130
    IO_DO = 131
    IO_PWM = 132
    IO_DI = 133
    IO_ADC = 134
    E_MOTOR = 135
    QUEUE_START = 240
    QUEUE_STOP = 241
    QUEUE_FORCE_STOP = 242
    QUEUE_CLEAR = 245
    QUEUE_CURRENT_INDEX = 246
    QUEUE_LEFT_SPACE = 247


@dataclass(frozen=True)
class CommandLayout:
    """
    Parameter sizes of one command, as the protocol's structures define them [bytes].

    ``write``: the accepted sizes of a write's parameters (None: any, e.g. a string);
    ``read``: the size of the reply to a read (None: any); ``request``: the size of a read's
    own parameters (the EIO reads name their address); ``queueable``: may be queued.
    """

    write: tuple = (0,)
    read: int = 0
    request: int = 0
    queueable: bool = False


# The Dobot Magician communication protocol's commands and their structures (DobotDll's
# tagXxx types), enough to frame every request and to tell a reply of the wrong size.
C = CommandId
LAYOUTS = {
    C.DEVICE_SN: CommandLayout(write=None, read=None),
    C.DEVICE_NAME: CommandLayout(write=None, read=None),
    C.DEVICE_VERSION: CommandLayout(write=(), read=3),
    C.DEVICE_TIME: CommandLayout(write=(), read=4),
    C.GET_POSE: CommandLayout(write=(), read=32),
    C.RESET_POSE: CommandLayout(write=(9,), read=0),
    C.ALARMS: CommandLayout(write=(0,), read=None),     # 16 bytes here; clients take any
    C.HOME_PARAMS: CommandLayout(write=(16,), read=16, queueable=True),
    C.HOME: CommandLayout(write=(0, 4), read=0, queueable=True),   # u32 reserved, optional
    C.ARM_ORIENTATION: CommandLayout(write=(1,), read=1, queueable=True),
    C.END_EFFECTOR_PARAMS: CommandLayout(write=(12,), read=12, queueable=True),
    C.END_EFFECTOR_LASER: CommandLayout(write=(2,), read=2, queueable=True),
    C.END_EFFECTOR_SUCTION_CUP: CommandLayout(write=(2,), read=2, queueable=True),
    C.END_EFFECTOR_GRIPPER: CommandLayout(write=(2,), read=2, queueable=True),
    C.JOG_JOINT_PARAMS: CommandLayout(write=(32,), read=32, queueable=True),
    C.JOG_COORDINATE_PARAMS: CommandLayout(write=(32,), read=32, queueable=True),
    C.JOG_COMMON_PARAMS: CommandLayout(write=(8,), read=8, queueable=True),
    C.JOG: CommandLayout(write=(2,), read=0, queueable=True),
    C.PTP_JOINT_PARAMS: CommandLayout(write=(32,), read=32, queueable=True),
    C.PTP_COORDINATE_PARAMS: CommandLayout(write=(16,), read=16, queueable=True),
    C.PTP_JUMP_PARAMS: CommandLayout(write=(8,), read=8, queueable=True),
    C.PTP_COMMON_PARAMS: CommandLayout(write=(8,), read=8, queueable=True),
    C.PTP: CommandLayout(write=(17,), read=0, queueable=True),
    C.CP_PARAMS: CommandLayout(write=(13,), read=13, queueable=True),
    # u8 mode + x, y, z, velocity; pydobot-style clients send the mode, x, y, z and one
    # byte (14): the missing velocity reads as 0
    C.CP: CommandLayout(write=(14, 17), read=0, queueable=True),
    C.ARC_PARAMS: CommandLayout(write=(16,), read=16, queueable=True),
    C.WAIT: CommandLayout(write=(4,), read=0, queueable=True),
    C.IO_MULTIPLEXING: CommandLayout(write=(2,), read=2, request=1, queueable=True),
    C.IO_DO: CommandLayout(write=(2,), read=2, request=1, queueable=True),
    C.IO_PWM: CommandLayout(write=(9,), read=9, request=1, queueable=True),
    C.IO_DI: CommandLayout(write=(), read=2, request=1),
    C.IO_ADC: CommandLayout(write=(), read=3, request=1),
    C.E_MOTOR: CommandLayout(write=(6,), read=0, queueable=True),
    C.QUEUE_START: CommandLayout(),
    C.QUEUE_STOP: CommandLayout(),
    C.QUEUE_FORCE_STOP: CommandLayout(),
    C.QUEUE_CLEAR: CommandLayout(),
    C.QUEUE_CURRENT_INDEX: CommandLayout(write=(), read=8),
    C.QUEUE_LEFT_SPACE: CommandLayout(write=(), read=4),
}
del C


def reply_length(request):
    """
    Return the parameter bytes of the device's reply to `request` (None: any length).

    A queued write is answered with its u64 queue index, any other write with no
    parameters, a read with the command's structure (``LAYOUTS``).
    """
    if request.write:
        return 8 if request.queued else 0
    layout = LAYOUTS.get(request.command_id)
    return None if layout is None else layout.read


def reply_matches(reply, request):
    """Whether `reply` can be the answer to `request`: same id and ctrl, right length."""
    if not is_reply_to(reply, request):
        return False
    expected = reply_length(request)
    return expected is None or len(reply.params) == expected


class PtpMode(enum.IntEnum):
    """SetPTPCmd modes used by helio (the device knows more)."""

    JUMP_XYZ = 0
    MOVJ_XYZ = 1
    MOVL_XYZ = 2
    MOVJ_ANGLE = 4


class Alarm(enum.IntEnum):
    """Alarm codes of the Magician firmware (bit number in the alarm state bitfield)."""

    COMMON_RESETTING = 0x00
    COMMON_UNDEFINED_INSTRUCTION = 0x01
    PLAN_INV_SINGULARITY = 0x10
    PLAN_INV_CALC = 0x11
    PLAN_INV_LIMIT = 0x12
    MOVE_INV_SINGULARITY = 0x20
    MOVE_INV_CALC = 0x21
    MOVE_INV_LIMIT = 0x22
    OVERSPEED_AXIS1 = 0x30
    OVERSPEED_AXIS2 = 0x31
    OVERSPEED_AXIS3 = 0x32
    OVERSPEED_AXIS4 = 0x33
    LIMIT_AXIS1_POS = 0x40
    LIMIT_AXIS1_NEG = 0x41
    LIMIT_AXIS2_POS = 0x42
    LIMIT_AXIS2_NEG = 0x43
    LIMIT_AXIS3_POS = 0x44
    LIMIT_AXIS3_NEG = 0x45
    LIMIT_AXIS4_POS = 0x46
    LIMIT_AXIS4_NEG = 0x47


ALARM_STATE_BYTES = 16    # 128 alarm bits


def alarm_description(code):
    """Human-readable name of an alarm code (unknown codes are shown in hex)."""
    try:
        alarm = Alarm(code)
    except ValueError:
        return f'alarm 0x{code:02X}'
    text = alarm.name.lower()
    if alarm.name.startswith('LIMIT_AXIS'):
        axis, side = alarm.name[len('LIMIT_AXIS'):].split('_')
        return f'joint limit: j{axis} beyond its {"upper" if side == "POS" else "lower"} limit'
    return f'{text} (0x{code:02X})'


def encode_alarm_state(codes):
    """Pack alarm codes into the 16-byte bitfield of command 20 (bit n = code n)."""
    state = bytearray(ALARM_STATE_BYTES)
    for code in codes:
        if not 0 <= code < 8 * ALARM_STATE_BYTES:
            raise ProtocolError(f'alarm code {code} outside 0..{8 * ALARM_STATE_BYTES - 1}')
        state[code // 8] |= 1 << (code % 8)
    return bytes(state)


def decode_alarm_state(params):
    """Alarm codes set in the bitfield of command 20, ascending."""
    return sorted(byte_index * 8 + bit for byte_index, value in enumerate(params)
                  for bit in range(8) if value & (1 << bit))


def checksum(command_id, ctrl, params=b''):
    """Two's-complement checksum over id, ctrl and params (a byte)."""
    return (256 - (command_id + ctrl + sum(params)) % 256) % 256


@dataclass(frozen=True)
class Frame:
    """One protocol frame: command id, ctrl bits and raw parameter bytes."""

    command_id: int
    ctrl: int = 0
    params: bytes = b''

    @property
    def write(self):
        """Whether the rw bit is set."""
        return bool(self.ctrl & CTRL_WRITE)

    @property
    def queued(self):
        """Whether the isQueued bit is set."""
        return bool(self.ctrl & CTRL_QUEUED)

    def encode(self):
        """Serialise to bytes with header, length and checksum."""
        return encode_frame(self.command_id, self.params, ctrl=self.ctrl)


def encode_frame(command_id, params=b'', write=False, queued=False, ctrl=None):
    """Frame bytes for a command id, its parameters and the rw/queued bits."""
    params = bytes(params)
    if not 0 <= command_id <= 255:
        raise ProtocolError(f'command id {command_id} outside 0..255')
    if len(params) > MAX_PARAMS:
        raise ProtocolError(f'{len(params)} parameter bytes exceed the maximum {MAX_PARAMS}')
    if ctrl is None:
        ctrl = (CTRL_WRITE if write else 0) | (CTRL_QUEUED if queued else 0)
    return (HEADER + bytes([2 + len(params), command_id, ctrl]) + params
            + bytes([checksum(command_id, ctrl, params)]))


def decode_frame(data):
    """Parse exactly one complete frame from bytes; raise ProtocolError saying what is wrong."""
    data = bytes(data)
    if len(data) < FRAME_OVERHEAD:
        raise ProtocolError(f'frame of {len(data)} bytes is shorter than {FRAME_OVERHEAD}')
    if data[:2] != HEADER:
        raise ProtocolError(f'frame starts with {data[:2].hex()} instead of aaaa')
    length = data[2]
    if length < 2:
        raise ProtocolError(f'length byte {length} is below 2')
    if len(data) != length + 4:
        raise ProtocolError(f'length byte {length} means {length + 4} bytes, got {len(data)}')
    command_id, ctrl, params, received = data[3], data[4], data[5:-1], data[-1]
    expected = checksum(command_id, ctrl, params)
    if received != expected:
        raise ProtocolError(f'checksum 0x{received:02X} should be 0x{expected:02X}')
    return Frame(command_id, ctrl, bytes(params))


class FrameReader:
    """
    Incremental, resynchronising frame parser.

    Feed it any chunks of bytes; it returns the complete valid frames found. Garbage before
    a header, frames with a bad checksum and truncated frames are skipped one byte at a time
    and counted, so a valid frame that follows them is never lost: when a candidate frame is
    still incomplete, a later header that already holds a complete valid frame wins (the
    incomplete candidate was a partial frame or garbage).
    """

    def __init__(self):
        """Start with an empty buffer and zero error counts."""
        self._buffer = bytearray()
        self.checksum_errors = 0
        self.skipped_bytes = 0

    def reset(self):
        """Drop buffered bytes (after a timeout, before a retry)."""
        self.skipped_bytes += len(self._buffer)
        self._buffer.clear()

    @property
    def pending(self):
        """Count the bytes buffered but not yet parsed."""
        return len(self._buffer)

    def feed(self, data):
        """Add bytes and return the list of complete valid frames now available."""
        self._buffer.extend(data)
        frames = []
        while True:
            start = self._buffer.find(HEADER)
            if start < 0:
                keep = 1 if self._buffer[-1:] == HEADER[:1] else 0
                self._skip(len(self._buffer) - keep)
                return frames
            self._skip(start)
            status, frame = self._try_parse(0)
            if status == 'ok':
                frames.append(frame)
                del self._buffer[:frame_length(frame)]
            elif status == 'bad':
                self._skip(1)
            else:   # incomplete: a later complete valid frame means this one is broken
                later = self._later_valid_frame()
                if later is None:
                    return frames
                self._skip(later)

    def _skip(self, count):
        if count > 0:
            self.skipped_bytes += count
            del self._buffer[:count]

    def _try_parse(self, offset):
        buffer = self._buffer
        if len(buffer) - offset < 3:
            return 'incomplete', None
        length = buffer[offset + 2]
        if length < 2:
            return 'bad', None
        end = offset + length + 4
        if len(buffer) < end:
            return 'incomplete', None
        command_id, ctrl = buffer[offset + 3], buffer[offset + 4]
        params = bytes(buffer[offset + 5:end - 1])
        if buffer[end - 1] != checksum(command_id, ctrl, params):
            if offset == 0:
                self.checksum_errors += 1
            return 'bad', None
        return 'ok', Frame(command_id, ctrl, params)

    def _later_valid_frame(self):
        offset = self._buffer.find(HEADER, 1)
        while offset >= 0:
            if self._try_parse(offset)[0] == 'ok':
                return offset
            offset = self._buffer.find(HEADER, offset + 1)
        return None


def frame_length(frame):
    """Count the bytes `frame` takes on the wire."""
    return FRAME_OVERHEAD + len(frame.params)


# ---- typed commands -------------------------------------------------------------------------

@dataclass(frozen=True)
class Pose:
    """GetPose reply: Cartesian x, y, z [mm], r [deg] and joints j1..j4 [deg]."""

    x: float
    y: float
    z: float
    r: float
    j1: float
    j2: float
    j3: float
    j4: float

    @property
    def cartesian(self):
        """Return (x, y, z, r) in mm and degrees."""
        return (self.x, self.y, self.z, self.r)

    @property
    def joints(self):
        """Return (j1, j2, j3, j4) in degrees."""
        return (self.j1, self.j2, self.j3, self.j4)


@dataclass(frozen=True)
class PtpJointParams:
    """PTP joint parameters: per-joint velocity [deg/s] and acceleration [deg/s^2]."""

    velocity: tuple = (100.0, 100.0, 100.0, 100.0)
    acceleration: tuple = (100.0, 100.0, 100.0, 100.0)


@dataclass(frozen=True)
class PtpCoordinateParams:
    """PTP coordinate parameters: xyz [mm/s, mm/s^2] and r [deg/s, deg/s^2]."""

    xyz_velocity: float = 100.0
    r_velocity: float = 100.0
    xyz_acceleration: float = 100.0
    r_acceleration: float = 100.0


@dataclass(frozen=True)
class PtpCommonParams:
    """PTP common ratios [%] applied to every PTP velocity and acceleration."""

    velocity_ratio: float = 100.0
    acceleration_ratio: float = 100.0


@dataclass(frozen=True)
class PtpCommand:
    """SetPTPCmd: mode and four floats (x, y, z [mm], r [deg] or j1..j4 [deg])."""

    mode: int
    a: float
    b: float
    c: float
    d: float


def _floats(count):
    return struct.Struct('<' + 'f' * count)


_POSE = _floats(8)
_JOINT_PARAMS = _floats(8)
_COORD_PARAMS = _floats(4)
_COMMON_PARAMS = _floats(2)
_JUMP_PARAMS = _floats(2)
_PTP = struct.Struct('<B4f')
_U32 = struct.Struct('<I')
_U64 = struct.Struct('<Q')


def get_pose_request():
    """Build GetPose (id 10, read)."""
    return Frame(CommandId.GET_POSE)


def get_alarms_request():
    """Build GetAlarmsState (id 20, read)."""
    return Frame(CommandId.ALARMS)


def clear_alarms_request():
    """Build ClearAllAlarmsState (id 20, write)."""
    return Frame(CommandId.ALARMS, CTRL_WRITE)


def home_request(queued=True):
    """Build SetHOMECmd (id 31, write, queued): one reserved u32."""
    return Frame(CommandId.HOME, CTRL_WRITE | (CTRL_QUEUED if queued else 0), _U32.pack(0))


def home_params_request(params=None, queued=False):
    """Build SetHOMEParams (id 30, write: x, y, z, r [mm, deg]) or, with params None, the read."""
    if params is None:
        return Frame(CommandId.HOME_PARAMS)
    return Frame(CommandId.HOME_PARAMS, CTRL_WRITE | (CTRL_QUEUED if queued else 0),
                 _COORD_PARAMS.pack(*params))


def ptp_jump_params_request(jump_height, max_jump_height, queued=False):
    """Build SetPTPJumpParams (id 82, write): jump height and its limit [mm]."""
    return Frame(CommandId.PTP_JUMP_PARAMS, CTRL_WRITE | (CTRL_QUEUED if queued else 0),
                 _JUMP_PARAMS.pack(jump_height, max_jump_height))


def ptp_joint_params_request(params=None, queued=False):
    """Build SetPTPJointParams (id 80, write) or, with params None, the read."""
    if params is None:
        return Frame(CommandId.PTP_JOINT_PARAMS)
    return Frame(CommandId.PTP_JOINT_PARAMS, CTRL_WRITE | (CTRL_QUEUED if queued else 0),
                 _JOINT_PARAMS.pack(*params.velocity, *params.acceleration))


def ptp_coordinate_params_request(params=None, queued=False):
    """Build SetPTPCoordinateParams (id 81, write) or, with params None, the read."""
    if params is None:
        return Frame(CommandId.PTP_COORDINATE_PARAMS)
    return Frame(CommandId.PTP_COORDINATE_PARAMS, CTRL_WRITE | (CTRL_QUEUED if queued else 0),
                 _COORD_PARAMS.pack(params.xyz_velocity, params.r_velocity,
                                    params.xyz_acceleration, params.r_acceleration))


def ptp_common_params_request(params=None, queued=False):
    """Build SetPTPCommonParams (id 83, write) or, with params None, the read."""
    if params is None:
        return Frame(CommandId.PTP_COMMON_PARAMS)
    return Frame(CommandId.PTP_COMMON_PARAMS, CTRL_WRITE | (CTRL_QUEUED if queued else 0),
                 _COMMON_PARAMS.pack(params.velocity_ratio, params.acceleration_ratio))


def ptp_request(command, queued=True):
    """Build SetPTPCmd (id 84, write, queued): u8 mode + 4 float32."""
    if command.mode not in tuple(PtpMode):
        raise ProtocolError(f'PTP mode {command.mode} is not one of {[int(m) for m in PtpMode]}')
    return Frame(CommandId.PTP, CTRL_WRITE | (CTRL_QUEUED if queued else 0),
                 _PTP.pack(command.mode, command.a, command.b, command.c, command.d))


def wait_request(milliseconds, queued=True):
    """Build SetWAITCmd (id 110, write, queued): u32 wait time [ms]."""
    if not 0 <= milliseconds < 2 ** 32:
        raise ProtocolError(f'wait of {milliseconds} ms outside the u32 range')
    return Frame(CommandId.WAIT, CTRL_WRITE | (CTRL_QUEUED if queued else 0),
                 _U32.pack(int(milliseconds)))


def queue_start_request():
    """Build SetQueuedCmdStartExec (id 240, write)."""
    return Frame(CommandId.QUEUE_START, CTRL_WRITE)


def queue_stop_request():
    """Build SetQueuedCmdStopExec (id 241, write): stop after the current command."""
    return Frame(CommandId.QUEUE_STOP, CTRL_WRITE)


def queue_force_stop_request():
    """Build SetQueuedCmdForceStopExec (id 242, write): stop now, mid-move."""
    return Frame(CommandId.QUEUE_FORCE_STOP, CTRL_WRITE)


def queue_clear_request():
    """Build SetQueuedCmdClear (id 245, write): drop the commands not yet executed."""
    return Frame(CommandId.QUEUE_CLEAR, CTRL_WRITE)


def queue_current_index_request():
    """Build GetQueuedCmdCurrentIndex (id 246, read): reply u64 executed index."""
    return Frame(CommandId.QUEUE_CURRENT_INDEX)


def queue_left_space_request():
    """Build GetQueuedCmdLeftSpace (id 247, read): reply u32 free places in the queue."""
    return Frame(CommandId.QUEUE_LEFT_SPACE)


# ---- parameter decoding (both directions, used by the client and the emulator) -------------

def _unpack(layout, params, what):
    if len(params) != layout.size:
        raise ProtocolError(f'{what}: expected {layout.size} parameter bytes, got {len(params)}')
    return layout.unpack(params)


def encode_pose(pose):
    """Parameter bytes of a GetPose reply."""
    return _POSE.pack(*pose.cartesian, *pose.joints)


def decode_pose(params):
    """Pose from the parameter bytes of a GetPose reply."""
    return Pose(*_unpack(_POSE, params, 'GetPose reply'))


def decode_ptp_joint_params(params):
    """Decode PtpJointParams from the parameter bytes of id 80."""
    values = _unpack(_JOINT_PARAMS, params, 'PTP joint params')
    return PtpJointParams(tuple(values[:4]), tuple(values[4:]))


def decode_ptp_coordinate_params(params):
    """Decode PtpCoordinateParams from the parameter bytes of id 81."""
    return PtpCoordinateParams(*_unpack(_COORD_PARAMS, params, 'PTP coordinate params'))


def decode_ptp_common_params(params):
    """Decode PtpCommonParams from the parameter bytes of id 83."""
    return PtpCommonParams(*_unpack(_COMMON_PARAMS, params, 'PTP common params'))


def decode_ptp(params):
    """Decode PtpCommand from the parameter bytes of id 84."""
    return PtpCommand(*_unpack(_PTP, params, 'SetPTPCmd'))


def decode_wait(params):
    """Wait time [ms] from the parameter bytes of id 110."""
    return _unpack(_U32, params, 'SetWAITCmd')[0]


def encode_index(index):
    """u64 queue index parameter bytes."""
    return _U64.pack(index)


def decode_index(params):
    """u64 queue index from reply parameter bytes (queued write or id 246)."""
    return _unpack(_U64, params, 'queue index')[0]


def encode_u32(value):
    """u32 parameter bytes (SetWAITCmd, GetQueuedCmdLeftSpace's reply)."""
    return _U32.pack(value)


def decode_u32(params):
    """u32 from parameter bytes."""
    return _unpack(_U32, params, 'u32')[0]


def decode_home_params(params):
    """Home position (x, y, z [mm], r [deg]) from the parameter bytes of id 30."""
    return _unpack(_COORD_PARAMS, params, 'HOME params')


def command_name(command_id):
    """Return the protocol name of a command id (``PTP``), or ``command N`` for others."""
    try:
        return CommandId(command_id).name
    except ValueError:
        return f'command {command_id}'


def is_reply_to(reply, request):
    """Whether `reply` answers `request` (the device echoes id and ctrl)."""
    return reply.command_id == request.command_id and reply.ctrl == request.ctrl
