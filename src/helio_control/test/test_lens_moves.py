"""Focus moves: the focus never travels across the panel at heating distance."""

import math

from helio_control.lens_moves import (
    focus_point, MovePlanningError, plan_focus_moves, safe_to_travel_at)
from helio_optics.focus_targeting import FocusTargeting
from helio_optics.geometry import direction_from_angles
from helio_optics.lens import LensParameters
from helio_optics.rig_kinematics import Rig
import numpy as np
import pytest

SUN = -direction_from_angles(math.radians(46.0), math.radians(275.0))   # elevation 44 deg
HEAT, TRAVEL = 0.082, 0.112
TRAVELS = (TRAVEL, HEAT + 0.015, HEAT - 0.015)


@pytest.fixture(scope='module')
def targeting():
    return FocusTargeting(Rig(), LensParameters(aperture_diameter=0.038), rays=500)


def pose_at(targeting, point, d_lp):
    rig = targeting.rig
    return targeting.aim(point, SUN, d_lp, rig.parameters.T_robot_world).lens.x


def test_focus_point_is_where_the_ray_through_the_lens_centre_meets_the_panel(targeting):
    rig = targeting.rig
    x = pose_at(targeting, (0.06, 0.07), HEAT)
    point, distance = focus_point(rig, x, SUN, rig.parameters.T_robot_world)
    centre = rig.forward(x).T_robot_lens[:3, 3]
    T = rig.parameters.T_robot_world
    # independent: the lens centre's height over the panel along the ray's slope
    height = (centre - T[:3, 3]) @ T[:3, 2]
    assert distance == pytest.approx(height / -SUN[2], rel=1e-12)
    assert distance == pytest.approx(HEAT, abs=2e-4)        # the aim correction is small
    assert np.hypot(*(point[:2] - (0.06, 0.07))) < 2e-4


def test_from_a_heated_dot_to_the_next_the_lens_retreats_travels_and_approaches(targeting):
    rig = targeting.rig
    T = rig.parameters.T_robot_world
    x_now = pose_at(targeting, (0.06, 0.06), HEAT)
    legs = plan_focus_moves(targeting, x_now, (0.08, 0.07), HEAT, SUN, T, HEAT, TRAVELS)
    assert [leg.name for leg in legs] == ['retreat', 'travel', 'approach']
    # where each leg ends: up over the old dot, at travel distance over the new, then down
    ends = [focus_point(rig, leg.x, SUN, T) for leg in legs]
    assert np.hypot(*(ends[0][0][:2] - (0.06, 0.06))) < 3e-4 and ends[0][1] > TRAVEL - 5e-4
    assert np.hypot(*(ends[1][0][:2] - (0.08, 0.07))) < 3e-4 and ends[1][1] > TRAVEL - 5e-4
    assert ends[2][1] == pytest.approx(HEAT, abs=3e-4)
    # along the travel leg (joint-space interpolation, as MOVJ moves) the lens stays at
    # least 2.5 cm farther than the heating distance from the panel
    for fraction in np.linspace(0.0, 1.0, 21):
        x = (1 - fraction) * legs[0].x + fraction * legs[1].x
        assert focus_point(rig, x, SUN, T)[1] > HEAT + 0.025


def test_retreating_on_the_same_dot_is_one_move_along_the_ray(targeting):
    T = targeting.rig.parameters.T_robot_world
    x_now = pose_at(targeting, (0.06, 0.06), HEAT)
    legs = plan_focus_moves(targeting, x_now, (0.06, 0.06), TRAVEL, SUN, T, HEAT, TRAVELS)
    assert [leg.name for leg in legs] == ['direct']


def test_an_unreachable_goal_names_the_leg_and_the_joint(targeting):
    T = targeting.rig.parameters.T_robot_world
    x_now = pose_at(targeting, (0.06, 0.06), TRAVEL)
    with pytest.raises(MovePlanningError, match=r'the goal at d_lp 8.2 cm is unreachable: .*'
                                                r'(j\d|reach)'):
        plan_focus_moves(targeting, x_now, (0.6, 0.6), HEAT, SUN, T, HEAT, TRAVELS)


def test_where_the_paper_retreat_is_out_of_reach_a_nearer_safe_distance_is_taken(targeting):
    rig = targeting.rig
    T = rig.parameters.T_robot_world
    x_now = pose_at(targeting, (0.06, 0.06), HEAT)
    # a travel distance of 30 cm is out of the arm's reach: the next safe one is taken
    legs = plan_focus_moves(targeting, x_now, (0.08, 0.07), HEAT, SUN, T, HEAT,
                            (0.30, HEAT + 0.015))
    assert [leg.name for leg in legs] == ['retreat', 'travel', 'approach']
    assert legs[0].d_lp == legs[1].d_lp == pytest.approx(HEAT + 0.015)
    assert focus_point(rig, legs[1].x, SUN, T)[1] == pytest.approx(HEAT + 0.015, abs=1e-6)
    # and a travel distance too near the heating distance is not taken at all
    with pytest.raises(MovePlanningError, match='no travel distance'):
        plan_focus_moves(targeting, x_now, (0.08, 0.07), HEAT, SUN, T, HEAT, (HEAT + 0.005,))


def test_the_focus_may_travel_at_the_safe_margin_or_beyond_on_either_side():
    heating, margin = 0.082, 0.015
    # exactly the margin away is safe, whatever the last bit of the difference
    assert safe_to_travel_at(heating + margin, heating, margin * (1.0 + 1e-12))
    assert safe_to_travel_at(heating + margin, heating, margin)
    assert safe_to_travel_at(heating - margin, heating, margin)
    assert safe_to_travel_at(0.112, heating, margin)        # the paper's 3 cm
    assert not safe_to_travel_at(heating + 0.0149, heating, margin)
    assert not safe_to_travel_at(heating, heating, margin)
