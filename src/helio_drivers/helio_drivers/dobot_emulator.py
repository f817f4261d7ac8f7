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
import threading
import time

from helio_drivers import dobot_protocol as proto
from helio_drivers.motion_profile import synchronised_profile, TrapezoidProfile
from helio_drivers.pty_device import PtyDevice
from helio_optics.arm_kinematics import DobotArm, UnreachableError
import numpy as np

J4_LIMITS_DEG = (-150.0, 150.0)


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
                 coordinate_params=None, common_params=None, seed=0, line_baudrate=None):
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
        self.last_refusal = ''
        self.motion_durations = {}     # queue index -> planned motion time [s] (benchmarks)
        self.frames_received = 0
        self.checksum_errors_seen = 0
        self._reader = proto.FrameReader()
        limits = self.arm.parameters.limits()
        self._limits_deg = [(math.degrees(limit.lower), math.degrees(limit.upper))
                            for limit in limits] + [J4_LIMITS_DEG]
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

    def raise_alarm(self, code):
        """Set an alarm as the firmware would (fault injection beyond the link)."""
        with self._lock:
            self._alarms.add(int(code))

    # ---- protocol ---------------------------------------------------------------------------

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
        """Act on one frame and return the reply Frame (None: the device stays silent)."""
        with self._lock:
            now = self._advance()
            cid, ctrl = frame.command_id, frame.ctrl
            try:
                if frame.queued and cid in _QUEUEABLE:
                    self._decode_queued(frame)          # malformed parameters: no reply
                    self._last_index += 1
                    self._queue.append((self._last_index, frame, now))
                    self._advance()
                    return proto.Frame(cid, ctrl, proto.encode_index(self._last_index))
                return self._immediate(frame, now)
            except proto.ProtocolError:
                self._alarms.add(proto.Alarm.COMMON_UNDEFINED_INSTRUCTION)
                return None

    def _immediate(self, frame, now):
        cid, ctrl, write = frame.command_id, frame.ctrl, frame.write
        C = proto.CommandId
        if cid == C.GET_POSE and not write:
            params = proto.encode_pose(self._pose(self._joints_now(now)))
        elif cid == C.ALARMS:
            if write:
                self._alarms.clear()
                params = b''
            else:
                params = proto.encode_alarm_state(self._alarms)
        elif cid == C.PTP_JOINT_PARAMS:
            if write:
                self._joint_params = proto.decode_ptp_joint_params(frame.params)
                params = b''
            else:
                params = proto.ptp_joint_params_request(self._joint_params).params
        elif cid == C.PTP_COORDINATE_PARAMS:
            if write:
                self._coordinate_params = proto.decode_ptp_coordinate_params(frame.params)
                params = b''
            else:
                params = proto.ptp_coordinate_params_request(self._coordinate_params).params
        elif cid == C.PTP_COMMON_PARAMS:
            if write:
                self._common_params = proto.decode_ptp_common_params(frame.params)
                params = b''
            else:
                params = proto.ptp_common_params_request(self._common_params).params
        elif cid == C.QUEUE_START and write:
            if not self._executing:
                self._executing = True
                self._free_at = max(self._free_at, now)
                self._advance()
            params = b''
        elif cid == C.QUEUE_STOP and write:
            self._executing = False           # the current command still finishes
            params = b''
        elif cid == C.QUEUE_FORCE_STOP and write:
            self._executing = False
            if self._current is not None:     # halt where the arm is now
                self._joints = self._joints_now(now)
                self._current = None
                self._free_at = now
            params = b''
        elif cid == C.QUEUE_CLEAR and write:
            self._queue.clear()
            params = b''
        elif cid == C.QUEUE_CURRENT_INDEX and not write:
            params = proto.encode_index(self._executed_index)
        elif cid in (C.HOME, C.PTP, C.WAIT) and write:
            # Unqueued motion commands: the firmware accepts them; helio always queues them.
            self._last_index += 1
            self._queue.appendleft((self._last_index, frame, now))
            self._advance()
            params = b''
        else:
            raise proto.ProtocolError(f'command {cid} ctrl {ctrl} is not emulated')
        return proto.Frame(cid, ctrl, params)

    @staticmethod
    def _decode_queued(frame):
        C = proto.CommandId
        if frame.command_id == C.PTP:
            proto.decode_ptp(frame.params)
        elif frame.command_id == C.WAIT:
            proto.decode_wait(frame.params)
        elif frame.command_id == C.HOME and len(frame.params) != 4:
            raise proto.ProtocolError('SetHOMECmd takes 4 parameter bytes')
        elif frame.command_id == C.PTP_JOINT_PARAMS:
            proto.decode_ptp_joint_params(frame.params)
        elif frame.command_id == C.PTP_COORDINATE_PARAMS:
            proto.decode_ptp_coordinate_params(frame.params)
        elif frame.command_id == C.PTP_COMMON_PARAMS:
            proto.decode_ptp_common_params(frame.params)

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
        if cid == C.PTP_JOINT_PARAMS:
            self._joint_params = proto.decode_ptp_joint_params(frame.params)
            return None
        if cid == C.PTP_COORDINATE_PARAMS:
            self._coordinate_params = proto.decode_ptp_coordinate_params(frame.params)
            return None
        if cid == C.PTP_COMMON_PARAMS:
            self._common_params = proto.decode_ptp_common_params(frame.params)
            return None
        if cid == C.WAIT:
            duration = proto.decode_wait(frame.params) / 1000.0
            held = self._joints.copy()
            return _Motion(index, start, duration, lambda t: held.copy())
        if cid == C.HOME:
            return self._joint_move(index, start, self.home_joints_deg.copy())
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

    def _refuse(self, alarm, reason):
        self._alarms.add(int(alarm))
        self.last_refusal = reason

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
            profile = synchronised_profile(
                [j4_distance], [self._coordinate_params.r_velocity * velocity_ratio],
                [self._coordinate_params.r_acceleration * acceleration_ratio])
            if profile is None:
                return None
        else:
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


_QUEUEABLE = frozenset((proto.CommandId.HOME, proto.CommandId.PTP, proto.CommandId.WAIT,
                        proto.CommandId.PTP_JOINT_PARAMS, proto.CommandId.PTP_COORDINATE_PARAMS,
                        proto.CommandId.PTP_COMMON_PARAMS))
