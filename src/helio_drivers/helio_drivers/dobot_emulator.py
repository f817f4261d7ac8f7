"""
Byte-exact Dobot Magician emulator on a pseudo-terminal.

It answers the frames of ``dobot_protocol`` like the firmware: reads reply with data, writes
echo id and ctrl, queued writes reply with their u64 queue index and run later, in order,
while the queue is started. Motion follows an injected clock (any callable returning seconds:
``time.monotonic`` or a simulated clock), so the simulated world can host the arm and read
where it is with ``joint_positions()`` at its own time:

- PTP MOVJ (joint-interpolated, also JUMP which is treated as MOVJ) and MOVJ_ANGLE: all joints
  start and stop together on one trapezoidal profile that respects each joint's velocity and
  acceleration (PTP joint params x common ratio, capped by the hardware limits);
- MOVL: the flange follows a straight line on a trapezoid under the coordinate params; the
  joints follow by inverse kinematics at each instant;
- HOME: a joint move to the home joints; WAIT: a pause.

Targets are checked when a command starts executing, as the device does: a Cartesian target
out of reach raises PLAN_INV_CALC, joints beyond their limits raise PLAN_INV_LIMIT (Cartesian)
and LIMIT_AXISn_POS/NEG naming the joint; the command is then skipped (its index still counts
as executed). Force-stop halts the arm where it is. Kinematics come from
``helio_optics.arm_kinematics.DobotArm`` (SI) with the protocol's mm and degrees converted.
"""

import collections
from dataclasses import dataclass
import math
import struct
import threading
import time

from helio_drivers import dobot_protocol as proto
from helio_drivers.motion_profile import synchronised_profile, TrapezoidProfile
from helio_drivers.pty_device import PtyDevice
from helio_optics.arm_kinematics import DobotArm, UnreachableError
import numpy as np


@dataclass(frozen=True)
class DobotHardwareLimits:
    """The emulated arm's physical caps on PTP parameters (what the motors can do)."""

    joint_velocity_dps: float = 320.0          # [deg/s]
    joint_acceleration_dps2: float = 1000.0    # [deg/s^2]
    xyz_velocity_mmps: float = 500.0           # [mm/s]
    xyz_acceleration_mmps2: float = 2000.0     # [mm/s^2]


class _Motion:
    """A queued command being executed: joints [deg] as a function of clock time."""

    def __init__(self, index, start, duration, joints_at):
        self.index = index
        self.start = start
        self.end = start + duration
        self.joints_at = joints_at          # callable(t since start) -> np.array(4) [deg]


class DobotEmulator(PtyDevice):
    """The Dobot Magician on a pty; see the module docstring."""

    def __init__(self, port_path=None, clock=time.monotonic, arm=None,
                 home_joints_deg=(0.0, 10.0, 10.0, 0.0), initial_joints_deg=None,
                 hardware_limits=DobotHardwareLimits(), joint_params=None,
                 coordinate_params=None, common_params=None, seed=0, line_baudrate=None,
                 queue_capacity=32, firmware_version=(3, 7, 0)):
        """Start the device idle at `initial_joints_deg` (home if None), queue started."""
        self.clock = clock
        self.arm = arm or DobotArm()
        self.hardware = hardware_limits
        self.home_joints_deg = np.array(home_joints_deg, dtype=float)
        start = home_joints_deg if initial_joints_deg is None else initial_joints_deg
        self._joints = np.array(start, dtype=float)
        self._joint_params = joint_params or proto.PtpJointParams()
        self._coordinate_params = coordinate_params or proto.PtpCoordinateParams()
        self._common_params = common_params or proto.PtpCommonParams()
        self._lock = threading.RLock()
        self._queue = collections.deque()       # (index, frame, time it became runnable)
        self._current = None
        self._executing = True
        self._free_at = clock()
        self._last_index = 0
        self._executed_index = 0
        self._alarms = set()
        self._lost_replies = {}                 # command id -> replies still to lose
        self._missized_replies = {}             # command id -> replies still to mis-size
        self._forged_replies = {}               # command id -> replies still to forge
        self._settings = {}                     # command id (, address) -> bytes written
        self._home_params = None                # SetHOMEParams (mm, deg), None: home joints
        self._started_at = clock()
        self.queue_capacity = queue_capacity
        self.firmware_version = tuple(firmware_version)
        self.last_refusal = ''
        self.motion_durations = {}     # queue index -> planned motion time [s] (benchmarks)
        self.frames_received = 0
        self.checksum_errors_seen = 0
        self._reader = proto.FrameReader()
        limits = self.arm.parameters.limits() + (self.arm.parameters.end_servo_limit(),)
        self._limits_deg = [(math.degrees(limit.lower), math.degrees(limit.upper))
                            for limit in limits]
        super().__init__(port_path=port_path, seed=seed, name='dobot',
                         line_baudrate=line_baudrate)

    # ---- in-process accessors (for the simulated world and tests) ---------------------------

    def joint_positions_deg(self):
        """Return j1..j4 [deg] at the clock's present time."""
        with self._lock:
            return self._joints_now(self._advance()).copy()

    def joint_positions(self):
        """Return j1..j4 [rad] at the clock's present time."""
        return np.radians(self.joint_positions_deg())

    def pose(self):
        """Return the current GetPose answer (mm, deg)."""
        with self._lock:
            return self._pose(self._joints_now(self._advance()))

    @property
    def executed_index(self):
        """Index of the last queued command executed."""
        with self._lock:
            self._advance()
            return self._executed_index

    @property
    def alarms(self):
        """Active alarm codes, ascending."""
        with self._lock:
            self._advance()
            return sorted(self._alarms)

    def is_moving(self):
        """Whether a queued motion is in progress now."""
        with self._lock:
            self._advance()
            return self._current is not None

    @property
    def last_queued_index(self):
        """Index the device gave the last queued command (the truth a client must report)."""
        with self._lock:
            return self._last_index

    @property
    def queued_count(self):
        """Commands queued and not yet started."""
        with self._lock:
            self._advance()
            return len(self._queue)

    def raise_alarm(self, code):
        """Set an alarm as the firmware would (fault injection beyond the link)."""
        with self._lock:
            self._alarms.add(int(code))

    # ---- protocol ---------------------------------------------------------------------------

    def lose_replies(self, command_id, count=1):
        """Act on the next `count` frames of `command_id` but send no reply (lost replies)."""
        with self._lock:
            self._lost_replies[int(command_id)] = int(count)

    def missize_replies(self, command_id, count=1):
        """Answer the next `count` frames of `command_id` with one parameter byte too few."""
        with self._lock:
            self._missized_replies[int(command_id)] = int(count)

    def forge_replies(self, command_id, count=1):
        """
        Answer the next `count` frames of `command_id` with random parameter bytes.

        Framed as the device frames them, with a valid checksum: the line noise one frame
        in 256 of which passes the checksum; only the client's check of the values can
        catch it.
        """
        with self._lock:
            self._forged_replies[int(command_id)] = int(count)

    def handle_input(self, data):
        """Parse frames and return their replies (bytes)."""
        errors_before = self._reader.checksum_errors
        frames = self._reader.feed(data)
        self.checksum_errors_seen += self._reader.checksum_errors - errors_before
        replies = []
        for frame in frames:
            self.frames_received += 1
            reply = self.handle_frame(frame)
            if reply is not None:
                replies.append(reply.encode())
        return replies

    def handle_frame(self, frame):
        """Act on one frame and return the reply Frame (None: the reply is lost)."""
        with self._lock:
            reply = self._answer(frame, self._advance())
            cid = frame.command_id
            if self._lost_replies.get(cid, 0) > 0:
                self._lost_replies[cid] -= 1
                return None
            if self._forged_replies.get(cid, 0) > 0:
                self._forged_replies[cid] -= 1
                noise = bytes(self._random.randrange(256) for _ in reply.params)
                return proto.Frame(cid, reply.ctrl, noise)
            if self._missized_replies.get(cid, 0) > 0:
                self._missized_replies[cid] -= 1
                params = reply.params[:-1] if reply.params else b'\x00'
                return proto.Frame(cid, reply.ctrl, params)
            return reply

    def _answer(self, frame, now):
        cid, ctrl = frame.command_id, frame.ctrl
        layout = proto.LAYOUTS.get(cid)
        if layout is None:
            # Not a command of the protocol: the firmware flags an undefined instruction.
            # The frame is still echoed (no parameters), so a client waiting for it does not
            # hang; a client checking the reply's size sees that it is not an answer.
            self._refuse(proto.Alarm.COMMON_UNDEFINED_INSTRUCTION,
                         f'command {cid} is not in the protocol')
            return proto.Frame(cid, ctrl)
        problem = _malformed(frame, layout)
        if problem:
            self._refuse(proto.Alarm.COMMON_UNDEFINED_INSTRUCTION, problem)
            return proto.Frame(cid, ctrl)
        if frame.write and frame.queued and layout.queueable:
            self._last_index += 1
            self._queue.append((self._last_index, frame, now))
            self._advance()
            return proto.Frame(cid, ctrl, proto.encode_index(self._last_index))
        return proto.Frame(cid, ctrl, self._immediate(frame, now))

    def _immediate(self, frame, now):
        """Act on an unqueued frame; return its reply's parameter bytes."""
        cid, write = frame.command_id, frame.write
        C = proto.CommandId
        if cid == C.GET_POSE:
            return proto.encode_pose(self._pose(self._joints_now(now)))
        if cid == C.ALARMS:
            if write:
                self._alarms.clear()
                return b''
            return proto.encode_alarm_state(self._alarms)
        if cid == C.QUEUE_START:
            if not self._executing:
                self._executing = True
                self._free_at = max(self._free_at, now)
                self._advance()
        elif cid == C.QUEUE_STOP:
            self._executing = False           # the current command still finishes
        elif cid == C.QUEUE_FORCE_STOP:
            self._executing = False
            if self._current is not None:     # halt where the arm is now
                self._joints = self._joints_now(now)
                self._current = None
                self._free_at = now
        elif cid == C.QUEUE_CLEAR:
            self._queue.clear()
        elif cid == C.QUEUE_CURRENT_INDEX:
            return proto.encode_index(self._executed_index)
        elif cid == C.QUEUE_LEFT_SPACE:
            return proto.encode_u32(max(0, self.queue_capacity - len(self._queue)))
        elif cid == C.DEVICE_VERSION:
            return bytes(self.firmware_version)
        elif cid == C.DEVICE_TIME:
            return proto.encode_u32(int((now - self._started_at) * 1000.0) % 2 ** 32)
        elif cid == C.HOME_PARAMS and not write:
            return proto.home_params_request(self._home_position()).params
        elif write and cid in _MOTION:
            # Unqueued motion commands: the firmware runs them next; helio always queues.
            self._last_index += 1
            self._queue.appendleft((self._last_index, frame, now))
            self._advance()
        elif write:
            self._apply_setting(frame)
        else:
            return self._setting(frame)
        return b''

    def _apply_setting(self, frame):
        """Store a written setting (PTP parameters take effect on the next move)."""
        C = proto.CommandId
        cid, params = frame.command_id, bytes(frame.params)
        if cid == C.PTP_JOINT_PARAMS:
            self._joint_params = proto.decode_ptp_joint_params(params)
        elif cid == C.PTP_COORDINATE_PARAMS:
            self._coordinate_params = proto.decode_ptp_coordinate_params(params)
        elif cid == C.PTP_COMMON_PARAMS:
            self._common_params = proto.decode_ptp_common_params(params)
        elif cid == C.HOME_PARAMS:
            self._home_params = proto.decode_home_params(params)
        layout = proto.LAYOUTS[cid]
        key = (cid, params[0]) if layout.request and params else cid
        self._settings[key] = params

    def _setting(self, frame):
        """Reply bytes of a read: the last value written, or the device's default."""
        C = proto.CommandId
        cid = frame.command_id
        if cid == C.PTP_JOINT_PARAMS:
            return proto.ptp_joint_params_request(self._joint_params).params
        if cid == C.PTP_COORDINATE_PARAMS:
            return proto.ptp_coordinate_params_request(self._coordinate_params).params
        if cid == C.PTP_COMMON_PARAMS:
            return proto.ptp_common_params_request(self._common_params).params
        layout = proto.LAYOUTS[cid]
        if layout.request:          # addressed (EIO): the address, then its value
            address = bytes(frame.params[:1]) or b'\x00'
            stored = self._settings.get((cid, address[0]), address + bytes(layout.read - 1))
            return address + stored[1:layout.read]
        default = _DEFAULT_SETTINGS.get(cid, bytes(layout.read or 0))
        return self._settings.get(cid, default)

    def _home_position(self):
        """Return the homing target (x, y, z [mm], r [deg]): SetHOMEParams, else home joints."""
        if self._home_params is not None:
            return self._home_params
        return self._pose(self.home_joints_deg).cartesian

    # ---- motion -----------------------------------------------------------------------------

    def _pose(self, joints_deg):
        position_mm = self.arm.forward(np.radians(joints_deg[:3])) * 1000.0
        r = joints_deg[0] + joints_deg[3]
        return proto.Pose(*position_mm, r, *joints_deg)

    def _joints_now(self, now):
        if self._current is None:
            return self._joints.copy()
        return self._current.joints_at(now - self._current.start)

    def _advance(self):
        """Run the queue up to the clock's present time; return that time."""
        now = self.clock()
        while True:
            if self._current is not None:
                if now < self._current.end:
                    break
                self._joints = self._current.joints_at(self._current.end - self._current.start)
                self._executed_index = self._current.index
                self._free_at = self._current.end
                self._current = None
            if not self._executing or not self._queue:
                break
            index, frame, runnable_at = self._queue.popleft()
            start = max(self._free_at, runnable_at)
            motion = self._plan(index, frame, start)
            if motion is None:      # refused or instantaneous: executed at once
                self._executed_index = index
                self._free_at = start
            else:
                self._current = motion
                self.motion_durations[index] = motion.end - motion.start
        return now

    def _ratios(self):
        return (self._common_params.velocity_ratio / 100.0,
                self._common_params.acceleration_ratio / 100.0)

    def _plan(self, index, frame, start):
        C = proto.CommandId
        cid = frame.command_id
        if cid == C.WAIT:
            duration = proto.decode_wait(frame.params) / 1000.0
            held = self._joints.copy()
            return _Motion(index, start, duration, lambda t: held.copy())
        if cid == C.HOME:
            if self._home_params is None:
                return self._joint_move(index, start, self.home_joints_deg.copy())
            target = self._inverse(np.array(self._home_params, dtype=float))
            return None if target is None else self._joint_move(index, start, target)
        if cid == C.CP:
            return self._continuous_path(index, start, frame.params)
        if cid != C.PTP:        # a setting, queued: it takes effect in its turn
            self._apply_setting(frame)
            return None
        command = proto.decode_ptp(frame.params)
        mode = command.mode
        values = np.array([command.a, command.b, command.c, command.d], dtype=float)
        if mode == proto.PtpMode.MOVJ_ANGLE:
            if not self._check_joint_limits(values, cartesian=False):
                return None
            return self._joint_move(index, start, values)
        if mode in (proto.PtpMode.MOVJ_XYZ, proto.PtpMode.JUMP_XYZ, proto.PtpMode.MOVL_XYZ):
            target = self._inverse(values)
            if target is None:
                return None
            if mode == proto.PtpMode.MOVL_XYZ:
                return self._linear_move(index, start, values, target)
            return self._joint_move(index, start, target)
        self._refuse(proto.Alarm.COMMON_UNDEFINED_INSTRUCTION, f'PTP mode {mode} not emulated')
        return None

    def _continuous_path(self, index, start, params):
        """SetCPCmd: a straight line to (x, y, z) [mm], absolute (mode 1) or relative (0)."""
        mode = params[0]
        x, y, z = struct.unpack('<3f', bytes(params[1:13]))
        here = self._pose(self._joints)
        target = np.array([x, y, z, here.r], dtype=float)
        if mode == 0:
            target[:3] += np.array(here.cartesian[:3])
        joints = self._inverse(target)
        return None if joints is None else self._linear_move(index, start, target, joints)

    def _refuse(self, alarm, reason):
        self._alarms.add(int(alarm))
        self.last_refusal = reason

    def _limits_usable(self, index, kind, velocities, accelerations):
        """
        Whether the PTP limits of a move can plan it; if not, refuse it with an alarm.

        The settings are stored as written (the protocol's acknowledgement cannot refuse
        one), so a zero, negative or non-finite velocity or acceleration meets its move
        here: the move is skipped with PLAN_INV_CALC, as a target it cannot plan, and the
        device goes on answering (issue 35: it used to kill the emulated arm's thread).
        """
        bad = [f'{name} {value:g}' for name, values in (('velocity', velocities),
                                                        ('acceleration', accelerations))
               for value in values if not (math.isfinite(value) and value > 0.0)]
        if bad:
            self._refuse(proto.Alarm.PLAN_INV_CALC,
                         f'move {index} refused: {kind} {", ".join(bad)} (PTP parameters '
                         'must be positive)')
        return not bad

    def _check_joint_limits(self, joints_deg, cartesian):
        for axis, (value, (lower, upper)) in enumerate(zip(joints_deg, self._limits_deg)):
            if lower - 1e-3 <= value <= upper + 1e-3:
                continue
            positive = value > upper
            alarm = proto.Alarm.LIMIT_AXIS1_POS + 2 * axis + (0 if positive else 1)
            if cartesian:
                self._alarms.add(int(proto.Alarm.PLAN_INV_LIMIT))
            self._refuse(alarm, f'j{axis + 1} target {value:.2f} deg outside '
                                f'[{lower:.1f}, {upper:.1f}] deg')
            return False
        return True

    def _inverse(self, cartesian_mm_deg):
        """Joints [deg] for (x, y, z [mm], r [deg]), or None after raising the alarm."""
        try:
            joints = self.arm.inverse(cartesian_mm_deg[:3] / 1000.0, check_limits=False)
        except UnreachableError as error:
            self._refuse(proto.Alarm.PLAN_INV_CALC, str(error))
            return None
        joints_deg = np.degrees(joints)
        joints_deg = np.append(joints_deg, cartesian_mm_deg[3] - joints_deg[0])
        if not self._check_joint_limits(joints_deg, cartesian=True):
            return None
        return joints_deg

    def _joint_move(self, index, start, target_deg):
        origin = self._joints.copy()
        distance = target_deg - origin
        velocity_ratio, acceleration_ratio = self._ratios()
        velocities = [min(v * velocity_ratio, self.hardware.joint_velocity_dps)
                      for v in self._joint_params.velocity]
        accelerations = [min(a * acceleration_ratio, self.hardware.joint_acceleration_dps2)
                         for a in self._joint_params.acceleration]
        if not self._limits_usable(index, 'joint', velocities, accelerations):
            return None
        profile = synchronised_profile(distance, velocities, accelerations)
        if profile is None or profile.duration == 0.0:
            self._joints = target_deg.copy()
            return None
        return _Motion(index, start, profile.duration,
                       lambda t: origin + distance * profile.position(t))

    def _linear_move(self, index, start, target_cartesian, target_joints):
        origin_joints = self._joints.copy()
        origin = self._pose(origin_joints)
        origin_xyz = np.array(origin.cartesian[:3])
        target_xyz = np.array(target_cartesian[:3], dtype=float)
        length = float(np.linalg.norm(target_xyz - origin_xyz))
        j4_distance = target_joints[3] - origin_joints[3]
        for s in np.linspace(0.0, 1.0, 41)[1:-1]:     # the whole line must stay reachable
            point = origin_xyz + (target_xyz - origin_xyz) * s
            if self._inverse(np.append(point, 0.0)) is None:
                return None
        velocity_ratio, acceleration_ratio = self._ratios()
        v = min(self._coordinate_params.xyz_velocity * velocity_ratio,
                self.hardware.xyz_velocity_mmps)
        a = min(self._coordinate_params.xyz_acceleration * acceleration_ratio,
                self.hardware.xyz_acceleration_mmps2)
        if length < 1e-9:
            r_limits = ([self._coordinate_params.r_velocity * velocity_ratio],
                        [self._coordinate_params.r_acceleration * acceleration_ratio])
            if not self._limits_usable(index, 'rotation', *r_limits):
                return None
            profile = synchronised_profile([j4_distance], *r_limits)
            if profile is None:
                return None
        else:
            if not self._limits_usable(index, 'Cartesian', [v], [a]):
                return None
            profile = TrapezoidProfile(v / length, a / length)
        arm = self.arm

        def joints_at(t):
            s = profile.position(t)
            if s >= 1.0:
                return target_joints.copy()
            point = (origin_xyz + (target_xyz - origin_xyz) * s) / 1000.0
            joints = np.degrees(arm.inverse(point, check_limits=False))
            return np.append(joints, origin_joints[3] + j4_distance * s)

        return _Motion(index, start, profile.duration, joints_at)


_MOTION = frozenset((proto.CommandId.HOME, proto.CommandId.PTP, proto.CommandId.WAIT,
                     proto.CommandId.CP))

_DEFAULT_SETTINGS = {
    proto.CommandId.DEVICE_SN: b'HELIO-EMULATOR-0001\x00',
    proto.CommandId.DEVICE_NAME: b'Dobot Magician (helio emulator)\x00',
    proto.CommandId.PTP_JUMP_PARAMS: struct.pack('<2f', 20.0, 100.0),
}


def _malformed(frame, layout):
    """Why a frame's parameters do not fit its command's structure ('' when they do)."""
    name = proto.command_name(frame.command_id)
    size = len(frame.params)
    if frame.write:
        if layout.write is not None and size not in layout.write:
            if not layout.write:
                return f'{name} cannot be written'
            sizes = ' or '.join(map(str, layout.write))
            return f'{name} takes {sizes} parameter bytes, got {size}'
        if frame.command_id == proto.CommandId.PTP and frame.params[0] not in tuple(proto.PtpMode):
            return f'PTP mode {frame.params[0]} not emulated'
    elif size not in (0, layout.request):
        return f'reading {name} takes {layout.request} parameter bytes, got {size}'
    return ''
