"""Eq 17 scaling by hand, canvas bounds, dot spacing, rejected dots with reasons."""

import math

from helio_control.dot_layout import DotGrid, min_spacing, too_close
from helio_control.plan import plan_dots, plan_picture, PlanOptions
from helio_control.samples import SAMPLE_NAMES
import numpy as np
import pytest


def binary_blocks(width, height, block, cells):
    """White picture with black block x block squares at the given (u, v) cells."""
    picture = np.full((height, width), 255, np.uint8)
    for u, v in cells:
        picture[v * block:(v + 1) * block, u * block:(u + 1) * block] = 0
    return picture


def eq17_options(**changes):
    values = {'canvas_size': 0.04, 'dot_radius': 0.002, 'offset_x': 0.05, 'offset_y': 0.05,
              'feature_mode': 'threshold', 'ordering': 'paper'}
    values.update(changes)
    return PlanOptions(**values)


def test_eq17_scaling_factor_by_hand():
    # 80 x 40 px picture on a 4 cm canvas of 2 mm dots: omega_s = 0.04 / (80 * 0.002) = 0.25,
    # so the feature image is 20 x 10 and each dot stands for 4 x 4 picture pixels.
    grid = DotGrid(80, 40, 0.04, 0.002, 0.05, 0.05, 'paper')
    assert grid.omega_s == pytest.approx(0.25)
    assert grid.shape == (10, 20)


@pytest.mark.parametrize('v_axis, expected', [
    # by hand: x = u * 0.002 + 0.05; paper y = v * 0.002 + 0.05; flip y = (9 - v) * 0.002 + 0.05
    ('paper', [(0.050, 0.050), (0.056, 0.054), (0.088, 0.068), (0.088, 0.050)]),
    ('flip', [(0.050, 0.068), (0.056, 0.064), (0.088, 0.050), (0.088, 0.068)]),
])
def test_binary_picture_gives_the_hand_computed_eq17_dots(v_axis, expected):
    cells = [(0, 0), (3, 2), (19, 9), (19, 0)]
    picture = binary_blocks(80, 40, 4, cells)
    plan = plan_picture(picture, eq17_options(v_axis=v_axis))
    got = sorted(map(tuple, np.round(plan.dots, 9)))
    assert got == sorted(expected)
    assert plan.parameters['omega_s'] == pytest.approx(0.25)
    assert not plan.rejected


def test_paper_ordering_groups_by_u_then_v():
    cells = [(5, 7), (5, 1), (2, 8), (9, 0), (2, 3)]
    plan = plan_picture(binary_blocks(80, 40, 4, cells), eq17_options())
    assert [tuple(uv) for uv in plan.grid_uv] == [(2, 3), (2, 8), (5, 1), (5, 7), (9, 0)]


@pytest.mark.parametrize('name', SAMPLE_NAMES)
def test_samples_stay_on_the_canvas_and_never_overlap(name):
    options = PlanOptions(feature_mode='auto', ordering='nearest')
    plan = plan_picture(f'sample:{name}', options)
    x0, y0, side = options.offset_x, options.offset_y, options.canvas_size
    assert np.all(plan.dots[:, 0] >= x0) and np.all(plan.dots[:, 0] <= x0 + side)
    assert np.all(plan.dots[:, 1] >= y0) and np.all(plan.dots[:, 1] <= y0 + side)
    assert min_spacing(plan.dots) >= options.dot_radius - 1e-9


def test_explicit_points_outside_or_too_close_are_rejected_with_reasons():
    options = PlanOptions(ordering='paper')
    points = [[0.06, 0.06], [0.061, 0.06], [0.30, 0.06], [0.07, 0.07]]
    plan = plan_dots(points, options)
    assert len(plan) + len(plan.rejected) == len(points)
    reasons = {(r['x_m'], r['y_m']): r['reason'] for r in plan.rejected}
    assert 'outside the canvas' in reasons[(0.30, 0.06)]
    assert 'closer than the dot pitch' in reasons[(0.061, 0.06)]
    assert sorted(map(tuple, plan.dots)) == [(0.06, 0.06), (0.07, 0.07)]


def test_unreachable_dots_are_reported_with_the_rigs_reason():
    # Sun behind the arm (towards -x of the robot): the lens would have to sit inside the
    # arm's reach for part of the canvas.
    elevation, azimuth = math.radians(60.0), math.radians(180.0)
    sun = -np.array([math.cos(elevation) * math.cos(azimuth),
                     math.cos(elevation) * math.sin(azimuth), math.sin(elevation)])
    u, v = np.meshgrid(np.arange(0, 40, 4), np.arange(0, 40, 4))
    points = 0.05 + 0.002 * np.column_stack([u.ravel(), v.ravel()])
    plan = plan_dots(points, PlanOptions(ordering='paper'), sun_ray_robot=sun)
    assert plan.rejected and len(plan) > 0
    assert len(plan) + len(plan.rejected) == len(points)
    assert all(r['reason'].startswith('unreachable') for r in plan.rejected)


def test_too_close_keeps_the_first_of_each_crowded_pair():
    points = np.array([[0.0, 0.0], [0.0015, 0.0], [0.003, 0.0], [0.004, 0.0]])
    assert too_close(points, 0.002) == {1: 0, 3: 2}
