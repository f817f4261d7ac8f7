"""
Dobot Magician client over pyserial: typed commands with timeouts and bounded retries.

Every request waits for the reply that echoes its id and ctrl with the parameter size the
protocol defines for it (and, for a queued write, an index above those given before), up to
``timeout`` seconds; a missing, corrupted (bad checksum), truncated or mis-sized reply is
retried up to ``retries`` more times, then ``DeviceTimeoutError`` says which command failed.
After a timeout or a retry the next request first settles the line (a read that the device
answers after every earlier reply), so a late reply never answers a later request.
Retrying a queued move whose reply was lost may queue it twice; PTP targets are absolute,
so the duplicate is a move of zero length (and the driver node force-stops and clears the
queue whenever a move fails). A failing port (unplugged) raises
``LinkError`` at once and closes the port.

A queued move is complete when the executed index (command 246) reaches the index its
reply gave (``wait_for_index``), never when the reply arrives. ``check_target`` refuses a
target beyond the joint limits before anything is sent, naming the joint, using
``helio_optics.arm_kinematics.DobotArm``; units are converted here between SI (m, rad) and
the protocol (mm, deg).
"""

import math
import time

from helio_drivers import dobot_protocol as proto
from helio_drivers.serial_link import (
    DeviceTimeoutError, LinkError, PORT_FAILURES, SerialClient)
from helio_optics.arm_kinematics import check_joint_limits, DobotArm
import numpy as np
import serial

# The read that settles the line after a timeout (see DobotClient._settle).
_SETTLE = proto.ptp_common_params_request()

CARTESIAN_MODES = (proto.PtpMode.MOVJ_XYZ, proto.PtpMode.MOVL_XYZ, proto.PtpMode.JUMP_XYZ)
# no Dobot Magician reports its end farther from its base [mm] (its reach is 320 mm): a pose
# farther out is noise that passed the checksum (``DobotClient.possible_pose``)
POSE_RADIUS_MAX_MM = 1000.0


def target_to_protocol(mode, target):
    """PTP parameters (mm, deg) for an SI target: (x, y, z [m], r [rad]) or j1..j4 [rad]."""
    target = [float(v) for v in target]
    if len(target) != 4 or not all(math.isfinite(v) for v in target):
        raise ValueError(f'target must be 4 finite numbers, got {target}')
    if mode == proto.PtpMode.MOVJ_ANGLE:
        return tuple(math.degrees(v) for v in target)
    if mode in CARTESIAN_MODES:
        return (target[0] * 1000.0, target[1] * 1000.0, target[2] * 1000.0,
                math.degrees(target[3]))
    raise ValueError(f'mode {mode} is not one of MOVJ_XYZ (1), MOVL_XYZ (2), MOVJ_ANGLE (4)')


def _describe_pose(pose):
    return (f'x, y, z {pose.x:.6g}, {pose.y:.6g}, {pose.z:.6g} mm, joints '
            f'{", ".join(f"{j:.6g}" for j in pose.joints)} deg')


def pose_to_si(pose):
    """Return (x, y, z [m], r [rad]) and (j1..j4 [rad]) of a GetPose reply."""
    cartesian = (pose.x / 1000.0, pose.y / 1000.0, pose.z / 1000.0, math.radians(pose.r))
    return cartesian, tuple(math.radians(j) for j in pose.joints)


def check_target(arm, mode, target):
    """
    Raise UnreachableError (naming the joint and the excess) for a target beyond the limits.

    `target` is SI as in MoveArm: Cartesian (m, rad) or joints (rad). The end servo j4 is
    checked against the arm parameters' ``j4_limits`` as well.
    """
    values = np.array([float(v) for v in target])
    if mode == proto.PtpMode.MOVJ_ANGLE:
        joints = values[:3]
        arm.check_limits(joints)
        j4 = values[3]
    elif mode in CARTESIAN_MODES:
        joints = arm.inverse(values[:3], check_limits=True)
        j4 = values[3] - joints[0]
    else:
        raise ValueError(f'mode {mode} is not one of MOVJ_XYZ (1), MOVL_XYZ (2), MOVJ_ANGLE (4)')
    check_joint_limits([arm.parameters.end_servo_limit()], [j4])


class DobotClient(SerialClient):
    """A Dobot Magician on a serial port (thread-safe: one request at a time)."""

    def __init__(self, port, baudrate=115200, timeout=0.2, retries=2, arm=None):
        """Configure; nothing is opened until connect()."""
        super().__init__(port, baudrate, timeout, retries)
        self.arm = arm or DobotArm()
        self._reader = proto.FrameReader()
        self.requests = 0
        self.mismatched_replies = 0     # frames with the right id and ctrl but the wrong size
        self.stale_replies = 0          # queued-write replies repeating an earlier index
        self._last_queue_index = 0      # highest queue index this link was given
        self._unsettled = False         # a reply to an earlier request may still arrive
        self.settles = 0                # settling reads sent (after timeouts and retries)

    # ---- link -------------------------------------------------------------------------------

    @property
    def checksum_errors(self):
        """Count the replies dropped for a bad checksum since creation."""
        return self._reader.checksum_errors

    @property
    def skipped_bytes(self):
        """Count the bytes skipped as no frame's (line noise, cut frames) since creation."""
        return self._reader.skipped_bytes

    def _on_open(self):
        self._reader.reset()
        self._last_queue_index = 0      # a device reopened may have restarted its queue
        self._unsettled = False

    # ---- requests ---------------------------------------------------------------------------

    def request(self, frame, timeout=None):
        """
        Send `frame` and return its reply Frame; retries, then DeviceTimeoutError.

        A reply must echo the request's id and ctrl and carry the parameter bytes the
        protocol defines for it (``dobot_protocol.reply_length``); a queued write's index
        must be above every index this client was given on this link (a repeated one is a
        late reply to an earlier request). Frames that fail these checks are counted and
        skipped. After a timeout, or once an attempt went unanswered, the next request first
        settles the line (``_settle``), so a late reply can never answer a later request.
        """
        timeout = self.timeout if timeout is None else timeout
        name = _command_name(frame)
        with self._lock:
            if self._serial is None:
                raise LinkError(f'{name}: port {self.port} is not open')
            data = frame.encode()
            silent_at = self.silent_at(time.monotonic())
            attempts = 0
            try:
                if self._unsettled:
                    self._settle(name, timeout, silent_at)
                for attempt in range(self.retries + 1):
                    if time.monotonic() >= silent_at:
                        break
                    if attempt:
                        self.retried += 1
                    self.requests += 1
                    attempts += 1
                    self._serial.reset_input_buffer()
                    self._reader.reset()
                    try:
                        self._serial.write(data)
                    except serial.SerialTimeoutException:
                        continue        # a slow link, not a lost one: retry
                    reply = self._await_reply(frame, min(time.monotonic() + timeout, silent_at))
                    if reply is not None:
                        # an earlier attempt may still be answered: settle before the next
                        self._unsettled = attempt > 0
                        self._accepted(frame, reply)
                        return reply
                self._unsettled = True
            except PORT_FAILURES as error:
                self._close_locked()
                raise LinkError(f'{name}: link to {self.port} lost: {error}') from error
        if time.monotonic() >= silent_at:
            raise DeviceTimeoutError(self.silence_message(name, attempts))
        raise DeviceTimeoutError(
            f'{name}: no valid reply from {self.port} within {timeout:.3f} s '
            f'after {self.retries + 1} attempts')

    def _settle(self, name, timeout, silent_at=math.inf):
        """
        Wait until the replies to every earlier request have passed (lock held).

        The device answers in order: once the reply to a read sent now arrives, any late
        reply to an earlier request came before it and was skipped. The read is one this
        client sends for nothing else (GetPTPCommonParams), so a late reply to an earlier
        settling read can only settle, never answer a request.
        """
        self.settles += 1
        for attempt in range(self.retries + 1):
            if time.monotonic() >= silent_at:
                raise DeviceTimeoutError(self.silence_message(f'{name} (settling)', attempt))
            self._serial.reset_input_buffer()
            self._reader.reset()
            self._serial.write(_SETTLE.encode())
            if self._await_reply(_SETTLE, min(time.monotonic() + timeout,
                                              silent_at)) is not None:
                self._unsettled = False
                return
        raise DeviceTimeoutError(
            f'{name}: not sent: no answer from {self.port} to a settling read within '
            f'{timeout:.3f} s after {self.retries + 1} attempts (late replies may be pending)')

    def _accepted(self, request, reply):
        if request.write and request.queued:
            self._last_queue_index = proto.decode_index(reply.params)

    def _await_reply(self, frame, deadline):
        port = self._serial
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0.0:
                return None
            port.timeout = min(remaining, 0.05)
            chunk = port.read(max(1, port.in_waiting))
            for reply in self._reader.feed(chunk):
                if not proto.is_reply_to(reply, frame):
                    continue
                if not proto.reply_matches(reply, frame):
                    self.mismatched_replies += 1        # right id and ctrl, wrong size
                elif (frame.write and frame.queued
                      and proto.decode_index(reply.params) <= self._last_queue_index):
                    self.stale_replies += 1             # an index given out before
                else:
                    return reply

    # ---- typed commands ---------------------------------------------------------------------

    def get_pose(self):
        """Return the current Pose (mm, deg); one no Dobot can report is asked for again."""
        return self.checked(lambda: proto.decode_pose(self.request(proto.get_pose_request())
                                                      .params),
                            'GET_POSE', self.possible_pose, _describe_pose)

    @staticmethod
    def possible_pose(pose):
        """
        Tell whether a Dobot can report `pose` (finite, within half a turn and a metre).

        Every joint within half a turn, and the end within a metre of the base (its reach is
        a third of that). The frame's checksum lets one random frame in 256 through. The
        Cartesian values are not checked against the arm model: they include the end
        effector's offset that the firmware is configured with (DobotStudio sets one per
        tool), unknown here.
        """
        if not all(math.isfinite(v) for v in (pose.x, pose.y, pose.z, pose.r, *pose.joints)):
            return False
        return (all(abs(j) <= 180.0 for j in pose.joints)
                and math.hypot(pose.x, pose.y, pose.z) <= POSE_RADIUS_MAX_MM)

    def get_alarms(self):
        """Return the active alarm codes."""
        return proto.decode_alarm_state(self.request(proto.get_alarms_request()).params)

    def clear_alarms(self):
        """Clear every alarm."""
        self.request(proto.clear_alarms_request())

    def set_ptp_joint_params(self, params):
        """Set PTP joint velocities [deg/s] and accelerations [deg/s^2]."""
        self.request(proto.ptp_joint_params_request(params))

    def get_ptp_joint_params(self):
        """Return the PTP joint parameters."""
        return proto.decode_ptp_joint_params(
            self.request(proto.ptp_joint_params_request()).params)

    def set_ptp_coordinate_params(self, params):
        """Set PTP Cartesian velocity/acceleration."""
        self.request(proto.ptp_coordinate_params_request(params))

    def set_ptp_common_params(self, params):
        """Set the PTP velocity and acceleration ratios [%]."""
        self.request(proto.ptp_common_params_request(params))

    def home(self):
        """Queue the homing procedure; return its queue index."""
        return proto.decode_index(self.request(proto.home_request()).params)

    def queue_left_space(self):
        """Return how many more commands the device's queue takes."""
        return proto.decode_u32(self.request(proto.queue_left_space_request()).params)

    def ptp(self, mode, values):
        """Queue a PTP move (mode, four values in mm/deg); return its queue index."""
        return proto.decode_index(
            self.request(proto.ptp_request(proto.PtpCommand(int(mode), *values))).params)

    def move(self, mode, target):
        """Check an SI target against the limits, queue it; return the queue index."""
        check_target(self.arm, mode, target)
        return self.ptp(mode, target_to_protocol(mode, target))

    def wait(self, milliseconds):
        """Queue a pause; return its queue index."""
        return proto.decode_index(self.request(proto.wait_request(milliseconds)).params)

    def queue_start(self):
        """Start executing the command queue."""
        self.request(proto.queue_start_request())

    def queue_stop(self):
        """Stop the queue after the current command."""
        self.request(proto.queue_stop_request())

    def queue_force_stop(self):
        """Stop the queue and the arm now."""
        self.request(proto.queue_force_stop_request())

    def queue_clear(self):
        """Drop the queued commands not yet executed."""
        self.request(proto.queue_clear_request())
        # Whether a firmware restarts its indices after a clear is not documented: accept
        # any index again (the drain after every timeout keeps late replies out).
        self._last_queue_index = 0

    def stop_and_clear(self):
        """Force-stop, clear the queue and restart it (ready for the next move)."""
        self.queue_force_stop()
        self.queue_clear()
        self.queue_start()

    def executed_index(self):
        """Return the index of the last queued command executed."""
        return proto.decode_index(self.request(proto.queue_current_index_request()).params)

    def wait_for_index(self, index, timeout, poll_period=0.02, stop_event=None):
        """
        Poll until the executed index reaches `index`; return True, or False if stopped.

        Raises DeviceTimeoutError when `timeout` [s] passes first.
        """
        deadline = time.monotonic() + timeout
        while True:
            if self.executed_index() >= index:
                return True
            if time.monotonic() >= deadline:
                raise DeviceTimeoutError(
                    f'queued command {index} not executed within {timeout:.1f} s')
            if stop_event is not None and stop_event.wait(poll_period):
                return False
            if stop_event is None:
                time.sleep(poll_period)


def _command_name(frame):
    return proto.command_name(frame.command_id) + (' (write)' if frame.write else '')
