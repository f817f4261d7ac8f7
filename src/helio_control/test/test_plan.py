"""The Plan: JSON round trip, goal fields, quality figures against hand-made cases."""

from types import SimpleNamespace

from helio_control.cycle_model import load_cycle_config
from helio_control.plan import GOAL_FIELDS, load_plan_options, options_from_goal, Plan
from helio_control.plan import plan_picture, PlanOptions, PlanOptionsError
from helio_control.quality import chamfer_mm, render_dots, ssim_of_dots
import numpy as np
import pytest


@pytest.fixture(scope='module')
def logo_plan():
    return plan_picture('sample:logo', PlanOptions(feature_mode='edges'))


def test_plan_json_round_trip(logo_plan):
    again = Plan.from_json(logo_plan.to_json())
    np.testing.assert_array_equal(again.dots, logo_plan.dots)
    np.testing.assert_array_equal(again.n_p_targets, logo_plan.n_p_targets)
    np.testing.assert_array_equal(again.grid_uv, logo_plan.grid_uv)
    for name in ('rejected', 'travel_m', 'travel_s', 'time_estimate', 'quality', 'mode',
                 'ordering', 'parameters', 'warnings', 'notes'):
        assert getattr(again, name) == getattr(logo_plan, name), name
    with pytest.raises(ValueError, match='not a helio plan'):
        Plan.from_json('{"format": "other"}')


def test_plan_holds_what_the_painter_needs(logo_plan):
    plan = logo_plan
    assert plan.dots.shape == (len(plan), 2) and len(plan.n_p_targets) == len(plan)
    assert np.all(plan.n_p_targets == 30)
    estimate = plan.time_estimate
    parts = ('start_s', 'heating_s', 'retreat_cooling_s', 'approach_s', 'travel_s',
             'overhead_s')
    assert sum(estimate[p] for p in parts) == pytest.approx(estimate['total_s'])
    assert estimate['travel_s'] == pytest.approx(plan.travel_s)
    assert estimate['total_low_s'] < estimate['total_s'] < estimate['total_high_s']
    steps = np.diff(plan.dots, axis=0)
    assert plan.travel_m == pytest.approx(np.sum(np.hypot(steps[:, 0], steps[:, 1])))
    assert plan.parameters['sun_source'].startswith('nominal')


def test_config_file_defaults_are_the_papers():
    options = load_plan_options()
    assert (options.dot_radius, options.offset_x, options.offset_y, options.n_p_target,
            options.d_lp, options.retreat) == (0.002, 0.05, 0.05, 30, 0.082, 0.03)
    assert options.canvas_size < 0.10


def test_goal_fields_override_only_when_set():
    defaults = PlanOptions()
    fields = dict.fromkeys(GOAL_FIELDS, 0)
    fields.update(feature_mode='', ordering='')
    unset = SimpleNamespace(**fields)
    assert options_from_goal(unset, defaults) == defaults
    goal = SimpleNamespace(canvas_size=0.06, dot_radius=0.003, offset_x=0.04, offset_y=0.0,
                           n_p_target=40, feature_mode='edges', ordering='nearest')
    options = options_from_goal(goal, defaults)
    assert (options.canvas_size, options.dot_radius, options.offset_x, options.offset_y,
            options.n_p_target, options.feature_mode, options.ordering) == \
        (0.06, 0.003, 0.04, 0.05, 40, 'edges', 'nearest')


def test_chamfer_by_hand():
    # strokes along v = 0 from u = 0 to 4 (dense); dots at v = 0.5 over u = 0..4:
    # every dot is 0.5 pitch from the strokes, every stroke point 0.5 pitch from a dot
    # (u between two dots is farther: sqrt(0.5^2 + du^2)).
    strokes = np.column_stack([np.linspace(0, 4, 4001), np.zeros(4001)])
    dots = np.column_stack([np.arange(5.0), np.full(5, 0.5)])
    figures = chamfer_mm(dots, strokes, pitch=0.002)
    assert figures['dots_to_strokes_mm'] == pytest.approx(1.0)
    du = np.minimum(strokes[:, 0] % 1.0, 1.0 - strokes[:, 0] % 1.0)
    assert figures['strokes_to_dots_mm'] == pytest.approx(
        2.0 * np.mean(np.hypot(0.5, du)), rel=1e-6)


def test_ssim_is_one_for_a_perfect_rendering_and_falls_with_missing_dots():
    dots = np.array([[u, v] for u in range(2, 8) for v in range(3, 6)], dtype=float)
    reference = render_dots(dots, (80, 80), 8)
    assert ssim_of_dots(dots, reference, 8) == pytest.approx(1.0)
    half = ssim_of_dots(dots[::2], reference, 8)
    none = ssim_of_dots(np.zeros((0, 2)), reference, 8)
    assert 1.0 > half > none


def test_line_plans_report_chamfer_and_fill_plans_ssim(logo_plan):
    assert logo_plan.quality['kind'] == 'chamfer_mm'
    assert 0.0 < logo_plan.quality['value'] < 1.0      # under half a 2 mm pitch
    tones = plan_picture('sample:portrait', PlanOptions(feature_mode='tones'))
    assert tones.quality['kind'] == 'ssim' and 0.7 < tones.quality['value'] <= 1.0


def test_tone_dot_size_scales_n_p_with_darkness():
    ramp = np.tile(np.repeat([0.6, 0.1], 200), (400, 1))    # light left, dark right
    plan = plan_picture(ramp, PlanOptions(feature_mode='tones', tone_dot_size=True,
                                          n_p_min=10, v_axis='paper'))
    left = plan.n_p_targets[plan.grid_uv[:, 0] < 20]
    right = plan.n_p_targets[plan.grid_uv[:, 0] >= 20]
    assert np.all(left == round(10 + 20 * 0.4)) and np.all(right == round(10 + 20 * 0.9))


def test_the_window_rules_plan_keeps_hot_neighbours_apart_and_waits_no_cooling():
    # the painter's window rule: min_separation and no cooling wait in the estimate; the
    # separation's penalty is still the cooling wait a hot neighbour would cost
    paper = plan_picture('sample:text', PlanOptions(dot_radius=0.003))
    window = plan_picture('sample:text', PlanOptions(dot_radius=0.003, min_separation=0.0075,
                                                     cooling_wait=False))
    assert window.parameters['close_steps'] == 0
    steps = np.diff(window.dots, axis=0)
    assert np.hypot(steps[:, 0], steps[:, 1]).min() >= 0.0075
    model, _ = load_cycle_config()
    saved = (paper.time_estimate['total_s'] - paper.time_estimate['heating_s']) - (
        window.time_estimate['total_s'] - window.time_estimate['heating_s'])
    # per dot the paper's rule waits max(cooling, retreat move) and the window rule only the
    # retreat move; the window's longer tour costs a little of it back
    assert 0.5 * model.cooling_s * len(paper) < saved < model.cooling_s * len(paper)
    # and its dots, 7.5 mm or more from the dot before, heat the wood the next one needs
    # no more: each heats about as long as a dot alone (the paper's, 3 mm apart, less)
    alone = float(model.heating_time(30))
    assert window.time_estimate['heating_s'] > 0.97 * alone * len(window)
    assert paper.time_estimate['heating_s'] < 0.85 * alone * len(paper)
    with pytest.raises(PlanOptionsError, match='cooling_wait'):
        PlanOptions(cooling_wait='no').validate()
