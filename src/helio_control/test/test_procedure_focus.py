"""
The focus procedure in-process against a model rig (``fake_lens_rig``): where the spot lands.

The truth is the model rig's: its sun and lens cast the spot (``SpotModel``) from the joints
the procedure moved to; the procedure plans with the same rig and a known sun estimate.
"""

from fake_lens_rig import FakeLensRig, run, sun_at
from geometry_msgs.msg import PointStamped
from helio_control.procedures import focus
from helio_control.procedures.lens_rig_port import GoalCanceled, GoalFailed
from helio_msgs.action import FocusLens
import numpy as np
import pytest

SUN = sun_at(50.0, 230.0)   # the retreat distance (11.2 cm) in reach over the targets
# the paper's distances (Sec. IV-B), independent of the code: heat at 8.2 cm, retreat 3 cm
PAPER_HEATING, PAPER_RETREAT = 0.082, 0.082 + 0.03


def goal(x, y, z=0.0, d_lp=0.0, travel=0.0, frame='world', distance=0, travel_offset=0.0):
    target = PointStamped()
    target.header.frame_id = frame
    target.point.x, target.point.y, target.point.z = x, y, z
    return FocusLens.Goal(target=target, d_lp=d_lp, travel_d_lp=travel, distance=distance,
                          travel_offset=travel_offset)


def distance_along_ray(rig, x, sun, T_robot_world):
    """Return the lens centre's distance from the panel along the sun ray [m]."""
    centre = rig.forward(x).T_robot_lens[:3, 3]
    normal, point = T_robot_world[:3, 2], T_robot_world[:3, 3]
    return float((centre - point) @ normal / -(sun @ normal))


@pytest.fixture
def rig():
    return FakeLensRig(SUN, believed_sun=SUN, world_calibrated=True)


def test_the_spot_lands_on_the_target_and_the_lens_travels_retreated(rig):
    result = FocusLens.Result()
    run(focus.focus(rig, goal(0.06, 0.04), result))
    # the model's spot within 0.3 mm of the target (the contour's centre; the procedure
    # aims the power centre)
    assert np.linalg.norm(rig.true_spot_centre()[:2] - [0.06, 0.04]) < 3e-4
    T = rig.T_true_robot_world
    assert distance_along_ray(rig.true_rig, rig.x, SUN, T) == pytest.approx(0.082, abs=1e-3)
    # every leg before the last ends a safe margin or more from the heating distance
    for x in rig.moves[:-1]:
        assert abs(distance_along_ray(rig.true_rig, x, SUN, T) - 0.082) >= 0.015 - 1e-4
    assert len(rig.moves) >= 2
    assert rig.placed_at == (True, False)
    assert result.position_error < 1e-9
    assert result.message.startswith('focused on (6.00, 4.00) cm at d_lp 8.20 cm in ')
    assert result.achieved.joints == pytest.approx(list(rig.x))
    assert rig.feedbacks and rig.feedbacks[0].distance_remaining > 0.0


def test_a_second_point_moves_on_at_the_retreat_distance(rig):
    run(focus.focus(rig, goal(0.06, 0.04), FocusLens.Result()))
    first = len(rig.moves)
    run(focus.focus(rig, goal(0.09, 0.07), FocusLens.Result()))
    assert np.linalg.norm(rig.true_spot_centre()[:2] - [0.09, 0.07]) < 3e-4
    T = rig.T_true_robot_world
    travel = [distance_along_ray(rig.true_rig, x, SUN, T) for x in rig.moves[first:-1]]
    assert travel and travel[0] == pytest.approx(PAPER_RETREAT, abs=1e-3)
    assert min(travel) >= 0.082 + 0.015 - 1e-4


def test_a_focus_at_the_retreat_distance_leaves_the_lens_not_heating(rig):
    run(focus.focus(rig, goal(0.06, 0.04, d_lp=0.112), FocusLens.Result()))
    assert rig.placed_at == (False, False)


@pytest.mark.parametrize('distance, d_lp, heating', [
    (FocusLens.Goal.HEATING, 0.0, True), (FocusLens.Goal.RETREAT, 0.0, False),
    (FocusLens.Goal.HEATING, 0.2, True),            # a named distance: d_lp is not read
    (FocusLens.Goal.AT_D_LP, 0.0, True)])           # d_lp 0: the heating distance
def test_a_goal_names_the_heating_or_the_retreat_distance(rig, distance, d_lp, heating):
    run(focus.focus(rig, goal(0.06, 0.04, distance=distance, d_lp=d_lp), FocusLens.Result()))
    reached = distance_along_ray(rig.true_rig, rig.x, SUN, rig.T_true_robot_world)
    assert reached == pytest.approx(PAPER_HEATING if heating else PAPER_RETREAT, abs=1e-3)
    assert rig.placed_at == (heating, False)


def test_the_named_distances_follow_the_focal_calibration(rig):
    # a focal calibration 3 mm beyond the paper's focus: the heating distance, the retreat
    # distance and the travel between points all move with it
    rig.use_focus(PAPER_HEATING + 0.003, 1e-6, 0.01, 21)
    run(focus.focus(rig, goal(0.06, 0.04, distance=FocusLens.Goal.HEATING),
                    FocusLens.Result()))
    T = rig.T_true_robot_world
    assert distance_along_ray(rig.true_rig, rig.x, SUN, T) == pytest.approx(0.085, abs=1e-3)
    first = len(rig.moves)
    run(focus.focus(rig, goal(0.09, 0.07, distance=FocusLens.Goal.HEATING),
                    FocusLens.Result()))
    assert distance_along_ray(rig.true_rig, rig.moves[first], SUN, T) == pytest.approx(
        0.115, abs=1e-3)                           # retreated 3 cm beyond the new focus
    run(focus.focus(rig, goal(0.09, 0.07, distance=FocusLens.Goal.RETREAT),
                    FocusLens.Result()))
    assert distance_along_ray(rig.true_rig, rig.x, SUN, T) == pytest.approx(0.115, abs=1e-3)


def test_a_travel_offset_moves_the_focus_that_far_beyond_the_heating_distance(rig):
    run(focus.focus(rig, goal(0.06, 0.04), FocusLens.Result()))
    first = len(rig.moves)
    run(focus.focus(rig, goal(0.09, 0.07, distance=FocusLens.Goal.HEATING,
                              travel_offset=0.015), FocusLens.Result()))
    T = rig.T_true_robot_world
    travel = [distance_along_ray(rig.true_rig, x, SUN, T) for x in rig.moves[first:-1]]
    assert travel and travel[0] == pytest.approx(PAPER_HEATING + 0.015, abs=1e-3)


@pytest.mark.parametrize('bad, words', [
    (goal(0.06, 0.04, frame='robot'), "target frame 'robot'"),
    (goal(float('nan'), 0.04), 'is not finite'),
    (goal(0.06, 0.04, z=0.01), 'off the panel'),
    (goal(0.06, 0.04, d_lp=-0.01), 'd_lp must be a finite distance'),
    (goal(0.06, 0.04, travel=0.09), 'safe_margin'),
    (goal(0.06, 0.04, travel_offset=0.008), 'travel_offset 0.008 m: .*safe_margin'),
    (goal(0.06, 0.04, distance=3), 'distance 3: give AT_D_LP'),
])
def test_a_bad_goal_fails_before_any_move(rig, bad, words):
    with pytest.raises(GoalFailed, match=words):
        run(focus.focus(rig, bad, FocusLens.Result()))
    assert rig.moves == []


def test_without_a_sun_estimate_the_goal_fails_and_nothing_moves():
    rig = FakeLensRig(SUN, world_calibrated=True)
    with pytest.raises(GoalFailed, match='no sun estimate'):
        run(focus.focus(rig, goal(0.06, 0.04), FocusLens.Result()))
    assert rig.moves == []


def test_a_cancel_ends_the_focus_and_the_lens_is_not_said_placed():
    rig = FakeLensRig(SUN, believed_sun=SUN, world_calibrated=True, cancel_after=1)
    with pytest.raises(GoalCanceled):
        run(focus.focus(rig, goal(0.06, 0.04), FocusLens.Result()))
    assert len(rig.moves) == 1 and rig.placed_at is None


def test_the_retreat_lifts_the_focus_along_the_ray_to_the_retreat_distance(rig):
    run(focus.focus(rig, goal(0.06, 0.04), FocusLens.Result()))
    run(focus.retreat(rig))
    T = rig.T_true_robot_world
    assert distance_along_ray(rig.true_rig, rig.x, SUN, T) == pytest.approx(0.112, abs=1e-3)
    # over the same point: the axis still meets the panel at the target
    here = rig.true_rig.forward(rig.x).T_robot_lens
    axis_hit = here[:3, 3] + SUN * distance_along_ray(rig.true_rig, rig.x, SUN, T)
    world = np.linalg.inv(T) @ np.append(axis_hit, 1.0)
    assert np.linalg.norm(world[:2] - [0.06, 0.04]) < 2e-3
