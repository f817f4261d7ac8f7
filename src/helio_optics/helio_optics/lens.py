"""
Spherical Fresnel lens and its vectorised ray tracer (paper Sec. III-A/B, Eqs 1-6).

The lens (Fig. 4d) keeps the slopes of a reference sphere of radius r_s = f (n - 1) on
facets laid on a flat plate: a ray entering at radius r on the upper plane meets the facet
normal of the sphere at polar angle phi_l = asin(r / r_s) (Eqs 1, 3), refracts by the
vector form of Snell's law (Eqs 4-5), crosses the plate (thickness t; the paper's thin
assumption is ``thickness=0``), refracts again at the flat lower face (normal +z) and
travels to a plane (Eq 6). Rays meeting total internal reflection are dropped and counted.

Frames (DESIGN.md): ``lens`` has its origin at the centre of the upper surface, z along the
lens axis towards the sun side; ``optics`` is parallel to it with its origin at the centre
of the reference sphere, ``T_lens_optics = translate(0, 0, -r_s cos(phi_lb))`` (Eq 1).

API
---
``LensParameters(focal_length=0.080, refractive_index=1.4914, thickness=0.002,
aperture_diameter=0.058, transmission=0.92, facets='corrected')``: the paper's lens by
default (``facets='spherical'`` is Eq 3 verbatim; see ``facet_sin_polar``); derived
``sphere_radius`` (r_s), ``bounding_polar_angle`` (phi_lb), ``aperture_area`` (A_l),
``T_lens_optics``; ``LensParameters.from_sphere(r_s, phi_lb, ...)``.

Samples (reusable, build once): ``ring_samples(lens, rings, per_ring, sun_disk_points)``
(Sec. III-B: rings r_li evenly spaced up to the rim, equal theta_l steps; with sun-disk
points each lens point is traced for rays from the rim of the sun's disk, which bounds the
outermost contour), ``outer_ring_samples(lens, per_ring, sun_disk_points)`` (the rim only),
``area_samples(lens, count, seed)`` (uniform over the aperture area, each ray from a random
point of the sun's disk, equal power: for energy and irradiance).

``trace(lens, samples, sun_direction, T_frame_lens=I, plane_point=0, plane_normal=+z,
irradiance=900.0) -> TraceResult``: sun_direction is the ray direction s0 (the way light
travels) in ``frame``; the plane is given in ``frame`` too. ``TraceResult`` holds
``points`` (N, 3) in ``frame`` (NaN where no hit), ``power`` (N,) [W] including the
transmission (0 for TIR), ``hit`` (N,) bool, ``tir_count``, ``incident_power`` [W]
(Eq 13: q_s A_l cos(beta)), ``ring`` (N,) ring index of each ray and ``directions``
(N, 3) of the leaving rays in ``frame``.

``trace_bands(lens, samples, refractive_indices, sun_direction, ...)``: the same samples
at B indices (spectral bands, the facets cut for the design index) in one pass; results
with a leading band axis, element for element what B calls of ``trace`` give.

``paraxial_focus_distance(lens)``: thick-lens back focus measured from the lens centre
O_l, f + t (1 - 1/n).
"""

from dataclasses import dataclass, replace
import math

from helio_optics.config_files import read_parameter_section
from helio_optics.geometry import homogeneous, unit
import numpy as np

SUN_ANGULAR_DIAMETER = math.radians(0.533)  # mean apparent diameter of the sun's disk [rad]


@dataclass(frozen=True)
class LensParameters:
    """Spherical Fresnel lens (paper Sec. II-B, III-A); SI units."""

    focal_length: float = 0.080          # thin-lens focal length f = r_s / (n - 1) [m]
    refractive_index: float = 1.4914     # acrylic (PMMA) at 587.6 nm [-]
    thickness: float = 0.002             # plate thickness t [m] (0: the paper's thin lens)
    aperture_diameter: float = 0.058     # clear aperture diameter [m]
    transmission: float = 0.92           # kappa of Eq 16: power leaving / power entering [-]
    facets: str = 'corrected'            # 'corrected' (every zone focuses at the paraxial
    #                                      focus, as cut commercially) or 'spherical' (Eq 3)

    def __post_init__(self):
        """Reject parameters that describe no lens."""
        if not self.focal_length > 0.0:
            raise ValueError(f'focal_length must be > 0 m, got {self.focal_length}')
        if not self.refractive_index > 1.0:
            raise ValueError(f'refractive_index must be > 1, got {self.refractive_index}')
        if not self.thickness >= 0.0:
            raise ValueError(f'thickness must be >= 0 m, got {self.thickness}')
        if not 0.0 < self.transmission <= 1.0:
            raise ValueError(f'transmission must be in (0, 1], got {self.transmission}')
        if self.facets not in ('corrected', 'spherical'):
            raise ValueError(f"facets must be 'corrected' or 'spherical', got {self.facets!r}")
        if not 0.0 < self.aperture_diameter < 2.0 * self.sphere_radius:
            raise ValueError(
                f'aperture_diameter must be in (0, 2 r_s = {2.0 * self.sphere_radius:.4f}) m, '
                f'got {self.aperture_diameter}')

    @classmethod
    def from_sphere(cls, sphere_radius, bounding_polar_angle, refractive_index=1.4914,
                    **kwargs):
        """Build from the paper's parameters r_s [m] and phi_lb [rad] (Eq 1)."""
        return cls(focal_length=sphere_radius / (refractive_index - 1.0),
                   refractive_index=refractive_index,
                   aperture_diameter=2.0 * sphere_radius * math.sin(bounding_polar_angle),
                   **kwargs)

    @property
    def sphere_radius(self):
        """Radius r_s of the reference sphere [m] (lensmaker, plano-convex: f (n - 1))."""
        return self.focal_length * (self.refractive_index - 1.0)

    @property
    def aperture_radius(self):
        """Clear aperture radius r_s sin(phi_lb) [m]."""
        return 0.5 * self.aperture_diameter

    @property
    def bounding_polar_angle(self):
        """Lens bounding polar angle phi_lb [rad] (Sec. III-A)."""
        return math.asin(self.aperture_radius / self.sphere_radius)

    @property
    def aperture_area(self):
        """Lens area A_l [m^2] (Eqs 13, 16)."""
        return math.pi * self.aperture_radius ** 2

    @property
    def T_lens_optics(self):  # noqa: N802 (the project's transform naming)
        """Transform of the optics frame (sphere centre) into the lens frame (Eq 1)."""
        return homogeneous(translation=[0.0, 0.0, -self.sphere_radius *
                                        math.cos(self.bounding_polar_angle)])


# Sunlight through acrylic (DESIGN.md): PMMA's index falls from 1.502 at 437 nm to about
# 1.482 at 1.5 um (Cauchy fit n = A + B / l^2 through 1.4914 at 587.6 nm, 1.502 at 437 nm,
# 1.489 at 633 nm), so the focus of a tilted lens spreads by colour and its power centre
# moves. The bands: (centre wavelength [um], share of the direct solar power (AM1.5 direct)
# that acrylic passes).
PMMA_CAUCHY_A = 1.4799
PMMA_CAUCHY_B = 0.00434     # [um^2]
SOLAR_BANDS = ((0.45, 0.17), (0.55, 0.18), (0.65, 0.16), (0.80, 0.22), (1.00, 0.15),
               (1.30, 0.12))


def pmma_index(wavelength_um):
    """Return acrylic's refractive index at `wavelength_um` [um] (Cauchy fit)."""
    return PMMA_CAUCHY_A + PMMA_CAUCHY_B / wavelength_um ** 2


def spectral_lenses(lens, bands=SOLAR_BANDS):
    """
    Return [(band lens, weight)]: `lens` at each band's index, weights summing to 1.

    The facets are cut once, for the design index: every band keeps the design's sphere
    radius (so its focal length is r_s / (n_band - 1)); trace each band with samples made
    for the design lens and ``replace(samples, lens=band_lens)`` to keep the facet slopes.
    """
    weights = np.array([w for _, w in bands], dtype=float)
    if weights.ndim != 1 or np.any(weights < 0.0) or weights.sum() <= 0.0:
        raise ValueError('spectral band weights must be >= 0 with a positive sum')
    weights /= weights.sum()
    offset = lens.refractive_index - pmma_index(0.5876)
    lenses = []
    for (wavelength, _), weight in zip(bands, weights):
        index = pmma_index(wavelength) + offset
        lenses.append((replace(lens, refractive_index=index,
                               focal_length=lens.sphere_radius / (index - 1.0)),
                       float(weight)))
    return lenses


def load_lens_parameters(path):
    """Read LensParameters from a ROS 2 parameter file's ``lens`` section (config/lens.yaml)."""
    flat = read_parameter_section(path, 'lens')
    names = set(LensParameters.__dataclass_fields__)
    unknown = sorted(set(flat) - names)
    if unknown:
        raise ValueError(f'{path}: unknown lens parameter(s) {unknown}; known: {sorted(names)}')
    return LensParameters(**flat)


def paraxial_focus_distance(lens):
    """Distance [m] from O_l to the paraxial focus: f + t (1 - 1/n) (thick plano-convex)."""
    return lens.focal_length + lens.thickness * (1.0 - 1.0 / lens.refractive_index)


def facet_sin_polar(lens, radius):
    """
    Sine of the facet normal's polar angle phi_l at radius r on the plate (Eq 3).

    'spherical' facets copy the reference sphere, sin(phi_l) = r / r_s (the paper's model;
    strong spherical aberration for a fast lens). 'corrected' facets are tilted so that a
    ray parallel to the axis leaves towards the paraxial focus, as commercial Fresnel
    lenses are cut; both agree near the axis.
    """
    radius = np.asarray(radius, dtype=float)
    if lens.facets == 'spherical':
        return radius / lens.sphere_radius
    n, t = lens.refractive_index, lens.thickness
    back_focus = lens.focal_length - t / n  # from the flat face to the paraxial focus
    low, high = np.zeros_like(radius), np.full_like(radius, math.asin(1.0 / n) - 1e-9)
    for _ in range(60):  # bisection on the internal ray angle alpha_1 (monotone residual)
        alpha = 0.5 * (low + high)
        exit_angle = np.arcsin(np.minimum(n * np.sin(alpha), 1.0))
        residual = radius - t * np.tan(alpha) - back_focus * np.tan(exit_angle)
        low, high = np.where(residual > 0.0, alpha, low), np.where(residual > 0.0, high, alpha)
    alpha = 0.5 * (low + high)
    # Snell in vector form: the normal is parallel to s0 - n s1, s0 = -z, s1 inward.
    nx, nz = n * np.sin(alpha), n * np.cos(alpha) - 1.0
    return nx / np.hypot(nx, nz)


@dataclass(frozen=True)
class LensSamples:
    """
    Incident points on the lens and sun-disk offsets, one entry per traced ray.

    ``radius``, ``azimuth``: polar position (r_li, theta_l) on the upper plane [m, rad];
    ``weight``: aperture area each ray stands for [m^2] (sums to A_l over the lens for
    every sampling); ``disk_u``, ``disk_v``:
    angular offsets of the ray from the sun's centre [rad]; ``ring``: ring index (0 = rim);
    ``facet_sin``: sin(phi_l) of the facet normal at each ray's radius; ``lens``: the lens
    the samples were made for (trace refuses another).
    """

    lens: LensParameters
    facet_sin: np.ndarray
    radius: np.ndarray
    azimuth: np.ndarray
    weight: np.ndarray
    disk_u: np.ndarray
    disk_v: np.ndarray
    ring: np.ndarray

    def __post_init__(self):
        """Precompute entry points (Eq 1) and facet normals (Eq 3) in the lens frame."""
        cos_az, sin_az = np.cos(self.azimuth), np.sin(self.azimuth)
        object.__setattr__(self, 'entry_x', self.radius * cos_az)
        object.__setattr__(self, 'entry_y', self.radius * sin_az)
        object.__setattr__(self, 'normal_x', self.facet_sin * cos_az)
        object.__setattr__(self, 'normal_y', self.facet_sin * sin_az)
        object.__setattr__(self, 'normal_z', np.sqrt(1.0 - self.facet_sin ** 2))

    def __len__(self):
        """Return the number of rays."""
        return self.radius.size


def _disk_rim(points, sun_angular_diameter):
    """Offsets on the rim of the sun's disk (or the centre alone for 0/1 points)."""
    if points <= 1 or sun_angular_diameter <= 0.0:
        return np.zeros(1), np.zeros(1)
    angle = 2.0 * math.pi * (np.arange(points) + 0.5) / points
    half = 0.5 * sun_angular_diameter
    return half * np.cos(angle), half * np.sin(angle)


def ring_samples(lens, rings=8, per_ring=64, sun_disk_points=8,
                 sun_angular_diameter=SUN_ANGULAR_DIAMETER):
    """
    Sample the lens on rings as in Sec. III-B (r_li evenly spaced, equal theta_l steps).

    Ring 0 is the rim (r = aperture radius), ring k has radius R (rings - k) / rings. Each
    lens point is traced for ``sun_disk_points`` rays from the rim of the sun's disk (1:
    the sun's centre only). Weights are the annulus area each ring stands for.
    """
    if rings < 1 or per_ring < 3:
        raise ValueError('ring sampling needs rings >= 1 and per_ring >= 3')
    outer = lens.aperture_radius
    radii = outer * (rings - np.arange(rings)) / rings
    edges = outer * (rings - np.arange(rings + 1) + 0.5) / rings
    edges[0], edges[-1] = outer, 0.0
    annulus = math.pi * (edges[:-1] ** 2 - edges[1:] ** 2)
    du, dv = _disk_rim(sun_disk_points, sun_angular_diameter)
    theta = 2.0 * math.pi * np.arange(per_ring) / per_ring
    ring, th, k = np.meshgrid(np.arange(rings), theta, np.arange(du.size), indexing='ij')
    ring, th, k = ring.ravel(), th.ravel(), k.ravel()
    return LensSamples(lens=lens, facet_sin=facet_sin_polar(lens, radii)[ring],
                       radius=radii[ring], azimuth=th,
                       weight=annulus[ring] / (per_ring * du.size), disk_u=du[k], disk_v=dv[k],
                       ring=ring)


def outer_ring_samples(lens, per_ring=64, sun_disk_points=8,
                       sun_angular_diameter=SUN_ANGULAR_DIAMETER, radius_fraction=1.0):
    """
    Sample one ring: the rim (its projection is the outermost contour, Sec. III-B).

    ``radius_fraction`` < 1 samples an inner ring instead (r = fraction x aperture radius),
    whose projection is the contour of a brighter part of the spot.
    """
    if not 0.0 < radius_fraction <= 1.0:
        raise ValueError(f'radius_fraction must be in (0, 1], got {radius_fraction}')
    samples = ring_samples(lens, 1, per_ring, sun_disk_points, sun_angular_diameter)
    if radius_fraction == 1.0:
        return samples
    radius = samples.radius * radius_fraction
    return LensSamples(lens=lens, facet_sin=facet_sin_polar(lens, radius), radius=radius,
                       azimuth=samples.azimuth, weight=samples.weight, disk_u=samples.disk_u,
                       disk_v=samples.disk_v, ring=samples.ring)


def area_samples(lens, count=20000, seed=0, sun_angular_diameter=SUN_ANGULAR_DIAMETER):
    """
    Sample the aperture uniformly by area (sunflower pattern), each ray from a point of the sun.

    Every ray carries the same aperture area A_l / count; sun-disk offsets are uniform over
    the disk (seeded, reproducible); ring is -1.
    """
    if count < 1:
        raise ValueError('area sampling needs count >= 1')
    index = np.arange(count) + 0.5
    radius = lens.aperture_radius * np.sqrt(index / count)
    azimuth = np.mod(index * math.pi * (3.0 - math.sqrt(5.0)), 2.0 * math.pi)
    rng = np.random.default_rng(seed)
    rho = 0.5 * sun_angular_diameter * np.sqrt(rng.random(count))
    psi = 2.0 * math.pi * rng.random(count)
    return LensSamples(lens=lens, facet_sin=facet_sin_polar(lens, radius),
                       radius=radius, azimuth=azimuth,
                       weight=np.full(count, lens.aperture_area / count),
                       disk_u=rho * np.cos(psi), disk_v=rho * np.sin(psi),
                       ring=np.full(count, -1))


@dataclass
class TraceResult:
    """Rays traced through the lens onto a plane (see the module docstring)."""

    points: np.ndarray
    power: np.ndarray
    hit: np.ndarray
    tir_count: int
    incident_power: float
    ring: np.ndarray
    directions: np.ndarray

    @property
    def ground_power(self):
        """Total power [W] landing on the plane."""
        return float(self.power[self.hit].sum())


def _perpendicular_basis(direction):
    """Two unit vectors completing unit `direction` (..., 3) to an orthonormal basis."""
    direction = np.asarray(direction, dtype=float)
    helper = np.zeros_like(direction)
    use_x = np.abs(direction[..., 0]) < 0.9
    helper[..., 0] = use_x
    helper[..., 1] = ~use_x
    e1 = unit(np.cross(direction, helper))
    return e1, np.cross(direction, e1)


def _refract(nx, ny, nz, sx, sy, sz, ratio):
    """
    Vector Snell's law (Eqs 4-5): s' = w n + N s, w = N cos(g) - sqrt(1 - N^2 + (N cos(g))^2).

    `n` faces the incoming ray (n . s < 0), N = xi_in / xi_out. Returns s', the mask of rays
    that refract (False: total internal reflection or a ray meeting the facet's back) and
    the mask of rays without total internal reflection.
    """
    cos_gamma = -(nx * sx + ny * sy + nz * sz)
    root = 1.0 - ratio * ratio + (ratio * cos_gamma) ** 2
    no_tir = root >= 0.0
    w = ratio * cos_gamma - np.sqrt(np.maximum(root, 0.0))
    return w * nx + ratio * sx, w * ny + ratio * sy, w * nz + ratio * sz, \
        no_tir & (cos_gamma > 0.0), no_tir


_CHUNK = 8192  # rays per block: keeps the temporaries in cache (several times faster)


def _trace_block(lens, samples, block, s0, e1, e2, p_plane, n_plane):
    """
    Trace rays `block` (a slice) in the lens frame; return hit points, masks, directions.

    The sun and plane vectors are indexed by axis first (``s0[0]`` is x) and may hold
    (K, 1) arrays to trace K lens poses at once (results then have shape (K, N)).
    """
    u, v = samples.disk_u[block], samples.disk_v[block]
    sx = s0[0] + u * e1[0] + v * e2[0]
    sy = s0[1] + u * e1[1] + v * e2[1]
    sz = s0[2] + u * e1[2] + v * e2[2]
    inverse_norm = 1.0 / np.sqrt(sx * sx + sy * sy + sz * sz)
    sx *= inverse_norm
    sy *= inverse_norm
    sz *= inverse_norm
    # Eq 1 (entry point on the upper plane) and Eq 3 (facet normal), precomputed per sample.
    px, py = samples.entry_x[block], samples.entry_y[block]
    nx, ny, nz = samples.normal_x[block], samples.normal_y[block], samples.normal_z[block]
    n = lens.refractive_index
    s1x, s1y, s1z, ok1, _ = _refract(nx, ny, nz, sx, sy, sz, 1.0 / n)
    ok1 &= s1z < 0.0
    if lens.thickness > 0.0:  # cross the plate to the flat lower face z = -t
        depth = lens.thickness / np.where(ok1, -s1z, 1.0)
        qx, qy = px + depth * s1x, py + depth * s1y
    else:
        qx, qy = px, py
    qz = -lens.thickness
    # Flat face, normal +z (Eq 3), glass to air: N = n.
    cos_gamma = -s1z
    root = 1.0 - n * n + (n * cos_gamma) ** 2
    no_tir = root >= 0.0
    w = n * cos_gamma - np.sqrt(np.maximum(root, 0.0))
    s2x, s2y, s2z = n * s1x, n * s1y, w + n * s1z
    ok = ok1 & no_tir
    tir = np.count_nonzero(ok1 & ~no_tir, axis=-1)
    # Eq 6: p_g = p_l2 + K s2 with (p_g - p_g0) . n_g = 0.
    denominator = s2x * n_plane[0] + s2y * n_plane[1] + s2z * n_plane[2]
    hit = ok & (np.abs(denominator) > 1e-15)
    safe = np.where(hit, denominator, 1.0)
    k = ((p_plane[0] - qx) * n_plane[0] + (p_plane[1] - qy) * n_plane[1]
         + (p_plane[2] - qz) * n_plane[2]) / safe
    hit &= k > 0.0
    return (qx + k * s2x, qy + k * s2y, qz + k * s2z), (s2x, s2y, s2z), ok, hit, tir


def _in_lens_frame(lens, samples, sun_direction, T_frame_lens, plane_point, plane_normal):
    """
    Return (R, origin, s0, n_plane, p_plane): the lens pose and the inputs in the lens frame.

    The samples must have been cut for `lens` (ValueError otherwise); s0 is made unit.
    """
    if samples.lens != lens:
        raise ValueError('the samples were made for another lens; build them for this one')
    T = np.eye(4) if T_frame_lens is None else np.asarray(T_frame_lens, dtype=float)
    R, origin = T[:3, :3], T[:3, 3]
    s0 = unit(R.T @ np.asarray(sun_direction, dtype=float).reshape(3))
    n_plane = R.T @ unit(np.asarray(plane_normal, dtype=float).reshape(3))
    p_plane = R.T @ (np.asarray(plane_point, dtype=float).reshape(3) - origin)
    return R, origin, s0, n_plane, p_plane


def trace(lens, samples, sun_direction, T_frame_lens=None, plane_point=(0.0, 0.0, 0.0),
          plane_normal=(0.0, 0.0, 1.0), irradiance=900.0):
    """
    Trace sun rays through the lens onto a plane (Eqs 1-6); see the module docstring.

    ``sun_direction``: s0 in ``frame`` (need not be unit). ``T_frame_lens``: the lens pose in
    ``frame`` (default identity: everything in the lens frame). ``irradiance``: direct
    normal irradiance q_s [W/m^2]. If the sun is behind the lens no ray hits (power 0).
    """
    R, origin, s0, n_plane, p_plane = _in_lens_frame(lens, samples, sun_direction,
                                                     T_frame_lens, plane_point, plane_normal)
    count = len(samples)
    cos_beta = -s0[2]
    if cos_beta <= 0.0:  # the sun shines on the lens from below: nothing is focused
        nan = np.full((count, 3), np.nan)
        return TraceResult(points=nan, power=np.zeros(count), hit=np.zeros(count, bool),
                           tir_count=0, incident_power=0.0, ring=samples.ring,
                           directions=nan.copy())
    e1, e2 = _perpendicular_basis(s0)
    local = np.empty((count, 3))
    leaving = np.empty((count, 3))
    ok = np.empty(count, bool)
    hit = np.empty(count, bool)
    tir_count = 0
    for start in range(0, count, _CHUNK):
        block = slice(start, min(start + _CHUNK, count))
        point, direction, ok[block], hit[block], tir = _trace_block(
            lens, samples, block, s0, e1, e2, p_plane, n_plane)
        for axis in range(3):
            local[block, axis] = point[axis]
            leaving[block, axis] = direction[axis]
        tir_count += int(tir)
    local[~hit] = np.nan
    points = local @ R.T + origin
    directions = leaving @ R.T
    power = np.where(ok, samples.weight * irradiance * cos_beta * lens.transmission, 0.0)
    incident = irradiance * cos_beta * float(samples.weight.sum())
    return TraceResult(points=points, power=power, hit=hit, tir_count=tir_count,
                       incident_power=incident, ring=samples.ring, directions=directions)


@dataclass
class BatchTraceResult:
    """K lens poses traced at once: ``points`` (K, N, 3) in ``frame``, ``hit`` (K, N)."""

    points: np.ndarray
    hit: np.ndarray
    tir_count: np.ndarray


def trace_batch(lens, samples, sun_directions, T_frame_lens, plane_point=(0.0, 0.0, 0.0),
                plane_normal=(0.0, 0.0, 1.0)):
    """
    Trace the same samples for K (sun direction, lens pose) pairs in one vectorised pass.

    ``sun_directions``: (K, 3) or (3,) in ``frame``; ``T_frame_lens``: (K, 4, 4); the plane
    (point, normal) is one plane in ``frame`` or (K, 3) arrays. For the estimators' inner
    loops (few rays, many poses); power is not computed. A pose whose lens faces away from
    the sun gets no hits.
    """
    if samples.lens != lens:
        raise ValueError('the samples were made for another lens; build them for this one')
    T = np.asarray(T_frame_lens, dtype=float).reshape(-1, 4, 4)
    count = T.shape[0]
    R, origin = T[:, :3, :3], T[:, :3, 3]
    Rt = np.transpose(R, (0, 2, 1))
    s_frame = unit(np.broadcast_to(np.asarray(sun_directions, dtype=float), (count, 3)))
    s0 = np.einsum('kij,kj->ki', Rt, s_frame)
    n_plane = np.einsum('kij,kj->ki', Rt, unit(np.broadcast_to(
        np.asarray(plane_normal, dtype=float), (count, 3))))
    p_plane = np.einsum('kij,kj->ki', Rt, np.broadcast_to(
        np.asarray(plane_point, dtype=float), (count, 3)) - origin)
    e1, e2 = _perpendicular_basis(s0)
    columns = [a.T[:, :, None] for a in (s0, e1, e2, p_plane, n_plane)]
    point, _, _, hit, tir = _trace_block(lens, samples, slice(None), *columns)
    hit = hit & (s0[:, 2:3] < 0.0)
    local = np.stack(np.broadcast_arrays(*point), axis=-1)
    points = np.einsum('kij,knj->kni', R, local) + origin[:, None, :]
    points[~hit] = np.nan
    return BatchTraceResult(points=points, hit=hit, tir_count=np.asarray(tir))


def trace_bands(lens, samples, refractive_indices, sun_direction, T_frame_lens=None,
                plane_point=(0.0, 0.0, 0.0), plane_normal=(0.0, 0.0, 1.0), irradiance=900.0):
    """
    Trace the same samples at B refractive indices (spectral bands) in one vectorised pass.

    What B calls of ``trace`` give, each with a copy of `lens` at one of
    `refractive_indices` (the facets keep the slopes `samples` were cut with), element for
    element the same arithmetic: one pass instead of B saves the per-call work that
    dominates a few thousand rays. Returns a ``TraceResult`` with a leading band axis:
    ``points`` and ``directions`` (B, N, 3), ``power`` and ``hit`` (B, N), ``tir_count``
    (B,); ``incident_power`` is one band's (the same for all).
    """
    R, origin, s0, n_plane, p_plane = _in_lens_frame(lens, samples, sun_direction,
                                                     T_frame_lens, plane_point, plane_normal)
    indices = np.asarray(refractive_indices, dtype=float).reshape(-1)
    bands = indices.size
    count = len(samples)
    cos_beta = -s0[2]
    if cos_beta <= 0.0:  # the sun shines on the lens from below: nothing is focused
        nan = np.full((bands, count, 3), np.nan)
        return TraceResult(points=nan, power=np.zeros((bands, count)),
                           hit=np.zeros((bands, count), bool),
                           tir_count=np.zeros(bands, int), incident_power=0.0,
                           ring=samples.ring, directions=nan.copy())
    e1, e2 = _perpendicular_basis(s0)
    band_lens = _BandLens(indices[:, None], lens.thickness)
    local = np.empty((bands, count, 3))
    leaving = np.empty((bands, count, 3))
    ok = np.empty((bands, count), bool)
    hit = np.empty((bands, count), bool)
    tir_count = np.zeros(bands, int)
    chunk = max(1, _CHUNK // bands)
    for start in range(0, count, chunk):
        block = slice(start, min(start + chunk, count))
        point, direction, ok[:, block], hit[:, block], tir = _trace_block(
            band_lens, samples, block, s0, e1, e2, p_plane, n_plane)
        for axis in range(3):
            local[:, block, axis] = point[axis]
            leaving[:, block, axis] = direction[axis]
        tir_count += tir
    local[~hit] = np.nan
    points = local @ R.T + origin
    directions = leaving @ R.T
    power = np.where(ok, samples.weight * irradiance * cos_beta * lens.transmission, 0.0)
    incident = irradiance * cos_beta * float(samples.weight.sum())
    return TraceResult(points=points, power=power, hit=hit, tir_count=tir_count,
                       incident_power=incident, ring=samples.ring, directions=directions)


@dataclass(frozen=True)
class _BandLens:
    """What ``_trace_block`` reads of a lens, with one refractive index per band (B, 1)."""

    refractive_index: np.ndarray
    thickness: float
