"""Algorithm 1 for one dot (paper Sec. IV-B) and the loss-of-sun rule, on reading sequences."""

from helio_control.dot_cycle import CycleSettings, Decision, DotCycle, Phase
import pytest

CAP = 180.9


def run(cycle, readings, start=0.0, period=0.115):
    """Feed (n_p, t_max) readings every `period` s; return the decisions."""
    decisions = []
    for k, (n_p, t_max) in enumerate(readings):
        decisions.append(cycle.update(start + (k + 1) * period, n_p, t_max, CAP))
    return decisions


def test_the_papers_rule_heats_to_the_target_then_waits_for_zero():
    cycle = DotCycle(CycleSettings(n_p_target=30))
    cycle.start_heating(10.0)
    heating = [(0, 60.0), (0, 120.0), (5, CAP), (18, CAP), (29, CAP), (31, CAP)]
    cooling = [(31, CAP), (12, CAP), (3, CAP), (0, 170.0)]
    decisions = run(cycle, heating + cooling, start=10.0)
    assert decisions[:5] == [Decision.HEAT] * 5
    assert decisions[5] is Decision.RETREAT                 # N_p 31 >= 30, Alg. 1 line 6
    assert decisions[6:9] == [Decision.WAIT] * 3             # lines 10-13: N_p still > 0
    assert decisions[9] is Decision.NEXT and cycle.phase is Phase.DONE
    assert cycle.outcome == 'charred' and cycle.peak_n_p == 31
    assert cycle.heating_time == pytest.approx(6 * 0.115)
    assert cycle.cooling_time == pytest.approx(4 * 0.115)


def test_without_the_cooling_wait_the_next_dot_follows_the_retreat():
    cycle = DotCycle(CycleSettings(n_p_target=2, wait_for_zero=False))
    cycle.start_heating(0.0)
    decisions = run(cycle, [(1, CAP), (2, CAP), (40, CAP)])
    assert decisions == [Decision.HEAT, Decision.RETREAT, Decision.NEXT]


def test_a_dot_held_past_its_longest_heating_is_given_up():
    cycle = DotCycle(CycleSettings(n_p_target=30, max_heating=1.0))
    cycle.start_heating(0.0)
    decisions = run(cycle, [(5, CAP)] * 12, period=0.1)
    assert decisions[:10] == [Decision.HEAT] * 10
    assert decisions[10] is Decision.RETREAT and cycle.outcome == 'max_heating'


def test_frames_without_a_reading_keep_the_time_limit_and_nothing_else():
    # the window rule's frames whose camera pose is unknown: they neither end the heating
    # nor look like a cloud (no falling N_p), but the dot is still given up in time
    cycle = DotCycle(CycleSettings(n_p_target=30, max_heating=1.0))
    cycle.start_heating(0.0)
    assert cycle.update(0.1, 20, 150.0) is Decision.HEAT
    assert [cycle.update_unread(0.1 * i) for i in range(2, 10)] == [Decision.HEAT] * 8
    assert cycle.peak_n_p == 20 and cycle.clouds == 0
    assert cycle.update(0.95, 22, 151.0) is Decision.HEAT
    assert cycle.update_unread(1.1) is Decision.RETREAT and cycle.outcome == 'max_heating'
    with pytest.raises(RuntimeError):
        cycle.update_unread(1.2)                      # not heating any more


@pytest.mark.parametrize('readings, words', [
    ([(0, 90.0), (0, 130.0), (0, 150.0), (0, 144.0)], 'T_max fell from 150.0 to 144.0'),
    ([(0, CAP), (8, CAP), (14, CAP), (10, CAP)], 'N_p fell from 14 to 10'),
])
def test_a_cloud_is_told_by_the_thermal_image_and_the_dot_is_heated_again(readings, words):
    cycle = DotCycle(CycleSettings(n_p_target=30))
    cycle.start_heating(0.0)
    decisions = run(cycle, readings)
    assert decisions[:-1] == [Decision.HEAT] * (len(readings) - 1)
    assert decisions[-1] is Decision.CLOUD and words in cycle.cloud_reason
    cycle.restart()                         # same dot, from the start, full target
    assert cycle.phase is Phase.APPROACH and cycle.peak_n_p == 0 and cycle.clouds == 1
    cycle.start_heating(20.0)
    assert run(cycle, [(29, CAP), (30, CAP)], start=20.0) == [Decision.HEAT, Decision.RETREAT]


def test_saturated_readings_falling_noise_is_not_a_cloud():
    # at the cap T_max cannot fall as the wood heats; a 0.05 K read-out wobble is no cloud
    cycle = DotCycle()
    cycle.start_heating(0.0)
    assert run(cycle, [(3, CAP), (4, CAP - 0.04), (5, CAP), (6, CAP)]) == [Decision.HEAT] * 4


def test_no_spot_seen_long_enough_is_a_cloud():
    cycle = DotCycle(CycleSettings(cloud_dark_time=0.5))
    cycle.start_heating(0.0)
    assert cycle.update(0.2, 0, 100.0, CAP, sun_seen=False) is Decision.HEAT
    assert cycle.update(0.4, 0, 101.0, CAP, sun_seen=True) is Decision.HEAT   # seen: reset
    assert cycle.update(0.6, 0, 102.0, CAP, sun_seen=False) is Decision.HEAT
    assert cycle.update(1.2, 0, 102.5, CAP, sun_seen=False) is Decision.CLOUD
    assert 'no light spot seen for 0.6 s' in cycle.cloud_reason


def test_misuse_and_bad_settings_are_refused():
    with pytest.raises(RuntimeError, match='before start_heating'):
        DotCycle().update(0.0, 0)
    with pytest.raises(ValueError, match='n_p_target'):
        CycleSettings(n_p_target=0)
    with pytest.raises(ValueError, match='cloud_n_p_drop'):
        CycleSettings(cloud_n_p_drop=0)


def test_a_held_dot_counts_only_the_time_at_its_target():
    # readings every 0.5 s: the target is reached at 1.0 s, then the hold of 2 s counts the
    # intervals between readings both at or above it; the dip at 2.5 s stops the count
    cycle = DotCycle(CycleSettings(n_p_target=30, hold=2.0))
    cycle.start_heating(0.0)
    n_ps = [20, 30, 31, 31, 29, 31, 33, 34, 35, 35]     # 29: 2 under the peak, no cloud
    decisions = [cycle.update(0.5 * (k + 1), n_p, CAP, CAP) for k, n_p in enumerate(n_ps)]
    # held: 1.0-1.5, 1.5-2.0 (1.0 s); 2.5 below; 3.0-3.5, 3.5-4.0 (2.0 s) -> retreat at 4.0
    assert decisions[:7] == [Decision.HEAT] * 7
    assert decisions[7] is Decision.RETREAT and cycle.outcome == 'charred'
    assert cycle.reached == pytest.approx(1.0) and cycle.held == pytest.approx(2.0)
    assert cycle.heating_time == pytest.approx(4.0)


def test_a_hold_does_not_go_on_through_frozen_frames_and_extends_the_time_limit():
    cycle = DotCycle(CycleSettings(n_p_target=10, max_heating=1.0, hold=3.0))
    cycle.start_heating(0.0)
    assert cycle.update(0.5, 10, CAP, CAP) is Decision.HEAT
    assert cycle.update_unread(1.5) is Decision.HEAT          # a frozen frame: not held
    assert cycle.update(2.0, 11, CAP, CAP) is Decision.HEAT
    assert cycle.held == 0.0                                   # 0.5-2.0 had no reading
    assert cycle.update(3.5, 12, CAP, CAP) is Decision.HEAT   # held 1.5 s
    # max_heating 1 s + hold 3 s: given up after 4 s although the hold is not complete
    assert cycle.update(4.1, 12, CAP, CAP) is Decision.RETREAT
    assert cycle.outcome == 'max_heating' and cycle.held == pytest.approx(2.1)
    with pytest.raises(ValueError, match='hold'):
        CycleSettings(hold=-1.0)
