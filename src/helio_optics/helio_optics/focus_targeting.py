"""
Put the focus, not only the lens axis, on a target point (paper Eqs 14-15, corrected).

Eq 14 places the lens centre O_l at p_l = p_i - d_lp s0 and Eq 15 turns its axis onto the
sun ray, so the ray through the lens centre hits the target. The concentrated spot is not
centred on that ray: the lens plate shifts the rays that cross it off-axis (a 2 mm plate
tilted to the ground) and the outer zones focus a little aside, so at a low sun the spot's
power centre sits up to a few tenths of a millimetre from the target. ``FocusTargeting``
predicts where the power of the spot lands for a lens pose (the lens model traced with
area-sampled rays in the solar spectrum's bands through acrylic's dispersion, as the wood
sees it) and moves the aim point until the predicted power centre is on the target (a
fixed-point iteration; two or three steps).

API
---
``FocusTargeting(rig, lens, rays=4000, bands=SOLAR_BANDS)``;
``.aim(target_world, sun_robot, d_lp, T_robot_world, preferred_yaw=None) -> FocusSolution``
with ``lens`` (the ``LensTarget`` of Eqs 14-15 for the corrected aim point, joints ``x``),
``predicted_focus`` (where the model says the spot's power centre lands, world frame),
``correction`` (aim point minus target, world frame [m]), ``iterations``;
``.power_centre(x, sun_robot, T_robot_world)``: the model's spot power centre for joints x
(world frame), or None when no ray reaches the panel. Bad input (non-finite numbers, a sun
that does not shine down, d_lp <= 0) raises ValueError naming it; an unreachable pose
returns the LensTarget with ``x`` None and its reason.
"""

from dataclasses import dataclass, replace

from helio_optics.geometry import invert_transform, transform_points, unit
from helio_optics.lens import area_samples, spectral_lenses, trace
import numpy as np


@dataclass
class FocusSolution:
    """A lens pose whose spot's power centre is predicted on the target."""

    lens: object                  # rig_kinematics.LensTarget (x None when unreachable)
    predicted_focus: np.ndarray   # world frame (3,) [m]; NaN when unreachable
    correction: np.ndarray        # aim point - target, world frame (3,) [m]
    iterations: int


def _finite(name, values, size):
    array = np.asarray(values, dtype=float).ravel()
    if array.size != size or not np.all(np.isfinite(array)):
        raise ValueError(f'{name} must be {size} finite numbers, got {values!r}')
    return array


class FocusTargeting:
    """See the module docstring."""

    def __init__(self, rig, lens, rays=4000, bands=None, tolerance=2e-6, max_iterations=6):
        """
        Keep the rig and the lens model; `rays` area samples per spectral band trace the spot.

        `bands` as ``lens.spectral_lenses`` takes them (default: the solar bands); an empty
        tuple traces the design index only.
        """
        self.rig = rig
        self.lens = lens
        design = area_samples(lens, rays, seed=1)
        self.bands = ([(lens, 1.0)] if bands == () else
                      spectral_lenses(lens) if bands is None else spectral_lenses(lens, bands))
        self._traced = [(band, replace(design, lens=band), weight)
                        for band, weight in self.bands]
        self.tolerance = float(tolerance)
        self.max_iterations = int(max_iterations)

    def power_centre(self, x, sun_robot, T_robot_world):
        """Return the world-frame power centre (3,) of the spot for joints x, or None."""
        T_robot_world = np.asarray(T_robot_world, dtype=float)
        pose = self.rig.forward(x)
        moment, total = np.zeros(3), 0.0
        for band, samples, weight in self._traced:
            result = trace(band, samples, sun_robot, pose.T_robot_lens,
                           T_robot_world[:3, 3], T_robot_world[:3, 2])
            power = weight * np.where(result.hit, result.power, 0.0)
            moment += (np.nan_to_num(result.points) * power[:, None]).sum(axis=0)
            total += float(power.sum())
        if total <= 0.0:
            return None
        return transform_points(invert_transform(T_robot_world), moment / total)

    def aim(self, target_world, sun_robot, d_lp, T_robot_world, preferred_yaw=None):
        """Return the FocusSolution for `target_world` (x, y[, z]) at `d_lp` [m]."""
        target = np.zeros(3)
        given = np.asarray(target_world, dtype=float).ravel()
        target[:min(3, given.size)] = given[:3]
        _finite('the target', target, 3)
        sun = unit(_finite('the sun direction', sun_robot, 3))
        if not np.isfinite(d_lp) or d_lp <= 0.0:
            raise ValueError(f'd_lp must be a finite distance > 0 m, got {d_lp!r}')
        T_robot_world = np.asarray(T_robot_world, dtype=float)
        aim_point = target.copy()
        lens = None
        predicted = np.full(3, np.nan)
        iterations = 0
        for iterations in range(1, self.max_iterations + 1):
            lens = self.rig.lens_pose_for_target(transform_points(T_robot_world, aim_point),
                                                 sun, d_lp, preferred_yaw)
            if lens.x is None:
                return FocusSolution(lens, np.full(3, np.nan), aim_point - target, iterations)
            centre = self.power_centre(lens.x, sun, T_robot_world)
            if centre is None:
                lens.reason = 'no ray of the lens model reaches the panel for this pose'
                lens.x = None
                return FocusSolution(lens, np.full(3, np.nan), aim_point - target, iterations)
            predicted = centre
            miss = target[:2] - centre[:2]
            if float(np.hypot(*miss)) <= self.tolerance or iterations == self.max_iterations:
                break
            aim_point[:2] += miss
        return FocusSolution(lens, predicted, aim_point - target, iterations)
