"""dobot_driver in-process against the emulator on a pty: moves, limits, cancel, unplug, time."""

import contextlib
import math
import threading
import time

from helio_drivers.dobot_driver_node import DobotDriverNode
from helio_drivers.dobot_emulator import DobotEmulator
from helio_msgs.action import MoveArm
from helio_optics.arm_kinematics import DobotArm
from node_harness import driver_on, DriverGraph, SimClock, wait_for
import pytest


class Graph(DriverGraph):
    """dobot_driver on the emulator's pty with fast motion and short timeouts."""

    def __init__(self, emulator, **overrides):
        super().__init__(DobotDriverNode, MoveArm, 'move_arm', 'dobot/status', {
            'port': emulator.port_path, 'timeout_s': 0.1, 'retries': 1,
            'joint_state_rate_hz': 50.0, 'status_period_s': 0.2,
            'reconnect_initial_s': 0.05, 'reconnect_max_s': 0.2,
            'joint_velocity_dps': [60.0] * 4, 'joint_acceleration_dps2': [400.0] * 4,
            **overrides})

    def send(self, mode, target, feedback=None):
        return super().send(MoveArm.Goal(mode=mode, target=[float(v) for v in target]),
                            feedback)

    def move(self, mode, target):
        return wait_for(self.send(mode, target).get_result_async())


# j1 0 -> 85 deg at 60 deg/s and 400 deg/s^2: a trapezoid of 85/60 + 60/400 = 1.57 s.
LONG_MOVE = (math.radians(85.0), 0.2, 0.2, 0.0)
SLOW_SIM = 0.25          # the simulated clock runs at a quarter of real time


@pytest.fixture
def graph():
    with driver_on(DobotEmulator(), Graph) as emulator_and_graph:
        yield emulator_and_graph


def test_moves_succeed_with_feedback_and_joint_states(graph):
    emulator, graph = graph
    target = (0.21, 0.04, 0.06, 0.2)
    feedback = []
    handle = graph.send(MoveArm.Goal.MOVJ_XYZ, target, feedback=feedback.append)
    response = wait_for(handle.get_result_async())
    assert response.result.success, response.result.message
    assert list(response.result.achieved_cartesian) == pytest.approx(target, abs=2e-5)
    assert DobotArm().forward(emulator.joint_positions()[:3]) == pytest.approx(
        target[:3], abs=2e-5)
    assert feedback, 'no feedback during the move'
    response = graph.move(MoveArm.Goal.MOVJ_ANGLE, (0.1, 0.4, 0.3, 0.0))
    assert response.result.success
    assert list(response.result.achieved_joints) == pytest.approx((0.1, 0.4, 0.3, 0.0),
                                                                  abs=1e-6)
    assert graph.joint_states[-1].name == ['dobot_j1', 'dobot_j2', 'dobot_j3', 'dobot_j4']
    assert graph.wait_status(lambda s: s.connected and s.device == 'dobot')


def test_a_goal_beyond_a_joint_limit_is_refused_naming_the_joint(graph):
    emulator, graph = graph
    before = emulator.frames_received
    response = graph.move(MoveArm.Goal.MOVJ_ANGLE, (0.0, math.radians(100.0), 0.2, 0.0))
    assert not response.result.success
    assert 'j2' in response.result.message
    assert not emulator.is_moving() and emulator.executed_index == 0
    assert emulator.frames_received >= before
    response = graph.move(MoveArm.Goal.MOVL_XYZ, (0.6, 0.0, 0.0, 0.0))
    assert not response.result.success and 'reach' in response.result.message


def passed_j1(degrees):
    """Return a feedback callback and an event set once j1 has passed `degrees`."""
    event = threading.Event()

    def on_feedback(message):
        if message.feedback.current_joints[0] >= math.radians(degrees):
            event.set()
    return on_feedback, event


def test_cancel_mid_move_stops_the_arm_and_clears_the_queue(graph):
    emulator, graph = graph
    on_feedback, moving = passed_j1(10.0)
    handle = graph.send(MoveArm.Goal.MOVJ_ANGLE, (math.radians(85.0), 0.2, 0.2, 0.0),
                        feedback=on_feedback)
    assert moving.wait(5.0)
    wait_for(handle.cancel_goal_async())
    response = wait_for(handle.get_result_async())
    assert response.status == 5      # GoalStatus.STATUS_CANCELED
    assert 'force-stopped' in response.result.message
    stopped = emulator.joint_positions_deg()[0]
    assert 10.0 <= stopped < 85.0 and not emulator.is_moving()
    # the queue was restarted: the next move runs
    assert graph.move(MoveArm.Goal.MOVJ_ANGLE, (0.0, 0.2, 0.2, 0.0)).result.success


def test_unplug_mid_move_aborts_within_half_a_second_then_reconnects(graph):
    emulator, graph = graph
    response, seconds = graph.unplug_mid_move(
        emulator, MoveArm.Goal(mode=MoveArm.Goal.MOVJ_ANGLE, target=LONG_MOVE),
        lambda feedback: feedback.current_joints[0] >= math.radians(5.0))
    assert seconds < 0.5
    assert not response.result.success and 'link lost' in response.result.message
    assert graph.wait_status(lambda s: not s.connected)
    # goals fail fast while the port is gone
    home = MoveArm.Goal(mode=MoveArm.Goal.MOVJ_ANGLE, target=[0.0, 0.2, 0.2, 0.0])
    response, seconds = graph.timed_run(home)
    assert not response.result.success and 'not connected' in response.result.message
    assert seconds < 0.5
    assert graph.replug(emulator)
    assert graph.move(home.mode, home.target).result.success


@contextlib.contextmanager
def sim_time_graph(move_timeout_s):
    """Run dobot_driver with use_sim_time, move_timeout_s [sim s], /clock at SLOW_SIM."""
    def make_graph(emulator):
        return Graph(emulator, use_sim_time=True, move_timeout_s=move_timeout_s)
    with driver_on(DobotEmulator(), make_graph) as (emulator, graph):
        clock = SimClock(graph.node, SLOW_SIM)
        try:
            yield emulator, graph
        finally:
            clock.stop()


def test_under_a_slow_sim_clock_a_move_longer_in_wall_time_than_its_timeout_succeeds():
    with sim_time_graph(move_timeout_s=1.0) as (emulator, graph):
        started = time.monotonic()
        response = graph.move(MoveArm.Goal.MOVJ_ANGLE, LONG_MOVE)
        wall = time.monotonic() - started
        assert response.result.success, response.result.message
        assert wall > 1.0      # longer in wall time than the timeout; 0.4 s of sim time
        assert emulator.joint_positions_deg()[0] == pytest.approx(85.0, abs=1e-3)


def test_under_a_slow_sim_clock_a_move_past_its_timeout_in_sim_seconds_aborts():
    with sim_time_graph(move_timeout_s=0.2) as (emulator, graph):
        started = time.monotonic()
        response = graph.move(MoveArm.Goal.MOVJ_ANGLE, LONG_MOVE)
        wall = time.monotonic() - started
        assert not response.result.success
        assert 'within 0.20 s on the node clock' in response.result.message
        assert 'arm force-stopped' in response.result.message
        # 0.2 s of sim time is 0.2 / SLOW_SIM = 0.8 s of wall time, not a wall-clock 0.2 s
        assert wall > 0.9 * 0.2 / SLOW_SIM
        stopped = emulator.joint_positions_deg()[0]
        assert 5.0 < stopped < 85.0 and not emulator.is_moving()
        achieved = math.degrees(response.result.achieved_joints[0])
        assert achieved == pytest.approx(stopped, abs=0.5)
