"""
The focal calibration procedure in-process against a model rig: the lens' true focus found.

The model rig's lens has a focal length 2 % longer than the lens file's (its smallest spot
about 1.6 mm farther); the spot areas it reports are that lens' A_c (``spot_area``) at each
pose. The procedure's minimum must be the true lens' (found here by a dense scan of the same
model), and once applied the planner's lens model must focus there.
"""

from dataclasses import replace
import math

from fake_lens_rig import FakeLensRig, run, sun_at
from helio_control.procedures.focal_calibration_run import calibrate_focus
from helio_control.procedures.focal_calibration_run import model_best_distance
from helio_control.procedures.lens_rig_port import GoalFailed
from helio_msgs.action import CalibrateFocus
from helio_optics.config_files import config_path
from helio_optics.lens import load_lens_parameters
from helio_optics.spot import spot_area_at
import numpy as np
import pytest

SUN = sun_at(50.0, 230.0)
FILE_LENS = load_lens_parameters(config_path('lens.yaml'))
TRUE_LENS = replace(FILE_LENS, focal_length=FILE_LENS.focal_length * 1.02)


@pytest.fixture(scope='module')
def true_best():
    """Return the true lens' smallest spot [m]: a 0.1 mm scan of its A_c, lens on the sun."""
    distances = np.arange(0.075, 0.095, 1e-4)
    areas = [spot_area_at(TRUE_LENS, d, math.radians(50.0)) for d in distances]
    return float(distances[np.argmin(areas)])


def request(**fields):
    return CalibrateFocus.Goal(d_min=0.074, d_max=0.094, step=0.001, **fields)


def test_the_sweep_finds_the_true_focus_and_the_lens_model_is_moved_there(true_best):
    rig = FakeLensRig(SUN, true_lens=TRUE_LENS, believed_sun=SUN, world_calibrated=True)
    result = CalibrateFocus.Result()
    run(calibrate_focus(rig, request(apply=True), result))
    assert abs(true_best - model_best_distance(FILE_LENS, 0.082)) > 1e-3   # a real shift
    assert result.heating_distance == pytest.approx(true_best, abs=5e-4)
    assert len(result.d_lp) == 21 and np.all(np.isfinite(result.areas))
    assert rig.heating_distance == result.heating_distance
    # the planner's lens model now has its own smallest spot where the sweep found it
    assert model_best_distance(rig.lens, rig.heating_distance) == pytest.approx(
        rig.heating_distance, abs=5e-4)
    tree, _ = rig.saved['focus.yaml']
    assert tree['heating_distance'] == result.heating_distance and tree['samples'] == 21
    assert result.message.startswith(f'smallest spot at d_lp {true_best * 100:.1f}')
    assert [f.index for f in rig.feedbacks] == list(range(21))


def test_unapplied_the_planner_keeps_its_lens():
    rig = FakeLensRig(SUN, true_lens=TRUE_LENS, believed_sun=SUN, world_calibrated=True)
    result = CalibrateFocus.Result()
    run(calibrate_focus(rig, request(apply=False), result))
    assert rig.heating_distance == 0.082 and rig.lens == FILE_LENS and not rig.saved
    assert result.message.endswith('(not applied)')


@pytest.mark.parametrize('fields, words', [
    ({'d_min': 0.09, 'd_max': 0.08}, 'bad sweep: d_min 0.09'),
    ({'step': float('inf')}, 'every number must be finite'),
    ({'step': 1e-6}, 'bad sweep'),
])
def test_a_bad_sweep_is_refused_before_any_move(fields, words):
    rig = FakeLensRig(SUN, believed_sun=SUN, world_calibrated=True)
    goal = request()
    for name, value in fields.items():
        setattr(goal, name, value)
    with pytest.raises(GoalFailed, match=words):
        run(calibrate_focus(rig, goal, CalibrateFocus.Result()))
    assert rig.moves == []


def test_no_spot_at_all_fails_saying_how_many_distances_gave_one():
    rig = FakeLensRig(SUN, believed_sun=SUN, world_calibrated=True, clouds=True)
    with pytest.raises(GoalFailed, match=r'focal calibration: .*\(0 of 21 distances'):
        run(calibrate_focus(rig, request(), CalibrateFocus.Result()))
