"""MoveDeadline: move limits on the node clock (sim time) with a wall-clock guard."""

from helio_drivers.device_support import MoveDeadline, TwoClockSchedule
import pytest


def test_a_slow_sim_clock_lets_a_move_run_longer_in_wall_time_than_its_limit():
    deadline = MoveDeadline(1.0, 10.0, node_now_s=100.0, wall_now_s=5000.0)
    # 3 s of wall time, but only 0.75 s of a quarter-speed simulated clock
    assert deadline.exceeded(100.75, 5003.0) is None
    why = deadline.exceeded(101.01, 5004.04)
    assert why == 'move not finished within 1.00 s on the node clock'


def test_a_fast_sim_clock_ends_a_move_early_in_wall_time():
    deadline = MoveDeadline(60.0, 600.0, node_now_s=10.0, wall_now_s=0.0)
    assert deadline.exceeded(70.5, 6.05) is not None      # 10x real time: 60 s after 6 s


def test_a_stopped_clock_is_caught_by_the_wall_guard():
    deadline = MoveDeadline(1.0, 2.0, node_now_s=100.0, wall_now_s=0.0)
    assert deadline.exceeded(100.0, 1.9) is None
    why = deadline.exceeded(100.0, 2.1)
    assert 'within 2.00 s of wall time' in why and 'advanced only 0.00 s' in why
    assert '/clock' in why


def test_no_sim_time_yet_and_a_clock_going_back_re_anchor_instead_of_counting():
    deadline = MoveDeadline(1.0, 100.0, node_now_s=0.0, wall_now_s=0.0)   # no /clock yet
    assert deadline.exceeded(500.0, 0.1) is None       # the first /clock is not 500 s elapsed
    assert deadline.exceeded(500.9, 0.2) is None
    assert deadline.exceeded(3.0, 0.3) is None         # simulation restarted: re-anchored
    assert deadline.exceeded(3.9, 0.4) is None
    assert deadline.exceeded(4.1, 0.5) is not None


@pytest.mark.parametrize('limits', [(0.0, 1.0), (1.0, 0.0), (-1.0, 1.0)])
def test_limits_must_be_positive(limits):
    with pytest.raises(ValueError, match='must be positive'):
        MoveDeadline(*limits, node_now_s=0.0, wall_now_s=0.0)


def test_joint_states_follow_a_fast_sim_clock_and_a_paused_one_alike():
    """TwoClockSchedule: due every period of simulated time, and of wall time while paused."""
    schedule = TwoClockSchedule(0.05)
    assert schedule.due(0.0, 0.0)                      # at once, before any /clock
    # a world at 50x real time: 0.1 s simulated steps 2 ms of wall time apart
    ticks = [schedule.due(1000.0 + 0.1 * i, 0.002 * (i + 1)) for i in range(50)]
    assert all(ticks)                                  # every step: 10 per simulated second
    assert not schedule.due(1004.9, 0.101)             # the same instant again: not due
    # the world paused (holding for a slow consumer): due every 0.05 s of wall time
    paused = [schedule.due(1004.9, 0.101 + 0.01 * i) for i in range(1, 11)]
    assert paused == [False, False, False, False, True] * 2
    # a world slower than real time: every 0.05 s of either clock, whichever is first
    schedule = TwoClockSchedule(0.05)
    assert schedule.due(10.0, 0.0)
    assert not schedule.due(10.02, 0.04) and schedule.due(10.025, 0.05)


def test_a_period_of_one_world_step_is_due_at_every_step_of_an_epoch_clock():
    # the node clock in epoch seconds (ns * 1e-9, as the driver reads it): ticks one 0.1 s
    # world step apart come out up to ~0.5 us short of 0.1 s
    schedule = TwoClockSchedule(0.1)
    start_ns = 1_782_028_800 * 10**9                   # 2026-06-21, the world's default day
    ticks = [schedule.due((start_ns + i * 10**8) * 1e-9, 0.002 * (i + 1)) for i in range(100)]
    assert sum(ticks) == 100
    assert not schedule.due((start_ns + 99 * 10**8 + 5 * 10**7) * 1e-9, 0.201)   # half a step


def test_a_restarted_sim_clock_re_anchors_the_schedule():
    schedule = TwoClockSchedule(0.05)
    assert schedule.due(500.0, 0.0)
    assert schedule.due(0.1, 0.001)                    # a new simulation: due at once
    assert schedule.due(0.15, 0.002) and not schedule.due(0.16, 0.003)
    with pytest.raises(ValueError):
        TwoClockSchedule(0.0)
