"""
Solar flux on the panel through the lens (issue 6, item 2; paper Eqs 1-6, 13, 16).

The rays are traced by ``helio_optics.lens.trace_bands`` (the one ray tracer's arithmetic,
every spectral band in one pass) from the lens pose the emulated devices reached
(``helio_optics.rig_kinematics``) onto the panel plane z = 0 of the world frame. Sunlight
is not one colour: acrylic's index falls from 1.502 at 437 nm to about 1.482 at 1.5 um, so
the focus spreads along the axis by a few millimetres (DESIGN.md).
The world's lens is traced in spectral bands (Cauchy fit n(l) = A + B / l^2 of PMMA, band
weights of the direct solar spectrum), every band through the same facets (cut for the
design index), each carrying its share of the power. Rays are sampled uniformly over the
aperture and the sun's disk (``lens.area_samples``, seeded), binned into the grid cells of
the wood patch and divided by the cell areas: irradiance [W/m^2] on the panel.

The light that misses the lens lands on the panel directly: DNI cos(incidence) everywhere
except in the lens shadow (the aperture projected along the sun ray). The map is kept per
unit DNI and re-traced only when the lens or the sun turned noticeably (a lens that only moved
carries its traced rays along, exactly); a cloud just scales it.
"""

from dataclasses import dataclass, replace
import math

from helio_drivers.sim.kernels import (bin_points, carried_points, chosen_rays, points_summary,
                                       shadow_grid, shadow_shares)
from helio_optics.geometry import invert_transform
from helio_optics.lens import (area_samples, LensParameters, pmma_index, SOLAR_BANDS,
                               trace_bands)
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
        total, sx, sy = self._summary()[:3]
        return None if total <= 0.0 else np.array([sx / total, sy / total])

    def bounds(self):
        """Return the rays' box (x_min, y_min), (x_max, y_max) [m], or None without rays."""
        if not self.points.size:
            return None
        summary = self._summary()
        return np.array(summary[3:5]), np.array(summary[5:7])

    def _summary(self):
        """Return (power, power-weighted x and y sums, box) of the rays, once per field."""
        if not hasattr(self, '_sums'):
            self._sums = points_summary(np.ascontiguousarray(self.points, dtype=float),
                                        np.ascontiguousarray(self.power, dtype=float))
        return self._sums

    def total_power(self):
        """Concentrated power on the panel per unit DNI [m^2]."""
        return float(self.power.sum())

    def in_shadow(self, x, y):
        """
        Tell which panel points (x, y) lie in the lens shadow (sunward ray meets the lens).

        Following the sun ray from a panel point to the lens plane is a parallel projection,
        affine in (x, y): the offset from the lens centre there is a x + b y + c, so the
        test is a quadratic form and the distance along the ray an affine one (broadcast
        over x and y: a grid costs a few passes, not a 3-vector per point).
        """
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        shape = np.broadcast_shapes(x.shape, y.shape)
        form = self._shadow_form()
        if form is None:
            return np.zeros(shape, bool)
        aa, ab2, bb, ac2, bc2, cc, r2, d0, n0, n1, denominator = form
        radial2 = aa * x * x + ab2 * x * y + bb * y * y + ac2 * x + bc2 * y + cc
        distance = (d0 - n0 * x - n1 * y) / denominator
        return np.broadcast_to((distance > 0.0) & (radial2 <= r2), shape)

    def in_shadow_grid(self, xs, ys):
        """
        Return ``in_shadow(xs[None, :], ys[:, None])`` (len(ys), len(xs)) in one pass.

        The same arithmetic compiled over the grid (``kernels.shadow_grid``).
        """
        xs = np.ascontiguousarray(xs, dtype=float)
        ys = np.ascontiguousarray(ys, dtype=float)
        out = np.zeros((len(ys), len(xs)), bool)
        form = self._shadow_form()
        if form is not None:
            shadow_grid(xs, ys, form, out)
        return out

    def _shadow_form(self):
        """
        Return the coefficients of the shadow test (see ``in_shadow``), or None.

        (aa, 2ab, bb, 2ac, 2bc, cc, r^2, d0, n0, n1, denominator); None when the sun ray
        runs in the lens plane.
        """
        if not hasattr(self, '_form'):
            towards_sun = -self.sun_ray
            normal = self.lens_axis
            denominator = float(towards_sun @ normal)
            if abs(denominator) < 1e-9:
                self._form = None
                return None
            # offset at the lens plane of panel point p: Q (p - O), Q the oblique projector
            projector = np.eye(3) - np.outer(towards_sun, normal) / denominator
            a, b = projector[:, 0], projector[:, 1]
            c = -projector @ self.lens_centre
            self._form = (float(a @ a), float(2.0 * (a @ b)), float(b @ b),
                          float(2.0 * (a @ c)), float(2.0 * (b @ c)), float(c @ c),
                          float(self.aperture_radius ** 2), float(self.lens_centre @ normal),
                          float(normal[0]), float(normal[1]), denominator)
        return self._form


class LensFlux:
    """Traces the world's (true) lens and makes irradiance maps on the wood patch."""

    def __init__(self, lens=None, rays=30000, seed=0, bands=DEFAULT_BANDS,
                 move_tolerance=2e-5, angle_tolerance=5e-4, beam_spread=0.0,
                 moving_rays=None, moving_angle_tolerance=5e-3):
        """
        Trace `rays` samples of `lens` (LensParameters, design index) in spectral `bands`.

        `moving_rays` (default `rays`) per band are traced instead while the lens keeps
        moving (``field(..., moving=True)``): every k-th sample of the sunflower pattern,
        each standing for k times the aperture area, so the power is the same and the
        spot is as wide, only noisier.

        `beam_spread` [rad] is the standard deviation of a Gaussian angular error added to
        every ray (per axis): the facet slope and profile errors of a real moulded lens,
        convolved with the sun's disk as solar ray tracers do. The map is re-traced when
        the lens axis or sun ray turned more than `angle_tolerance` [rad] and carried along
        with the lens (exactly) when it moved more than `move_tolerance` [m]. While the lens
        keeps moving its fewer rays are carried along while it turned by up to
        `moving_angle_tolerance` [rad] (the emulated arm and servos do not reach their
        targets together: the servos jump, the arm's joints ramp, so the lens wobbles by a
        few mrad in a move between dots): a turn of 5 mrad moves the spot's centre by a
        few um (a 40th of a fine cell) and changes its map on 0.2 mm cells by 1.5 % (L1,
        the sun on the lens axis) to 6 % (45 mrad off it), under half the moving map's own
        sampling noise (16 %; tested).
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
        # The facets are cut once, for the design index: every band traces the design
        # samples (their slopes) with its own index, all bands in one pass (trace_bands).
        offset = self.lens.refractive_index - pmma_index(0.5876)
        self._indices = np.array([pmma_index(wavelength) + offset for wavelength, _ in bands])
        self._weights = weights
        stride = max(1, int(round(rays / moving_rays))) if moving_rays else 1
        self._samples = design
        self._moving_samples = _every(design, stride)
        self.moving_stride = stride
        self.move_tolerance = move_tolerance
        self.angle_tolerance = angle_tolerance
        self.moving_angle_tolerance = max(float(moving_angle_tolerance), angle_tolerance)
        self._field = None
        self._key = None
        self._traced = None
        self._asked = None     # the last pose and sun ray asked for, as given
        self._field_is_sparse = False
        self.traces = 0     # traces done
        self.fields = 0     # fields made (traced, or carried along with the lens)

    def field(self, T_world_lens, sun_ray_world, moving=False):
        """
        Return the FluxField for a lens pose and sun ray (world), re-traced only if turned.

        A lens that moved without turning (its axis and the sun ray within
        `angle_tolerance` of the traced ones: the rig keeps the lens's orientation while
        the arm moves it) gets the traced rays carried along exactly (``_TracedRays``);
        it is re-traced when either turned more. With `moving` the field holds the moving
        lens's fewer rays (every ``moving_stride``-th sample); a field so made is made in
        full again as soon as it is asked for without `moving`.
        """
        T = np.asarray(T_world_lens, dtype=float)
        s0 = np.asarray(sun_ray_world, dtype=float)
        asked = self._asked
        if (asked is not None and (moving or not self._field_is_sparse)
                and np.array_equal(T, asked[0]) and np.array_equal(s0, asked[1])):
            return self._field           # asked again for the same pose and sun (held still)
        self._asked = (T.copy(), s0.copy())
        s0 = s0 / np.linalg.norm(s0)
        sparse = moving and self.moving_stride > 1
        traced = self._traced
        if traced is not None:
            T_traced, s_traced = traced.key
            turned = math.acos(np.clip(T[:3, 2] @ T_traced[:3, 2], -1.0, 1.0))
            sun_turned = math.acos(np.clip(s0 @ s_traced, -1.0, 1.0))
            tolerance = self.moving_angle_tolerance if sparse else self.angle_tolerance
            if turned <= tolerance and sun_turned <= tolerance:
                moved = np.linalg.norm(T[:3, 3] - self._key[0][:3, 3])
                if moved <= self.move_tolerance and (moving or not self._field_is_sparse):
                    return self._field
                if sparse or not traced.sparse:
                    self._field = traced.carried(T[:3, 3], sparse)
                    self._field_is_sparse = sparse
                    self._key = (T.copy(), s0.copy())
                    self.fields += 1
                    return self._field
        self._traced = self._trace(T, s0, self._moving_samples if sparse else self._samples,
                                   sparse)
        self._field = self._traced.carried(T[:3, 3], sparse)
        self._field_is_sparse = sparse
        self._key = (T.copy(), s0.copy())
        self.traces += 1
        self.fields += 1
        return self._field

    @property
    def field_is_sparse(self):
        """Tell whether the present field holds the moving lens's fewer rays."""
        return self._field_is_sparse

    def _trace(self, T_world_lens, s0, samples, sparse):
        """Trace `samples` in every band at once; return their _TracedRays (per unit DNI)."""
        result = trace_bands(self.lens, samples, self._indices, s0, T_world_lens,
                             irradiance=1.0)
        power = self._weights[:, None] * result.power
        incident = result.incident_power
        # every stride-th sample of a full trace: the rays a sparse trace would give
        stride = 1 if sparse else self.moving_stride
        subset = np.zeros(result.hit.shape[1], bool)
        subset[::stride] = True
        return _TracedRays(
            key=(T_world_lens.copy(), s0.copy()), sparse=sparse, hit=result.hit,
            points=result.points, directions=result.directions, power=power,
            subset=subset, stride=stride, incident=incident,
            transmission=self.lens.transmission, direct=max(0.0, -float(s0[2])),
            lens_axis=T_world_lens[:3, 2].copy(), aperture_radius=self.lens.aperture_radius,
            sun_ray=s0.copy())


class _TracedRays:
    """
    The rays of one trace leaving the lens, to carry along with a lens that only moves.

    A ray leaving the lens is a line; the lens moved by t without turning moves every
    line by t, so the ray that met the panel (z = 0) at p with direction d now meets it at
    p + t_xy - t_z d_xy / d_z: the trace at the new pose, exactly (the power and the rays
    lost to total internal reflection do not change). Kept: the hit points and slopes
    d_xy / d_z of the rays that reach the panel, all of them and the moving lens's subset.
    """

    def __init__(self, key, sparse, hit, points, directions, power, subset, stride, incident,
                 transmission, direct, lens_axis, aperture_radius, sun_ray):
        """Keep the panel-reaching rays of a trace at lens pose `key` (see the class)."""
        self.key = key
        self.sparse = sparse
        self._origin = key[0][:3, 3].copy()
        self._common = {'direct': direct, 'lens_axis': lens_axis,
                        'aperture_radius': aperture_radius, 'sun_ray': sun_ray}
        self._trace = (hit, points, directions, power, subset, stride, incident * transmission,
                       incident)
        self._sets = {}

    def _set(self, name):
        """Return (points, slopes, power, TIR share) of the rays of set `name`, once."""
        if self.sparse:
            name = 'all'     # a sparse trace holds the moving lens's rays only
        if name not in self._sets:
            hit, points, directions, power, subset, stride, passed, incident = self._trace
            chosen = hit if name == 'all' else hit & subset[None, :]
            # the rays that reach the panel, band after band (as B separate traces gave them)
            count = int(np.count_nonzero(chosen))
            chosen_points, slopes = np.empty((count, 2)), np.empty((count, 2))
            chosen_power = np.empty(count)
            chosen_rays(chosen, points, directions, power,
                        1.0 if name == 'all' else float(stride), chosen_points, slopes,
                        chosen_power)
            lost = passed - float(chosen_power.sum())
            self._sets[name] = (chosen_points, slopes, chosen_power,
                                lost / incident if incident > 0.0 else 0.0)
        return self._sets[name]

    def carried(self, lens_centre, sparse):
        """Return the FluxField of these rays with the lens moved to `lens_centre` (world)."""
        points, slopes, power, tir_fraction = self._set('moving' if sparse else 'all')
        shift = np.asarray(lens_centre, dtype=float) - self._origin
        if np.any(shift):
            moved = np.empty_like(points)
            carried_points(points, slopes, float(shift[0]), float(shift[1]), float(shift[2]),
                           moved)
            points = moved
        return FluxField(points=points, power=power, lens_centre=np.array(lens_centre,
                                                                          dtype=float),
                         tir_fraction=tir_fraction, **self._common)


def _every(samples, stride):
    """Return every `stride`-th of LensSamples, each standing for `stride` times the area."""
    if stride == 1:
        return samples
    picked = {name: getattr(samples, name)[::stride]
              for name in ('facet_sin', 'radius', 'azimuth', 'disk_u', 'disk_v', 'ring')}
    return replace(samples, weight=samples.weight[::stride] * stride, **picked)


def bin_on_edges(x, y, weights, x_edges, y_edges):
    """
    Sum `weights` of points (x, y) per cell of increasing edges: (len(y_edges) - 1, ...x).

    What ``np.histogram2d(y, x, bins=(y_edges, x_edges), weights=weights)`` gives (a point
    on the last edge counts in the last cell), in one compiled loop over the points
    (``kernels.bin_points``: histogram2d on uneven edges costs tens of times more).
    """
    x_edges = np.ascontiguousarray(x_edges, dtype=float)
    y_edges = np.ascontiguousarray(y_edges, dtype=float)
    out = np.zeros((len(y_edges) - 1, len(x_edges) - 1))
    bin_points(np.asarray(x, dtype=float), np.asarray(y, dtype=float),
               np.asarray(weights, dtype=float), x_edges, y_edges, _even_run(x_edges),
               _even_run(y_edges), out)
    return out


_EVEN_RUNS = {}


def _even_run(edges):
    """Return (first, last) edge indices of the longest run of equal cells (1e-9 rel.)."""
    key = edges.tobytes()
    if key not in _EVEN_RUNS:
        if len(_EVEN_RUNS) > 64:
            _EVEN_RUNS.clear()
        _EVEN_RUNS[key] = _find_even_run(edges)
    return _EVEN_RUNS[key]


def _find_even_run(edges):
    """Find ``_even_run``'s answer."""
    widths = np.diff(edges)
    if widths.size == 0:
        return (0, 0)
    same = np.abs(np.diff(widths)) <= 1e-9 * widths[1:]
    # runs of cells: a new run starts at every cell not equal to the one before it
    starts = np.concatenate([[0], np.flatnonzero(~same) + 1])
    ends = np.concatenate([starts[1:], [widths.size]])
    longest = int(np.argmax(ends - starts))
    return int(starts[longest]), int(ends[longest])


def irradiance_on_cells(field, x_edges, y_edges, dni, shadow_samples=3):
    """
    Irradiance [W/m^2] on the cells of a grid (y, x) for direct normal irradiance `dni`.

    Concentrated rays are binned by cell; the direct sun covers the rest of each cell outside
    the lens shadow (shadow fraction from `shadow_samples`^2 points per cell).
    """
    x_edges, y_edges = np.asarray(x_edges, float), np.asarray(y_edges, float)
    areas = np.outer(np.diff(y_edges), np.diff(x_edges))
    binned = bin_on_edges(field.points[:, 0], field.points[:, 1], field.power, x_edges,
                          y_edges)
    shadow = shadow_fractions(field, x_edges, y_edges, shadow_samples)
    return dni * (binned / areas + field.direct * (1.0 - shadow))


def shadow_fractions(field, x_edges, y_edges, samples=3):
    """
    Share of each cell (y, x) in the lens shadow, from `samples`^2 points per cell.

    The shadow is convex: a cell whose four corners are in it is in it, and one whose
    corners are all out and whose neighbours' corners are all out too is out of it (the
    shadow, the aperture's size, is far larger than a cell); only the cells along its
    edge are sampled (``kernels.shadow_shares``, one compiled pass).
    """
    x_edges = np.ascontiguousarray(x_edges, dtype=float)
    y_edges = np.ascontiguousarray(y_edges, dtype=float)
    shadow = np.zeros((len(y_edges) - 1, len(x_edges) - 1))
    form = field._shadow_form()
    if form is not None:
        shadow_shares(x_edges, y_edges, form, int(samples), shadow)
    return shadow


def lens_pose_in_world(T_robot_world, T_robot_lens):
    """Return T_world_lens from the rig's T_robot_world and T_robot_lens."""
    return invert_transform(T_robot_world) @ T_robot_lens
