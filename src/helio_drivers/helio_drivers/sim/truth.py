"""
The world's own truth, for tests and experiments that must not depend on the controller.

``true_sun_focus_joints`` aims the lens with the simulated sun's TRUE direction (Eqs 14-15
and the rig's inverse kinematics): what an ideal sun estimate would give. The controller
never uses it: the sun estimator finds the sun from the light spot. Calibration experiments
and the tests of the world itself use it to put the focus where they want it.
"""

from helio_optics.geometry import transform_points
import numpy as np


def true_sun_focus_joints(world, target_world, d_lp):
    """
    Return the joints x that focus the world's TRUE sun on `target_world` at `d_lp` [m].

    `target_world` is (x, y) or (x, y, z) in the world frame. Raise ValueError naming the
    joint (or the reach) when the pose is unreachable.
    """
    target = np.zeros(3)
    values = np.asarray(target_world, dtype=float).ravel()
    target[:values.size] = values
    s0_robot = world.sun.ray_robot(world.clock.datetime())
    lens = world.rig.lens_pose_for_target(transform_points(world.T_robot_world, target),
                                          s0_robot, d_lp)
    if lens.x is None:
        raise ValueError(f'target {values.tolist()} at d_lp {d_lp} m is unreachable: '
                         f'{lens.reason}')
    return lens.x
