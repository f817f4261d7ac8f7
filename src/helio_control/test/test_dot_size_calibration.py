"""
The dot-size calibration (issue 29, item 3): fit, inverse, store, and the plan that uses it.

Samples are drawn from a known law (d^2 = a + b N_p, dwell = c exp(e N_p)) with noise; the
fit must recover it, refuse what it cannot fit, and the plan must burn and time its dots by it.
"""

from dataclasses import replace
import math
import os

from helio_control.calibration_store import CalibrationRefused, rig_description
from helio_control.cycle_model import load_cycle_config
from helio_control.dot_check import expected_dot
from helio_control.dot_size_calibration import (
    calibration_row, dot_size_for_painting, DotCalibrationError, DotSample, fit_dot_size,
    load_dot_calibration, samples_from_journal, save_dot_calibration, sized_options)
from helio_control.plan import load_plan_options, plan_dots
from helio_control.run_journal import JournalWriter, read_journal
import numpy as np
import pytest

# the simulated world's law, about (test/test_painter.py: N_p 15, 20, 30 -> 1.40, 1.61, 1.97 mm)
AREA_INTERCEPT = 0.12e-6     # [m^2]
AREA_PER_N_P = 0.1253e-6     # [m^2]
DWELL_AT_ZERO = 0.94         # [s] the world's about (3.0 s at N_p 15, 48.5 s at N_p 40),
DWELL_RATE = 0.1113          # [1/pixel] an exponential law, log-interpolated exactly: a check


def law_dwell(n_p):
    """Return the known law's dwell [s] at N_p `n_p`."""
    return DWELL_AT_ZERO * math.exp(DWELL_RATE * n_p)


def law_samples(targets=(10, 15, 20, 30, 40, 50), per_target=2, noise=0.02, seed=4):
    """Return DotSamples of the known law, the diameters and dwells off by `noise` (relative)."""
    rng = np.random.default_rng(seed)
    samples = []
    for n_p in targets:
        for _ in range(per_target):
            diameter = math.sqrt(AREA_INTERCEPT + AREA_PER_N_P * n_p)
            dwell = law_dwell(n_p)
            samples.append(DotSample(n_p, diameter * (1.0 + noise * rng.standard_normal()),
                                     dwell * (1.0 + noise * rng.standard_normal())))
    return samples


def test_the_fit_recovers_a_known_law_and_says_its_residual():
    exact = fit_dot_size(law_samples(noise=0.0))
    assert exact.area_intercept == pytest.approx(AREA_INTERCEPT, abs=1e-12)
    assert exact.area_per_n_p == pytest.approx(AREA_PER_N_P, rel=1e-9)
    # the dwells of an exponential law: interpolated and extrapolated along it exactly
    for n_p in (5, 10, 12.5, 31, 50, 70):
        assert exact.dwell(n_p) == pytest.approx(law_dwell(n_p))
    assert exact.residual_rms < 1e-12 and (exact.n_p_min, exact.n_p_max) == (10, 50)
    noisy = fit_dot_size(law_samples(noise=0.02))
    truth = np.sqrt(AREA_INTERCEPT + AREA_PER_N_P * np.arange(10, 51))
    # 2 % noise on 12 dots: the law within 2 % over the range, the residual says ~2 %
    assert np.max(np.abs(noisy.diameter(np.arange(10, 51)) / truth - 1.0)) < 0.02
    assert 0.005 < noisy.residual_rms / float(np.mean(truth)) < 0.04
    assert noisy.samples == 12 and 'residual RMS' in noisy.summary()[1]


def test_the_inverse_gives_the_n_p_target_and_the_dwell_of_a_diameter():
    calibration = fit_dot_size(law_samples(noise=0.0))
    for n_p in range(5, 60):
        assert calibration.n_p_target(float(calibration.diameter(n_p))) == n_p
    # 2.0 mm: (4.0 - 0.12) / 0.1253 = 31.0 pixels, heated 10.6 + 0.176 x 31 s
    assert calibration.n_p_target(2.0e-3) == 31
    assert calibration.dwell(31) == pytest.approx(law_dwell(31))
    assert calibration.n_p_target(0.1e-3) == 1          # smaller than any: the least
    assert calibration.within(2.0e-3) and not calibration.within(3.5e-3)
    with pytest.raises(ValueError):
        calibration.n_p_target(0.0)


@pytest.mark.parametrize('samples, words', [
    (law_samples(targets=(20, 30), per_target=1), 'too few test dots: 2 measured'),
    (law_samples(targets=(30,), per_target=4), 'at 1 N_p target'),
    ([DotSample(15, 1.4e-3, 13.0), DotSample(30, 0.0, 16.0), DotSample(30, 0.0, 16.0)],
     '2 without a diameter'),
    ([DotSample(15, 1.6e-3, 13.0), DotSample(20, 1.7e-3, 14.0), DotSample(30, 1.5e-3, 16.0)],
     'do not grow with N_p: N_p 20 burnt 1.70 mm, N_p 30 1.50 mm'),
    ([DotSample(15, 1.4e-3, 13.0), DotSample(20, 1.6e-3, 9.0), DotSample(30, 2.0e-3, 16.0)],
     'a higher N_p target took less time: N_p 15 in 13.0 s, N_p 20 in 9.0 s'),
])
def test_samples_a_law_cannot_be_fitted_to_are_refused_with_the_reason(samples, words):
    with pytest.raises(DotCalibrationError, match=words.replace('(', r'\(')):
        fit_dot_size(samples)


def test_the_calibration_reads_back_for_its_rig_and_is_refused_for_another(tmp_path):
    rig = tmp_path / 'rig.yaml'
    rig.write_text('rig:\n  link_2: 0.135\n')
    calibration = fit_dot_size(law_samples())
    directory = str(tmp_path / 'cal')
    path = save_dot_calibration(directory, calibration, rig_description(str(rig)))
    assert os.path.basename(path) == 'dots.yaml'
    assert load_dot_calibration(directory, rig_description(str(rig))) == calibration
    assert dot_size_for_painting(directory, str(rig)) == (calibration, '')
    rig.write_text('rig:\n  link_2: 0.136\n')     # another rig: refused, and said so
    with pytest.raises(CalibrationRefused, match='made for rig description'):
        load_dot_calibration(directory, rig_description(str(rig)))
    refused, note = dot_size_for_painting(directory, str(rig))
    assert refused is None and 'not used' in note and 'calibrate again' in note
    assert dot_size_for_painting(str(tmp_path / 'none'), str(rig)) == (None, '')


def test_the_samples_are_the_journals_burnt_dots_the_camera_measured(tmp_path):
    path = str(tmp_path / 'journal.jsonl')
    with JournalWriter(path) as journal:
        journal.run({'n_p_target': 20}, 0.0, 0.0)
        for index, (outcome, measured) in enumerate((('burnt', 1.6e-3), ('burnt', 0.0),
                                                     ('failed', 1.2e-3), ('burnt', 1.7e-3))):
            journal.dot(index=index, target=[0.06 + 0.005 * index, 0.04], n_p_target=20,
                        start=0.0, end=20.0, dwell=14.0 + index, peak_n_p=20, t_max=181.0,
                        outcome=outcome, measured_diameter=measured)
    samples = samples_from_journal(read_journal(path))
    assert samples == [DotSample(20, 1.6e-3, 14.0), DotSample(20, 1.7e-3, 17.0)]


def test_a_plan_burns_and_times_its_dots_by_the_calibration():
    calibration = fit_dot_size(law_samples(noise=0.0))
    points = np.array([[0.06 + 0.004 * i, 0.08] for i in range(4)])
    options = replace(load_plan_options(), dot_radius=0.0025)
    # the goal's dot_radius: the dot's width, 2.5 mm -> N_p (6.25 - 0.12) / 0.1253 = 49
    sized = sized_options(options, calibration)[0]
    assert sized.n_p_target == 49 and options.n_p_target == 30
    assert sized_options(options, calibration, n_p_given=True)[0].n_p_target == 30
    assert sized_options(options, None)[0].n_p_target == 30
    plan = plan_dots(points, sized, dot_size=calibration)
    assert list(plan.n_p_targets) == [49] * 4
    # the first dot alone, each later one 4 mm after the one before: its heat left in the
    # wood shortens the dwell past the onset by share x exp(-(4 mm / reach)^2)
    model, _ = load_cycle_config()
    left = 1.0 - model.preheat_share * math.exp(-(0.004 / model.preheat_reach) ** 2)
    dwell = float(calibration.dwell(49))
    assert plan.time_estimate['heating_s'] == pytest.approx(
        dwell + 3 * (model.preheat_onset_s + (dwell - model.preheat_onset_s) * left))
    expected, _ = expected_dot(plan, 0)
    assert expected == pytest.approx(2.5e-3, rel=0.01)
    # without it, today's plan: N_p 30, the cycle model's heating, 2.5 mm expected at N_p 30
    plain = plan_dots(points, options)
    assert list(plain.n_p_targets) == [30] * 4 and 'dot_size' not in plain.parameters
    assert plain.time_estimate['heating_s'] != pytest.approx(plan.time_estimate['heating_s'])
    assert expected_dot(plain, 0)[0] == pytest.approx(2.5e-3)


def test_the_test_row_is_one_goal_per_target_each_dot_inside_its_own_canvas():
    from helio_control.dot_layout import outside_canvas
    goals = calibration_row((15, 30, 45), per_target=2, start=(0.06, 0.04), pitch=0.005)
    assert [goal.n_p_target for goal in goals] == [15, 30, 45]
    points = np.array([p for goal in goals for p in goal.points])
    assert np.allclose(points[:, 0], 0.06 + 0.005 * np.arange(6)) and np.all(points[:, 1] == 0.04)
    for goal in goals:
        options = replace(load_plan_options(), offset_x=goal.offset_x, offset_y=goal.offset_y,
                          canvas_size=goal.canvas_size).validate()
        assert not np.any(outside_canvas(np.array(goal.points), options))
        # the canvas of one goal holds none of the others' dots
        others = np.array([p for other in goals if other is not goal for p in other.points])
        assert np.all(outside_canvas(others, options))
    with pytest.raises(ValueError, match='3 dots at 2 N_p targets'):
        calibration_row((30,), per_target=5)


def held_samples(holds=(20.0, 45.0), growth=0.02e-6, per_target=2):
    """Return law samples to N_p 30 and dots held there: area + growth x hold [m^2 / s]."""
    samples = law_samples(targets=(10, 20, 30), per_target=per_target, noise=0.0)
    area30 = AREA_INTERCEPT + AREA_PER_N_P * 30
    dwell30 = law_dwell(30)
    for hold in holds:
        samples += [DotSample(30, math.sqrt(area30 + growth * hold), dwell30 + hold, hold)
                    ] * per_target
    return samples


def test_held_dots_extend_the_law_past_the_largest_n_p_target():
    growth = 0.02e-6                                  # [m^2 / s] held at N_p 30
    calibration = fit_dot_size(held_samples(growth=growth))
    assert (calibration.hold_n_p, calibration.hold_s) == (30, (20.0, 45.0))
    assert calibration.samples == 10
    area30 = AREA_INTERCEPT + AREA_PER_N_P * 30
    # a linear growth in the hold: interpolated and extrapolated along it exactly
    for hold in (5.0, 20.0, 30.0, 70.0):
        width = math.sqrt(area30 + growth * hold)
        n_p, held = calibration.dot_for(width)
        assert n_p == 30 and held == pytest.approx(hold)
        assert calibration.diameter_of(30, hold) == pytest.approx(width)
        assert calibration.heating_time(30, hold) == pytest.approx(law_dwell(30) + hold)
    # within the N_p law's range nothing is held
    assert calibration.dot_for(math.sqrt(AREA_INTERCEPT + AREA_PER_N_P * 20)) == (20, 0.0)
    assert calibration.within(math.sqrt(area30 + growth * 45.0))
    assert not calibration.within(math.sqrt(area30 + growth * 60.0))
    assert any('held at N_p 30' in line for line in calibration.summary())
    # a calibration without held dots (an older dots.yaml) reads back and holds nothing
    old = {name: value for name, value in fit_dot_size(law_samples()).to_parameters().items()
           if not name.startswith('hold')}
    unheld = type(calibration).from_parameters(old)
    assert unheld.hold_s == () and unheld.dot_for(0.003)[1] == 0.0
    assert type(calibration).from_parameters(calibration.to_parameters()) == calibration


def test_held_dots_that_do_not_grow_or_at_another_target_are_refused():
    with pytest.raises(DotCalibrationError, match='do not grow with the hold'):
        fit_dot_size(held_samples(growth=-0.001e-6))
    stray = law_samples(targets=(10, 20, 30), noise=0.0) + [DotSample(20, 2e-3, 40.0, 10.0)]
    with pytest.raises(DotCalibrationError, match='largest N_p target 30, not \\[20\\]'):
        fit_dot_size(stray)
    assert [(goal.n_p_target, goal.hold) for goal in calibration_row(
        (10, 20, 30), 1, (0.06, 0.14), 0.005, holds=(0.0, 15.0))] == [
            (10, 0.0), (20, 0.0), (30, 0.0), (30, 15.0)]


def test_the_rows_measured_cooling_replaces_the_cycle_models_in_the_plan():
    # a Lepton in high gain counts pixels above 140 degC: its N_p takes longer back to 0
    # than the cycle model's 3.1 s (the paper's camera); the row's own waits are used
    samples = [replace(sample, cooling=2.0 + 0.1 * sample.n_p_target)
               for sample in law_samples(targets=(10, 20, 30), noise=0.0)]
    samples += [DotSample(30, 2.2e-3, 60.0, 20.0, 7.0)] * 2
    calibration = fit_dot_size(samples)
    assert calibration.cooling_s == pytest.approx((3.0, 4.0, 5.0))
    assert calibration.cooling(25) == pytest.approx(4.5)
    assert calibration.cooling(30, 20.0) == pytest.approx(7.0)
    points = np.array([[0.06 + 0.004 * i, 0.08] for i in range(3)])
    options = sized_options(replace(load_plan_options(), dot_radius=0.0018), calibration)[0]
    plan = plan_dots(points, options, dot_size=calibration)
    assert plan.parameters['cycle_model']['cooling_s'] == pytest.approx(
        2.0 + 0.1 * options.n_p_target)
    # a row that measured no cooling (the window rule, older files) leaves the model's
    unmeasured = fit_dot_size(law_samples(noise=0.0))
    assert unmeasured.cooling_s == () and unmeasured.cooling(30) is None
