"""
Sun-orientation estimation from light-spot observations (paper Sec. III-C, Eqs 10-12).

Unknown: the sun ray s0 in the robot frame, as ray angles vartheta = (phi0, theta0) of Eq 2
(phi0 in (pi/2, pi): the ray goes down). These are the optics-frame angles of the paper for
the rig at x = 0, where the optics axes are parallel to the robot's.

An observation is the ellipse centre of the spot on the ground (robot frame) with the lens
pose T_robot_lens at the time of the image and the ground plane. The model is
``spot.SpotModel``: the lens rim traced for a candidate s0 (the outermost contour, Sec.
III-B) and its ellipse centre.

Two methods:
- ``interaction_matrix`` (the paper, Eqs 11-12): per observation,
  vartheta_{t+1} = vartheta_t - lambda A_t^-1 (y_t - y_img) with y = [Pi, Theta] of Eq 10 in
  that observation's optics frame and A_t by forward differences of step delta; stops when
  ||y_t - y_img|| < tolerance. Several observations (a yaw sweep, Sec. V-B) are solved one
  by one and averaged as unit vectors, as the paper reports the mean of a sweep; the
  covariance is the spread of the per-image estimates divided by their number.
- ``levenberg_marquardt``: all observations jointly, residuals = (model centre - measured
  centre) / sigma on the ground, unknowns = the horizontal components of s0 (no
  singularity at the zenith), Huber weights against outliers, damped Gauss-Newton steps;
  covariance (J^T W J)^-1 (scaled up by the reduced chi-square when it exceeds 1), mapped to
  (phi0, theta0). Its ``residual`` is the rms distance between model and measured centres
  [m] (the interaction-matrix method reports the largest final ||y_t - y_img||).

The initial guess for both is the chief ray: the line from the lens centre to the spot
centre (a ray through the centre of a thin lens is not deviated), unless ``initial`` is
given; the interaction-matrix method keeps phi0 away from pi (the singularity of A_t).

API
---
``Observation(centre, T_robot_lens, plane_point=(0,0,0), plane_normal=(0,0,1),
sigma=0.5e-3)``; ``SunEstimator(lens, rim_points=64, contour_fraction=1.0)`` with
``.estimate(observations, method='levenberg_marquardt', initial=None, **options)``,
``.interaction_matrix(observations, ...)``, ``.levenberg_marquardt(observations, ...)``,
``.synthetic_observation(s0, T_robot_lens, ...)`` (the model's own spot, for tests and the
simulation); all return ``SunEstimateResult`` (phi0, theta0, direction, covariance (2x2),
method, iterations, residual, converged, reason, observations, per_observation).
"""

from dataclasses import dataclass, field
import math

from helio_optics.geometry import angles_from_direction, direction_from_angles, unit
from helio_optics.spot import centres_in_optics, position_features, SpotModel
import numpy as np

METHODS = ('interaction_matrix', 'levenberg_marquardt')


@dataclass
class Observation:
    """A spot centre on a plane with the lens pose when it was seen (robot frame, SI)."""

    centre: np.ndarray
    T_robot_lens: np.ndarray
    plane_point: np.ndarray = field(default_factory=lambda: np.zeros(3))
    plane_normal: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    sigma: float = 0.5e-3  # standard deviation of the centre on the plane, per axis [m]

    def __post_init__(self):
        """Check shapes and values."""
        self.centre = np.asarray(self.centre, dtype=float).reshape(3)
        self.T_robot_lens = np.asarray(self.T_robot_lens, dtype=float).reshape(4, 4)
        self.plane_point = np.asarray(self.plane_point, dtype=float).reshape(3)
        self.plane_normal = unit(np.asarray(self.plane_normal, dtype=float).reshape(3))
        if not (np.all(np.isfinite(self.centre)) and np.all(np.isfinite(self.T_robot_lens))):
            raise ValueError('observation holds NaN or infinite values')
        if not self.sigma > 0.0:
            raise ValueError(f'sigma must be > 0 m, got {self.sigma}')


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


def _wrap(angle):
    return np.remainder(np.asarray(angle) + math.pi, 2.0 * math.pi) - math.pi


class SunEstimator:
    """Estimate s0 from spot observations with the lens model (see the module docstring)."""

    def __init__(self, lens, rim_points=64, contour_fraction=1.0):
        """Build the spot model of `lens`: `rim_points` rays on the ring of `contour_fraction`."""
        self.lens = lens
        self.model = SpotModel(lens, rim_points, contour_fraction)

    # -- the forward model -------------------------------------------------------------------
    def predicted_centres(self, directions, observations):
        """Model spot centres (M, K, 3) for M candidate rays (M, 3) and K observations."""
        directions = np.atleast_2d(directions)
        m, k = directions.shape[0], len(observations)
        poses = np.stack([o.T_robot_lens for o in observations])
        points = np.stack([o.plane_point for o in observations])
        normals = np.stack([o.plane_normal for o in observations])
        centres = self.model.centres(np.repeat(directions, k, axis=0), np.tile(poses, (m, 1, 1)),
                                     np.tile(points, (m, 1)), np.tile(normals, (m, 1)))
        return centres.reshape(m, k, 3)

    def synthetic_observation(self, sun_direction, T_robot_lens, plane_point=(0.0, 0.0, 0.0),
                              plane_normal=(0.0, 0.0, 1.0), sigma=0.5e-3, noise=None):
        """Return the model's spot for a known s0, plus optional noise (2,) on the plane [m]."""
        probe = Observation(np.zeros(3), T_robot_lens, plane_point, plane_normal, sigma)
        centre = self.predicted_centres(unit(sun_direction), [probe])[0, 0]
        if np.any(np.isnan(centre)):
            raise ValueError('the rim does not reach the plane for this pose: no spot')
        if noise is not None:
            u, v = _plane_basis(probe.plane_normal)
            centre = centre + noise[0] * u + noise[1] * v
        probe.centre = centre
        return probe

    def initial_guess(self, observations):
        """Chief-ray guess: the mean direction from the lens centres to the spot centres."""
        rays = [unit(o.centre - o.T_robot_lens[:3, 3]) for o in observations]
        guess = unit(np.mean(rays, axis=0))
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
    def estimate(self, observations, method='levenberg_marquardt', initial=None, **options):
        """Estimate with `method` ('interaction_matrix' or 'levenberg_marquardt')."""
        if method not in METHODS:
            raise ValueError(f'unknown method {method!r}; use one of {METHODS}')
        if not observations:
            raise ValueError('no observation to estimate from')
        if method == 'interaction_matrix':
            return self.interaction_matrix(observations, initial=initial, **options)
        return self.levenberg_marquardt(observations, initial=initial, **options)

    # -- the paper's method (Eqs 11-12) ------------------------------------------------------
    def _paired_features(self, angles, observations):
        """y_t (K, P, 2): Eq 10 features for P candidate angles (K, P, 2) per observation."""
        k, probes = angles.shape[:2]
        poses = np.repeat(np.stack([o.T_robot_lens for o in observations]), probes, axis=0)
        points = np.repeat(np.stack([o.plane_point for o in observations]), probes, axis=0)
        normals = np.repeat(np.stack([o.plane_normal for o in observations]), probes, axis=0)
        flat = angles.reshape(-1, 2)
        directions = direction_from_angles(flat[:, 0], flat[:, 1])
        centres = self.model.centres(directions, poses, points, normals)
        features = position_features(centres_in_optics(poses, self.lens.T_lens_optics, centres))
        return features.reshape(k, probes, 2)

    def interaction_matrix(self, observations, initial=None, gain=0.9, delta=1e-5,
                           tolerance=1e-9, max_iterations=60, min_polar=0.5 * math.pi + 0.01):
        """
        Eqs 11-12 for each observation (vectorised over them), then their mean.

        Each observation runs its own iteration (stopped when ||y_t - y_img|| < tolerance);
        one that fails (singular A_t, rim lost, no convergence) is left out with its reason.
        """
        if not observations:
            raise ValueError('no observation to estimate from')
        if not 0.0 < gain <= 2.0 or not delta > 0.0:
            raise ValueError('gain must be in (0, 2] and delta > 0')
        count = len(observations)
        poses = np.stack([o.T_robot_lens for o in observations])
        y_img = position_features(centres_in_optics(
            poses, self.lens.T_lens_optics, np.stack([o.centre for o in observations])))
        vartheta = np.empty((count, 2))
        for i, observation in enumerate(observations):
            start = unit(initial) if initial is not None else self.feasible_start(
                self.initial_guess([observation]), [observation])
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
            y = self._paired_features(vartheta[index, None, :] + steps[None],
                                      [observations[i] for i in index])
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
        iterations = int(used.max())
        failed = [r for r, ok in zip(reasons, done) if not ok]
        if not done.any():
            return self._failure('interaction_matrix', observations, iterations,
                                 '; '.join(dict.fromkeys(failed)))
        estimates = vartheta[done]
        mean = unit(direction_from_angles(estimates[:, 0], estimates[:, 1]).mean(axis=0))
        phi, theta = (float(v) for v in angles_from_direction(mean))
        covariance = np.zeros((2, 2))
        if len(estimates) > 1:
            spread = estimates - [phi, theta]
            spread[:, 1] = _wrap(spread[:, 1])
            covariance = np.cov(spread.T) / len(estimates)
        reason = '' if not failed else \
            f'{len(failed)} of {count} observations left out: ' + '; '.join(dict.fromkeys(failed))
        return SunEstimateResult(phi0=phi, theta0=theta, direction=mean, covariance=covariance,
                                 method='interaction_matrix', iterations=iterations,
                                 residual=float(residual[done].max()), converged=True,
                                 reason=reason, observations=int(done.sum()),
                                 per_observation=[tuple(v) for v in estimates])

    # -- joint damped Gauss-Newton / Levenberg-Marquardt -------------------------------------
    def _residuals(self, parameters, observations):
        """Whitened centre residuals (M, 3K) for parameter rows (M, 2) = (s0_x, s0_y)."""
        parameters = np.atleast_2d(parameters)
        horizontal = np.sum(parameters ** 2, axis=1)
        directions = np.column_stack([parameters, -np.sqrt(np.maximum(1.0 - horizontal, 0.0))])
        centres = self.predicted_centres(directions, observations)
        measured = np.stack([o.centre for o in observations])
        sigma = np.array([o.sigma for o in observations])
        residual = (centres - measured[None]) / sigma[None, :, None]
        residual[horizontal >= 1.0] = np.nan
        return residual.reshape(len(parameters), -1)

    def levenberg_marquardt(self, observations, initial=None, max_iterations=50,
                            tolerance=1e-12, huber=3.0, delta=1e-7, damping=1e-3,
                            max_rms=10.0):
        """
        Joint robust fit over all observations (see the module docstring).

        Converged means a stationary point whose rms whitened residual is below `max_rms`
        (in units of sigma); a larger one is reported as not converged with its reason.
        """
        if not observations:
            raise ValueError('no observation to estimate from')
        start = unit(initial) if initial is not None else self.feasible_start(
            self.initial_guess(observations), observations)
        p = np.array(start[:2], dtype=float)
        reason, converged, iteration = '', False, 0
        cost, normal = float('inf'), None
        for iteration in range(1, max_iterations + 1):
            probes = np.array([p, p + [delta, 0.0], p + [0.0, delta]])
            r = self._residuals(probes, observations)
            if np.any(np.isnan(r[0])):
                reason = f'the rim misses the plane at iteration {iteration} (TIR or no hit)'
                break
            jacobian = ((r[1:] - r[0]) / delta).T
            weights = np.minimum(1.0, huber / np.maximum(np.abs(r[0]), 1e-300))
            cost = float(np.sum(weights * r[0] ** 2))
            normal = jacobian.T @ (weights[:, None] * jacobian)
            gradient = jacobian.T @ (weights * r[0])
            # Stop when even the undamped Gauss-Newton step would gain nothing measurable.
            try:
                gain_expected = float(gradient @ np.linalg.solve(normal, gradient))
            except np.linalg.LinAlgError:
                gain_expected = float('inf')
            if gain_expected < 1e-12 * max(1.0, cost):
                converged = True
                break
            improved = False
            for _ in range(12):
                step = np.linalg.solve(normal + damping * np.diag(np.diag(normal)), -gradient)
                trial = self._residuals(p + step, observations)[0]
                if not np.any(np.isnan(trial)):
                    trial_weights = np.minimum(1.0, huber / np.maximum(np.abs(trial), 1e-300))
                    if np.sum(trial_weights * trial ** 2) <= cost:
                        improved = True
                        break
                damping *= 10.0
            if not improved:
                # No damped step lowers the cost: a minimum within the model's numerical
                # resolution if the residuals are those of the noise, a trap otherwise.
                whitened_rms = math.sqrt(cost / (2 * len(observations)))
                converged = gain_expected < 1e-6 * max(1.0, cost) or whitened_rms < 3.0
                reason = '' if converged else 'no step reduces the cost (damping exhausted)'
                break
            p = p + step
            damping = max(damping / 10.0, 1e-9)
            if np.linalg.norm(step) < tolerance:
                converged = True
                break
        else:
            reason = f'no convergence in {max_iterations} iterations'
        if np.sum(p ** 2) >= 1.0:
            return self._failure('levenberg_marquardt', observations, iteration,
                                 'the solution left the sky (|s0_xy| >= 1)')
        direction = np.array([p[0], p[1], -math.sqrt(1.0 - p @ p)])
        phi, theta = (float(v) for v in angles_from_direction(direction))
        final = self._residuals(p, observations)[0]
        rms = float(np.sqrt(np.sum(final ** 2) / (2 * len(observations))))
        sigma = np.repeat([o.sigma for o in observations], 3)
        distance_rms = float(np.sqrt(np.sum((final * sigma) ** 2) / len(observations)))
        if converged and not rms < max_rms:
            converged = False
            reason = (f'rms residual {rms:.3g} sigma exceeds {max_rms:g}: the observations '
                      'do not fit one sun direction (bad pose, wrong spot, or rim lost)')
        degrees = final.size - len(observations) - 2  # one residual per obs is along the normal
        covariance = np.zeros((2, 2))
        try:
            if normal is None:
                raise np.linalg.LinAlgError('no iteration')
            cov_p = np.linalg.inv(normal)
            chi2 = float(np.sum(final ** 2))
            if degrees > 0:
                cov_p *= max(1.0, chi2 / degrees)
            # d(phi, theta) / d(s_x, s_y) for s_z = -sqrt(1 - s_x^2 - s_y^2).
            sx, sy = p
            rho2 = sx * sx + sy * sy
            sz = -math.sqrt(1.0 - rho2)
            dphi = -np.array([sx, sy]) / (math.sqrt(rho2) * -sz)
            dtheta = np.array([-sy, sx]) / rho2
            jac = np.vstack([dphi, dtheta])
            covariance = jac @ cov_p @ jac.T
        except (np.linalg.LinAlgError, ZeroDivisionError):
            reason = reason or 'covariance unavailable (singular normal matrix)'
        return SunEstimateResult(phi0=phi, theta0=theta, direction=direction,
                                 covariance=covariance, method='levenberg_marquardt',
                                 iterations=iteration,
                                 residual=distance_rms,
                                 converged=converged, reason=reason,
                                 observations=len(observations))

    def _failure(self, method, observations, iterations, reason):
        nan = float('nan')
        return SunEstimateResult(phi0=nan, theta0=nan, direction=np.full(3, nan),
                                 covariance=np.zeros((2, 2)), method=method,
                                 iterations=iterations, residual=nan, converged=False,
                                 reason=reason, observations=len(observations))


def _plane_basis(normal):
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = unit(np.cross(normal, helper))
    return u, np.cross(normal, u)
