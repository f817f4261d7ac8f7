"""
The simulated world against the paper's figures (issue 6, item 4; paper Sec. IV-B, V-A).

Two experiments, as the paper ran them on the rig, using the world's TRUE sun to aim (the
experiments calibrate the world, not the controller):

- ``focal_sweep``: lens aligned with the sun, focused on a target at d_lp from 6.4 to 9.8 cm
  in 1 mm steps; the spot area is the region the RGB camera sees saturated (irradiance above
  ``bright_ratio`` times the direct sun), measured on the panel (Fig. 10c: minimum at 8.2 cm).
- ``char_experiment``: hold d_lp (8.2 cm) and read the thermal camera at 8.7 Hz; when N_p
  (pixels at the read-out cap, Sec. IV-B) reaches 30, retreat by 3 cm, then wait until N_p is
  back to 0 (Algorithm 1). Reports the time to N_p = 30 (paper: about 20 s), the charred dot's
  diameter (paper: about 2 mm) and how long T_max stays at the cap after the retreat (paper:
  about 3 s).
"""

from dataclasses import dataclass

import cv2
from helio_drivers.sim_flux import lens_pose_in_world
from helio_optics.geometry import transform_points
from helio_perception.thermal import ThermalAnalyzer, ThermalConfig
import numpy as np


@dataclass
class CharFigures:
    """Result of one char experiment (times in simulated seconds)."""

    d_lp: float                   # lens-to-target distance held [m]
    time_to_np: float             # from the start of heating to N_p >= threshold [s] (nan: never)
    dot_diameter_at_np: float     # equivalent diameter of the char when N_p was reached [m]
    cap_hold_after_retreat: float  # T_max stayed at the cap this long after the retreat [s]
    time_to_np_zero: float        # from the retreat to N_p = 0 [s]
    final_dot_diameter: float     # after cooling [m]
    peak_surface_temperature: float  # hottest true surface temperature seen [degC]


def aim(world, target_world, d_lp):
    """Joints that focus the world's TRUE sun on `target_world` at `d_lp` (Eqs 14-15)."""
    s0_robot = world.sun.ray_robot(world.clock.datetime())
    target = transform_points(world.T_robot_world, np.asarray(target_world, float))
    lens = world.rig.lens_pose_for_target(target, s0_robot, d_lp)
    if lens.x is None:
        raise ValueError(f'target {target_world} at d_lp {d_lp} m is unreachable: {lens.reason}')
    return lens.x


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
        pose = world.rig.forward(aim(world, target_world, d_lp))
        field = world.flux.field(lens_pose_in_world(world.T_robot_world, pose.T_robot_lens),
                                 s0_world)
        areas.append(spot_area(field))
    return np.asarray(distances, float), np.asarray(areas)


def char_experiment(world, target_world=(0.07, 0.07, 0.0), d_lp=0.082, retreat=0.03,
                    np_threshold=30, timeout=60.0, thermal_rate=8.7):
    """Heat one dot as Algorithm 1 does and return its CharFigures (see the module docstring)."""
    cap = world.settings.thermal.cap
    thermal = ThermalAnalyzer(ThermalConfig(threshold=cap, camera_cap=cap))  # T_p = cap
    world.set_joints(aim(world, target_world, d_lp))
    start = world.time
    next_frame = start
    retreat_time = np.nan
    figures = CharFigures(d_lp, np.nan, np.nan, np.nan, np.nan, np.nan, -np.inf)
    while world.time - start < timeout:
        world.step()
        figures.peak_surface_temperature = max(figures.peak_surface_temperature,
                                               float(world.panel.surface_temperature().max()))
        if world.time + 1e-9 < next_frame:
            continue
        next_frame += 1.0 / thermal_rate
        read_out = world.thermal_temperatures(noise=False).astype(np.float32)
        stats = thermal.statistics(read_out, '32FC1')
        n_p = stats.n_p
        if np.isnan(retreat_time):
            if n_p >= np_threshold:
                figures.time_to_np = world.time - start
                figures.dot_diameter_at_np = _largest_dot(world)
                world.set_joints(aim(world, target_world, d_lp + retreat))
                retreat_time = world.time
            continue
        if np.isnan(figures.cap_hold_after_retreat) and not stats.saturated:
            figures.cap_hold_after_retreat = world.time - retreat_time
        if n_p == 0:
            figures.time_to_np_zero = world.time - retreat_time
            break
    figures.final_dot_diameter = _largest_dot(world)
    return figures


def _largest_dot(world):
    dots = world.charred_dots()
    return max((dot.diameter for dot in dots), default=0.0)
