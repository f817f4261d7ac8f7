"""Cycle model: a hand-computed estimate, config values, fitting recovers known parameters."""

import os

from helio_control.cycle_model import CycleModel, estimate_time, fit_cycle_model
from helio_control.cycle_model import load_cycle_config
import numpy as np
import pytest

CONFIG = os.path.join(os.path.dirname(__file__), '..', '..', '..', 'config', 'cycle_model.yaml')


def test_estimate_of_three_dots_by_hand():
    model = CycleModel(heating_onset_s=10.0, heating_per_pixel_s=0.25, cooling_s=3.0,
                       thermal_frame_s=0.1, move_overhead_s=0.2, start_s=30.0,
                       heating_spread=0.1)
    estimate = estimate_time(model, [20, 30, 40], approach_s=[0.5, 0.5, 0.5],
                             retreat_s=[0.5, 0.5, 3.5], travel_s=[1.0, 2.0])
    # heating 15 + 17.5 + 20; cooling max(3, 0.7) twice and max(3, 3.7) once; approach 1.5;
    # travel 3; overhead (3 approaches + 2 travels) * 0.2 + 6 frames * 0.1
    assert estimate['heating_s'] == pytest.approx(52.5)
    assert estimate['retreat_cooling_s'] == pytest.approx(9.7)
    assert estimate['overhead_s'] == pytest.approx(1.6)
    assert estimate['total_s'] == pytest.approx(30 + 52.5 + 9.7 + 1.5 + 3 + 1.6)
    assert estimate['total_high_s'] - estimate['total_s'] == pytest.approx(5.25)


def test_config_file_matches_the_documented_defaults():
    model, limits = load_cycle_config(CONFIG)
    assert model == CycleModel()
    assert model.heating_time(30) == pytest.approx(16.28)     # a dot burnt alone
    assert np.degrees(limits.arm_velocity) == pytest.approx([100.0] * 3)
    assert np.degrees(limits.wrist_acceleration) == pytest.approx(450.0)


def test_fit_recovers_the_parameters_that_made_the_logs():
    truth = CycleModel(heating_onset_s=14.0, heating_per_pixel_s=0.15)
    rng = np.random.default_rng(0)
    records = []
    for n_p in rng.choice([20, 30, 40, 50], 200):
        records.append({'n_p_target': int(n_p),
                        'heating_s': float(truth.heating_time(n_p) + rng.normal(0, 0.5)),
                        'cooling_s': float(3.4 + rng.normal(0, 0.2)),
                        'move_s': 0.8 + 0.25, 'predicted_move_s': 0.8})
    fitted, report = fit_cycle_model(records)
    assert fitted.heating_onset_s == pytest.approx(14.0, abs=0.3)
    assert fitted.heating_per_pixel_s == pytest.approx(0.15, abs=0.01)
    assert fitted.cooling_s == pytest.approx(3.4, abs=0.05)
    assert fitted.move_overhead_s == pytest.approx(0.25)
    assert report['heating_rms_residual_s'] == pytest.approx(0.5, abs=0.1)


def test_fit_with_one_target_scales_the_heating():
    records = [{'heating_s': 27.0, 'cooling_s': 3.0, 'move_s': 1.0}] * 5
    fitted, _ = fit_cycle_model(records)
    assert fitted.heating_time(30) == pytest.approx(27.0)


def test_bad_parameters_are_named():
    with pytest.raises(ValueError, match='cooling_s'):
        CycleModel(cooling_s=-1.0)
    with pytest.raises(ValueError, match='unknown cycle model parameter'):
        CycleModel.from_parameters({'warmup_s': 1.0})
    with pytest.raises(ValueError, match='no records'):
        fit_cycle_model([])


def test_the_heat_a_dot_leaves_shortens_the_next_ones_heating_by_its_distance():
    model = CycleModel(preheat_share=0.4, preheat_reach=0.004, preheat_onset_s=3.0)
    # 1 - 0.4 exp(-(r / 4 mm)^2): at 0, 4 mm, 8 mm; none before (inf, NaN): a dot alone
    assert model.preheat_factor([0.0, 0.004, 0.008, np.inf, np.nan]) == pytest.approx(
        [0.6, 1.0 - 0.4 / np.e, 1.0 - 0.4 * np.exp(-4.0), 1.0, 1.0])
    assert CycleModel(preheat_reach=0.0).preheat_factor(0.001) == pytest.approx(1.0)
    alone = estimate_time(model, [30, 30], [0.5, 0.5], [0.5, 0.5], [1.0])
    after = estimate_time(model, [30, 30], [0.5, 0.5], [0.5, 0.5], [1.0],
                          previous_distance=[np.inf, 0.004])
    # the first 3 s (the hot spot forming) are not shortened, the rest is
    assert alone['heating_s'] - after['heating_s'] == pytest.approx(
        0.4 / np.e * (float(model.heating_time(30)) - 3.0))
    short = estimate_time(model, [30, 30], [0.5, 0.5], [0.5, 0.5], [1.0],
                          previous_distance=[np.inf, 0.0],
                          heating_time=lambda n_p: np.full(len(n_p), 2.0))
    assert short['heating_s'] == pytest.approx(4.0)    # a dot under the onset: as alone
