"""
The Dobot driver's services, called on the installed node in its own process.

A service callback of the drivers awaits the device thread's answer. In the node's default
(mutually exclusive) callback group that await held the group, and the executor left every
other entity of it (the timers, /clock, the guard condition that brings the answer) out of
its wait set: ``dobot/clear_alarms`` and ``dobot/home`` never answered, and the driver took
no goal after them (issue 35). The node's own in-process test did not show it: other nodes
in that process kept waking the executor.

Last, a driver signalled (Ctrl-C or SIGTERM, as ``ros2 launch`` signals every node at once)
goes on serving goals until none has come for ``shutdown_grace``, then stops (issue 30).
"""

import math
import signal
import time

from conftest import graph_of_processes
from helio_control.bringup import wait_for_devices
from helio_drivers import dobot_protocol as proto
from helio_drivers.dobot_emulator import DobotEmulator
from helio_msgs.action import MoveArm
import pytest
from std_srvs.srv import Trigger

# wall seconds for an answer (the hang never answers): generous for a loaded 2-core machine
ANSWER_TIMEOUT = 30.0


def test_clear_alarms_answers_every_call_and_the_arm_still_moves_after(tmp_path):
    with graph_of_processes(tmp_path, ('sim_world', 'dobot_driver'),
                            {'sim_world': {'real_time_factor': 0.0, 'flux_rays': 2000}}) \
            as (_, graph):
        wait_for_devices(graph, 60.0, ('dobot',))
        clear = graph.helper.create_client(Trigger, 'dobot/clear_alarms')
        for _ in range(3):
            response = graph.call(clear, Trigger.Request(), ANSWER_TIMEOUT)
            assert response.success, response.message
            assert response.message == 'no alarm was active'
        arm = graph.action_client(MoveArm, 'move_arm', ANSWER_TIMEOUT)
        target = [0.1, 0.6, 0.6, 0.0]
        reply = graph.run_goal(arm, MoveArm.Goal(mode=MoveArm.Goal.MOVJ_ANGLE, target=target),
                               timeout=120.0)
        assert reply.result.success, reply.result.message
        assert list(reply.result.achieved_joints) == pytest.approx(target, abs=1e-3)
        # and the service still answers after the move
        assert graph.call(clear, Trigger.Request(), ANSWER_TIMEOUT).success


def test_after_a_joint_limit_alarm_goals_are_refused_until_clear_alarms_answers_in_a_second(
        tmp_path):
    # issue 35's first "done when": the installed driver as its own process, on an emulated
    # Dobot in this process that raises the alarm as the firmware does (the driver refuses
    # targets beyond the limits itself, so no goal can provoke one)
    with DobotEmulator() as emulator, graph_of_processes(
            tmp_path, ('dobot_driver',), {'dobot_driver': {'port': emulator.port_path}}) \
            as (_, graph):
        wait_for_devices(graph, 60.0, ('dobot',))
        clear = graph.helper.create_client(Trigger, 'dobot/clear_alarms')
        arm = graph.action_client(MoveArm, 'move_arm', ANSWER_TIMEOUT)
        emulator.raise_alarm(proto.Alarm.LIMIT_AXIS2_POS)
        refused = graph.run_goal(arm, MoveArm.Goal(mode=MoveArm.Goal.MOVJ_ANGLE,
                                                   target=[0.1, 0.5, 0.5, 0.0]), timeout=60.0)
        assert not refused.result.success
        assert 'joint limit: j2 beyond its upper limit' in refused.result.message
        assert 'dobot/clear_alarms' in refused.result.message          # says what to do
        asked = time.monotonic()
        response = graph.call(clear, Trigger.Request(), ANSWER_TIMEOUT)
        took = time.monotonic() - asked
        print(f'\nclear_alarms answered in {took:.3f} s: {response.message}')
        assert response.success and 'j2 beyond its upper limit' in response.message
        assert took <= 1.0
        assert emulator.alarms == []
        target = [0.1, 0.5, 0.5, 0.0]
        moved = graph.run_goal(arm, MoveArm.Goal(mode=MoveArm.Goal.MOVJ_ANGLE, target=target),
                               timeout=60.0)
        assert moved.result.success, moved.result.message
        assert list(moved.result.achieved_joints) == pytest.approx(target, abs=1e-3)


def test_a_signalled_driver_serves_the_goals_that_follow_then_stops(tmp_path):
    # issue 30: ros2 launch signals every node at once, and the lens planner's retreat comes
    # after its own signal: the driver must still move the arm, then stop on its own
    with DobotEmulator() as emulator, graph_of_processes(
            tmp_path, ('dobot_driver',), {'dobot_driver': {'port': emulator.port_path}},
            may_die=('dobot_driver',)) as (group, graph):
        wait_for_devices(graph, 60.0, ('dobot',))
        arm = graph.action_client(MoveArm, 'move_arm', ANSWER_TIMEOUT)
        driver = next(p for p in group.processes if p.label == 'dobot_driver')
        driver.signal(signal.SIGINT)
        signalled = time.monotonic()
        target = [0.2, 0.5, 0.5, 0.0]
        moved = graph.run_goal(arm, MoveArm.Goal(mode=MoveArm.Goal.MOVJ_ANGLE, target=target),
                               timeout=60.0)
        ended = time.monotonic()
        assert moved.result.success, moved.result.message
        assert emulator.joint_positions_deg()[0] == pytest.approx(math.degrees(0.2), abs=0.1)
        # then it stops by itself, a grace (0.5 s) after the last goal
        status = driver.process.wait(30.0)
        gone = time.monotonic()
        print(f'\ngoal served {ended - signalled:.2f} s after SIGINT; the driver exited '
              f'{gone - ended:.2f} s after it, status {status}')
        assert gone - ended >= 0.5
        assert status == 0, driver.tail()
