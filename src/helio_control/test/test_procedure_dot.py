"""
One dot (Algorithm 1 lines 6-14) against a modelled rig: held to N_p*, clouds, the watchdog.

The rig is ``painter_rig_model.RigModel``: wood that heats as a first-order system under the
focus, a thermal camera that reads its N_p every frame, a sun that clouds can hide, a
thermal stream that can stop or freeze. The truths the dot procedure is held to are the
model's own: where and when the focus rested on the wood, what each frame showed, and the
dwell its first-order law needs to reach a target.
"""

import math

from helio_control.dot_cycle import CycleSettings
from helio_control.procedures import dot_procedure
from helio_control.procedures.dot_procedure import DotProcedure, SunReturn
from helio_control.procedures.painter_port import PaintCanceled, PaintFailed, PaintFeedback
import numpy as np
from painter_rig_model import FRAME, MOVE, RigModel, run, settings, SPOT_PERIOD
import pytest

TARGET = (0.05, 0.07)      # world [m]


def dot_rig(tmp_path, **overrides):
    """Return a RigModel and a DotProcedure working on it."""
    model = RigModel(settings(tmp_path, **overrides))
    return model, DotProcedure(model, model.settings)


def heat(procedure, n_p_target=30, cooling='paper'):
    """Burn the dot at TARGET; return its journal record's fields."""
    return run(procedure.heat(PaintFeedback(), 0, np.array(TARGET), n_p_target, cooling,
                              False))


def dwell_to_reach(wood, n_p_target, rise=0.0):
    """Return the dwell [s] the wood's first-order law needs from `rise` [K] to N_p*."""
    return -wood.tau * math.log((wood.rise - wood.rise_reaching(n_p_target))
                                / (wood.rise - rise))


def frames_while(model, since, until):
    """Return [(time, N_p of TARGET)] of the frames in (since, until]."""
    return [(t, n_p.get(TARGET, 0)) for t, n_p in model.frames if since < t <= until]


def longest_blind(model):
    """Return the longest time the focus rested on the wood with no thermal frame [s]."""
    longest = 0.0
    for since, until in model.heated(TARGET):
        times = [since] + [t for t, _ in frames_while(model, since, until)] + [until]
        longest = max(longest, max(np.diff(times)))
    return longest


@pytest.mark.parametrize('n_p_target', [15, 30])
def test_a_dot_is_held_until_the_woods_n_p_reaches_its_target(tmp_path, n_p_target):
    model, procedure = dot_rig(tmp_path)
    record = heat(procedure, n_p_target)
    assert record['outcome'] == 'burnt' and record['restarts'] == 0
    [(since, until)] = model.heated(TARGET)
    seen = frames_while(model, since, until)
    # retreated on the first frame that shows the target: the one before did not
    assert seen[-1][1] >= n_p_target > seen[-2][1]
    assert until == pytest.approx(seen[-1][0])
    truth = dwell_to_reach(model.wood, n_p_target)
    assert truth <= until - since <= truth + FRAME
    assert record['dwell'] == pytest.approx(until - since, abs=1e-6)
    assert record['peak_n_p'] >= n_p_target
    # the paper's rule: the dot ends once the wood shows no N_p any more
    assert model.true_n_p(TARGET) == 0 and procedure.at_heating is None


def test_a_cloud_breaks_the_heating_off_and_the_dot_is_heated_again_to_its_target(tmp_path):
    model, procedure = dot_rig(tmp_path)
    model.clouds = [(2.5, 12.0)]
    record = heat(procedure)
    first, second = model.heated(TARGET)
    # off the wood on the first frame after the shaded wood cooled by cloud_t_drop (5 K,
    # dot_cycle) from its peak, by the first-order law
    wood = model.wood
    peak = wood.rise * (1.0 - math.exp(-(2.5 - first[0]) / wood.tau))
    cooled = 2.5 + wood.tau * math.log(peak / (peak - CycleSettings().cloud_t_drop))
    assert cooled <= first[1] <= cooled + FRAME
    # back on the wood once the spot was seen in sun_back_frames frames in a row
    frames = model.settings.sun_back_frames
    assert 12.0 + (frames - 1) * SPOT_PERIOD <= second[0] - MOVE <= 12.0 + frames * SPOT_PERIOD
    seen = frames_while(model, *second)
    assert seen[-1][1] >= 30 > seen[-2][1]              # the full target, not what was left
    assert record['outcome'] == 'burnt' and record['restarts'] == 1
    assert record['dwell'] == pytest.approx(second[1] - second[0], abs=1e-6)
    # the wait: from the retreat's end to the sun's return, before the move back
    assert procedure.cloud_wait == pytest.approx(second[0] - first[1] - 2 * MOVE, abs=1e-6)


def test_a_stale_thermal_stream_takes_the_focus_off_the_wood_within_thermal_stale(tmp_path):
    model, procedure = dot_rig(tmp_path)
    model.stream_down = [(2.0, 4.0)]
    record = heat(procedure)
    first, second = model.heated(TARGET)
    last_frame = max(t for t, _ in model.frames if t < 2.0)
    assert 0.0 < first[1] - last_frame <= model.settings.thermal_stale + 1e-9
    assert longest_blind(model) <= model.settings.thermal_stale + 1e-9
    assert second[0] >= 4.0                             # heated again once frames came back
    assert record['outcome'] == 'burnt' and record['restarts'] == 1
    assert procedure.thermal_interruptions == 1


def test_a_thermal_stream_that_does_not_come_back_ends_the_painting_retreated(tmp_path):
    model, procedure = dot_rig(tmp_path)
    model.stream_down = [(2.0, math.inf)]
    with pytest.raises(PaintFailed, match='not back within 30 s'):
        heat(procedure)
    [(since, until)] = model.heated(TARGET)
    assert until <= 2.0 + model.settings.thermal_stale
    assert model.lens[1] == pytest.approx(model.heating_distance + model.retreat_offset)
    assert procedure.at_heating is None


@pytest.mark.parametrize('freeze, heatings', [((2.0, 2.8), 1), ((2.0, 8.0), 2)])
def test_a_frozen_camera_is_heated_through_blind_for_thermal_freeze_max_only(
        tmp_path, freeze, heatings):
    model, procedure = dot_rig(tmp_path)
    model.frozen = [freeze]
    record = heat(procedure)
    intervals = model.heated(TARGET)
    assert len(intervals) == heatings and record['outcome'] == 'burnt'
    live = max(t for t, _ in model.frames if t < freeze[0])
    if heatings == 1:                    # a short freeze (a flat-field correction): no stop
        assert record['restarts'] == 0
    else:                                # off the wood once blind for thermal_freeze_max
        assert intervals[0][1] - live == pytest.approx(model.settings.thermal_freeze_max,
                                                       abs=1e-6)
        assert intervals[1][0] >= freeze[1] and record['restarts'] == 1


def test_the_window_rule_heats_on_without_a_window_reading_only_below_the_target(tmp_path):
    model, procedure = dot_rig(tmp_path)
    model.window_blind = [(1.5, 2.5)]            # early: the whole image is below N_p*
    record = heat(procedure, cooling='window')
    assert len(model.heated(TARGET)) == 1 and record['restarts'] == 0
    assert record['outcome'] == 'burnt'


def test_a_window_rule_dot_at_its_target_without_a_window_reading_retreats_in_time(tmp_path):
    model, procedure = dot_rig(tmp_path)
    reached = 0.8 + dwell_to_reach(model.wood, 30)     # the move, then the heating [s]
    model.window_blind = [(reached - 1.0, reached + 2.0)]
    record = heat(procedure, cooling='window')
    first = model.heated(TARGET)[0]
    # the image shows N_p* (the window might not): at most thermal_stale more, read on a frame
    at_target = min(t for t, n_p in frames_while(model, *first) if n_p >= 30)
    assert 0.0 < first[1] - at_target <= model.settings.thermal_stale + FRAME
    assert record['outcome'] == 'burnt' and record['restarts'] >= 1


def test_a_servo_alarm_while_heating_leaves_the_retreat_to_the_arm_alone(tmp_path):
    model, procedure = dot_rig(tmp_path)
    model.fault_at = 2.0
    with pytest.raises(PaintFailed, match='device fault: servo alarm'):
        heat(procedure)
    said = run(procedure.retreat('device fault'))
    assert said == 'the wrist could not move (servo alarm: overload); the arm lifted the lens'
    [(since, until)] = model.heated(TARGET)
    assert until == pytest.approx(2.0) and [way for _, way in model.escapes] == ['arm']
    assert procedure.at_heating is None


def test_a_retreat_that_finds_no_way_is_tried_again_until_one_comes_back(tmp_path):
    # both devices at fault at once (the Dobot's link reset as the servo driver died): no
    # way to move the lens, until the Dobot is back half a second later
    model, procedure = dot_rig(tmp_path)
    model.fault_at, model.arm_fault = 2.0, (2.0, 2.5)
    with pytest.raises(PaintFailed, match='device fault: dobot not connected'):
        heat(procedure)
    said = run(procedure.retreat('device fault'))
    period = model.settings.retreat_retry_period
    tries = 1 + math.ceil(0.5 / period)                 # the first try after 2.5 s works
    assert said == ('the wrist could not move (servo alarm: overload); the arm lifted the '
                    f'lens (at the try {tries}; the first: RETREAT FAILED: dobot not '
                    'connected (link reset); servo alarm: overload)')
    [(at, way)] = model.escapes
    assert way == 'arm' and at == pytest.approx(2.0 + (tries - 1) * period)
    assert procedure.at_heating is None


def test_a_cancel_while_heating_ends_the_dot_at_once(tmp_path):
    model, procedure = dot_rig(tmp_path)
    model.cancel_at = 2.0
    with pytest.raises(PaintCanceled):
        heat(procedure)
    assert procedure.at_heating == pytest.approx(TARGET)
    assert model.lens == (pytest.approx(TARGET), model.heating_distance)
    assert run(procedure.retreat('cancel')) == 'retreated (cancel)'
    [(since, until)] = model.heated(TARGET)
    assert until == pytest.approx(2.0) and model.moves[-1][4]      # the urgent retreat


@pytest.mark.parametrize('char_rise, heatings, verdict, outcome', [
    (20.0, 1, 'charred', 'burnt'),
    (70.0, 2, 'not charred', 'failed'),          # wood that chars only hotter (wet wood)
])
def test_the_camera_checks_each_dot_and_a_dot_without_char_is_heated_again_once(
        tmp_path, monkeypatch, char_rise, heatings, verdict, outcome):
    model, procedure = dot_rig(tmp_path, verify_dots=True)
    model.camera, model.wood.char_rise = True, char_rise
    monkeypatch.setattr(dot_procedure, 'measure_in_image', model.measure)
    expected = 2.0e-3                                    # the plan's dot at N_p 30 [m]
    record = run(procedure.paint(PaintFeedback(), 0, np.array(TARGET), 30, 'paper', False,
                                 expected=expected))
    assert len(model.heated(TARGET)) == heatings == record['reheats'] + 1
    truth = model.wood.char_diameter(model.peak[TARGET])
    assert (truth >= model.settings.verify_min_diameter_ratio * expected) == (
        verdict == 'charred')
    assert (record['verdict'], record['outcome']) == (verdict, outcome)
    assert record['measured_diameter'] == pytest.approx(truth)


def test_the_sun_is_back_after_frames_in_a_row_only():
    back = SunReturn(3)
    assert [back.seen(valid) for valid in (True, True, False, True, True, True)] == [
        False, False, False, False, False, True]
