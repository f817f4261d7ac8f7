"""
Rig calibration: measure what the build got wrong (issue 28; beyond the paper, Sec. II-B).

The paper takes the rig's mount transforms as known and measures only T_robot_world from the
ArUco marker. A real build differs from its rig file by millimetres and degrees; the marker
and the light spot, seen at poses chosen to tell the errors apart, measure them. Two fits,
each a robust nonlinear least squares (``scipy.optimize.least_squares``, soft-L1 loss):

1. **The camera chain** (``fit_camera_chain``): at each pose i the RGB camera's pose in the
   world is measured from the marker (Eqs 7-9, the spot detector's ``camera_pose``) and
   predicted by the rig model, T_world_rgb(x_i) = T_robot_world^-1 T_robot_rgb(x_i; theta).
   Residuals: the position difference over ``sigma_position`` and the rotation vector
   between the two orientations over ``sigma_angle``. ``CAMERA_CHAIN`` are the terms fitted:
   T_robot_world (4), the Dobot's j2, j3 zeros, both servos' zero and scale, the yaw and
   pitch axes' horizontal offsets, the RGB camera's position and turn in its mount.
2. **The lens centre** (``fit_lens_centre``): at each still pose the spot's centre on the
   panel (world frame) is predicted from the lens pose and the sun: by default where the
   chief ray meets the panel (it goes straight through the lens: Eq 14 read backwards);
   the lens planner passes the lens model's centre of the spot's outermost contour
   (``spot.SpotModel``, what the detector measures; Eq 10). Fitted: the lens centre across
   its axis in the holder (2) and the sun's direction at a reference time (2; each spot's
   sun moved from it by Eq 18). The cameras stay where the first fit put them.

Each term has a prior: the rig file's value, within ``prior_sigma`` (a 3D-printed build's
spread), so the fit is a maximum a posteriori estimate that stays well posed whatever the
poses. What the poses cannot observe is named, not guessed (``UNOBSERVED``, with why); a
fitted term whose posterior standard deviation is above ``OBSERVED_RATIO`` of its prior's
is named too (it stays near the rig file). Uncertainties are the covariance (J^T J)^-1 of
the whitened residuals, scaled by the reduced chi-square when it exceeds 1.

API: ``marker_view_poses(rig, camera, marker_side, points, count)`` (the poses);
``fit_camera_chain(nominal, joints, T_world_rgb) -> RigFit``;
``fit_lens_centre(parameters, joints, spots, sun_guess, angle_offsets) -> RigFit``;
``RigFit.parameters`` is the calibrated RigParameters, ``estimates`` the fitted terms with
their uncertainties, ``build_terms(parameters)`` the flat values a calibration saves.
"""

from dataclasses import dataclass, field, replace
import math

from helio_control.sun_sweep import spread
from helio_control.world_calibration import marker_view_candidates
from helio_optics.geometry import angles_from_direction, direction_from_angles
from helio_optics.geometry import invert_transform, unit
from helio_optics.rig_kinematics import Rig
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation


@dataclass(frozen=True)
class Term:
    """One fitted number: a RigParameters field (and its index), its unit and prior spread."""

    field: str
    index: int = None
    unit: str = 'm'
    prior_sigma: float = 0.002    # how far a build may be from the rig file (one sigma)

    @property
    def name(self):
        """Return 'field' or 'field[index]' (the flat names of config/rig.yaml)."""
        return self.field if self.index is None else f'{self.field}[{self.index}]'

    def value_in(self, parameters):
        """Return the term's value in `parameters`."""
        value = getattr(parameters, self.field)
        return float(value if self.index is None else value[self.index])

    def set_in(self, parameters, value):
        """Return `parameters` with the term set to `value`."""
        if self.index is None:
            return replace(parameters, **{self.field: float(value)})
        values = list(getattr(parameters, self.field))
        values[self.index] = float(value)
        return replace(parameters, **{self.field: tuple(values)})


DEG = math.radians(1.0)
MOUNT, TURN = 0.002, 2.0 * DEG          # a 3D-printed build's offsets and turns, one sigma
CAMERA_CHAIN = (
    Term('world_in_robot', 0, 'm', 0.01), Term('world_in_robot', 1, 'm', 0.01),
    Term('world_in_robot', 2, 'm', 0.01), Term('world_yaw', None, 'rad', 3.0 * DEG),
    Term('joint_offsets', 1, 'rad', 0.5 * DEG), Term('joint_offsets', 2, 'rad', 0.5 * DEG),
    Term('joint_offsets', 3, 'rad', 2.0 * DEG), Term('joint_offsets', 4, 'rad', 2.0 * DEG),
    Term('joint_scales', 3, '-', 0.06), Term('joint_scales', 4, '-', 0.06),
    Term('yaw_axis_offset', 0, 'm', MOUNT), Term('yaw_axis_offset', 1, 'm', MOUNT),
    Term('pitch_axis_offset', 0, 'm', MOUNT), Term('pitch_axis_offset', 1, 'm', MOUNT),
    Term('rgb_position', 0, 'm', MOUNT), Term('rgb_position', 1, 'm', MOUNT),
    Term('rgb_position', 2, 'm', MOUNT), Term('rgb_rotation', 0, 'rad', TURN),
    Term('rgb_rotation', 1, 'rad', TURN), Term('rgb_rotation', 2, 'rad', TURN))
LENS_CENTRE = (Term('lens_offset', 0, 'm', MOUNT), Term('lens_offset', 1, 'm', MOUNT))
OBSERVED_RATIO = 0.5     # a posterior sigma above this share of the prior's: not observed
UNOBSERVED = {
    'joint_offsets[0]': "the Dobot's base zero turns the arm as T_robot_world's yaw does "
                        '(in world_yaw)',
    'yaw_axis_offset[2]': 'a vertical offset moves everything as world_in_robot[2] does',
    'pitch_axis_offset[2]': 'a vertical offset moves everything as world_in_robot[2] does',
    'lens_offset[2]': "along the lens axis: the focal sweep's heating distance holds it",
    'lens_tilt': 'turns the lens about its centre: the chief ray and the spot centre stay',
    'arm links': "over the painting's poses a link's length acts as the Dobot's joint "
                 'zeros (rear arm, forearm within 0.5 mm by the specification)',
    'joint_scales[0:3]': "the Dobot's encoders: its specification's repeatability",
    'thermal mount': 'the thermal camera sees no marker; its pose places only the hottest '
                     'point, which no placement uses',
    'camera intrinsics': 'taken from camera_info; their errors bias the marker poses, which '
                         'the camera turn absorbs in part (the residual shows the rest)'}


@dataclass
class Estimate:
    """A fitted term: its value, its prior (the rig file's) and standard deviation."""

    name: str
    value: float
    prior: float
    std: float
    unit: str


@dataclass
class RigFit:
    """The outcome of a fit: calibrated parameters, estimates, residuals, what was left."""

    parameters: object                  # RigParameters
    estimates: list
    residual_position: float            # rms [m] (camera chain) or spot distance (lens)
    residual_angle: float               # rms [rad] (camera chain; NaN for the lens centre)
    chi_square: float                   # reduced
    used: int
    rejected: list = field(default_factory=list)    # indices of the views left out
    unobserved: dict = field(default_factory=dict)  # name -> why
    sun_direction: np.ndarray = None    # robot frame (the lens-centre fit)

    def table(self):
        """Return the estimates as text lines: name, value, prior, one sigma."""
        lines = []
        for e in self.estimates:
            scale, unit = (1000.0, 'mm') if e.unit == 'm' else \
                ((180.0 / math.pi, 'deg') if e.unit == 'rad' else (1.0, ''))
            lines.append(f'{e.name}: {e.value * scale:.4f} {unit} (rig file '
                         f'{e.prior * scale:.4f}, +- {e.std * scale:.4f})')
        return lines


def _parameters_of(nominal, terms, values):
    parameters = nominal
    for term, value in zip(terms, values):
        parameters = term.set_in(parameters, value)
    return parameters


def _rotation_vectors(R):
    return Rotation.from_matrix(R).as_rotvec()


def _check_views(joints, transforms, what):
    joints = np.asarray(joints, dtype=float)
    transforms = np.asarray(transforms, dtype=float)
    if joints.ndim != 2 or joints.shape[1] != 5:
        raise ValueError(f'joints must be (N, 5), got shape {joints.shape}')
    if len(transforms) != len(joints):
        raise ValueError(f'{len(joints)} joint sets but {len(transforms)} {what}')
    if not (np.all(np.isfinite(joints)) and np.all(np.isfinite(transforms))):
        raise ValueError(f'the joints or {what} hold NaN or infinite values')
    return joints, transforms


def _covariance(jacobian, chi_square):
    information = jacobian.T @ jacobian
    try:
        covariance = np.linalg.inv(information)
    except np.linalg.LinAlgError:
        covariance = np.linalg.pinv(information)
    return covariance * max(1.0, chi_square)


def _fit(terms, priors, model_residuals, keep, outlier_sigma, extra=(), extra_scale=()):
    """
    Robust MAP fit: `model_residuals(values, index)` whitened, plus each term's prior.

    `priors` the terms' prior values; `extra` more free numbers without a prior (the sun).
    Views (blocks of model residuals) over `outlier_sigma` after a fit are left out and the
    fit redone (at most a quarter of them). Return (solution, chi-square, covariance, keep).
    """
    sigmas = np.array([term.prior_sigma for term in terms])
    start = np.concatenate([priors, extra])
    scale = np.concatenate([sigmas, extra_scale])
    for attempt in range(4):
        index = np.flatnonzero(keep)

        def residuals(values, index=index):
            prior = (values[:len(terms)] - priors) / sigmas
            return np.concatenate([model_residuals(values, index), prior])

        solution = least_squares(residuals, start, x_scale=scale, loss='soft_l1', f_scale=3.0,
                                 max_nfev=100 * len(start))
        model = solution.fun[:-len(terms)]
        per_view = np.sqrt(np.mean(model.reshape(len(index), -1) ** 2, axis=1))
        bad = per_view > outlier_sigma
        if bad.any() and bad.sum() <= 0.25 * len(index) and attempt < 3:
            keep = keep.copy()
            keep[index[bad]] = False
            start = solution.x
            continue
        break
    dof = max(1, model.size - len(extra))
    chi_square = float(model @ model / dof)
    return solution, chi_square, _covariance(solution.jac, chi_square), keep


def _estimates(terms, values, covariance, priors, nominal, unobserved, why):
    """Return the Estimates; name a term whose posterior is about its prior in `unobserved`."""
    estimates = []
    for i, term in enumerate(terms):
        std = float(math.sqrt(max(covariance[i, i], 0.0)))
        if std > OBSERVED_RATIO * term.prior_sigma:
            unobserved[term.name] = (f'{why} (one sigma {std:.3g} {term.unit}, prior '
                                     f'{term.prior_sigma:.3g}): left near the rig file')
        estimates.append(Estimate(term.name, float(values[i]), term.value_in(nominal), std,
                                  term.unit))
    return estimates


def fit_camera_chain(nominal, joints, T_world_rgb, terms=CAMERA_CHAIN, sigma_position=3e-4,
                     sigma_angle=math.radians(0.15), outlier_sigma=6.0, world_guess=None):
    """
    Fit the camera chain's terms to marker views: RigFit (see the module docstring).

    `nominal` the rig file's RigParameters (the priors, each term within its
    ``prior_sigma``), `joints` (N, 5) the reported joints of each view, `T_world_rgb`
    (N, 4, 4) the camera poses the marker gave. `world_guess` (world_in_robot, world_yaw)
    replaces the rig file's T_robot_world as its prior (a robot-world calibration's).
    ValueError when there are fewer than 3 views.
    """
    joints, T_world_rgb = _check_views(joints, T_world_rgb, 'camera poses')
    if len(joints) < 3:
        raise ValueError(f'{len(joints)} marker views: at least 3 are needed')
    prior_parameters = nominal if world_guess is None else replace(
        nominal, world_in_robot=tuple(float(v) for v in world_guess[0]),
        world_yaw=float(world_guess[1]))
    priors = np.array([term.value_in(prior_parameters) for term in terms])
    measured_position, measured_rotation = T_world_rgb[:, :3, 3], T_world_rgb[:, :3, :3]

    def predicted(values, index):
        parameters = _parameters_of(prior_parameters, terms, values)
        rig, T_world_robot = Rig(parameters), invert_transform(parameters.T_robot_world)
        return [T_world_robot @ rig.forward(joints[i]).T_robot_rgb for i in index]

    def model_residuals(values, index):
        out = np.empty((len(index), 6))
        for row, (i, T) in enumerate(zip(index, predicted(values, index))):
            out[row, :3] = (T[:3, 3] - measured_position[i]) / sigma_position
            out[row, 3:] = _rotation_vectors(T[:3, :3].T @ measured_rotation[i]) / sigma_angle
        return out.ravel()

    solution, chi_square, covariance, keep = _fit(
        terms, priors, model_residuals, np.ones(len(joints), bool), outlier_sigma)
    index = np.flatnonzero(keep)
    errors = [(np.linalg.norm(T[:3, 3] - measured_position[i]),
               np.linalg.norm(_rotation_vectors(T[:3, :3].T @ measured_rotation[i])))
              for i, T in zip(index, predicted(solution.x, index))]
    unobserved = dict(UNOBSERVED)
    estimates = _estimates(terms, solution.x, covariance, priors, nominal, unobserved,
                           'these marker views do not tell it apart')
    return RigFit(parameters=_parameters_of(prior_parameters, terms, solution.x),
                  estimates=estimates,
                  residual_position=float(np.sqrt(np.mean([e[0] ** 2 for e in errors]))),
                  residual_angle=float(np.sqrt(np.mean([e[1] ** 2 for e in errors]))),
                  chi_square=chi_square, used=len(index),
                  rejected=np.flatnonzero(~keep).tolist(), unobserved=unobserved)


def chief_ray_centres(rays, T_robot_lens, T_robot_world):
    """
    Return the world (x, y) (K, 2) where each ray (K, 3) through its lens centre meets z = 0.

    The chief ray crosses a thin lens undeviated, so a focused spot's centre lies on it
    (Eq 14, p_i = p_l + d_lp s0, read from the lens to the panel). The default spot model of
    ``fit_lens_centre``; the lens planner passes the lens model's (``spot.SpotModel``).
    """
    T_world_robot = invert_transform(T_robot_world)
    s = np.einsum('ij,kj->ki', T_world_robot[:3, :3], np.asarray(rays, float))
    centres = np.einsum('ij,kj->ki', T_world_robot[:3, :3], T_robot_lens[:, :3, 3]) \
        + T_world_robot[:3, 3]
    along = -centres[:, 2] / s[:, 2]
    return centres[:, :2] + along[:, None] * s[:, :2]


def fit_lens_centre(parameters, joints, spots, sun_guess, angle_offsets=None,
                    terms=LENS_CENTRE, sigma_spot=2e-4, outlier_sigma=6.0,
                    spot_model=chief_ray_centres):
    """
    Fit the lens centre across its axis and the sun to still spots: RigFit.

    `parameters` the camera chain's RigParameters (the priors), `joints` (M, 5) reported,
    `spots` (M, 2) the spot centres on the panel (world frame) [m], `sun_guess` the sun ray
    in the robot frame at the reference time (pointing down; the ephemeris' or an estimate),
    `angle_offsets` (M, 2) each spot's Eq 18 change of the ray angles (dphi, dtheta) from
    the reference time (default none: a still sun). `spot_model(rays, T_robot_lens,
    T_robot_world)` gives the model's spot centres (world x, y). The cameras keep their
    place in the holder (their offsets change by the opposite of the lens centre's); the
    fitted sun is ``sun_direction`` (robot frame, the reference time). ValueError with fewer
    than 4 spots.
    """
    joints = np.asarray(joints, dtype=float)
    spots = np.asarray(spots, dtype=float)[:, :2]
    if len(joints) != len(spots) or len(joints) < 4:
        raise ValueError(f'{len(spots)} spots for {len(joints)} joint sets: at least 4 '
                         'pairs are needed')
    offsets = np.zeros((len(joints), 2)) if angle_offsets is None else \
        np.asarray(angle_offsets, dtype=float).reshape(len(joints), 2)
    phi, theta = angles_from_direction(unit(np.asarray(sun_guess, dtype=float)))
    priors = np.array([term.value_in(parameters) for term in terms])

    def predicted(values, index):
        moved = _moved_lens(parameters, terms, values[:len(terms)])
        rig = Rig(moved)
        rays = direction_from_angles(values[-2] + offsets[index, 0],
                                     values[-1] + offsets[index, 1])
        poses = np.array([rig.forward(joints[i]).T_robot_lens for i in index])
        return spot_model(rays, poses, moved.T_robot_world)

    def model_residuals(values, index):
        return ((predicted(values, index) - spots[index]) / sigma_spot).ravel()

    solution, chi_square, covariance, keep = _fit(
        terms, priors, model_residuals, np.ones(len(joints), bool), outlier_sigma,
        extra=[float(phi), float(theta)], extra_scale=[0.01, 0.01])
    index = np.flatnonzero(keep)
    values = solution.x[:len(terms)]
    misses = np.linalg.norm(predicted(solution.x, index) - spots[index], axis=1)
    unobserved = {}
    estimates = _estimates(terms, values, covariance, priors, parameters, unobserved,
                           'these spots do not tell it apart')
    return RigFit(parameters=_moved_lens(parameters, terms, values), estimates=estimates,
                  residual_position=float(np.sqrt(np.mean(misses ** 2))),
                  residual_angle=float('nan'), chi_square=chi_square, used=len(index),
                  rejected=np.flatnonzero(~keep).tolist(), unobserved=unobserved,
                  sun_direction=direction_from_angles(*solution.x[-2:]))


def mean_views(joints, T_world_rgb, groups):
    """
    Return one view per group: the mean joints and camera pose of a pose's frames.

    The frames of one still pose measure the same camera pose; their mean (positions
    averaged, orientations by the chordal mean) halves the noise of four frames and makes the
    fit four times cheaper. `groups` (N,) labels each view with its pose.
    """
    joints, T_world_rgb = _check_views(joints, T_world_rgb, 'camera poses')
    groups = np.asarray(groups)
    mean_joints, mean_poses = [], []
    for group in dict.fromkeys(groups.tolist()):
        members = np.flatnonzero(groups == group)
        pose = np.eye(4)
        pose[:3, 3] = T_world_rgb[members, :3, 3].mean(axis=0)
        pose[:3, :3] = Rotation.from_matrix(T_world_rgb[members, :3, :3]).mean().as_matrix()
        mean_joints.append(joints[members].mean(axis=0))
        mean_poses.append(pose)
    return np.array(mean_joints), np.array(mean_poses)


def marker_view_poses(rig, camera, marker_side, points, count, distances=(0.10, 0.14),
                      tilts=(0.0, 20.0, 35.0), azimuths=8, wrist_turns=(0.0, 1.2, -1.2),
                      margin=30.0, max_view_angle=math.radians(50.0)):
    """
    Return up to `count` joint vectors from which the RGB camera sees the whole marker.

    Chosen for the camera chain's observability: over the view `points` (world x, y),
    lens axes tilted `tilts` [deg] off the vertical towards `azimuths` directions, at
    `distances` [m] above the point, each with the wrist turned by `wrist_turns` [rad] (the
    same axis reached with another yaw, the servo's zero and scale then show), the marker
    seen at most `max_view_angle` off its normal (the spot detector refuses slanted views;
    a build's error must not push a view past its 60 deg). Spread over the candidates (any
    prefix covers them), by the rig model's belief of where the marker is.
    """
    candidates = [x for angle, x in marker_view_candidates(
        rig, camera, marker_side, points, distances, tilts,
        np.arange(azimuths) * 2.0 * math.pi / azimuths, wrist_turns, margin)
        if angle <= max_view_angle]
    unique = []
    for x in candidates:
        if all(np.max(np.abs(x - y)) > 1e-6 for y in unique):
            unique.append(x)
    return spread(unique)[:count]


def _moved_lens(parameters, terms, values):
    """Return `parameters` with the lens centre moved and the cameras kept in place."""
    moved = _parameters_of(parameters, terms, values)
    shift = np.subtract(moved.lens_offset, parameters.lens_offset)
    return replace(moved, rgb_position=tuple(np.subtract(parameters.rgb_position, shift)),
                   thermal_position=tuple(np.subtract(parameters.thermal_position, shift)))


# the RigParameters a rig calibration measures and saves (the rest stays the rig file's)
CALIBRATED_FIELDS = ('world_in_robot', 'world_yaw', 'joint_offsets', 'joint_scales',
                     'yaw_axis_offset', 'pitch_axis_offset', 'lens_offset', 'rgb_position',
                     'rgb_rotation', 'thermal_position')


def build_terms(parameters):
    """Return the flat {name: value} of CALIBRATED_FIELDS (floats and lists of floats)."""
    flat = parameters.to_parameters()
    return {name: flat[name] for name in CALIBRATED_FIELDS}
