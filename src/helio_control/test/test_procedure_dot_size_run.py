"""
The dot-size test row before a painting (issue 29, item 3) against a modelled rig.

The rig is ``painter_rig_model.RigModel``: a dot's hot region is a Gaussian of width w, so
its N_p (pixels of side p above the threshold) is pi w^2 ln(dT / theta) / p^2 and the char
it leaves (where the rise passed the same theta) is 2 w sqrt(ln(dT_peak / theta)) wide: its
area grows as d^2 = (4 p^2 / pi) N_p, the law the fit must find (intercept 0).
"""

import math

from geometry_msgs.msg import Point
from helio_control.dot_size_calibration import calibration_row, load_dot_calibration
from helio_control.procedures import dot_procedure, dot_size_run
from helio_control.procedures.dot_size_run import DotRowSettings, needs_test_row, row_conflict
from helio_control.procedures.painting_run import PaintingRun
from helio_msgs.action import PaintPattern
from painter_rig_model import RigModel, run, settings
import pytest

ROW = DotRowSettings(n_p_targets=(10, 20, 30), per_target=1, start=(0.05, 0.10), pitch=0.008,
                     holds=())
DOTS = [(0.05, 0.07), (0.066, 0.07)]        # the goal's own dots, world [m]
WIDTH = 1.2e-3                              # asked of them: within the row's N_p 10-30 [m]


def goal_of(points, run_dir, **fields):
    """Return a PaintPattern goal of world `points` written in `run_dir`, dots 1.2 mm wide."""
    return PaintPattern.Goal(points=[Point(x=x, y=y, z=0.0) for x, y in points],
                             run_dir=str(run_dir), fresh=True, dot_radius=WIDTH, **fields)


@pytest.fixture(autouse=True)
def camera_of_the_model(monkeypatch):
    """Let the model's RGB camera measure each dot's char (RigModel.measure)."""
    monkeypatch.setattr(dot_procedure, 'measure_in_image',
                        lambda *args: RigModel.measure(MEASURER, *args))


def model_of(tmp_path, rule, row=ROW):
    """Return a RigModel whose RGB camera measures the char, calibrate_dots `rule`."""
    model = RigModel(settings(tmp_path, verify_dots=True, calibrate_dots=rule, dot_row=row))
    model.camera = True
    MEASURER.wood, MEASURER.peak = model.wood, model.peak
    return model


class Measurer:
    """The model whose char the camera measures (the last made by model_of)."""


MEASURER = Measurer()


def test_the_row_is_burnt_first_fitted_saved_and_used_by_the_plan(tmp_path):
    model = model_of(tmp_path, 'missing')
    painting = PaintingRun(model, model.settings)
    result, ending = run(painting.execute(goal_of(DOTS, tmp_path / 'runs' / 'first')))
    assert ending == 'succeed' and result.success, result.message
    assert 'dot-size calibration from 3 test dots' in result.message
    tests = [point for goal in calibration_row(ROW.n_p_targets, 1, ROW.start, ROW.pitch)
             for point in goal.points]
    # each test dot heated once, all of them before the goal's first dot
    heated = [(tuple(round(v, 6) for v in target), since) for target, since, _ in
              model.heatings]
    assert [target for target, _ in heated[:3]] == [pytest.approx(p) for p in tests]
    assert [target for target, _ in heated[3:]] == [pytest.approx(p) for p in DOTS]
    calibration = load_dot_calibration(model.settings.calibration_dir, '')
    wood = model.wood
    law = 4.0 * wood.pixel ** 2 / math.pi                # the model's d^2 per pixel of N_p
    assert calibration.area_per_n_p == pytest.approx(law, rel=0.1)
    assert abs(calibration.area_intercept) <= 0.1 * law * 30
    assert calibration.samples == 3 and (calibration.n_p_min, calibration.n_p_max) == (10, 30)
    # the goal's dots planned from it: their N_p target is the law's for the width asked,
    # and they char that wide
    n_p = calibration.n_p_target(WIDTH)
    assert 10 < n_p < 30
    for target in DOTS:
        assert model.wood.char_diameter(model.peak[target]) == pytest.approx(WIDTH, rel=0.1)
    # a second painting finds the file: no row again
    again = model_of(tmp_path, 'missing')
    result, ending = run(PaintingRun(again, again.settings).execute(
        goal_of(DOTS, tmp_path / 'runs' / 'second')))
    assert ending == 'succeed' and 'test dots' not in result.message, result.message
    assert len(again.heatings) == len(DOTS)


def test_dots_wider_than_n_p_can_ask_for_are_held_as_the_held_test_dots_were(tmp_path):
    # the model's N_p levels off near 49 pixels (its rise settles at G = 300 K) while its
    # char keeps growing with the rise; a dot held h seconds at N_p >= 30 (rise r30) peaks
    # at G - (G - r30) exp(-h / tau): the char the hold law must predict
    row = DotRowSettings(n_p_targets=(10, 20, 30), per_target=1, start=(0.05, 0.10),
                         pitch=0.008, holds=(4.0, 12.0))
    model = model_of(tmp_path, 'missing', row)
    wood = model.wood
    widest_unheld = wood.char_diameter(wood.rise_reaching(30))
    width = widest_unheld + 0.6 * (wood.char_diameter(
        wood.rise - (wood.rise - wood.rise_reaching(30)) * math.exp(-12.0 / wood.tau))
        - widest_unheld)                              # between the two held test dots
    goal = goal_of(DOTS, tmp_path / 'runs' / 'held')
    goal.dot_radius = width
    result, ending = run(PaintingRun(model, model.settings).execute(goal))
    assert ending == 'succeed' and result.success, result.message
    assert 'dot-size calibration from 5 test dots' in result.message
    calibration = load_dot_calibration(model.settings.calibration_dir, '')
    assert calibration.hold_s == (4.0, 12.0) and calibration.hold_n_p == 30
    n_p, hold = calibration.dot_for(width)
    assert n_p == 30 and 0.0 < hold < 12.0
    for target in DOTS:                                # the char the model left, not the law
        assert wood.char_diameter(model.peak[target]) == pytest.approx(width, rel=0.1)
    # a held dot's dwell is the time to N_p 30 plus the hold, on the model's own clock
    to_30 = -wood.tau * math.log(1.0 - wood.rise_reaching(30) / wood.rise)
    assert calibration.heating_time(n_p, hold) == pytest.approx(to_30 + hold, abs=1.0)
    # wider than the held test dots: painted, extrapolated, and the log says so
    warnings = []
    model = model_of(tmp_path, 'missing', row)
    model.log.warning = lambda text, **_: warnings.append(text)
    goal = goal_of(DOTS, tmp_path / 'runs' / 'wider')
    goal.dot_radius = 1.05 * calibration.diameter_of(30, 12.0)
    result, ending = run(PaintingRun(model, model.settings).execute(goal))
    assert ending == 'succeed', result.message
    assert any('outside what the dot-size calibration measured' in w for w in warnings)


def test_no_row_on_a_dry_run_never_or_where_it_would_burn_into_the_goal(tmp_path):
    for rule, goal in (('never', goal_of(DOTS, tmp_path / 'runs' / 'never')),
                       ('always', goal_of(DOTS, tmp_path / 'runs' / 'dry', dry_run=True)),
                       ('always', goal_of([(0.058, 0.101)], tmp_path / 'runs' / 'near'))):
        model = model_of(tmp_path, rule)
        result, ending = run(PaintingRun(model, model.settings).execute(goal))
        assert ending == 'succeed', result.message
        own = [(p.x, p.y) for p in goal.points]
        assert all(tuple(target) in own for target, _, _ in model.heatings)  # its dots only
        assert load_dot_calibration(model.settings.calibration_dir, '') is None
    assert "a test dot lies 1.0 mm from one of the goal's points" in result.message


def test_a_row_on_the_canvas_or_near_the_points_is_refused_with_where():
    row = calibration_row((15, 30), 2, (0.06, 0.14), 0.005)
    assert row_conflict(row, (0.05, 0.05, 0.08), [], 0.01) == ''      # 1 cm above the canvas
    refusal = row_conflict(row, (0.05, 0.07, 0.08), [], 0.01)
    assert 'lies on the canvas (0.050, 0.070) m' in refusal and 'dot_calibration.start' in refusal
    assert row_conflict(row, None, [[0.1, 0.05]], 0.01) == ''
    assert '5.0 mm' in row_conflict(row, None, [[0.065, 0.145]], 0.01)
    assert needs_test_row('missing', False, False) and not needs_test_row('missing', True, False)
    assert needs_test_row('always', True, False) and not needs_test_row('always', True, True)
    assert not needs_test_row('never', False, False)
    with pytest.raises(ValueError, match='calibrate_dots must be one of'):
        needs_test_row('sometimes', False, False)
    assert dot_size_run.clearance_of(0.005, 0.002) == pytest.approx(0.01)


def test_a_target_out_of_the_cameras_reach_ends_the_row_and_the_holds_take_the_last_reached(
        tmp_path):
    # the model's N_p levels off below 49 (its rise settles at G = 300 K): N_p 60 is never
    # reached; its first test dot is given up at max_heating, its second is not tried, and
    # the held dots are held at 30, the largest target reached
    row = DotRowSettings(n_p_targets=(10, 20, 30, 60), per_target=2, start=(0.05, 0.10),
                         pitch=0.006, holds=(6.0,))
    model = model_of(tmp_path, 'always', row)
    said = []
    model.log.info = lambda text, **_: said.append(text)
    goal = goal_of(DOTS, tmp_path / 'runs' / 'reach')
    result, ending = run(PaintingRun(model, model.settings).execute(goal))
    assert ending == 'succeed' and result.success, result.message
    points = [p for goal in row.row() for p in goal.points]
    heated = [tuple(round(v, 6) for v in target) for target, _, _ in model.heatings]
    tried = [pytest.approx(p) for p in points[:7]] + [pytest.approx(p) for p in points[8:]]
    assert heated[:9] == tried                          # the second N_p-60 dot left out
    assert any('test dots 8-8 left out: N_p 60 was not reached' in line for line in said)
    calibration = load_dot_calibration(model.settings.calibration_dir, '')
    assert calibration.n_p_max == 30 and calibration.hold_n_p == 30
    assert calibration.hold_s == (6.0,)
