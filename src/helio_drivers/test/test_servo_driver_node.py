"""servo_driver in-process against the Maestro emulator on a pty."""

import math
import threading
import time

from helio_drivers import maestro_protocol as proto
from helio_drivers.maestro_emulator import MaestroEmulator
from helio_drivers.servo_driver_node import ServoDriverNode
from helio_msgs.action import MoveWrist
from node_harness import driver_on, DriverGraph, SimClock, wait_for
import pytest

# yaw reversed and offset, as a mounted servo may be; pitch on channel 3
YAW = proto.ServoCalibration('lens_yaw', 0, min_pulse_us=700.0, max_pulse_us=2300.0,
                             direction=-1, zero_offset_rad=0.1)
PITCH = proto.ServoCalibration('lens_pitch', 3)


class FreezableClock:
    """Monotonic seconds that stand still between freeze() and thaw() (the emulator's clock)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._offset = 0.0
        self._frozen_at = None

    def __call__(self):
        with self._lock:
            if self._frozen_at is not None:
                return self._frozen_at
            return time.monotonic() - self._offset

    def freeze(self):
        with self._lock:
            if self._frozen_at is None:
                self._frozen_at = time.monotonic() - self._offset

    def thaw(self):
        with self._lock:
            if self._frozen_at is not None:
                self._offset = time.monotonic() - self._frozen_at
                self._frozen_at = None


@pytest.fixture
def clock():
    return FreezableClock()


def wrist_parameters(emulator):
    """Return the driver parameters for the emulated wrist (fast, short timeouts)."""
    return {'port': emulator.port_path, 'timeout_s': 0.1, 'retries': 1,
            'joint_state_rate_hz': 50.0, 'status_period_s': 0.2,
            'reconnect_initial_s': 0.05, 'reconnect_max_s': 0.2,
            'position_tolerance_us': 0.25,
            'yaw.channel': 0, 'yaw.min_pulse_us': 700.0, 'yaw.max_pulse_us': 2300.0,
            'yaw.direction': -1, 'yaw.zero_offset_rad': 0.1,
            'yaw.speed_us_per_s': 4000.0, 'yaw.acceleration_us_per_s2': 40000.0,
            'pitch.channel': 3, 'pitch.speed_us_per_s': 1000.0,
            'pitch.acceleration_us_per_s2': 40000.0}


def wrist_graph(**overrides):
    """Return a function starting servo_driver on an emulator, with parameter overrides."""
    def make_graph(emulator):
        return DriverGraph(ServoDriverNode, MoveWrist, 'move_wrist', 'servo/status',
                           {**wrist_parameters(emulator), **overrides})
    return make_graph


@pytest.fixture
def wrist(clock):
    emulator = MaestroEmulator(calibrations=[YAW, PITCH], clock=clock)
    with driver_on(emulator, wrist_graph()) as emulator_and_graph:
        yield emulator_and_graph


def test_wrist_moves_to_calibrated_angles(wrist):
    emulator, graph = wrist
    feedback = []
    response = graph.run(MoveWrist.Goal(yaw=0.4, pitch=-0.3), feedback=feedback.append)
    assert response.result.success, response.result.message
    # quarter-microsecond resolution: 0.25 us / 636.6 us/rad ~ 0.0004 rad
    assert response.result.achieved_yaw == pytest.approx(0.4, abs=1e-3)
    assert response.result.achieved_pitch == pytest.approx(-0.3, abs=1e-3)
    # independent: the pulse the emulator outputs follows the calibration formula
    pulses = emulator.pulse_widths_us()
    assert pulses[0] == pytest.approx(1500.0 - 0.3 * 2000.0 / math.pi, abs=0.25)
    assert pulses[3] == pytest.approx(1500.0 - 0.3 * 2000.0 / math.pi, abs=0.25)
    assert feedback, 'no feedback during the move'
    assert graph.joint_states and graph.joint_states[-1].name == ['lens_yaw', 'lens_pitch']
    assert graph.wait_status(lambda s: s.connected and s.device == 'servo')


def test_out_of_range_angle_is_refused_naming_the_joint(wrist):
    emulator, graph = wrist
    response = graph.run(MoveWrist.Goal(yaw=2.0, pitch=0.0))
    assert not response.result.success and 'lens_yaw' in response.result.message
    assert emulator.pulse_widths_us()[0] == pytest.approx(1500.0)


def test_cancel_holds_the_servos_mid_move(wrist, clock):
    emulator, graph = wrist
    started = threading.Event()

    def on_feedback(message):
        if message.feedback.current_pitch > 0.1:
            # Stop the emulator's time mid-move, so however late the cancel arrives on a
            # loaded machine, the servo is still on its way to 1.5 rad when it does.
            clock.freeze()
            started.set()
    handle = graph.send(MoveWrist.Goal(yaw=0.1, pitch=1.5), feedback=on_feedback)
    assert started.wait(5.0)
    frozen_pitch = PITCH.angle(emulator.pulse_widths_us()[3])
    assert 0.1 < frozen_pitch < 1.4
    wait_for(handle.cancel_goal_async())
    response = wait_for(handle.get_result_async())
    clock.thaw()
    assert response.status == 5      # GoalStatus.STATUS_CANCELED
    # the new target is where the servo was when cancelled: it stops there, not at 1.5 rad
    held = PITCH.angle(emulator.target_pulse_widths_us()[3])
    assert held == pytest.approx(frozen_pitch, abs=1e-3)
    assert response.result.achieved_pitch == pytest.approx(held, abs=0.05)


def test_unplug_aborts_and_reconnects(wrist):
    emulator, graph = wrist
    response, seconds = graph.unplug_mid_move(
        emulator, MoveWrist.Goal(yaw=0.1, pitch=1.5),
        lambda feedback: feedback.current_pitch > 0.1)
    assert seconds < 0.5
    assert not response.result.success and 'link lost' in response.result.message
    assert graph.wait_status(lambda s: not s.connected)
    # goals fail fast while the port is gone
    response, seconds = graph.timed_run(MoveWrist.Goal(yaw=0.0, pitch=0.0))
    assert not response.result.success and 'not connected' in response.result.message
    assert seconds < 0.5
    assert graph.replug(emulator)
    assert graph.run(MoveWrist.Goal(yaw=0.0, pitch=0.0)).result.success


def test_a_stopped_sim_clock_cannot_hold_a_move_past_its_wall_clock_guard():
    make_graph = wrist_graph(use_sim_time=True, move_timeout_s=1.0, move_wall_timeout_s=0.4)
    with driver_on(MaestroEmulator(calibrations=[YAW, PITCH]), make_graph) as (emulator, graph):
        clock = SimClock(graph.node, rate=0.0)        # /clock published, never advancing
        try:
            started = time.monotonic()
            # pitch to 1.5 rad at 1000 us/s: 0.95 s of motion, longer than the 0.4 s guard
            response = graph.run(MoveWrist.Goal(yaw=0.1, pitch=1.5))
            wall = time.monotonic() - started
            assert not response.result.success
            assert 'within 0.40 s of wall time' in response.result.message
            assert '/clock' in response.result.message
            assert 0.4 < wall < 5.0
            # held short of the target, where it was
            held = PITCH.angle(emulator.target_pulse_widths_us()[3])
            assert held < 1.4
            assert response.result.achieved_pitch == pytest.approx(held, abs=0.05)
        finally:
            clock.stop()


def test_an_unexpected_error_aborts_the_goal_holds_the_servos_and_the_driver_goes_on(wrist):
    emulator, graph = wrist
    poll_move = graph.driver.poll_move
    calls = []

    def failing_once(move):
        calls.append(move)
        if len(calls) == 3:
            raise RuntimeError('injected bug')
        return poll_move(move)
    graph.driver.poll_move = failing_once
    response = graph.run(MoveWrist.Goal(yaw=0.1, pitch=1.5))
    assert not response.result.success
    assert response.result.message == 'driver error, move aborted: injected bug'
    held = PITCH.angle(emulator.target_pulse_widths_us()[3])
    assert held < 1.4                       # held where it was, not left moving to 1.5
    response = graph.run(MoveWrist.Goal(yaw=0.0, pitch=0.2))
    assert response.result.success, response.result.message
