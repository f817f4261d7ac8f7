"""Dobot Magician arm kinematics: closed-form poses, FK(IK) round trips, reasons."""

import math

from helio_optics.arm_kinematics import DobotArm, DobotArmParameters, UnreachableError
import numpy as np
import pytest


def test_known_pose_from_the_link_lengths():
    # j2 = 0 (rear arm vertical), j3 = 0 (forearm horizontal): the flange is at
    # reach L2 + tool_x and height L1, straight ahead.
    arm = DobotArm()
    p = arm.parameters
    np.testing.assert_allclose(arm.forward([0.0, 0.0, 0.0]),
                               [p.forearm + p.tool_x, 0.0, p.rear_arm], atol=1e-15)
    # Base turned by 90 deg: the same reach along +y.
    np.testing.assert_allclose(arm.forward([math.pi / 2, 0.0, 0.0]),
                               [0.0, p.forearm + p.tool_x, p.rear_arm], atol=1e-15)


def test_forward_of_inverse_over_the_workspace():
    arm = DobotArm()
    lim = arm.parameters.limits()
    count = 0
    for j1 in np.linspace(lim[0].lower, lim[0].upper, 7):
        for j2 in np.linspace(lim[1].lower, lim[1].upper, 9):
            for j3 in np.linspace(lim[2].lower, lim[2].upper, 9):
                position = arm.forward([j1, j2, j3])
                try:
                    joints = arm.inverse(position)
                except UnreachableError:
                    continue  # the elbow-down twin of an elbow-up pose; checked below
                np.testing.assert_allclose(arm.forward(joints), position, atol=1e-9)
                count += 1
    assert count > 300


def test_out_of_reach_says_by_how_much():
    arm = DobotArm(DobotArmParameters())
    with pytest.raises(UnreachableError) as error:
        arm.inverse([0.5, 0.0, 0.1])
    assert error.value.joint == 'reach'
    expected = math.hypot(0.5 - arm.parameters.tool_x, 0.1) - 0.135 - 0.147
    assert error.value.excess == pytest.approx(expected)
    assert 'mm' in str(error.value)


def test_joint_limit_violation_names_the_joint():
    arm = DobotArm()
    with pytest.raises(UnreachableError) as error:
        arm.inverse([-0.05, -0.2, 0.05])   # behind the base: j1 beyond -90 deg
    assert error.value.joint == 'j1 (base)'
    assert error.value.excess > 0.0


@pytest.mark.parametrize('bad', [math.nan, math.inf, -math.inf])
def test_non_finite_targets_and_joints_are_refused_with_the_reason(bad):
    arm = DobotArm()
    with pytest.raises(ValueError, match='not a finite position'):
        arm.inverse([0.2, bad, 0.05])
    # a NaN compares false with both limits: without the check it passed for inside them
    with pytest.raises(ValueError, match=r'j2 .* not a finite angle'):
        arm.check_limits([0.0, bad, 0.3])
