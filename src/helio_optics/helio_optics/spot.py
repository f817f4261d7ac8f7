"""
The concentrated light spot: outermost contour, ellipse, features (Eq 10), A_c and q_c (Eq 16).

Definitions
-----------
- Outermost contour (Sec. III-B): the convex hull of the projected points. The paper
  observes that the rim ring of the lens forms it; ``SpotModel`` traces the rim only
  (few rays, fast) while ``spot_area`` takes the hull of every ring traced from the rim
  of the sun's disk, so that the spot keeps its finite size (the sun's image,
  ~0.75 mm at f = 80 mm) at the focus.
- Ellipse of a contour: the ellipse with the same area, centroid and second moments as
  the filled polygon (exact for an elliptical contour). The model's spot centre is the
  centre of the conic fitted to the rim points (``conic_centres``), as ``cv2.fitEllipse``
  fits a detected contour: independent of how points crowd along the contour and smooth
  where the contour twists near a focus.
- Position features (Eq 10): from the ellipse centre (x_c, y_c) in the optics frame,
  Pi = sqrt(x_c^2 + y_c^2), Theta = atan2(y_c, x_c). Orientation/shape features (Sec. V-B):
  the major-axis angle in the optics frame and the eccentricity.
- Spot area A_c (Eq 16, Sec. V-A): ``definition='contour'`` (default) is the area inside
  the outermost contour, the paper's and the camera's notion (a thresholded image keeps
  the whole bright region); ``definition='power'`` is 4 pi sqrt(det C) of the
  power-weighted covariance C of area-sampled rays (the area of a uniform ellipse with
  the same second moments), a measure that ignores faint outliers.

API
---
``Ellipse`` (centre (2,), semi_major, semi_minor, orientation, area);
``ellipse_from_contour(points)``; ``outermost_contour(points)``;
``position_features(centre)`` (Eq 10); ``shape_features(ellipse)``;
``SpotModel(lens, rim_points=64, contour_fraction=1.0)``: ``.centres(sun_direction,
T_robot_lens, plane_point, plane_normal)`` for K poses at once, ``.features(...)`` ->
(K, 2) [Pi, Theta] in each pose's optics frame, ``.contours(...)`` the ring's points;
``spot_area(lens, sun_direction, T_frame_lens, plane_point, plane_normal, definition)``;
``spot_area_at(lens, d_lp, sun_elevation, definition)``: A_c(d_lp) with the lens aligned to
the sun and its centre d_lp from the target on a horizontal ground (Sec. IV-A, V-A);
``spot_area_curve(lens, d_lp_values, ...)``; ``concentrated_flux(lens, spot_area,
irradiance, absorptance)`` (Eq 16: q_c = alpha kappa q_s A_l / A_c).
"""

from dataclasses import dataclass
import math

from helio_optics.geometry import homogeneous, rotation_x, unit
from helio_optics.lens import area_samples, outer_ring_samples, ring_samples, trace
from helio_optics.lens import trace_batch
import numpy as np
from scipy.spatial import ConvexHull


@dataclass
class Ellipse:
    """An ellipse in a plane: centre (2,) [m], semi-axes [m], orientation [rad], area [m^2]."""

    centre: np.ndarray
    semi_major: float
    semi_minor: float
    orientation: float
    area: float

    @property
    def eccentricity(self):
        """Return sqrt(1 - (b / a)^2)."""
        return math.sqrt(max(0.0, 1.0 - (self.semi_minor / self.semi_major) ** 2))


def _polygon_moments(x, y):
    """Area, centroid and central second moments of closed polygons (last axis: vertices)."""
    xn, yn = np.roll(x, -1, axis=-1), np.roll(y, -1, axis=-1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum(axis=-1)
    cx = ((x + xn) * cross).sum(axis=-1) / (6.0 * area)
    cy = ((y + yn) * cross).sum(axis=-1) / (6.0 * area)
    return area, cx, cy, cross, xn, yn


def ellipse_from_contour(points):
    """Fit the ellipse with the contour's area, centroid and second moments (points (N, 2))."""
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[0] < 3 or points.shape[1] != 2:
        raise ValueError('a contour needs at least 3 points of shape (N, 2)')
    x, y = points[:, 0], points[:, 1]
    area, cx, cy, cross, xn, yn = _polygon_moments(x, y)
    if area < 0.0:
        area, cross = -area, -cross
    if area <= 0.0:
        raise ValueError('the contour encloses no area')
    # Central second moments of the filled polygon (Green's theorem).
    sxx = ((x * x + x * xn + xn * xn) * cross).sum() / 12.0 / area - cx * cx
    syy = ((y * y + y * yn + yn * yn) * cross).sum() / 12.0 / area - cy * cy
    sxy = ((x * yn + 2 * x * y + 2 * xn * yn + xn * y) * cross).sum() / 24.0 / area - cx * cy
    eigenvalues, vectors = np.linalg.eigh(np.array([[sxx, sxy], [sxy, syy]]))
    eigenvalues = np.maximum(eigenvalues, 0.0)
    major = vectors[:, 1]
    return Ellipse(centre=np.array([cx, cy]), semi_major=2.0 * math.sqrt(eigenvalues[1]),
                   semi_minor=2.0 * math.sqrt(eigenvalues[0]),
                   orientation=math.atan2(major[1], major[0]) % math.pi, area=float(area))


def outermost_contour(points):
    """Return the convex hull of points (N, 2) as an ordered contour (counter-clockwise)."""
    points = np.asarray(points, dtype=float)
    points = points[np.all(np.isfinite(points), axis=1)]
    if points.shape[0] < 3:
        raise ValueError('fewer than 3 projected points: no spot')
    return points[ConvexHull(points).vertices]


def position_features(centre):
    """Eq 10: y = [Pi, Theta] from ellipse centres (..., >= 2) in the optics frame."""
    centre = np.asarray(centre, dtype=float)
    return np.stack([np.hypot(centre[..., 0], centre[..., 1]),
                     np.arctan2(centre[..., 1], centre[..., 0])], axis=-1)


def shape_features(ellipse):
    """Orientation/shape features of Sec. V-B: (major-axis angle [rad], eccentricity)."""
    return ellipse.orientation, ellipse.eccentricity


class SpotModel:
    """The lens rim's projection: ellipse centres and Eq 10 features for given lens poses."""

    def __init__(self, lens, rim_points=64, contour_fraction=1.0):
        """
        Trace `rim_points` rays from the sun's centre through one ring of the lens.

        ``contour_fraction`` is that ring's radius over the aperture radius: 1 is the rim,
        the outermost contour of the paper; smaller values match the contour of a brighter
        part of the spot (a higher image threshold), which stays compact when a low sun
        makes the outermost rays graze the ground.
        """
        self.lens = lens
        self.samples = outer_ring_samples(lens, rim_points, sun_disk_points=1,
                                          radius_fraction=contour_fraction)
        self.T_lens_optics = lens.T_lens_optics

    def contours(self, sun_direction, T_robot_lens, plane_point, plane_normal):
        """Return rim points (K, N, 3) on the plane, robot frame (NaN where lost)."""
        return trace_batch(self.lens, self.samples, sun_direction, T_robot_lens,
                           plane_point, plane_normal).points

    def centres(self, sun_direction, T_robot_lens, plane_point=(0.0, 0.0, 0.0),
                plane_normal=(0.0, 0.0, 1.0)):
        """
        Return where the spots of K lens poses are centred: (K, 3), robot frame [m].

        The contour is taken in the plane's own 2D coordinates (so the ellipse is the one a
        camera sees on the ground); a pose whose rim loses rays (TIR, no hit) gets NaN.
        """
        T = np.asarray(T_robot_lens, dtype=float).reshape(-1, 4, 4)
        points = self.contours(sun_direction, T, plane_point, plane_normal)
        count = T.shape[0]
        normal = unit(np.broadcast_to(np.asarray(plane_normal, dtype=float), (count, 3)))
        origin = np.broadcast_to(np.asarray(plane_point, dtype=float), (count, 3))
        helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        u = unit(np.cross(normal, helper))
        v = np.cross(normal, u)
        relative = points - origin[:, None, :]
        x = np.einsum('kni,ki->kn', relative, u)
        y = np.einsum('kni,ki->kn', relative, v)
        cx, cy = conic_centres(x, y)
        centre = origin + cx[:, None] * u + cy[:, None] * v
        centre[np.any(np.isnan(x), axis=1)] = np.nan
        return centre

    def features(self, sun_direction, T_robot_lens, plane_point=(0.0, 0.0, 0.0),
                 plane_normal=(0.0, 0.0, 1.0)):
        """Return Eq 10's [Pi [m], Theta [rad]] (K, 2) in each pose's optics frame."""
        T = np.asarray(T_robot_lens, dtype=float).reshape(-1, 4, 4)
        centres = self.centres(sun_direction, T, plane_point, plane_normal)
        return position_features(centres_in_optics(T, self.T_lens_optics, centres))


def conic_centres(x, y):
    """
    Centres (cx, cy) of the conics a x^2 + b xy + c y^2 + d x + e y = 1 fitted to point rows.

    Least squares per row (K, N) in coordinates centred on the points' mean and scaled by
    their rms radius, the way ``cv2.fitEllipse`` fits a detected contour: for points on an
    ellipse the centre is exact however they are spaced along it, and it stays smooth when
    the contour twists near a focus (where a polygon's signed area would not). Rows whose
    points have collapsed to one point (< 1 nm) return their mean.
    """
    x, y = np.atleast_2d(x), np.atleast_2d(y)
    mx, my = x.mean(axis=1, keepdims=True), y.mean(axis=1, keepdims=True)
    scale = np.sqrt(np.mean((x - mx) ** 2 + (y - my) ** 2, axis=1, keepdims=True))
    collapsed = ~(scale[:, 0] > 1e-9)
    scale = np.where(scale > 1e-9, scale, 1.0)
    xs, ys = (x - mx) / scale, (y - my) / scale
    design = np.stack([xs * xs, xs * ys, ys * ys, xs, ys], axis=-1)
    normal = np.einsum('kni,knj->kij', design, design)
    rhs = design.sum(axis=1)
    normal[collapsed] = np.eye(5)
    a, b, c, d, e = np.moveaxis(np.linalg.solve(normal, rhs[..., None])[..., 0], -1, 0)
    determinant = 4.0 * a * c - b * b
    safe = np.where(np.abs(determinant) > 1e-12, determinant, 1.0)
    cx = np.where(np.abs(determinant) > 1e-12, (b * e - 2.0 * c * d) / safe, 0.0)
    cy = np.where(np.abs(determinant) > 1e-12, (b * d - 2.0 * a * e) / safe, 0.0)
    cx = np.where(collapsed, 0.0, cx) * scale[:, 0] + mx[:, 0]
    cy = np.where(collapsed, 0.0, cy) * scale[:, 0] + my[:, 0]
    return cx, cy


def centres_in_optics(T_robot_lens, T_lens_optics, centres_robot):
    """Express robot-frame points (K, 3) in the optics frame of each of K lens poses."""
    T = np.asarray(T_robot_lens, dtype=float).reshape(-1, 4, 4) @ T_lens_optics
    relative = np.asarray(centres_robot, dtype=float).reshape(-1, 3) - T[:, :3, 3]
    return np.einsum('kji,kj->ki', T[:, :3, :3], relative)


def ellipse_of_points(points_3d, plane_point, plane_normal):
    """Ellipse of the outermost contour of points lying on a plane (2D plane coordinates)."""
    normal = unit(np.asarray(plane_normal, dtype=float))
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = unit(np.cross(normal, helper))
    v = np.cross(normal, u)
    relative = np.asarray(points_3d, dtype=float) - np.asarray(plane_point, dtype=float)
    return ellipse_from_contour(outermost_contour(np.stack([relative @ u, relative @ v], -1)))


_AREA_SAMPLES = {}


def _samples_for(lens, definition):
    key = (lens, definition)
    if key not in _AREA_SAMPLES:
        _AREA_SAMPLES[key] = (ring_samples(lens, rings=6, per_ring=48, sun_disk_points=8)
                              if definition == 'contour' else area_samples(lens, 20000))
    return _AREA_SAMPLES[key]


def spot_area(lens, sun_direction, T_frame_lens=None, plane_point=(0.0, 0.0, 0.0),
              plane_normal=(0.0, 0.0, 1.0), definition='contour', samples=None):
    """A_c [m^2] for any lens-ground configuration (see the module docstring)."""
    if definition not in ('contour', 'power'):
        raise ValueError(f"definition must be 'contour' or 'power', got {definition!r}")
    samples = samples or _samples_for(lens, definition)
    result = trace(lens, samples, sun_direction, T_frame_lens, plane_point, plane_normal)
    hits = result.points[result.hit]
    if hits.shape[0] < 3:
        raise ValueError('no spot: fewer than 3 rays reach the plane')
    if definition == 'contour':
        return ellipse_of_points(hits, plane_point, plane_normal).area
    normal = unit(np.asarray(plane_normal, dtype=float))
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = unit(np.cross(normal, helper))
    v = np.cross(normal, u)
    planar = np.stack([hits @ u, hits @ v], axis=-1)
    covariance = np.cov(planar.T, aweights=result.power[result.hit])
    return 4.0 * math.pi * math.sqrt(max(np.linalg.det(covariance), 0.0))


def spot_area_at(lens, d_lp, sun_elevation=0.5 * math.pi, definition='contour'):
    """
    Return A_c(d_lp) [m^2]: lens aligned with the sun, centre d_lp [m] from a level target.

    The ground is z = 0; the sun ray comes down at `sun_elevation` [rad] (Sec. IV-A: the
    lens is always aligned with the estimated sun, so A_c depends on d_lp only).
    """
    tilt = 0.5 * math.pi - sun_elevation
    sun = np.array([0.0, math.sin(tilt), -math.cos(tilt)])
    T_world_lens = homogeneous(rotation_x(tilt), -d_lp * sun)  # lens axis along -s0
    return spot_area(lens, sun, T_world_lens, definition=definition)


def spot_area_curve(lens, d_lp_values, sun_elevation=0.5 * math.pi, definition='contour'):
    """A_c [m^2] over d_lp values [m] (the model curve of Sec. V-A, Fig. 10c)."""
    return np.array([spot_area_at(lens, d, sun_elevation, definition) for d in d_lp_values])


def concentrated_flux(lens, spot_area_m2, irradiance=900.0, absorptance=0.4):
    """Eq 16: q_c = alpha kappa q_s A_l / A_c [W/m^2] (kappa: the lens transmission)."""
    if not spot_area_m2 > 0.0:
        raise ValueError(f'spot area must be > 0 m^2, got {spot_area_m2}')
    return absorptance * lens.transmission * irradiance * lens.aperture_area / spot_area_m2
