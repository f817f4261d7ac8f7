"""Dobot emulator over a real pty: motion on an injected clock, queue, limits, faults."""

import math
import time

from conftest import open_port
from helio_drivers import dobot_protocol as proto
from helio_drivers.dobot_emulator import DobotEmulator
from helio_optics.arm_kinematics import DobotArm
import numpy as np
import pytest


def exchange(port, frame, timeout=1.0):
    """Send a frame and return the first reply frame (None on timeout)."""
    reader = proto.FrameReader()
    port.reset_input_buffer()
    port.write(frame.encode())
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        frames = reader.feed(port.read(max(1, port.in_waiting)))
        if frames:
            return frames[0]
    return None


@pytest.fixture
def arm(manual_clock):
    emulator = DobotEmulator(clock=manual_clock)
    port = open_port(emulator.port_path, timeout=0.05)
    try:
        yield emulator, port, manual_clock
    finally:
        port.close()
        emulator.close()


def queue(port, command):
    reply = exchange(port, proto.ptp_request(command))
    assert reply is not None and reply.command_id == proto.CommandId.PTP
    return proto.decode_index(reply.params)


def executed(port):
    return proto.decode_index(exchange(port, proto.queue_current_index_request()).params)


def test_get_pose_reports_forward_kinematics_of_the_joints(arm):
    emulator, port, _ = arm
    pose = proto.decode_pose(exchange(port, proto.get_pose_request()).params)
    joints = np.radians(emulator.home_joints_deg[:3])
    # independent evaluation of the Magician's linkage (rear arm from vertical, forearm from
    # horizontal, 59.7 mm flange offset)
    reach = 135.0 * math.sin(joints[1]) + 147.0 * math.cos(joints[2]) + 59.7
    height = 135.0 * math.cos(joints[1]) - 147.0 * math.sin(joints[2])
    assert pose.x == pytest.approx(reach, abs=1e-3)
    assert pose.z == pytest.approx(height, abs=1e-3)
    assert pose.joints == pytest.approx(tuple(emulator.home_joints_deg), abs=1e-5)


def test_joint_move_follows_the_clock_on_a_trapezoid(arm):
    emulator, port, clock = arm
    start = emulator.joint_positions_deg()
    # 30 deg on j2 at 100 deg/s and 100 deg/s^2: triangular, T = 2 sqrt(30 / 100) s
    index = queue(port, proto.PtpCommand(proto.PtpMode.MOVJ_ANGLE, 0.0, 40.0, 10.0, 0.0))
    duration = 2.0 * math.sqrt(30.0 / 100.0)
    assert executed(port) == index - 1
    clock.advance(duration / 2.0)
    assert emulator.joint_positions_deg()[1] == pytest.approx(start[1] + 15.0, abs=1e-6)
    assert emulator.is_moving()
    clock.advance(duration / 4.0)       # 0.5 a t^2 from the far end: 30 - 50 * (T/4)^2
    assert emulator.joint_positions_deg()[1] == pytest.approx(
        start[1] + 30.0 - 50.0 * (duration / 4.0) ** 2, abs=1e-6)
    assert executed(port) == index - 1
    clock.advance(duration / 4.0 + 1e-6)
    assert executed(port) == index
    pose = proto.decode_pose(exchange(port, proto.get_pose_request()).params)
    assert pose.joints == pytest.approx((0.0, 40.0, 10.0, 0.0), abs=1e-5)


def test_velocity_and_acceleration_limits_hold_along_a_move(arm):
    emulator, port, clock = arm
    exchange(port, proto.ptp_joint_params_request(
        proto.PtpJointParams((50.0, 20.0, 80.0, 100.0), (200.0, 40.0, 100.0, 100.0))))
    queue(port, proto.PtpCommand(proto.PtpMode.MOVJ_ANGLE, 60.0, 50.0, 70.0, 0.0))
    dt = 0.01
    samples = []
    for _ in range(1000):
        samples.append(emulator.joint_positions_deg())
        clock.advance(dt)
    samples = np.array(samples)
    velocity = np.diff(samples, axis=0) / dt
    acceleration = np.diff(velocity, axis=0) / dt
    assert np.all(np.abs(velocity[:, :3]) <= np.array([50.0, 20.0, 80.0]) + 1e-6)
    assert np.all(np.abs(acceleration[:, :3]) <= np.array([200.0, 40.0, 100.0]) + 1.0)
    assert samples[-1] == pytest.approx([60.0, 50.0, 70.0, 0.0], abs=1e-6)
    # joint-interpolated: every joint is the same fraction of the way at every instant
    progress = (samples[:, :3] - samples[0, :3]) / (samples[-1, :3] - samples[0, :3])
    assert np.allclose(progress, progress[:, :1], atol=1e-9)


def test_queued_moves_execute_in_order_and_the_index_advances(arm):
    emulator, port, clock = arm
    targets = [(10.0, 20.0, 20.0, 0.0), (-10.0, 30.0, 5.0, 0.0), (0.0, 15.0, 25.0, 10.0)]
    indices = [queue(port, proto.PtpCommand(4, *t)) for t in targets]
    wait_reply = exchange(port, proto.wait_request(500))
    indices.append(proto.decode_index(wait_reply.params))
    assert indices == sorted(indices) and len(set(indices)) == 4
    seen = []
    for _ in range(2000):
        clock.advance(0.005)
        index = emulator.executed_index
        if not seen or index != seen[-1]:
            seen.append(index)
            if index in indices[:3]:
                # the next move may have run for at most one step (5 ms at <= 100 deg/s)
                target = targets[indices.index(index)]
                assert emulator.joint_positions_deg() == pytest.approx(target, abs=0.5)
    assert [i for i in seen if i in indices] == indices


def test_cartesian_targets_land_where_asked(arm):
    emulator, port, clock = arm
    target = (220.0, 40.0, 30.0, 15.0)
    queue(port, proto.PtpCommand(proto.PtpMode.MOVJ_XYZ, *target))
    clock.advance(10.0)
    pose = proto.decode_pose(exchange(port, proto.get_pose_request()).params)
    assert pose.cartesian == pytest.approx(target, abs=1e-3)
    # MOVL: the flange stays on the straight line between the two points
    line_end = np.array([180.0, -60.0, 60.0])
    queue(port, proto.PtpCommand(proto.PtpMode.MOVL_XYZ, *line_end, 0.0))
    origin = np.array(target[:3])
    direction = (line_end - origin) / np.linalg.norm(line_end - origin)
    kinematics = DobotArm()
    for _ in range(20):
        clock.advance(0.05)
        flange = kinematics.forward(emulator.joint_positions()[:3]) * 1000.0
        offset = flange - origin
        assert np.linalg.norm(offset - direction * (offset @ direction)) < 1e-6
    clock.advance(10.0)
    assert emulator.pose().cartesian[:3] == pytest.approx(tuple(line_end), abs=1e-3)


def test_joint_limit_raises_an_alarm_naming_the_joint_and_does_not_move(arm):
    emulator, port, clock = arm
    before = emulator.joint_positions_deg()
    index = queue(port, proto.PtpCommand(proto.PtpMode.MOVJ_ANGLE, 0.0, 100.0, 10.0, 0.0))
    clock.advance(0.001)
    assert executed(port) == index          # skipped, as the firmware does
    state = proto.decode_alarm_state(exchange(port, proto.get_alarms_request()).params)
    assert proto.Alarm.LIMIT_AXIS2_POS in state
    assert 'j2' in emulator.last_refusal
    assert emulator.joint_positions_deg() == pytest.approx(before)
    exchange(port, proto.clear_alarms_request())
    assert proto.decode_alarm_state(exchange(port, proto.get_alarms_request()).params) == []
    queue(port, proto.PtpCommand(proto.PtpMode.MOVJ_XYZ, 600.0, 0.0, 0.0, 0.0))
    clock.advance(0.001)
    assert proto.Alarm.PLAN_INV_CALC in emulator.alarms


@pytest.mark.parametrize('velocity, acceleration', [(0.0, 100.0), (-50.0, 100.0),
                                                    (100.0, 0.0), (math.nan, 100.0)])
def test_unusable_ptp_limits_refuse_the_move_and_the_device_keeps_answering(
        arm, velocity, acceleration):
    # issue 35: a zero velocity used to kill the emulated arm's thread (the arm went silent)
    emulator, port, clock = arm
    before = emulator.joint_positions_deg()
    exchange(port, proto.ptp_joint_params_request(
        proto.PtpJointParams((velocity,) * 4, (acceleration,) * 4)))
    index = queue(port, proto.PtpCommand(proto.PtpMode.MOVJ_ANGLE, 20.0, 10.0, 10.0, 0.0))
    clock.advance(0.001)
    assert executed(port) == index                  # skipped, as a target it cannot plan
    assert proto.Alarm.PLAN_INV_CALC in emulator.alarms
    assert 'must be positive' in emulator.last_refusal
    assert emulator.joint_positions_deg() == pytest.approx(before)
    assert exchange(port, proto.get_pose_request()) is not None
    # set right, the same move runs
    exchange(port, proto.clear_alarms_request())
    exchange(port, proto.ptp_joint_params_request(proto.PtpJointParams((100.0,) * 4,
                                                                       (100.0,) * 4)))
    index = queue(port, proto.PtpCommand(proto.PtpMode.MOVJ_ANGLE, 20.0, 10.0, 10.0, 0.0))
    clock.advance(10.0)
    assert executed(port) == index
    assert emulator.joint_positions_deg()[0] == pytest.approx(20.0, abs=1e-3)


def test_force_stop_halts_mid_move_and_clear_drops_the_rest(arm):
    emulator, port, clock = arm
    first = queue(port, proto.PtpCommand(4, 60.0, 10.0, 10.0, 0.0))
    queue(port, proto.PtpCommand(4, -60.0, 10.0, 10.0, 0.0))
    clock.advance(0.3)
    exchange(port, proto.queue_force_stop_request())
    exchange(port, proto.queue_clear_request())
    halted = emulator.joint_positions_deg()
    assert 0.0 < halted[0] < 60.0
    clock.advance(5.0)
    assert emulator.joint_positions_deg() == pytest.approx(halted)
    assert executed(port) < first
    exchange(port, proto.queue_start_request())
    index = queue(port, proto.PtpCommand(4, 0.0, 10.0, 10.0, 0.0))
    clock.advance(5.0)
    assert executed(port) == index


def test_faults_corrupt_truncate_drop_and_unplug(arm):
    emulator, port, _ = arm
    reader = proto.FrameReader()
    emulator.inject(corrupt_replies=1)
    port.write(proto.get_pose_request().encode())
    time.sleep(0)  # yield; the read below waits on the port's own timeout
    data = b''
    deadline = time.monotonic() + 1.0
    while len(data) < 38 and time.monotonic() < deadline:
        data += port.read(38 - len(data))
    assert len(data) == 38 and reader.feed(data) == [] and reader.checksum_errors == 1
    emulator.inject(drop_replies=1)
    assert exchange(port, proto.get_pose_request(), timeout=0.3) is None
    emulator.inject(truncate_replies=1)
    assert exchange(port, proto.get_pose_request(), timeout=0.3) is None
    assert exchange(port, proto.get_pose_request()) is not None      # faults used up
    path = emulator.port_path
    emulator.disconnect()
    with pytest.raises(Exception):
        port.read(1)
    port.close()
    emulator.reconnect()
    assert emulator.port_path == path
    port.port = path
    port.open()
    assert exchange(port, proto.get_pose_request()) is not None
