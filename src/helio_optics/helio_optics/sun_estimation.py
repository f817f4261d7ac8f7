"""
Sun-orientation estimation from light-spot observations (paper Sec. III-C, Eqs 10-12, 18).

Unknown: the sun ray s0 in the robot frame, as ray angles vartheta = (phi0, theta0) of Eq 2
(phi0 in (pi/2, pi): the ray goes down). These are the optics-frame angles of the paper for
the rig at x = 0, where the optics axes are parallel to the robot's.

An observation is the ellipse centre of the spot on the ground (robot frame) with the lens
pose T_robot_lens at the time of the image and the ground plane. The model is
``spot.SpotModel``: the lens rim traced for a candidate s0 (the outermost contour, Sec.
III-B) and its ellipse centre.

Time (Eq 18). The observations of a sweep span minutes while the sun moves ~0.25 deg a
minute. Each observation may carry ``angle_offset`` = (dphi, dtheta): the change of the ray
angles from a common reference time to its own time (``ephemeris.angle_offsets``); the
unknown is then the sun at the reference time and the model of observation k uses
(phi0 + dphi_k, theta0 + dtheta_k). Without offsets the sun is taken as fixed.

Two methods:
- ``interaction_matrix`` (the paper, Eqs 11-12): per observation,
  vartheta_{t+1} = vartheta_t - lambda A_t^-1 (y_t - y_img) with y = [Pi, Theta] of Eq 10 in
  that observation's optics frame and A_t by forward differences of step delta; stops when
  ||y_t - y_img|| < tolerance (an exact root). Each image's answer, moved to the reference
  time, carries its own information matrix I_k = J_k^T J_k (J_k: its whitened spot centre
  per (phi0, theta0)); the sweep's estimate is their information-weighted mean, its
  covariance (sum I_k)^-1, and the images' disagreement the chi-square
  sum (v_k - mean)^T I_k (v_k - mean) with 2 (K - 1) degrees of freedom.
- ``levenberg_marquardt``: all observations jointly, residuals = (model centre - measured
  centre) / sigma in the plane's two axes, unknowns = the horizontal components of s0 (no
  singularity at the zenith); a Huber-weighted fit first, then plain least squares on the
  inliers; covariance (J^T J)^-1 mapped to (phi0, theta0). Its ``residual`` is the rms
  distance between model and measured centres [m] (the interaction-matrix method reports
  the largest final ||y_t - y_img||).

When the estimate is trusted (``TrustSettings``):
- Screening: an observation that no sun can have cast is left out with its reason (centre
  not finite, off the plane, above the lens, lens not above the plane, chief ray grazing the
  plane: a centre metres away or at 1e300), and one the model cannot be trusted with: a lens
  axis farther than ``max_chief_ray_tilt`` from the sweep's chief ray (the median direction
  from the lens centres to the spot centres, nearly the sun's ray; off by default; the node
  sets the limit within which the spot's noise was measured, ``centre_noise``).
- Outliers: the observation (LM: whitened centre residual; interaction matrix: image
  answer against the mean of the others) beyond chi2_2(1 - outlier_alpha) is left out, one
  at a time, worst first, then the fit is repeated (``TrustSettings.worst_outlier``); the
  left-out ones must stay under max_outlier_fraction (a quarter) and at least two
  observations must remain, else "no clear majority".
- Converged means: a minimum that fits the data within the noise. A minimum: a quadratic
  fitted to the cost right around the solution has a positive definite Hessian H and a
  Newton step sqrt(g^T H^-1 g) shorter than step_tolerance standard deviations (judged on
  the cost itself, however the solver stopped: "no step lowers the cost" is not enough).
  Fits: the chi-square of the inliers' whitened residuals is below chi2_dof(1 - fit_alpha).
  Otherwise ``reason`` says which part failed.
- Ambiguity: another minimum of the joint cost that fits lies near a root of every single
  image, so the roots of the two best-fitted images are searched by Gauss-Newton from
  starts on rings (0.3-8 deg) around the estimate and those farther than
  ambiguity_separation are polished on all inliers; a minimum whose chi-square is within
  ambiguity_chi2 of the estimate's (and passes the fit test) makes the estimate
  ``ambiguous`` and is reported in ``alternatives`` (direction, chi-square, separation,
  covariance). A clearly better minimum found so replaces the estimate.
  ``trustworthy`` = converged and not ambiguous.

The initial guess is the chief ray: the median direction from the lens centres to the spot
centres (a ray through the centre of a thin lens is not deviated), unless ``initial`` is
given; the interaction-matrix method keeps phi0 away from pi (the singularity of A_t).

API
---
``Observation(centre, T_robot_lens, plane_point=(0,0,0), plane_normal=(0,0,1),
sigma=0.5e-3, angle_offset=(0, 0))`` (a pose whose rotation is not a rotation, or any
non-finite pose, plane, sigma or offset: ValueError naming it; a non-finite centre is
accepted and left out of estimates with its reason); ``TrustSettings(...)``;
``SunEstimator(lens, rim_points=64, contour_fraction=1.0, trust=TrustSettings())`` with
``.estimate(observations, method='levenberg_marquardt', initial=None, trust=None,
**options)``, ``.interaction_matrix(...)``, ``.levenberg_marquardt(...)``,
``.cost(directions, observations)`` (chi-square of each candidate ray),
``.screen(observations, trust)`` (kept indices, [(index, reason)] of those no sun casts),
``.synthetic_observation(s0, T_robot_lens, ...)`` (the model's own spot, for tests and the
simulation); all return ``SunEstimateResult`` (phi0, theta0, direction, covariance (2x2),
method, iterations, residual, converged, reason, observations (count used),
per_observation, chi2, dof, chi2_threshold, inliers, deviations, outliers [(index,
reason)], ambiguous, alternatives [Alternative], trustworthy).
"""

from dataclasses import dataclass, field
import math

from helio_optics.geometry import angles_from_direction, direction_from_angles
from helio_optics.geometry import transform_points, unit
from helio_optics.spot import centres_in_optics, position_features, SpotModel
import numpy as np
from scipy.stats import chi2 as chi_square

METHODS = ('interaction_matrix', 'levenberg_marquardt')

# States of a Gauss-Newton run (_RETURNED: came back to a minimum already known).
_ACTIVE, _CONVERGED, _STUCK, _INFEASIBLE, _EXHAUSTED, _RETURNED = range(6)
# Angular radii [deg] and directions of the ambiguity search's starts around an estimate.
_SEARCH_RADII_DEG = (0.3, 0.8, 2.0, 4.0, 8.0)
_SEARCH_DIRECTIONS = 6
_NO_MAJORITY = ('{} of {} observations left out and more disagree: no clear majority fits one '
                'sun')
# The minimum test fits a quadratic to the cost on a ring this many standard deviations of
# the estimate around it, but no more than _FIT_ANGLE [rad] (a direction the data hardly
# determine has a huge standard deviation).
_FIT_RADIUS = 0.003
_FIT_ANGLE = 1e-4


def _check_rigid(transform, name):
    """Raise ValueError unless `transform` is a finite 4x4 rigid transform (rotation det +1)."""
    if transform.shape != (4, 4) or not np.all(np.isfinite(transform)):
        raise ValueError(f'{name} must be a finite 4x4 transform, got {transform.tolist()}')
    rotation = transform[:3, :3]
    orthogonality = float(np.max(np.abs(rotation.T @ rotation - np.eye(3))))
    determinant = float(np.linalg.det(rotation))
    if orthogonality > 1e-6 or determinant < 0.0:
        raise ValueError(
            f'{name} is not a rigid transform: its rotation part is not a rotation '
            f'(max |R^T R - I| = {orthogonality:.3g}, det R = {determinant:.6g})')
    if np.any(transform[3] != [0.0, 0.0, 0.0, 1.0]):
        raise ValueError(f'{name} must end with the row [0, 0, 0, 1], got {transform[3]}')


@dataclass
class Observation:
    """A spot centre on a plane with the lens pose when it was seen (robot frame, SI)."""

    centre: np.ndarray
    T_robot_lens: np.ndarray
    plane_point: np.ndarray = field(default_factory=lambda: np.zeros(3))
    plane_normal: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    sigma: float = 0.5e-3  # standard deviation of the centre on the plane, per axis [m]
    angle_offset: tuple = (0.0, 0.0)  # (dphi, dtheta): sun ray now minus at reference [rad]

    def __post_init__(self):
        """Check shapes and values; a non-finite centre is kept (estimates leave it out)."""
        self.centre = np.asarray(self.centre, dtype=float).reshape(3)
        self.T_robot_lens = np.asarray(self.T_robot_lens, dtype=float).reshape(4, 4)
        _check_rigid(self.T_robot_lens, 'T_robot_lens')
        self.plane_point = np.asarray(self.plane_point, dtype=float).reshape(3)
        normal = np.asarray(self.plane_normal, dtype=float).reshape(3)
        if not (np.all(np.isfinite(self.plane_point)) and np.all(np.isfinite(normal))):
            raise ValueError(f'the plane holds non-finite values: point {self.plane_point}, '
                             f'normal {normal}')
        self.plane_normal = unit(normal)
        if not (math.isfinite(self.sigma) and self.sigma > 0.0):
            raise ValueError(f'sigma must be a finite value > 0 m, got {self.sigma}')
        offset = tuple(float(v) for v in np.asarray(self.angle_offset, dtype=float).reshape(2))
        if not all(math.isfinite(v) for v in offset):
            raise ValueError(f'angle_offset must be finite, got {offset}')
        self.angle_offset = offset

    @classmethod
    def seen_on_the_world_plane(cls, rig, T_robot_world, centre_world, joints, sigma=0.5e-3,
                                angle_offset=(0.0, 0.0)):
        """
        Return the observation of a spot centre seen on the world's plane (z = 0).

        `centre_world` in the world frame, the lens where `rig` (a ``Rig``) puts it at the
        reported `joints`, the plane and the centre taken to the robot frame by
        `T_robot_world`: as ``sun_estimator`` builds its observations.
        """
        T = np.asarray(T_robot_world, dtype=float)
        return cls(transform_points(T, centre_world), rig.forward(joints).T_robot_lens,
                   T[:3, 3], T[:3, 2], sigma, angle_offset)


@dataclass(frozen=True)
class TrustSettings:
    """When an estimate counts as converged, which observations are left out, ambiguity."""

    fit_alpha: float = 1e-3          # significance of the chi-square fit test [-]
    outlier_alpha: float = 1e-4      # significance of one observation's rejection [-]
    max_outlier_fraction: float = 0.25  # left-out (not screened) observations stay below [-]
    step_tolerance: float = 0.01     # converged: Newton step below this [std dev]
    ambiguity_chi2: float = 9.21     # another minimum within this chi-square is as good [-]
    ambiguity_separation: float = math.radians(0.05)  # closer minima are the same [rad]
    ambiguity_search: bool = True    # look for other minima at all
    plane_tolerance: float = 2e-3    # a centre farther off the plane is left out [m]
    min_chief_ray_elevation: float = math.radians(3.0)  # chief rays flatter: left out [rad]
    # An observation whose lens axis lies farther off the observations' median chief ray
    # (lens centre to spot: nearly the sun) is left out: there the rim model's centre errs by
    # far more than its noise, alike over a sweep, so no chi-square sees it
    # (centre_noise.CentreNoise.max_tilt, the node's 15 deg). pi: off.
    max_chief_ray_tilt: float = math.pi  # [rad]

    def __post_init__(self):
        """Reject values outside their ranges, naming them."""
        for name in ('fit_alpha', 'outlier_alpha', 'max_outlier_fraction'):
            value = getattr(self, name)
            if not 0.0 < value <= 1.0:
                raise ValueError(f'{name} must be in (0, 1], got {value}')
        for name in ('step_tolerance', 'ambiguity_chi2', 'ambiguity_separation',
                     'plane_tolerance'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be a finite value > 0, got {value}')
        if not 0.0 <= self.min_chief_ray_elevation < 0.5 * math.pi:
            raise ValueError('min_chief_ray_elevation must be in [0, pi/2) rad, got '
                             f'{self.min_chief_ray_elevation}')
        if not 0.0 < self.max_chief_ray_tilt <= math.pi:
            raise ValueError('max_chief_ray_tilt must be in (0, pi] rad, got '
                             f'{self.max_chief_ray_tilt}')

    def fit_threshold(self, dof):
        """Largest chi-square a fit with `dof` degrees of freedom may have (at least 1 dof)."""
        return float(chi_square.ppf(1.0 - self.fit_alpha, max(int(dof), 1)))

    def outlier_threshold(self):
        """Largest squared deviation (2 dof) an observation may have before it is left out."""
        return float(chi_square.ppf(1.0 - self.outlier_alpha, 2))

    def worst_outlier(self, squared, left_out, total):
        """
        Apply the rejection rule to squared deviations (2 dof each) of the observations kept.

        Returns (position of the worst one beyond ``outlier_threshold`` or None, whether
        leaving it out would break the majority: `left_out` + 1 of `total` reaching
        ``max_outlier_fraction``).
        """
        worst = int(np.argmax(squared))
        if not squared[worst] > self.outlier_threshold():
            return None, False
        if (left_out + 1) / total >= self.max_outlier_fraction:
            return None, True
        return worst, False


@dataclass
class Alternative:
    """Another minimum of the joint cost (ambiguity)."""

    direction: np.ndarray
    phi0: float
    theta0: float
    chi2: float
    separation: float      # angle to the estimate [rad]
    covariance: np.ndarray  # of (phi0, theta0) [rad^2]


@dataclass
class SunEstimateResult:
    """Estimated sun ray and solver diagnostics (mirrors helio_msgs/SunEstimate)."""

    phi0: float
    theta0: float
    direction: np.ndarray
    covariance: np.ndarray
    method: str
    iterations: int
    residual: float
    converged: bool
    reason: str
    observations: int
    per_observation: list = field(default_factory=list)
    chi2: float = float('nan')
    dof: int = 0
    chi2_threshold: float = float('nan')
    inliers: list = field(default_factory=list)    # indices of the observations used
    deviations: np.ndarray = field(default_factory=lambda: np.zeros(0))  # [std dev]
    outliers: list = field(default_factory=list)   # (index, reason) of those left out
    ambiguous: bool = False
    alternatives: list = field(default_factory=list)

    @property
    def trustworthy(self):
        """Return whether the estimate converged and no other minimum fits as well."""
        return bool(self.converged and not self.ambiguous)


class _Data:
    """The screened observations as arrays (a subset with ``take``)."""

    def __init__(self, observations, index):
        chosen = [observations[i] for i in index]
        self.index = np.asarray(index, dtype=int)
        self.centres = np.stack([o.centre for o in chosen]).reshape(-1, 3)
        self.poses = np.stack([o.T_robot_lens for o in chosen]).reshape(-1, 4, 4)
        self.points = np.stack([o.plane_point for o in chosen]).reshape(-1, 3)
        self.normals = np.stack([o.plane_normal for o in chosen]).reshape(-1, 3)
        self.sigma = np.array([o.sigma for o in chosen], dtype=float)
        self.offsets = np.array([o.angle_offset for o in chosen], dtype=float).reshape(-1, 2)
        self.u, self.v = _plane_basis(self.normals)

    def take(self, positions):
        """Return the subset at `positions` (into this data's rows)."""
        subset = object.__new__(_Data)
        for name, value in vars(self).items():
            setattr(subset, name, value[positions])
        return subset

    def __len__(self):
        """Return the number of observations."""
        return len(self.index)


@dataclass
class _Solutions:
    """Gauss-Newton runs: parameters (M, 2) = (s_x, s_y) and their final state."""

    p: np.ndarray
    cost: np.ndarray
    decrement: np.ndarray   # g^T N^-1 g: squared Gauss-Newton step [std dev^2]
    normal: np.ndarray      # J^T W J (M, 2, 2)
    state: np.ndarray
    iterations: np.ndarray
    largest: np.ndarray     # largest |whitened residual| [std dev]


def _wrap(angle):
    return np.remainder(np.asarray(angle) + math.pi, 2.0 * math.pi) - math.pi


def _solve2(matrix, vector):
    """Solve 2x2 systems (M, 2, 2) x = (M, 2); NaN where singular."""
    a, b, c, d = matrix[:, 0, 0], matrix[:, 0, 1], matrix[:, 1, 0], matrix[:, 1, 1]
    determinant = a * d - b * c
    scale = np.maximum(np.abs(a * d) + np.abs(b * c), 1e-300)
    with np.errstate(divide='ignore', invalid='ignore'):
        safe = np.where(np.abs(determinant) > 1e-12 * scale, determinant, np.nan)
        return np.stack([(d * vector[:, 0] - b * vector[:, 1]) / safe,
                         (a * vector[:, 1] - c * vector[:, 0]) / safe], axis=-1)


def _directions(parameters):
    """Return unit rays (M, 3) from (s_x, s_y) rows; NaN where the ray would leave the sky."""
    parameters = np.atleast_2d(np.asarray(parameters, dtype=float))
    horizontal = np.sum(parameters ** 2, axis=1)
    z = -np.sqrt(np.maximum(1.0 - horizontal, 0.0))
    directions = np.column_stack([parameters, z])
    directions[~(horizontal < 1.0)] = np.nan
    return directions


def _angles_jacobian(p):
    """d(phi0, theta0) / d(s_x, s_y) at (s_x, s_y) for s_z = -sqrt(1 - s_x^2 - s_y^2)."""
    sx, sy = p
    rho2 = sx * sx + sy * sy
    sz = -math.sqrt(max(1.0 - rho2, 1e-300))
    return np.vstack([-np.array([sx, sy]) / (math.sqrt(rho2) * -sz),
                      np.array([-sy, sx]) / rho2])


class SunEstimator:
    """Estimate s0 from spot observations with the lens model (see the module docstring)."""

    def __init__(self, lens, rim_points=64, contour_fraction=1.0, trust=None):
        """Build the spot model of `lens`: `rim_points` rays on the ring of `contour_fraction`."""
        self.lens = lens
        self.model = SpotModel(lens, rim_points, contour_fraction)
        self.trust = trust or TrustSettings()

    # -- the forward model -------------------------------------------------------------------
    def predicted_centres(self, directions, observations):
        """
        Model spot centres (M, K, 3) for M candidate rays and K observations.

        `directions` is (M, 3) (one ray for every observation) or (M, K, 3) (a ray per
        observation, e.g. moved along with the sun).
        """
        data = observations if isinstance(observations, _Data) else \
            _Data(observations, range(len(observations)))
        return self._centres(np.asarray(directions, dtype=float), data)

    def _centres(self, directions, data):
        k = len(data)
        if directions.ndim == 1:
            directions = directions[None]
        if directions.ndim == 2:
            directions = np.repeat(directions[:, None, :], k, axis=1)
        m = directions.shape[0]
        with np.errstate(invalid='ignore'):
            centres = self.model.centres(directions.reshape(-1, 3), np.tile(data.poses, (m, 1, 1)),
                                         np.tile(data.points, (m, 1)),
                                         np.tile(data.normals, (m, 1)))
        return centres.reshape(m, k, 3)

    def _rays(self, parameters, data):
        """Per-observation rays (M, K, 3) for the reference-time sun (s_x, s_y) rows."""
        directions = _directions(parameters)
        if not np.any(data.offsets):
            return np.repeat(directions[:, None, :], len(data), axis=1)
        # a trial step out of the sky (NaN row) stays NaN: a placeholder ray for the angles,
        # not a zero vector, which has none (a Levenberg-Marquardt trial of the ambiguity
        # search once ended an estimate there: "cannot normalise a zero vector")
        outside = ~np.all(np.isfinite(directions), axis=1)
        phi, theta = angles_from_direction(np.where(outside[:, None], [0.0, 0.0, -1.0],
                                                    directions))
        rays = direction_from_angles(phi[:, None] + data.offsets[None, :, 0],
                                     theta[:, None] + data.offsets[None, :, 1])
        rays[outside] = np.nan
        return rays

    def _whitened(self, parameters, data):
        """Whitened centre residuals (M, 2K) in each plane's axes for (s_x, s_y) rows."""
        parameters = np.atleast_2d(parameters)
        difference = self._centres(self._rays(parameters, data), data) - data.centres[None]
        along_u = np.einsum('mki,ki->mk', difference, data.u) / data.sigma
        along_v = np.einsum('mki,ki->mk', difference, data.v) / data.sigma
        return np.stack([along_u, along_v], axis=-1).reshape(len(parameters), -1)

    def cost(self, directions, observations):
        """Chi-square (M,) of reference-time rays (M, 3) against all `observations`."""
        data = _Data(observations, range(len(observations)))
        directions = unit(np.atleast_2d(directions))
        return np.sum(self._whitened(directions[:, :2], data) ** 2, axis=1)

    def synthetic_observation(self, sun_direction, T_robot_lens, plane_point=(0.0, 0.0, 0.0),
                              plane_normal=(0.0, 0.0, 1.0), sigma=0.5e-3, noise=None):
        """Return the model's spot for a known s0, plus optional noise (2,) on the plane [m]."""
        probe = Observation(np.zeros(3), T_robot_lens, plane_point, plane_normal, sigma)
        centre = self.predicted_centres(unit(sun_direction), [probe])[0, 0]
        if np.any(np.isnan(centre)):
            raise ValueError('the rim does not reach the plane for this pose: no spot')
        if noise is not None:
            u, v = _plane_basis(probe.plane_normal[None])
            centre = centre + noise[0] * u[0] + noise[1] * v[0]
        probe.centre = centre
        return probe

    def initial_guess(self, observations):
        """Chief-ray guess: the median direction from the lens centres to the spot centres."""
        rays = [unit(o.centre - o.T_robot_lens[:3, 3]) for o in observations]
        guess = unit(np.median(rays, axis=0))
        if guess[2] >= 0.0:
            raise ValueError('the spots are not below the lens: cannot guess the sun')
        return guess

    def feasible_start(self, guess, observations):
        """
        Move a guess towards the lens axes until every rim ray reaches the plane.

        A guess far off the lens axis can send rim rays into total internal reflection;
        the mean lens axis (the sun straight along it) always focuses.
        """
        guess = unit(guess)
        axis = -unit(np.mean([o.T_robot_lens[:3, 2] for o in observations], axis=0))
        for w in (0.0, 0.25, 0.5, 0.75, 0.9, 1.0):
            candidate = unit((1.0 - w) * guess + w * axis)
            if not np.any(np.isnan(self.predicted_centres(candidate, observations))):
                return candidate
        return guess

    # -- dispatch ----------------------------------------------------------------------------
    def estimate(self, observations, method='levenberg_marquardt', initial=None, trust=None,
                 **options):
        """Estimate with `method` ('interaction_matrix' or 'levenberg_marquardt')."""
        if method not in METHODS:
            raise ValueError(f'unknown method {method!r}; use one of {METHODS}')
        if not observations:
            raise ValueError('no observation to estimate from')
        if method == 'interaction_matrix':
            return self.interaction_matrix(observations, initial=initial, trust=trust,
                                           **options)
        return self.levenberg_marquardt(observations, initial=initial, trust=trust, **options)

    # -- screening ---------------------------------------------------------------------------
    def screen(self, observations, trust=None):
        """
        Split observations into those a sun can have cast and those it cannot.

        Returns (kept indices, [(index, reason)]): a non-finite centre, a lens not above the
        plane, a centre above the lens or off the plane, a chief ray flatter than
        ``min_chief_ray_elevation`` (a centre metres away), a lens axis farther than
        ``max_chief_ray_tilt`` from the observations' median chief ray (where the model is
        not trusted) are left out.
        """
        trust = trust or self.trust
        problems = [_screening_problem(o, trust) for o in observations]
        plausible = [o for o, problem in zip(observations, problems) if not problem]
        if plausible and trust.max_chief_ray_tilt < math.pi:
            # the sweep's chief ray: the median of its lens-to-spot directions, nearly the
            # sun's ray (a thin lens does not deviate the ray through its centre); judged
            # against it, not against each spot's own, a spot cannot move itself (or a
            # minority of spots move themselves) into or out of the model's reach
            chief = unit(np.median([unit(o.centre - o.T_robot_lens[:3, 3]) for o in plausible],
                                   axis=0))
            problems = [problem or _reach_problem(o, chief, trust)
                        for o, problem in zip(observations, problems)]
        kept, outliers = [], []
        for index, problem in enumerate(problems):
            if problem:
                outliers.append((index, problem))
            else:
                kept.append(index)
        return kept, outliers

    def _screened(self, observations, trust, method):
        """Return (trust, screened _Data, outliers, failure result when none is left)."""
        if not observations:
            raise ValueError('no observation to estimate from')
        trust = trust or self.trust
        kept, outliers = self.screen(observations, trust)
        if not kept:
            reasons = list(dict.fromkeys(reason for _, reason in outliers))
            return trust, None, outliers, self._failure(
                method, 0, "no observation a sun can have cast within the model's reach: "
                + reasons[0] + (f' (and {len(reasons) - 1} other reasons)' if len(reasons) > 1
                                else ''), outliers)
        return trust, _Data(observations, kept), outliers, None

    # -- the paper's method (Eqs 11-12) ------------------------------------------------------
    def _paired_features(self, angles, data):
        """y_t (K, P, 2): Eq 10 features for P candidate angles (K, P, 2) per observation."""
        k, probes = angles.shape[:2]
        poses = np.repeat(data.poses, probes, axis=0)
        flat = angles.reshape(-1, 2)
        directions = direction_from_angles(flat[:, 0], flat[:, 1])
        centres = self.model.centres(directions, poses, np.repeat(data.points, probes, axis=0),
                                     np.repeat(data.normals, probes, axis=0))
        features = position_features(centres_in_optics(poses, self.lens.T_lens_optics, centres))
        return features.reshape(k, probes, 2)

    def _solve_images(self, data, observations, initial, gain, delta, tolerance,
                      max_iterations, min_polar):
        """Eqs 11-12 per image (vectorised): angles (K, 2), done (K,), reasons, iterations."""
        count = len(data)
        y_img = position_features(centres_in_optics(data.poses, self.lens.T_lens_optics,
                                                    data.centres))
        vartheta = np.empty((count, 2))
        for i, index in enumerate(data.index):
            own = [observations[index]]
            start = unit(initial) if initial is not None else self.feasible_start(
                self.initial_guess(own), own)
            vartheta[i] = [float(v) for v in angles_from_direction(start)]
        vartheta[:, 0] = np.clip(vartheta[:, 0], min_polar, math.pi - 1e-6)
        active = np.ones(count, bool)
        done = np.zeros(count, bool)
        reasons = [''] * count
        residual = np.full(count, np.inf)
        used = np.zeros(count, int)
        steps = np.array([[0.0, 0.0], [delta, 0.0], [0.0, delta]])
        previous = vartheta.copy()
        halvings = np.zeros(count, int)
        for iteration in range(1, max_iterations + 1):
            index = np.flatnonzero(active)
            if index.size == 0:
                break
            y = self._paired_features(vartheta[index, None, :] + steps[None], data.take(index))
            used[index] = iteration
            for j, i in enumerate(index):
                if np.any(np.isnan(y[j])):
                    # The step went where the rim misses the plane: halve it and retry.
                    halvings[i] += 1
                    if iteration == 1 or halvings[i] > 10:
                        reasons[i] = f'the rim misses the plane at iteration {iteration}'
                        active[i] = False
                    vartheta[i] = previous[i] + 0.5 * (vartheta[i] - previous[i])
                    continue
                error = np.array([y[j, 0, 0] - y_img[i, 0], _wrap(y[j, 0, 1] - y_img[i, 1])])
                residual[i] = float(np.linalg.norm(error))
                if residual[i] < tolerance:
                    done[i], active[i] = True, False
                    continue
                # Eq 12: forward differences of y in each angle.
                a = np.column_stack([
                    [y[j, 1, 0] - y[j, 0, 0], _wrap(y[j, 1, 1] - y[j, 0, 1])],
                    [y[j, 2, 0] - y[j, 0, 0], _wrap(y[j, 2, 1] - y[j, 0, 1])]]) / delta
                if abs(np.linalg.det(a)) < 1e-14:
                    reasons[i] = f'singular interaction matrix at iteration {iteration}'
                    active[i] = False
                    continue
                previous[i] = vartheta[i]
                vartheta[i] = vartheta[i] - gain * np.linalg.solve(a, error)  # Eq 11
                vartheta[i, 0] = min(max(vartheta[i, 0], min_polar), math.pi - 1e-6)
                vartheta[i, 1] %= 2.0 * math.pi
        for i in np.flatnonzero(active):
            reasons[i] = (f'no convergence in {max_iterations} iterations '
                          f'(||y_t - y_img|| = {residual[i]:.3g})')
        return vartheta, done, reasons, residual, int(used.max(initial=0))

    def _image_information(self, angles, data, delta=1e-6):
        """I_k = J_k^T J_k (K, 2, 2): whitened centre Jacobian per (phi0, theta0) of each image."""
        probes = angles[:, None, :] + np.array([[0.0, 0.0], [delta, 0.0], [0.0, delta]])[None]
        flat = probes.reshape(-1, 2)
        centres = self.model.centres(direction_from_angles(flat[:, 0], flat[:, 1]),
                                     np.repeat(data.poses, 3, axis=0),
                                     np.repeat(data.points, 3, axis=0),
                                     np.repeat(data.normals, 3, axis=0)).reshape(-1, 3, 3)
        planar = np.stack([np.einsum('kpi,ki->kp', centres, data.u),
                           np.einsum('kpi,ki->kp', centres, data.v)], axis=-1)
        jacobian = (planar[:, 1:] - planar[:, :1]) / delta / data.sigma[:, None, None]
        jacobian = np.swapaxes(jacobian, 1, 2)  # (K, 2 residuals, 2 angles)
        return np.einsum('kri,krj->kij', jacobian, jacobian)

    def interaction_matrix(self, observations, initial=None, gain=0.9, delta=1e-5,
                           tolerance=1e-9, max_iterations=60, min_polar=0.5 * math.pi + 0.01,
                           trust=None):
        """
        Eqs 11-12 for each observation (vectorised over them), then their weighted mean.

        Each observation runs its own iteration (stopped when ||y_t - y_img|| < tolerance);
        one that fails (singular A_t, rim lost, no convergence) or whose answer disagrees
        with the others' beyond their uncertainty is left out with its reason (see the
        module docstring); converged only when the rest agree.
        """
        if not 0.0 < gain <= 2.0 or not delta > 0.0:
            raise ValueError('gain must be in (0, 2] and delta > 0')
        trust, data, outliers, failure = self._screened(observations, trust,
                                                        'interaction_matrix')
        if failure:
            return failure
        vartheta, done, reasons, residual, iterations = self._solve_images(
            data, observations, initial, gain, delta, tolerance, max_iterations, min_polar)
        rejected = [(int(data.index[i]), reasons[i]) for i in np.flatnonzero(~done)]
        if not done.any():
            return self._failure('interaction_matrix', iterations,
                                 'no image converged: ' + '; '.join(dict.fromkeys(
                                     r for _, r in rejected)), outliers + rejected)
        # Each image's answer at the reference time, with its information.
        answers = vartheta - data.offsets
        information = self._image_information(vartheta, data)
        rows = list(np.flatnonzero(done))
        threshold = trust.outlier_threshold()
        no_majority = False
        while len(rows) > 2:
            deviation = self._leave_one_out(answers[rows], information[rows])
            worst, no_majority = trust.worst_outlier(deviation, len(rejected), len(data))
            if worst is None:
                break
            rejected.append((int(data.index[rows[worst]]),
                             f'its answer lies {math.sqrt(deviation[worst]):.1f} standard '
                             "deviations from the other images' (limit "
                             f'{math.sqrt(threshold):.1f})'))
            del rows[worst]
        mean, covariance, chi2, deviations = self._weighted_mean(answers[rows],
                                                                 information[rows])
        dof = 2 * (len(rows) - 1)
        limit = trust.fit_threshold(dof)
        problems = []
        if len(rejected) / len(data) >= trust.max_outlier_fraction:
            problems.append(f'{len(rejected)} of {len(data)} images left out (limit: fewer '
                            f'than {trust.max_outlier_fraction:.0%})')
        if dof > 0 and not chi2 <= limit:
            problems.append(f'the images disagree: chi-square {chi2:.3g} > {limit:.3g} '
                            f'({dof} degrees of freedom), deviations '
                            + ', '.join(f'{d:.1f}' for d in deviations) + ' standard deviations')
            if no_majority:
                problems.append(_NO_MAJORITY.format(len(rejected), len(data)))
        if not np.all(np.isfinite(covariance)):
            problems.append('the images do not determine both angles (singular information)')
        direction = direction_from_angles(mean[0], mean[1])
        inliers = data.take(np.array(rows, dtype=int))
        result = SunEstimateResult(
            phi0=float(mean[0]), theta0=float(mean[1] % (2.0 * math.pi)), direction=direction,
            covariance=covariance, method='interaction_matrix', iterations=iterations,
            residual=float(residual[rows].max()), converged=not problems,
            reason='; '.join(problems), observations=len(rows),
            per_observation=[tuple(v) for v in answers[rows]], chi2=float(chi2), dof=dof,
            chi2_threshold=limit, inliers=[int(i) for i in inliers.index],
            deviations=deviations, outliers=sorted(outliers + rejected))
        if result.converged and trust.ambiguity_search:
            joint = float(np.sum(self._whitened(direction[None, :2], inliers) ** 2))
            runs, found = self._find_alternatives(inliers, direction[:2], joint, deviations,
                                                  trust)
            self._report_alternatives(result, direction[:2], runs, found)
        return result

    @staticmethod
    def _weighted_mean(answers, information):
        """Information-weighted mean of (phi, theta) rows, its covariance, chi2, deviations."""
        reference = answers[0]
        local = answers - reference
        local[:, 1] = _wrap(local[:, 1])
        total = information.sum(axis=0)
        try:
            covariance = np.linalg.inv(total)
        except np.linalg.LinAlgError:
            covariance = np.full((2, 2), np.inf)
            return reference.copy(), covariance, float('nan'), np.full(len(answers), np.nan)
        mean_local = covariance @ np.einsum('kij,kj->i', information, local)
        error = local - mean_local
        squared = np.einsum('ki,kij,kj->k', error, information, error)
        return reference + mean_local, covariance, float(squared.sum()), np.sqrt(squared)

    @staticmethod
    def _leave_one_out(answers, information):
        """Squared Mahalanobis distance of each answer from the mean of the others (2 dof)."""
        local = answers - answers[0]
        local[:, 1] = _wrap(local[:, 1])
        total = information.sum(axis=0)
        weighted = np.einsum('kij,kj->ki', information, local)
        distances = np.empty(len(answers))
        total_inverse = np.linalg.pinv(total)
        for k in range(len(answers)):
            others = total - information[k]
            others_mean = np.linalg.pinv(others) @ (weighted.sum(axis=0) - weighted[k])
            # (I_k^-1 + I_o^-1)^-1 = I_k (I_k + I_o)^-1 I_o
            metric = information[k] @ total_inverse @ others
            error = local[k] - others_mean
            distances[k] = float(error @ (0.5 * (metric + metric.T)) @ error)
        return distances

    # -- joint damped Gauss-Newton / Levenberg-Marquardt -------------------------------------
    def _local(self, data, p, huber, delta):
        """Return cost, normal matrix, gradient, decrement, largest |residual| at rows p."""
        m = len(p)
        probes = np.concatenate([p, p + [delta, 0.0], p + [0.0, delta]])
        r = self._whitened(probes, data)
        r0, forward = r[:m], r[m:].reshape(2, m, -1)
        step = np.full((2, m), delta)
        missing = np.any(~np.isfinite(forward), axis=2) & np.all(np.isfinite(r0), axis=1)
        if np.any(missing):  # near where the rim is lost: difference backwards instead
            axis, rows = np.nonzero(missing)
            offsets = np.zeros((len(rows), 2))
            offsets[np.arange(len(rows)), axis] = -delta
            forward[axis, rows] = self._whitened(p[rows] + offsets, data)
            step[axis, rows] = -delta
        jacobian = np.moveaxis((forward - r0[None]) / step[:, :, None], 0, -1)  # (M, R, 2)
        magnitude = np.abs(r0)
        if huber is None:
            weights = np.ones_like(r0)
            cost = np.sum(r0 ** 2, axis=1)
        else:
            weights = np.minimum(1.0, huber / np.maximum(magnitude, 1e-300))
            cost = np.sum(np.where(magnitude <= huber, r0 ** 2,
                                   2.0 * huber * magnitude - huber ** 2), axis=1)
        normal = np.einsum('mri,mr,mrj->mij', jacobian, weights, jacobian)
        gradient = np.einsum('mri,mr->mi', jacobian, weights * r0)
        with np.errstate(invalid='ignore'):
            decrement = np.einsum('mi,mi->m', gradient, _solve2(normal, gradient))
        decrement = np.where(np.isfinite(decrement) & np.isfinite(cost), decrement, np.inf)
        return cost, normal, gradient, decrement, np.max(magnitude, axis=1)

    def _gauss_newton(self, data, starts, huber=None, max_iterations=50, delta=1e-7,
                      damping=1e-3, step_tolerance=1e-3, known=None, known_radius=0.0):
        """
        Levenberg-Marquardt from each start (M, 2) at once; see ``_Solutions``.

        A damped step is tried by building the local model at the trial point (one model
        call per iteration, as the cost comes with it): a lower cost accepts the step and its
        model, a higher one keeps the old point and raises the damping; 14 refusals in a row
        end the run as _STUCK. A run that comes within `known_radius` [rad] of the ray
        `known` stops as _RETURNED (the ambiguity search does not polish the minimum it
        started from).
        """
        p = np.array(starts, dtype=float).reshape(-1, 2)
        m = len(p)
        state = np.full(m, _ACTIVE)
        lam = np.full(m, float(damping))
        iterations = np.zeros(m, int)
        refusals = np.zeros(m, int)
        cost, normal, gradient, decrement, largest = self._local(data, p, huber, delta)
        state[~np.isfinite(cost)] = _INFEASIBLE
        state[(state == _ACTIVE) & (decrement < step_tolerance ** 2)] = _CONVERGED
        for _ in range(15 * max_iterations):  # each accepted step after at most 14 refusals
            rows = np.flatnonzero(state == _ACTIVE)
            if rows.size == 0:
                break
            diagonal = np.einsum('mii->mi', normal[rows])
            diagonal = diagonal + 1e-12 * diagonal.sum(axis=1, keepdims=True) + 1e-300
            damped = normal[rows] + lam[rows, None, None] * (
                diagonal[:, :, None] * np.eye(2)[None])
            trial = p[rows] - _solve2(damped, gradient[rows])
            local = self._local(data, trial, huber, delta)
            better = np.isfinite(local[0]) & (local[0] < cost[rows])
            accepted, refused = rows[better], rows[~better]
            p[accepted] = trial[better]
            (cost[accepted], normal[accepted], gradient[accepted], decrement[accepted],
             largest[accepted]) = (value[better] for value in local)
            lam[accepted] = np.maximum(lam[accepted] / 10.0, 1e-9)
            iterations[accepted] += 1
            refusals[accepted] = 0
            lam[refused] *= 10.0
            refusals[refused] += 1
            state[refused[refusals[refused] >= 14]] = _STUCK
            state[accepted[decrement[accepted] < step_tolerance ** 2]] = _CONVERGED
            state[accepted[(iterations[accepted] >= max_iterations)
                           & (state[accepted] == _ACTIVE)]] = _EXHAUSTED
            if known is not None and accepted.size:
                near = _directions(p[accepted]) @ known > math.cos(known_radius)
                state[accepted[near]] = _RETURNED
        state[state == _ACTIVE] = _EXHAUSTED
        returned = state == _RETURNED
        cost[returned], decrement[returned] = np.inf, np.inf
        return _Solutions(p=p, cost=cost, decrement=decrement, normal=normal, state=state,
                          iterations=iterations, largest=largest)

    def _minimum_problem(self, data, p, normal, cost, step_tolerance):
        """
        Return ('' when p is a minimum of the plain cost, else why not; residuals at p).

        The test is the textbook one, on the cost itself rather than the Gauss-Newton model
        (which misjudges the curvature near a fold of the spot map): a quadratic fitted to
        the cost on a small ring around p (axes of J^T J, 0.003 standard deviations, at most
        1e-4 rad) gives the gradient g and Hessian H; a minimum has H positive definite and
        a Newton step sqrt(g^T H^-1 g) below `step_tolerance` standard deviations.
        """
        try:
            values, vectors = np.linalg.eigh(0.5 * (normal + normal.T))
        except np.linalg.LinAlgError:
            values, vectors = np.zeros(2), np.eye(2)
        angles = np.linspace(0.0, 2.0 * math.pi, 8, endpoint=False)
        circle = np.column_stack([np.cos(angles), np.sin(angles)])
        with np.errstate(divide='ignore', invalid='ignore'):
            radii = np.minimum(_FIT_RADIUS / np.sqrt(np.maximum(values, 0.0)), _FIT_ANGLE)
        d = (circle * np.nan_to_num(radii, nan=_FIT_ANGLE)) @ vectors.T
        residuals = self._whitened(np.vstack([p, p + d]), data)
        at_p = residuals[0]
        if not values[0] > 1e-12 * max(values[1], 1e-300):
            return ('the data do not determine the sun in one direction (singular normal '
                    'matrix)'), at_p
        around = np.sum(residuals[1:] ** 2, axis=1)
        if not np.all(np.isfinite(around)):
            return 'the rim misses the plane right next to the solution', at_p
        # cost(p + d) - cost(p) = g.d + (h11 d1^2 + 2 h12 d1 d2 + h22 d2^2) / 2 on the ring
        design = np.column_stack([d, 0.5 * d[:, 0] ** 2, d[:, 0] * d[:, 1], 0.5 * d[:, 1] ** 2])
        coefficients = np.linalg.lstsq(design, around - cost, rcond=None)[0]
        gradient = coefficients[:2]
        hessian = np.array([[coefficients[2], coefficients[3]],
                            [coefficients[3], coefficients[4]]])
        curvature = np.linalg.eigvalsh(hessian)
        if not curvature[0] > 0.0:
            return (f'not a minimum: the cost curves down in one direction (a saddle or a '
                    f'ridge; Hessian eigenvalues {curvature[0]:.3g}, {curvature[1]:.3g})'), at_p
        newton = float(gradient @ np.linalg.solve(hessian, gradient))
        if not newton < step_tolerance ** 2:
            return (f'not a minimum: the gradient is not zero (the Newton step is '
                    f'{math.sqrt(newton):.3g} standard deviations)'), at_p
        return '', at_p

    def levenberg_marquardt(self, observations, initial=None, max_iterations=50, huber=3.0,
                            delta=1e-7, damping=1e-3, trust=None):
        """
        Joint fit over all observations (see the module docstring).

        Converged means a minimum (positive definite Hessian, Newton step below
        ``trust.step_tolerance`` standard deviations) whose chi-square passes the fit test;
        otherwise ``reason`` says what failed.
        """
        trust, data, outliers, failure = self._screened(observations, trust,
                                                        'levenberg_marquardt')
        if failure:
            return failure
        chosen = [observations[i] for i in data.index]
        start = unit(initial) if initial is not None else self.feasible_start(
            self.initial_guess(chosen), chosen)
        options = {'max_iterations': max_iterations, 'delta': delta, 'damping': damping,
                   'step_tolerance': 0.1 * trust.step_tolerance}
        robust = self._gauss_newton(data, start[None, :2], huber=huber, **options)
        p = robust.p[0]
        iterations = int(robust.iterations[0])
        rows = list(range(len(data)))
        rejected = []
        threshold = trust.outlier_threshold()
        no_majority = False
        # Where no residual reaches the Huber corner the robust fit is the plain one.
        plain = robust.largest[0] <= huber and robust.state[0] != _INFEASIBLE
        while True:
            if plain:
                fit, plain = robust, False
            else:
                fit = self._gauss_newton(data.take(np.array(rows)), p[None], **options)
            p = fit.p[0]
            iterations += int(fit.iterations[0]) if fit is not robust else 0
            if fit.state[0] == _INFEASIBLE or len(rows) <= 2:
                break
            squared = np.sum(self._whitened(p, data.take(np.array(rows)))
                             .reshape(len(rows), 2) ** 2, axis=1)
            worst, no_majority = trust.worst_outlier(squared, len(rejected), len(data))
            if worst is None:
                break
            distance = math.sqrt(squared[worst]) * data.sigma[rows[worst]]
            rejected.append((int(data.index[rows[worst]]),
                             f'its centre lies {math.sqrt(squared[worst]):.1f} standard '
                             f'deviations ({distance * 1e3:.3g} mm) from the fit (limit '
                             f'{math.sqrt(threshold):.1f})'))
            del rows[worst]
        inliers = data.take(np.array(rows))
        counts = (len(rejected), len(data))
        result = self._lm_result(inliers, fit, 0, iterations, trust, outliers + rejected, counts)
        if no_majority and not result.converged:
            result.reason += '; ' + _NO_MAJORITY.format(len(rejected), len(data))
        if result.converged and trust.ambiguity_search:
            runs, found = self._find_alternatives(inliers, p, float(fit.cost[0]),
                                                  result.deviations, trust)
            if found and runs.cost[found[0]] < fit.cost[0] - max(0.01, 1e-6 * fit.cost[0]):
                # A clearly better minimum: it is the estimate, the first one an alternative.
                better = self._lm_result(inliers, runs, found[0], iterations, trust,
                                         outliers + rejected, counts)
                if better.converged:
                    result, p = better, runs.p[found[0]]
                    runs, found = self._find_alternatives(inliers, p, result.chi2,
                                                          result.deviations, trust)
            self._report_alternatives(result, p, runs, found)
        return result

    def _lm_result(self, data, solutions, row, iterations, trust, outliers, counts):
        """
        Build the result of Gauss-Newton run `row` on `data` (the inliers).

        `counts` = (observations left out by the fit, observations screened in).
        """
        p = solutions.p[row]
        direction = _directions(p)[0]
        if not np.all(np.isfinite(direction)):
            return self._failure('levenberg_marquardt', iterations,
                                 'the solution left the sky (|s0_xy| >= 1)', outliers)
        phi, theta = (float(v) for v in angles_from_direction(direction))
        cost = float(solutions.cost[row])
        dof = 2 * len(data) - 2
        limit = trust.fit_threshold(dof)
        state = solutions.state[row]
        problems = []
        problem, residuals = self._minimum_problem(data, p, solutions.normal[row], cost,
                                                   trust.step_tolerance)
        residuals = residuals.reshape(len(data), 2)
        deviations = np.sqrt(np.sum(residuals ** 2, axis=1))
        if state == _INFEASIBLE:
            problems.append('the rim misses the plane at the solution (TIR or no hit)')
        else:
            if problem and state == _EXHAUSTED:
                problem = f'no convergence in the iteration limit: {problem}'
            elif problem and state == _STUCK:
                problem = f'no step lowers the cost, but {problem}'
            if problem:
                problems.append(problem)
        if not cost <= limit:
            problems.append(
                f'the fit does not match the noise: chi-square {cost:.4g} > {limit:.4g} '
                f'({dof} degrees of freedom, significance {trust.fit_alpha:g}): the '
                'observations do not fit one sun (wrong pose or spot, sun motion not '
                'corrected, or sigma too small)')
        left_out, screened_in = counts
        if left_out / screened_in >= trust.max_outlier_fraction:
            problems.append(f'{left_out} of {screened_in} observations left out (limit: fewer '
                            f'than {trust.max_outlier_fraction:.0%})')
        covariance = _angle_covariance(p, solutions.normal[row])
        if not np.all(np.isfinite(covariance)):
            problems.append('covariance unavailable (singular normal matrix)')
        distances = residuals * data.sigma[:, None]
        distance_rms = float(np.sqrt(np.mean(np.sum(distances ** 2, axis=1))))
        return SunEstimateResult(
            phi0=phi, theta0=theta, direction=direction, covariance=covariance,
            method='levenberg_marquardt', iterations=iterations, residual=distance_rms,
            converged=not problems, reason='; '.join(problems), observations=len(data),
            chi2=cost, dof=dof, chi2_threshold=limit,
            inliers=[int(i) for i in data.index], deviations=deviations,
            outliers=sorted(outliers))

    # -- ambiguity ---------------------------------------------------------------------------
    def _search_starts(self, p):
        """Return starts (M, 2) on rings around the ray of p (see _SEARCH_RADII_DEG)."""
        centre = _directions(p)[0]
        helper = np.array([0.0, 0.0, 1.0]) if abs(centre[2]) < 0.9 else np.array([1.0, 0, 0])
        u = unit(np.cross(centre, helper))
        v = np.cross(centre, u)
        starts = []
        for radius in np.radians(_SEARCH_RADII_DEG):
            for angle in np.linspace(0.0, 2.0 * math.pi, _SEARCH_DIRECTIONS, endpoint=False):
                ray = math.cos(radius) * centre + math.sin(radius) * (
                    math.cos(angle) * u + math.sin(angle) * v)
                if ray[2] < 0.0:
                    starts.append(ray[:2])
        return np.array(starts).reshape(-1, 2)

    def _find_alternatives(self, data, p, cost, deviations, trust, max_iterations=30,
                           images=2):
        """
        Other minima of the plain cost that fit as well as p's `cost`.

        A joint minimum that fits within the noise fits every observation within a few
        standard deviations, so it lies near a root of each single image: the roots of the
        `images` best-fitted observations (smallest `deviations`) are searched from starts on
        rings around p (cheap: one observation each), and those away from p are polished on
        all observations.
        Returns (runs, rows): the joint Gauss-Newton runs and the rows of the distinct
        minima found, best first.
        """
        centre = _directions(p)[0]
        radius = 0.5 * trust.ambiguity_separation
        candidates = []
        for row in np.argsort(deviations)[:images]:
            single = data.take(np.array([row]))
            roots = self._gauss_newton(single, self._search_starts(p),
                                       max_iterations=max_iterations,
                                       step_tolerance=0.1 * trust.step_tolerance, known=centre,
                                       known_radius=radius)
            settled = (roots.state == _CONVERGED) | (roots.state == _STUCK)
            for k in np.flatnonzero(settled & (roots.cost <= trust.outlier_threshold())):
                ray = _directions(roots.p[k])[0]
                if _angle(ray, centre) > trust.ambiguity_separation and all(
                        _angle(ray, _directions(q)[0]) > radius for q in candidates):
                    candidates.append(roots.p[k])
        if not candidates:
            return None, []
        runs = self._gauss_newton(data, np.array(candidates), max_iterations=max_iterations,
                                  step_tolerance=0.1 * trust.step_tolerance, known=centre,
                                  known_radius=radius)
        limit = min(trust.fit_threshold(2 * len(data) - 2), cost + trust.ambiguity_chi2)
        found = []
        for k in np.argsort(runs.cost):
            if runs.state[k] in (_INFEASIBLE, _RETURNED) or not runs.cost[k] <= limit:
                continue
            ray = _directions(runs.p[k])[0]
            if _angle(ray, centre) <= trust.ambiguity_separation or any(
                    _angle(ray, _directions(runs.p[j])[0]) <= trust.ambiguity_separation
                    for j in found):
                continue
            if self._minimum_problem(data, runs.p[k], runs.normal[k], float(runs.cost[k]),
                                     trust.step_tolerance)[0]:
                continue
            found.append(int(k))
        return runs, found

    @staticmethod
    def _report_alternatives(result, p, runs, found):
        """Fill result.ambiguous, alternatives and reason from the minima found."""
        centre = _directions(p)[0]
        result.alternatives = []
        for k in found:
            ray = _directions(runs.p[k])[0]
            phi, theta = (float(v) for v in angles_from_direction(ray))
            result.alternatives.append(Alternative(
                direction=ray, phi0=phi, theta0=theta, chi2=float(runs.cost[k]),
                separation=_angle(ray, centre),
                covariance=_angle_covariance(runs.p[k], runs.normal[k])))
        result.ambiguous = bool(result.alternatives)
        if result.ambiguous:
            best = result.alternatives[0]
            others = f' (and {len(found) - 1} more)' if len(found) > 1 else ''
            result.reason = '; '.join(filter(None, [result.reason, (
                f'ambiguous: another minimum {math.degrees(best.separation):.3g} deg away fits '
                f'as well (chi-square {best.chi2:.4g} against {result.chi2:.4g}; phi0 '
                f'{math.degrees(best.phi0):.3f} deg, theta0 {math.degrees(best.theta0):.3f} '
                f'deg){others}: observe from poses that change the geometry (tilt as well as '
                'yaw)')]))

    @staticmethod
    def _failure(method, iterations, reason, outliers=()):
        nan = float('nan')
        return SunEstimateResult(phi0=nan, theta0=nan, direction=np.full(3, nan),
                                 covariance=np.full((2, 2), nan), method=method,
                                 iterations=iterations, residual=nan, converged=False,
                                 reason=reason, observations=0, outliers=sorted(outliers))


def _angle(a, b):
    """Angle between two unit vectors [rad]."""
    return math.acos(min(1.0, max(-1.0, float(a @ b))))


def _angle_covariance(p, normal):
    """Covariance of (phi0, theta0) from the normal matrix (J^T J) in (s_x, s_y) at p."""
    try:
        jacobian = _angles_jacobian(p)
        return jacobian @ np.linalg.inv(normal) @ jacobian.T
    except (np.linalg.LinAlgError, ZeroDivisionError, ValueError):
        return np.full((2, 2), np.nan)


def _screening_problem(observation, trust):
    """Why no sun can have cast this observation's spot ('' when one can)."""
    centre = observation.centre
    if not np.all(np.isfinite(centre)):
        return f'its centre {centre.tolist()} is not finite'
    normal = observation.plane_normal
    lens = observation.T_robot_lens[:3, 3]
    lens_height = float((lens - observation.plane_point) @ normal)
    if lens_height <= 0.0:
        return f'the lens is {-lens_height * 1e3:.3g} mm below the plane, not above it'
    with np.errstate(over='ignore', invalid='ignore'):
        ray = centre - lens
        drop = float(-(ray @ normal))
        if drop <= 0.0:
            return (f'its centre lies {-drop:.3g} m above the lens: light from the lens goes '
                    'down')
        off_plane = float((centre - observation.plane_point) @ normal)
        if abs(off_plane) > trust.plane_tolerance:
            return (f'its centre lies {off_plane * 1e3:.3g} mm off the plane (tolerance '
                    f'{trust.plane_tolerance * 1e3:.3g} mm)')
        along = ray + drop * normal
        scale = max(float(np.max(np.abs(along))), 1e-300)
        horizontal = scale * float(np.linalg.norm(along / scale))
        elevation = math.atan2(drop, horizontal)
    if elevation < trust.min_chief_ray_elevation:
        return (f'its centre is {horizontal:.3g} m from the lens foot: the chief ray rises '
                f'only {math.degrees(elevation):.3g} deg above the plane (limit '
                f'{math.degrees(trust.min_chief_ray_elevation):.3g} deg)')
    return ''


def _reach_problem(observation, chief, trust):
    """Why the model is not trusted with this observation, sun along `chief` ('' if it is)."""
    axis = observation.T_robot_lens[:3, 2]
    tilt = math.acos(max(-1.0, min(1.0, float(-(chief @ axis)))))
    if tilt <= trust.max_chief_ray_tilt:
        return ''
    return (f"the sweep's chief ray (the median lens-to-spot direction, nearly the sun's ray) "
            f'lies {math.degrees(tilt):.3g} deg off its lens axis (limit '
            f'{math.degrees(trust.max_chief_ray_tilt):.3g} deg): so far off its axis the rim '
            'model misplaces the spot by up to millimetres, alike over the sweep; face the '
            'lens to the sun')


def _plane_basis(normals):
    """Two unit vectors (K, 3) each completing a plane normal (K, 3) to a frame."""
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = unit(np.cross(normals, helper))
    return u, np.cross(normals, u)
