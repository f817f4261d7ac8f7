"""Orderings: each dot once, exhaustive optimum on small cases, sample-picture ratios."""

import itertools

from helio_control.arm_motion import MotionLimits, move_time, move_time_matrix
from helio_control.dot_layout import check_reach
from helio_control.path_ordering import fast_tsp_order, integer_matrix, order_dots, ORDERINGS
from helio_control.path_ordering import TravelMetric, two_opt
from helio_control.plan import default_rig, plan_picture, PlanOptions
from helio_control.samples import SAMPLE_NAMES
from helio_drivers.motion_profile import synchronised_profile, TrapezoidProfile
import numpy as np
import pytest

LIMITS = MotionLimits()


def test_move_time_matches_the_emulators_trapezoid_profiles():
    rng = np.random.default_rng(4)
    for _ in range(50):
        start, end = rng.normal(0, 0.4, 5), rng.normal(0, 0.4, 5)
        distance = np.abs(end - start)
        arm = synchronised_profile(distance[:3], LIMITS.arm_velocity,
                                   LIMITS.arm_acceleration).duration
        wrist = max(TrapezoidProfile(LIMITS.wrist_velocity / d,
                                     LIMITS.wrist_acceleration / d).duration
                    for d in distance[3:])
        assert move_time(start, end, LIMITS) == pytest.approx(max(arm, wrist), rel=1e-12)


def test_time_matrix_equals_pairwise_move_times_also_with_unequal_limits():
    rng = np.random.default_rng(5)
    joints = rng.normal(0, 0.3, (60, 5))
    for limits in (LIMITS, MotionLimits(arm_acceleration=(1.0, 2.0, 1.5))):
        expected = move_time(joints[:, None, :], joints[None, :, :], limits)
        np.testing.assert_allclose(move_time_matrix(joints, joints, limits), expected,
                                   rtol=1e-5, atol=1e-6)


def canvas_metric(count, seed):
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(np.arange(40), np.arange(40))
    cells = np.column_stack([u.ravel(), v.ravel()])[rng.choice(1600, count, replace=False)]
    points = 0.05 + 0.002 * cells
    options = PlanOptions()
    reach = check_reach(points, default_rig()[0], options.nominal_sun_ray(), options.d_lp,
                        options.retreat)
    assert all(not r for r in reach.reasons)
    return TravelMetric(reach.joints_retreat, LIMITS, points), cells


def exhaustive_best_path(matrix):
    count = len(matrix)
    best = np.inf
    for order in itertools.permutations(range(1, count)):
        for position in range(count):   # dot 0 anywhere: every open path once (or twice)
            path = list(order[:position]) + [0] + list(order[position:])
            best = min(best, sum(matrix[a, b] for a, b in zip(path, path[1:])))
    return best


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_fast_tsp_finds_the_exhaustive_optimum_of_small_open_paths(seed):
    metric, _ = canvas_metric(7, seed)
    matrix = metric.matrix().astype(float)
    best = exhaustive_best_path(matrix)
    for method in ('fast_tsp', 'nearest_2opt'):
        order = order_dots(metric, method)
        cost = sum(matrix[a, b] for a, b in zip(order, order[1:]))
        assert cost >= best - 1e-6
        if method == 'fast_tsp':
            assert cost == pytest.approx(best, abs=7 * 1e-4)   # 0.1 ms rounding per move


def test_integer_matrix_depot_costs_the_same_from_every_dot():
    metric, _ = canvas_metric(30, 3)
    scaled, unit = integer_matrix(metric.matrix())
    assert scaled.dtype == np.uint16
    assert len(set(scaled[-1, :-1].tolist())) == 1 and scaled[-1, -1] == 0
    np.testing.assert_allclose(scaled[:-1, :-1] * unit, metric.matrix(), atol=unit)
    # the triangle inequality holds through the depot
    assert 2 * int(scaled[-1, 0]) >= scaled[:-1, :-1].max()


@pytest.mark.parametrize('count', [1, 2, 3, 5, 200])
def test_every_ordering_visits_each_dot_exactly_once(count):
    metric, cells = canvas_metric(count, 7)
    for method in ORDERINGS:
        order = order_dots(metric, method, cells)
        assert sorted(order.tolist()) == list(range(count))


def test_two_opt_never_lengthens_a_path():
    metric, _ = canvas_metric(150, 8)
    matrix = metric.matrix()
    start = np.random.default_rng(0).permutation(150)
    improved = two_opt(start, matrix)
    assert sorted(improved.tolist()) == list(range(150))
    assert metric.path_time(improved) < 0.5 * metric.path_time(start)


@pytest.fixture(scope='module')
def sample_tours():
    tours = {}
    for name in SAMPLE_NAMES:
        options = PlanOptions(ordering='paper')
        plan = plan_picture(f'sample:{name}', options)
        reach = check_reach(plan.dots, default_rig()[0], options.nominal_sun_ray(), options.d_lp,
                            options.retreat)
        metric = TravelMetric(reach.joints_retreat, LIMITS, plan.dots)
        times = {method: metric.path_time(order_dots(metric, method, plan.grid_uv))
                 for method in ORDERINGS}
        long_budget = fast_tsp_order(metric.matrix(), 2.0, stop_when_converged=False)
        times['fast_tsp_long'] = metric.path_time(long_budget)
        tours[name] = times
    return tours


@pytest.mark.parametrize('name', SAMPLE_NAMES)
def test_nearest_2opt_travels_at_most_085_of_the_paper_order(sample_tours, name):
    times = sample_tours[name]
    assert times['nearest_2opt'] <= 0.85 * times['paper']


@pytest.mark.parametrize('name', SAMPLE_NAMES)
def test_default_ordering_is_within_3_percent_of_the_best_tour_found(sample_tours, name):
    times = sample_tours[name]
    assert times[PlanOptions().ordering] <= 1.03 * min(times.values())


@pytest.mark.parametrize('method', ['nearest', 'nearest_2opt', 'fast_tsp'])
def test_a_separation_keeps_successive_dots_out_of_each_others_hot_region(method):
    # the sample word at a 3 mm pitch: every dot has neighbours 3-4.2 mm away, so the
    # shortest tour steps to a hot neighbour almost every time
    options = PlanOptions(ordering='paper', dot_radius=0.003)
    plan = plan_picture('sample:text', options)
    reach = check_reach(plan.dots, default_rig()[0], options.nominal_sun_ray(), options.d_lp,
                        options.retreat)
    plain = TravelMetric(reach.joints_retreat, LIMITS, plan.dots)
    apart = TravelMetric(reach.joints_retreat, LIMITS, plan.dots, separation=0.0065,
                         separation_penalty=3.1)
    near_order = order_dots(plain, method, plan.grid_uv)
    apart_order = order_dots(apart, method, plan.grid_uv)
    assert sorted(apart_order.tolist()) == list(range(len(plan.dots)))
    assert apart.close_steps(near_order) > 0.8 * (len(plan.dots) - 1)
    steps = np.diff(plan.dots[apart_order], axis=0)
    close = int(np.sum(np.hypot(steps[:, 0], steps[:, 1]) < 0.0065))
    assert close == apart.close_steps(apart_order)
    # the greedy walk may corner itself among the last dots; the improved tours do not
    assert close <= (3 if method == 'nearest' else 0)
    # the arm's time is what the matrix of the plain metric says; jumping costs under a
    # second per dot, where a hot neighbour would wait the cooling (3.1 s)
    extra = apart.path_time(apart_order) - plain.path_time(near_order)
    assert 0.0 < extra < 1.0 * len(plan.dots)


def test_a_separation_needs_points_and_is_not_negative():
    joints = np.zeros((3, 5))
    with pytest.raises(ValueError, match='needs their points'):
        TravelMetric(joints, LIMITS, separation=0.005, separation_penalty=3.0)
    with pytest.raises(ValueError, match='>= 0'):
        TravelMetric(joints, LIMITS, np.zeros((3, 2)), separation=-0.001)
