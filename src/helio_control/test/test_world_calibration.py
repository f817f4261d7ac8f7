"""Robot-world calibration from marker poses: recovers a known transform from noisy views."""

import math

from helio_control.world_calibration import estimate_world_in_robot
from helio_optics.geometry import homogeneous, invert_transform, rotation_x, rotation_y
from helio_optics.geometry import rotation_z
import numpy as np
import pytest

TRUE_POSITION = np.array([0.151, -0.094, -0.137])
TRUE_YAW = math.radians(3.5)


def views(count, noise_position=0.0, noise_angle=0.0, seed=0):
    """Return (T_robot_rgb, T_world_rgb) of `count` camera poses over a known marker."""
    rng = np.random.default_rng(seed)
    T_robot_world = homogeneous(rotation_z(TRUE_YAW), TRUE_POSITION)
    robot, world = [], []
    for _ in range(count):
        camera = homogeneous(rotation_z(rng.uniform(-3, 3)) @ rotation_y(rng.uniform(2.5, 3.0)),
                             TRUE_POSITION + rng.uniform([-0.05, -0.05, 0.08],
                                                         [0.1, 0.1, 0.2]))
        robot.append(camera)
        seen = invert_transform(T_robot_world) @ camera          # T_world_rgb, exact
        error = homogeneous(rotation_x(rng.normal(0, noise_angle))
                            @ rotation_y(rng.normal(0, noise_angle))
                            @ rotation_z(rng.normal(0, noise_angle)),
                            rng.normal(0, noise_position, 3))
        world.append(seen @ error)
    return robot, world


def test_exact_views_give_the_transform_back():
    estimate = estimate_world_in_robot(*views(5))
    assert estimate.world_in_robot == pytest.approx(TRUE_POSITION, abs=1e-12)
    assert estimate.world_yaw == pytest.approx(TRUE_YAW, abs=1e-12)
    assert estimate.residual_position < 1e-12 and estimate.tilt < 1e-7
    assert estimate.T_robot_world[:3, :3] == pytest.approx(rotation_z(TRUE_YAW), abs=1e-12)


def test_noisy_views_average_to_within_their_noise_and_the_residual_says_how_noisy():
    # camera poses 0.5 mm and 0.2 deg off each: 12 views average it down by sqrt(12)
    estimate = estimate_world_in_robot(*views(12, 0.5e-3, math.radians(0.2), seed=3))
    error = np.linalg.norm(estimate.world_in_robot - TRUE_POSITION)
    assert error < 1.0e-3
    assert abs(math.degrees(estimate.world_yaw - TRUE_YAW)) < 0.2
    # the spread reflects the per-view noise (0.5 mm per axis position, plus the lever arm
    # of the camera's angle error over ~15 cm), not zero
    assert 0.3e-3 < estimate.residual_position < 2e-3


def test_a_wild_marker_pose_is_left_out_and_counted():
    robot, world = views(6)
    world[2] = world[2] @ homogeneous(translation=[0.02, 0.0, 0.0])   # 2 cm off
    estimate = estimate_world_in_robot(robot, world)
    assert estimate.rejected == [2] and estimate.used == 5
    assert estimate.world_in_robot == pytest.approx(TRUE_POSITION, abs=1e-9)


@pytest.mark.parametrize('robot, world, words', [
    ([np.eye(4)] * 2, [np.eye(4)] * 2, 'at least 3 poses'),
    ([np.eye(4)] * 3, [np.eye(4)] * 4, '3 kinematic poses but 4 marker poses'),
    ([np.full((4, 4), np.nan)] * 3, [np.eye(4)] * 3, 'NaN'),
    ([np.diag([2.0, 1.0, 1.0, 1.0])] * 3, [np.eye(4)] * 3, 'not a rotation'),
])
def test_bad_input_is_refused_naming_the_problem(robot, world, words):
    with pytest.raises(ValueError, match=words):
        estimate_world_in_robot(robot, world)


def test_views_that_disagree_everywhere_are_refused_with_the_spread():
    robot, world = views(4, noise_position=0.05, seed=1)
    with pytest.raises(ValueError, match='agree within'):
        estimate_world_in_robot(robot, world)
