"""
Solar flux on the panel through the lens (issue 6, item 2; paper Eqs 1-6, 13, 16).

The rays are traced by ``helio_optics.lens.trace`` (the one ray tracer) from the lens pose
the emulated devices reached (``helio_optics.rig_kinematics``) onto the panel plane z = 0 of
the world frame. Sunlight is not one colour: acrylic's index falls from 1.502 at 437 nm to
about 1.482 at 1.5 um, so the focus spreads along the axis by a few millimetres (DESIGN.md).
The world's lens is traced in spectral bands (Cauchy fit n(l) = A + B / l^2 of PMMA, band
weights of the direct solar spectrum), every band through the same facets (cut for the
design index), each carrying its share of the power. Rays are sampled uniformly over the
aperture and the sun's disk (``lens.area_samples``, seeded), binned into the grid cells of
the wood patch and divided by the cell areas: irradiance [W/m^2] on the panel.

The light that misses the lens lands on the panel directly: DNI cos(incidence) everywhere
except in the lens shadow (the aperture projected along the sun ray). The map is kept per
unit DNI and re-traced only when the lens or the sun moved noticeably; a cloud just scales it.
"""

from dataclasses import dataclass, replace
import math

from helio_optics.geometry import invert_transform
from helio_optics.lens import area_samples, LensParameters, pmma_index, SOLAR_BANDS, trace
import numpy as np

# The world's lens is acrylic in sunlight: the optics core's PMMA index (Cauchy fit) and the
# direct solar spectrum's bands, so the world and the controller's focus model are one model.
DEFAULT_BANDS = SOLAR_BANDS


@dataclass
class FluxField:
    """Concentrated rays on the panel and the lens shadow, per unit DNI."""

    points: np.ndarray        # (N, 2) hit points (x, y) in world [m]
    power: np.ndarray         # (N,) power per unit DNI [W / (W/m^2)] = [m^2]
    direct: float             # cos(incidence) of the direct sun on the panel [-]
    lens_centre: np.ndarray   # O_l in world [m]
    lens_axis: np.ndarray     # lens +z in world (unit)
    aperture_radius: float    # [m]
    sun_ray: np.ndarray       # s0 in world (unit)
    tir_fraction: float       # share of the traced power lost to total internal reflection

    def centroid(self):
        """Return the power-weighted centre of the concentrated spot (x, y) [m], or None."""
        if not hasattr(self, '_centroid'):
            total = float(self.power.sum())
            self._centroid = (None if total <= 0.0 else
                              (self.points * self.power[:, None]).sum(axis=0) / total)
        return self._centroid

    def total_power(self):
        """Concentrated power on the panel per unit DNI [m^2]."""
        return float(self.power.sum())

    def in_shadow(self, x, y):
        """Tell which panel points (x, y) lie in the lens shadow (sunward ray meets the lens)."""
        points = np.stack(np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float),
                                              0.0), axis=-1)
        towards_sun = -self.sun_ray
        denominator = towards_sun @ self.lens_axis
        if abs(denominator) < 1e-9:
            return np.zeros(points.shape[:-1], bool)
        distance = ((self.lens_centre - points) @ self.lens_axis) / denominator
        on_plane = points + distance[..., None] * towards_sun
        radial = np.linalg.norm(on_plane - self.lens_centre, axis=-1)
        return (distance > 0.0) & (radial <= self.aperture_radius)


class LensFlux:
    """Traces the world's (true) lens and makes irradiance maps on the wood patch."""

    def __init__(self, lens=None, rays=30000, seed=0, bands=DEFAULT_BANDS,
                 move_tolerance=2e-5, angle_tolerance=5e-4, beam_spread=0.0):
        """
        Trace `rays` samples of `lens` (LensParameters, design index) in spectral `bands`.

        `beam_spread` [rad] is the standard deviation of a Gaussian angular error added to
        every ray (per axis): the facet slope and profile errors of a real moulded lens,
        convolved with the sun's disk as solar ray tracers do. The map is re-traced when
        the lens moved more than `move_tolerance` [m] or the lens axis or sun ray turned
        more than `angle_tolerance` [rad].
        """
        self.lens = lens or LensParameters()
        if rays < 100:
            raise ValueError(f'rays must be >= 100, got {rays}')
        weights = np.array([w for _, w in bands], dtype=float)
        if np.any(weights < 0.0) or weights.sum() <= 0.0:
            raise ValueError('spectral band weights must be >= 0 with a positive sum')
        weights /= weights.sum()
        if not beam_spread >= 0.0:
            raise ValueError(f'beam_spread must be >= 0 rad, got {beam_spread}')
        design = area_samples(self.lens, rays, seed)
        if beam_spread > 0.0:
            errors = np.random.default_rng(seed + 1).normal(0.0, beam_spread, (2, rays))
            design = replace(design, disk_u=design.disk_u + errors[0],
                             disk_v=design.disk_v + errors[1])
        self._bands = []
        sphere_radius = self.lens.sphere_radius
        for (wavelength, _), weight in zip(bands, weights):
            index = pmma_index(wavelength) + (self.lens.refractive_index - pmma_index(0.5876))
            band_lens = replace(self.lens, refractive_index=index,
                                focal_length=sphere_radius / (index - 1.0))
            # The facets are cut once, for the design index: keep their slopes.
            samples = replace(design, lens=band_lens)
            self._bands.append((band_lens, samples, float(weight)))
        self.move_tolerance = move_tolerance
        self.angle_tolerance = angle_tolerance
        self._field = None
        self._key = None
        self.traces = 0

    def field(self, T_world_lens, sun_ray_world):
        """Return the FluxField for a lens pose and sun ray (world), re-traced only if moved."""
        T = np.asarray(T_world_lens, dtype=float)
        s0 = np.asarray(sun_ray_world, dtype=float)
        s0 = s0 / np.linalg.norm(s0)
        if self._key is not None:
            T_old, s_old = self._key
            moved = np.linalg.norm(T[:3, 3] - T_old[:3, 3])
            turned = math.acos(np.clip(T[:3, 2] @ T_old[:3, 2], -1.0, 1.0))
            sun_turned = math.acos(np.clip(s0 @ s_old, -1.0, 1.0))
            if (moved <= self.move_tolerance and turned <= self.angle_tolerance
                    and sun_turned <= self.angle_tolerance):
                return self._field
        self._field = self._trace(T, s0)
        self._key = (T.copy(), s0.copy())
        self.traces += 1
        return self._field

    def _trace(self, T_world_lens, s0):
        points, powers, lost, incident = [], [], 0.0, 0.0
        for band_lens, samples, weight in self._bands:
            result = trace(band_lens, samples, s0, T_world_lens, irradiance=1.0)
            hit = result.hit
            points.append(result.points[hit, :2])
            powers.append(weight * result.power[hit])
            incident += weight * result.incident_power
            lost += weight * (result.incident_power * band_lens.transmission
                              - float(result.power[result.hit].sum()))
        lens_axis = T_world_lens[:3, 2]
        return FluxField(points=np.concatenate(points), power=np.concatenate(powers),
                         direct=max(0.0, -float(s0[2])), lens_centre=T_world_lens[:3, 3].copy(),
                         lens_axis=lens_axis.copy(), aperture_radius=self.lens.aperture_radius,
                         sun_ray=s0.copy(),
                         tir_fraction=lost / incident if incident > 0.0 else 0.0)


def irradiance_on_cells(field, x_edges, y_edges, dni, shadow_samples=3):
    """
    Irradiance [W/m^2] on the cells of a grid (y, x) for direct normal irradiance `dni`.

    Concentrated rays are binned by cell; the direct sun covers the rest of each cell outside
    the lens shadow (shadow fraction from `shadow_samples`^2 points per cell).
    """
    x_edges, y_edges = np.asarray(x_edges, float), np.asarray(y_edges, float)
    areas = np.outer(np.diff(y_edges), np.diff(x_edges))
    binned, _, _ = np.histogram2d(field.points[:, 1], field.points[:, 0],
                                  bins=(y_edges, x_edges), weights=field.power)
    fractions = (np.arange(shadow_samples) + 0.5) / shadow_samples
    xs = x_edges[:-1, None] + fractions[None] * np.diff(x_edges)[:, None]   # (nx, s)
    ys = y_edges[:-1, None] + fractions[None] * np.diff(y_edges)[:, None]   # (ny, s)
    shadow = field.in_shadow(xs[None, :, None, :], ys[:, None, :, None]).mean(axis=(2, 3))
    return dni * (binned / areas + field.direct * (1.0 - shadow))


def lens_pose_in_world(T_robot_world, T_robot_lens):
    """Return T_world_lens from the rig's T_robot_world and T_robot_lens."""
    return invert_transform(T_robot_world) @ T_robot_lens
