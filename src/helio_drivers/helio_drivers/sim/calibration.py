"""
The simulated world's focal sweep, as the paper ran it on the rig (Sec. V-A, Fig. 10c).

``focal_sweep``: the lens aligned with the world's TRUE sun (the experiment calibrates the
world, not the controller), focused on a target at d_lp from 6.4 to 9.8 cm in 1 mm steps;
the spot area is the region the RGB camera sees saturated (irradiance above ``bright_ratio``
times the direct sun), measured on the panel (paper: minimum at 8.2 cm). The char experiment
(Algorithm 1 on one dot, Fig. 8) needs the thermal statistics and the painting cycle, so it
lives with the cross-package tests (``test/test_sim_calibration.py``).
"""

import cv2
from helio_drivers.sim.flux import lens_pose_in_world
from helio_drivers.sim.truth import true_sun_focus_joints
import numpy as np


def spot_area(field, pixel=5e-5, half_cells=200, bright_ratio=3.0):
    """Area [m^2] of the panel region lit above `bright_ratio` x the direct sun."""
    centre = field.centroid()
    if centre is None:
        return 0.0
    offsets = np.arange(-half_cells, half_cells + 1) * pixel
    binned, _, _ = np.histogram2d(field.points[:, 1], field.points[:, 0],
                                  bins=(centre[1] + offsets, centre[0] + offsets),
                                  weights=field.power)
    relative = binned / (pixel * pixel) / max(field.direct, 1e-9)
    relative = cv2.GaussianBlur(relative.astype(np.float32), (0, 0), 2.0)
    return float(np.count_nonzero(relative >= bright_ratio)) * pixel * pixel


def focal_sweep(world, target_world=(0.07, 0.07, 0.0), distances=None):
    """Return (d_lp [m], spot area [m^2]) over the paper's sweep 6.4..9.8 cm by 1 mm."""
    if distances is None:
        distances = np.round(np.arange(0.064, 0.0981, 0.001), 4)
    s0_world = world.sun.ray_world(world.clock.datetime())
    areas = []
    for d_lp in distances:
        pose = world.rig.forward(true_sun_focus_joints(world, target_world, d_lp))
        field = world.flux.field(lens_pose_in_world(world.T_robot_world, pose.T_robot_lens),
                                 s0_world)
        areas.append(spot_area(field))
    return np.asarray(distances, float), np.asarray(areas)
