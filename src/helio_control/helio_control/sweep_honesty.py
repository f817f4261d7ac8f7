"""
How honest the sun estimate is: sweeps over random suns in the simulated world (issue 35).

    python -m helio_control.sweep_honesty --sweeps 200 --json PATH [--seed N]

Each sweep is a new ``SimWorld`` at a random site (latitude -50..60 deg), date, time of day
and robot heading (its hidden truth; the sun 30-75 deg up). Then, as the graph does it
(``lens_planner``, ``spot_detector``, ``sun_estimator``), without ROS:

1. robot-world calibration from the marker (``world_calibration``: ``marker_poses``, each
   pose's marker pose against its kinematic camera pose), as ``calibrate_world`` does;
2. a coarse sun, as the acquisition gives one: the true ray turned by 0-2 deg in a random
   direction (the sweep is planned around it, never around the truth);
3. the poses of one kind of sweep (tilted and level in turn), as the calibrated planner
   plans them (the spot in view; the marker where it happens to be):
   - ``tilted``: ``sun_sweep.sweep_poses`` (the lens planner's sweep: the lens axis 0-10 deg
     off the sun in four directions, d_lp 7.6-8.8 cm, six poses);
   - ``level``: the paper's yaw sweep (Sec. V-B, ``helio_optics.bench._sweep_poses``): the
     lens axis leaning from the vertical towards the sun by 0 (the lens level, Sec. III-C)
     up to 10 deg short of facing it, its centre 6-7.6 cm up the ray from a panel point,
     yawed about the vertical through it by -25..25 deg in 5 deg steps (those poses from
     which the camera sees the spot, at least five);
4. per pose, a move (``move_seconds`` of simulated time, the world not stepped: no heat), the
   settle time and ``frames_per_pose`` rendered webcam frames at the camera's rate (5 Hz),
   each through ``SpotObserver`` (the marker's pose, else the kinematic camera pose through
   the calibration, as ``spot_detector`` after a calibration); FULL spots only;
5. the observations as ``sun_estimator`` builds them: the centre in the robot frame through
   the calibrated T_robot_world, the lens pose from the joints by the rig file, Eq 18
   offsets to the middle of the sweep from the ephemeris at the site (a deployment's
   ``site.yaml`` says where it stands); ``SunEstimator.estimate`` with the node's defaults;
6. the judge: the angle between the estimate and the world's TRUE sun at the reference time.

Three noise models run on the same frames (``MODELS``): ``before`` (every frame an
observation with sigma 0.5 mm, the node before issue 35), ``after`` (the node now:
``helio_optics.centre_noise``, the frames of a hold merged, the measured sigma, the model's
reach) and ``unscreened`` (``after`` without the reach). "Accepted" = converged and not
ambiguous (the node's ``success``); "flagged" = not accepted, counted by the kind of reason.

Only the harness reads the world's truth (the sun, for the judge and the residuals); the
controller side (``observations_of``) gets what the nodes get: frames, joints, stamps, the
rig and lens files, the site. The world is built from the same rig file the controller
reads (the simulated rig is its CAD): the kinematic camera pose is exact but for the
calibration, so a real rig's mount errors are not in these figures.

``frame_residuals`` measures the noise the estimator sees (item 1 of the issue): each FULL
frame's detected centre minus the centre the controller's ``SpotModel`` predicts for the
world's TRUE sun at that frame, on the ground plane, along and across the sun's azimuth;
``hold_noise`` and the ``noise_*`` figures summarise it per hold.
"""

import argparse
from dataclasses import dataclass, field
import datetime
import math
import time

from helio_control import sun_sweep
from helio_control.world_calibration import estimate_world_in_robot, marker_poses
from helio_drivers.sim.world import SimSettings, SimWorld
from helio_optics.bench_report import add_json_option, report
from helio_optics.centre_noise import CentreNoise, merge_holds
from helio_optics.config_files import config_path
from helio_optics.ephemeris import angle_offsets, Site, sun_position
from helio_optics.geometry import direction_from_angles, invert_transform, transform_points
from helio_optics.geometry import unit
from helio_optics.lens import load_lens_parameters
from helio_optics.node_kit.process_tuning import single_threaded_numerics
from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters, Rig
from helio_optics.rig_kinematics import UnreachableError
from helio_optics.sun_estimation import Observation, SunEstimator, TrustSettings
from helio_perception.spot_observer import SpotObserver
import numpy as np

KINDS = ('tilted', 'level')
MARKER_SIDE = 0.04          # the world's and the nodes' default [m]
VIEW_MARGIN = 30.0          # lens_planner view_margin [px]
LEVEL_YAWS_DEG = tuple(range(-25, 26, 5))
OLD_SIGMA = 0.5e-3          # the node's centre_sigma before issue 35 [m]


@dataclass(frozen=True)
class Sky:
    """Where and when a world stands: its hidden truth besides the lens."""

    latitude_deg: float
    longitude_deg: float
    start_time: str            # ISO 8601, UTC
    robot_heading_deg: float   # compass azimuth of the robot's x axis
    elevation_deg: float       # of the sun at the start

    def site(self):
        """Return the ephemeris Site (what a deployment's site.yaml holds)."""
        return Site(self.latitude_deg, self.longitude_deg)


def random_sky(rng, elevation_deg=(30.0, 75.0)):
    """Draw a site (latitude -50..60 deg), a day of 2026, a time, a heading; sun in range."""
    start = datetime.datetime(2026, 1, 1, tzinfo=datetime.timezone.utc)
    while True:
        site = Site(float(rng.uniform(-50.0, 60.0)), float(rng.uniform(-180.0, 180.0)))
        when = start + datetime.timedelta(seconds=float(rng.uniform(0.0, 365.0 * 86400.0)))
        elevation = math.degrees(sun_position(site, when).elevation)
        if elevation_deg[0] <= elevation <= elevation_deg[1]:
            return Sky(site.latitude_deg, site.longitude_deg, when.isoformat(),
                       float(rng.uniform(0.0, 360.0)), elevation)


def turned(ray, angle, rng):
    """Return the unit `ray` turned by `angle` [rad] towards a random direction."""
    ray = unit(ray)
    helper = np.array([0.0, 0.0, 1.0]) if abs(ray[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = unit(np.cross(ray, helper))
    v = np.cross(ray, u)
    turn = rng.uniform(0.0, 2.0 * math.pi)
    aside = math.cos(turn) * u + math.sin(turn) * v
    return unit(math.cos(angle) * ray + math.sin(angle) * aside)


def level_sweep_poses(rig, T_robot_world, sun, camera, points, rng, yaws_deg=LEVEL_YAWS_DEG,
                      distances=(0.06, 0.076), closer_to_sun_deg=10.0, min_poses=5,
                      attempts=40):
    """
    Return the joints of a paper-style yaw sweep around the (coarse) sun `sun` (robot frame).

    The lens axis leans from the vertical towards the sun by an angle drawn between 0 (the
    lens level, Sec. III-C) and the sun's zenith angle less `closer_to_sun_deg` (the lens
    facing the sun that much more level than square on: ``bench._sweep_poses`` takes 14 deg);
    its centre a drawn distance in `distances` up the ray from a panel point. The lens turns
    about the vertical through its centre by `yaws_deg` (alpha_l of Eq 15; beta_l kept).
    Poses from which the camera does not see the spot are left out; a draw with fewer than
    `min_poses` is tried again (up to `attempts`), else [].
    """
    zenith = math.acos(-sun[2])
    azimuth = math.atan2(-sun[1], -sun[0])
    for _ in range(attempts):
        point = points[int(rng.integers(len(points)))]
        distance = rng.uniform(*distances)
        lean = rng.uniform(0.0, max(zenith - math.radians(closer_to_sun_deg), 0.0))
        axis = direction_from_angles(lean, azimuth)
        centre = transform_points(T_robot_world, [point[0], point[1], 0.0]) - distance * sun
        for flip in rng.permutation([0.0, math.pi]):
            yaw, pitch = rig.yaw_pitch_for_axis(axis, math.atan2(centre[1], centre[0]) + flip)
            poses = []
            for turn in np.radians(yaws_deg):
                try:
                    x = rig.inverse(centre, yaw + turn, pitch)
                except UnreachableError:
                    continue
                if sun_sweep.sees_marker_and_spot(rig, x, sun, camera, T_robot_world,
                                                  MARKER_SIDE, VIEW_MARGIN, need_marker=False):
                    poses.append(x)
            if len(poses) >= min_poses:
                return poses
    return []


@dataclass
class Frame:
    """One frame of a sweep: what spot_detector gives and, for the judge only, the truth."""

    pose: int                      # index of the hold
    joints: np.ndarray             # x when the image was taken [rad]
    seconds: float                 # simulated time since the world's start [s]
    valid: bool                    # a FULL spot
    reason: str
    centre_world: np.ndarray       # ellipse centre, world frame [m]
    semi_major: float              # [m]
    semi_minor: float              # [m]
    pose_source: str               # 'marker' or 'kinematics'
    true_ray_robot: np.ndarray = field(repr=False, default=None)   # TRUTH: judge only


def calibrate_world(world, rig, camera, poses, settle_steps=3):
    """
    Robot-world calibration as ``calibrate_world`` does it: T_robot_world or None.

    Each pose's marker pose (from the rendered frame) against its kinematic camera pose.
    """
    observer = SpotObserver()
    robot_rgb, world_rgb = [], []
    for x in poses:
        world.set_joints(x)
        for _ in range(settle_steps):
            world.step()
        seen = observer.observe(world.rgb_image(), camera, world.time, x)
        if seen.pose_source == 'marker' and seen.T_world_camera is not None:
            robot_rgb.append(rig.forward(x).T_robot_rgb)
            world_rgb.append(seen.T_world_camera)
    try:
        return estimate_world_in_robot(robot_rgb, world_rgb).T_robot_world
    except ValueError:
        return None


def image_sweep(world, rig, camera, poses, T_robot_world, frames_per_pose=4, move_seconds=3.0,
                settle_seconds=0.3, frame_period=0.2):
    """
    Hold the lens at each pose and take frames as the graph does; return the Frames.

    The move takes `move_seconds` of simulated time (the clock advanced, nothing heated),
    then the world steps through the settle time and a frame is taken every `frame_period`.
    """
    observer = SpotObserver()
    T_world_robot = invert_transform(T_robot_world)
    step = world.settings.step
    frames = []
    for index, x in enumerate(poses):
        world.set_joints(x)
        world.clock.advance(move_seconds)
        for _ in range(max(1, round(settle_seconds / step))):
            world.step()
        kinematic = T_world_robot @ rig.forward(x).T_robot_rgb
        for _ in range(frames_per_pose):
            for _ in range(max(1, round(frame_period / step))):
                world.step()
            seen = observer.observe(world.rgb_image(), camera, world.time, x,
                                    T_world_camera_kinematic=kinematic)
            truth = world.T_robot_world[:3, :3] @ world.sun_ray_world()
            frames.append(Frame(
                pose=index, joints=np.array(x, dtype=float), seconds=world.time,
                valid=bool(seen.valid), reason=seen.reason,
                centre_world=np.array(seen.spot.center, dtype=float),
                semi_major=float(seen.spot.semi_major), semi_minor=float(seen.spot.semi_minor),
                pose_source=seen.pose_source, true_ray_robot=truth))
    return frames


def observations_of(frames, rig, T_robot_world, site, start, noise=None):
    """
    Build the estimator's input from the FULL frames, as ``sun_estimator`` builds it.

    `noise` None: one observation per frame with the old sigma 0.5 mm; a ``CentreNoise``:
    the frames of each hold merged (``merge_holds``) with its sigma. `site` None: no Eq 18
    offsets (the sun taken as fixed, as the node does without an ephemeris). Return
    (observations, reference seconds, frame indices of each observation).
    """
    used = [k for k, f in enumerate(frames) if f.valid]
    if not used:
        return [], float('nan'), []
    seconds = [frames[k].seconds for k in used]
    reference = 0.5 * (min(seconds) + max(seconds))
    observations = []
    for k in used:
        frame = frames[k]
        offset = (0.0, 0.0) if site is None else angle_offsets(
            sun_position(site, start + datetime.timedelta(seconds=reference)),
            sun_position(site, start + datetime.timedelta(seconds=frame.seconds)))
        observations.append(Observation.seen_on_the_world_plane(
            rig, T_robot_world, frame.centre_world, frame.joints, OLD_SIGMA, offset))
    if noise is None:
        return observations, reference, [[k] for k in used]
    holds = merge_holds(observations, noise)
    return ([h.observation for h in holds], reference,
            [[used[i] for i in h.members] for h in holds])


def angle_deg(a, b):
    """Angle between two rays [deg] (NaN when either is not finite)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        return float('nan')
    return math.degrees(math.acos(max(-1.0, min(1.0, float(unit(a) @ unit(b))))))


def frame_residuals(frames, model, rig, T_robot_world):
    """
    Return detected minus model centre at the TRUE sun per FULL frame: what the fit sees.

    The detected centre goes to the robot frame through the calibrated `T_robot_world` and
    the model (the controller's ``SpotModel``) traces the world's true sun at the frame's
    time through the rig file's lens pose onto that plane: their difference is the spot
    detector's noise plus the model's error plus the calibration's. Returns a dict of
    arrays over the K FULL frames: 'residual' (K, 3) robot frame [m], 'along_sun' and
    'across_sun' (K,) (in the plane, along the sun's horizontal direction and across it)
    [m], 'pose' (K,), 'size' (K,) (sqrt(a b) of the detected ellipse) [m], 'marker' (K,)
    (the camera pose from the marker, else from the kinematics), 'elevation' and 'tilt' (K,)
    (the chief ray, lens centre to the detected centre: above the plane, off the lens axis;
    what ``CentreNoise`` knows) [rad]; None without FULL frames.
    """
    rows = [f for f in frames if f.valid]
    if not rows:
        return None
    point, normal = T_robot_world[:3, 3], T_robot_world[:3, 2]
    residual, along, across, elevation, tilt = [], [], [], [], []
    for frame in rows:
        T_lens = rig.forward(frame.joints).T_robot_lens
        predicted = model.centres(frame.true_ray_robot, T_lens[None], point, normal)[0]
        detected = transform_points(T_robot_world, frame.centre_world)
        difference = detected - predicted
        sun = frame.true_ray_robot
        horizontal = unit(sun - (sun @ normal) * normal)
        residual.append(difference)
        along.append(float(difference @ horizontal))
        across.append(float(difference @ np.cross(normal, horizontal)))
        seen = Observation(detected, T_lens, point, normal)
        elevation.append(CentreNoise.elevation(seen))
        tilt.append(CentreNoise.tilt(seen))
    return {'residual': np.array(residual), 'along_sun': np.array(along),
            'across_sun': np.array(across), 'pose': np.array([f.pose for f in rows]),
            'size': np.array([math.sqrt(f.semi_major * f.semi_minor) for f in rows]),
            'marker': np.array([f.pose_source == 'marker' for f in rows]),
            'elevation': np.array(elevation), 'tilt': np.array(tilt)}


@dataclass
class Sweep:
    """One sweep: its world, poses, calibration and frames (None fields: it stopped there)."""

    kind: str
    sky: Sky
    poses: list
    T_robot_world: np.ndarray     # the calibration's (None: it failed)
    frames: list
    coarse_error_deg: float       # the coarse sun the poses were planned around, off the truth
    world: object = field(repr=False, default=None)


class SweepRunner:
    """The parts every sweep shares: the rig file, the lens file, view points, the estimator."""

    def __init__(self, frames_per_pose=4, flux_rays=20000, coarse_error_deg=2.0):
        """Load the controller's rig and lens files; plan the calibration poses once."""
        self.rig_parameters = load_rig_parameters(default_rig_file())
        self.rig = Rig(self.rig_parameters)
        self.lens = load_lens_parameters(config_path('lens.yaml'))
        self.estimator = SunEstimator(self.lens, rim_points=64, contour_fraction=1.0)
        self.model = self.estimator.model
        self.frames_per_pose = frames_per_pose
        self.flux_rays = flux_rays
        self.coarse_error = math.radians(coarse_error_deg)
        self.view_points = sun_sweep.view_points()
        self.camera = SimSettings().rgb.camera()
        self.calibration_poses = marker_poses(self.rig, self.camera, MARKER_SIDE,
                                              self.view_points, 0.11, 8, VIEW_MARGIN)

    def plan(self, kind, sun, rng):
        """Return the joints of a sweep of `kind` around the (coarse) robot-frame `sun`."""
        T_robot_world = self.rig_parameters.T_robot_world
        if kind == 'tilted':
            return sun_sweep.sweep_poses(self.rig, T_robot_world, sun, self.camera,
                                         MARKER_SIDE, self.view_points, 6,
                                         margin=VIEW_MARGIN, need_marker=False)
        if kind == 'level':
            return level_sweep_poses(self.rig, T_robot_world, sun, self.camera,
                                     self.view_points, rng)
        raise ValueError(f'unknown sweep kind {kind!r}; use one of {KINDS}')

    def sweep(self, kind, rng, tries=20):
        """Draw skies until one can be swept (poses found); image it; return the Sweep."""
        for _ in range(tries):
            sky = random_sky(rng)
            settings = SimSettings(latitude_deg=sky.latitude_deg,
                                   longitude_deg=sky.longitude_deg, start_time=sky.start_time,
                                   robot_heading_deg=sky.robot_heading_deg,
                                   flux_rays=self.flux_rays, seed=int(rng.integers(2 ** 31)))
            world = SimWorld(settings, self.rig_parameters)
            truth = world.T_robot_world[:3, :3] @ world.sun_ray_world()
            coarse = turned(truth, rng.uniform(0.0, self.coarse_error), rng)
            poses = self.plan(kind, coarse, rng)
            if len(poses) >= 2:
                break
        else:
            return None
        calibrated = calibrate_world(world, self.rig, world.rgb.camera, self.calibration_poses)
        frames = [] if calibrated is None else image_sweep(
            world, self.rig, world.rgb.camera, poses, calibrated, self.frames_per_pose)
        return Sweep(kind, sky, poses, calibrated, frames, angle_deg(coarse, truth), world)

    def truth_at(self, sweep, seconds):
        """Return the world's TRUE sun ray (robot frame) `seconds` after its start (judge)."""
        start = datetime.datetime.fromisoformat(sweep.sky.start_time)
        return sweep.world.sun.ray_robot(start + datetime.timedelta(seconds=seconds))


# 'before': every frame an observation, sigma 0.5 mm, no screen (the node before issue 35);
# 'after': the node now (CentreNoise: holds merged, its sigma, chief rays within max_tilt);
# 'unscreened': 'after' without the chief-ray screen (what the screen costs and saves).
MODELS = ('before', 'after', 'unscreened')


@dataclass
class Verdict:
    """What the estimator said of one sweep under one noise model, and the judge's angle."""

    accepted: bool          # converged and not ambiguous: the node's success
    error_deg: float        # angle to the world's true sun at the reference time (NaN: none)
    flag: str               # '' when accepted, else the reason's kind (see ``flag_of``)
    chi2: float
    dof: int
    observations: int       # observations fitted (frames before, holds after)
    reason: str


def flag_of(result):
    """Return the kind of reason an estimate is not accepted ('' when it is)."""
    if result.trustworthy:
        return ''
    reason = result.reason
    if result.converged and result.ambiguous:
        return 'ambiguous'
    if reason.startswith('no observation a sun can have cast'):
        return 'no_usable_observation'
    if 'chi-square' in reason:
        return 'chi_square'
    if 'left out (limit' in reason or 'majority' in reason:
        return 'outliers'
    if 'minimum' in reason or 'convergence' in reason or 'singular' in reason:
        return 'not_a_minimum'
    return 'other'


def judge(runner, sweep, model, noise):
    """Estimate the sun of `sweep` under `model` (one of ``MODELS``); return the Verdict."""
    if sweep.T_robot_world is None:
        return Verdict(False, float('nan'), 'no_calibration', float('nan'), 0, 0,
                       'robot-world calibration failed')
    start = datetime.datetime.fromisoformat(sweep.sky.start_time)
    observations, reference, _ = observations_of(
        sweep.frames, runner.rig, sweep.T_robot_world, sweep.sky.site(), start,
        None if model == 'before' else noise)
    if not observations:
        return Verdict(False, float('nan'), 'no_full_spot', float('nan'), 0, 0,
                       'no FULL spot in any frame')
    trust = TrustSettings(max_chief_ray_tilt=noise.max_tilt) if model == 'after' \
        else TrustSettings()
    result = runner.estimator.estimate(observations, trust=trust)
    return Verdict(result.trustworthy, angle_deg(result.direction,
                                                 runner.truth_at(sweep, reference)),
                   flag_of(result), float(result.chi2), int(result.dof), len(observations),
                   result.reason)


def hold_noise(residuals):
    """
    Per hold (the frames of one pose): the mean residual at the true sun and its chief ray.

    Returns (along, across, elevation, tilt) arrays over the holds [m, m, rad, rad] and the
    frames' rms scatter about their hold's mean [m].
    """
    along, across, elevation, tilt, scatter = [], [], [], [], []
    for pose in np.unique(residuals['pose']):
        chosen = residuals['pose'] == pose
        for name, out in (('along_sun', along), ('across_sun', across),
                          ('elevation', elevation), ('tilt', tilt)):
            out.append(float(np.mean(residuals[name][chosen])))
        for name in ('along_sun', 'across_sun'):
            scatter.extend(residuals[name][chosen] - np.mean(residuals[name][chosen]))
    return (np.array(along), np.array(across), np.array(elevation), np.array(tilt),
            float(np.sqrt(np.mean(np.square(scatter)))) if scatter else float('nan'))


def robust_std(values):
    """1.4826 times the median absolute deviation (NaN when empty)."""
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return float('nan')
    return float(1.4826 * np.median(np.abs(values - np.median(values))))


def summary(rows, noise_rows):
    """
    Return the flat figures of a run (units in the names) from its rows and hold residuals.

    `rows`: dicts with 'kind' and, per model, a Verdict; `noise_rows`: per hold (kind,
    along, across, elevation, tilt) and the frames' scatter.
    """
    figures = {'sweeps': len(rows)}
    for kind in KINDS:
        figures[f'sweeps_{kind}'] = sum(r['kind'] == kind for r in rows)
    for model in MODELS:
        for kind in ('all',) + KINDS:
            chosen = [r[model] for r in rows if kind == 'all' or r['kind'] == kind]
            prefix = f'{model}_{kind}'
            errors = np.array([v.error_deg for v in chosen], dtype=float)
            accepted = np.array([v.accepted for v in chosen], dtype=bool)
            good = errors <= 0.2
            figures[f'{prefix}_accepted'] = int(accepted.sum())
            figures[f'{prefix}_within_0p2deg'] = int(good.sum())
            figures[f'{prefix}_accepted_within_0p2_fraction'] = \
                float(np.sum(accepted & good) / good.sum()) if good.any() else float('nan')
            figures[f'{prefix}_accepted_over_0p3deg'] = int(np.sum(accepted & (errors > 0.3)))
            figures[f'{prefix}_flagged_over_0p3deg'] = int(np.sum(~accepted & (errors > 0.3)))
            if model == 'after':   # the sweeps as the fit without the screen judges them
                unscreened = np.array([r['unscreened'].error_deg for r in rows
                                       if kind == 'all' or r['kind'] == kind])
                figures[f'{prefix}_accepted_of_unscreened_within_0p2_fraction'] = float(
                    np.sum(accepted & (unscreened <= 0.2)) / np.sum(unscreened <= 0.2)) \
                    if np.any(unscreened <= 0.2) else float('nan')
                figures[f'{prefix}_accepted_of_unscreened_over_0p3deg'] = int(
                    np.sum(accepted & (unscreened > 0.3)))
            figures[f'{prefix}_worst_accepted_error_deg'] = \
                float(np.max(errors[accepted])) if accepted.any() else float('nan')
            figures[f'{prefix}_accepted_error_deg_median'] = \
                float(np.median(errors[accepted])) if accepted.any() else float('nan')
            fitted = [v for v, g in zip(chosen, good) if g and v.dof > 0]
            figures[f'{prefix}_chi2_per_dof_within_0p2'] = \
                float(sum(v.chi2 for v in fitted) / sum(v.dof for v in fitted)) \
                if fitted else float('nan')
            for flag in ('ambiguous', 'chi_square', 'outliers', 'not_a_minimum',
                         'no_usable_observation', 'no_full_spot', 'no_calibration', 'other'):
                count = sum(v.flag == flag for v in chosen)
                if count or kind == 'all':
                    figures[f'{prefix}_flagged_{flag}'] = count
    holds, scatter = noise_rows
    for kind in ('all',) + KINDS:
        chosen = [h for h in holds if kind == 'all' or h[0] == kind]
        if not chosen:
            continue
        along = np.array([h[1] for h in chosen])
        across = np.array([h[2] for h in chosen])
        elevation = np.array([h[3] for h in chosen])
        tilt = np.array([h[4] for h in chosen])
        prefix = f'noise_{kind}'
        figures[f'{prefix}_holds'] = len(chosen)
        figures[f'{prefix}_along_sun_bias_mm'] = float(np.median(along) * 1e3)
        figures[f'{prefix}_along_sun_robust_std_mm'] = robust_std(along) * 1e3
        figures[f'{prefix}_across_sun_bias_mm'] = float(np.median(across) * 1e3)
        figures[f'{prefix}_across_sun_robust_std_mm'] = robust_std(across) * 1e3
        for low, high in ((0, 8), (8, 12), (12, 15), (15, 20), (20, 30), (30, 90)):
            inside = (np.degrees(tilt) >= low) & (np.degrees(tilt) < high)
            if inside.sum() >= 5:
                figures[f'{prefix}_chief_ray_{low}_{high}deg_off_axis_holds'] = int(inside.sum())
                figures[f'{prefix}_chief_ray_{low}_{high}deg_off_axis_along_p95_mm'] = float(
                    np.percentile(np.abs(along[inside]), 95) * 1e3)
                figures[f'{prefix}_chief_ray_{low}_{high}deg_off_axis_across_p95_mm'] = float(
                    np.percentile(np.abs(across[inside]), 95) * 1e3)
        for low, high in ((0, 40), (40, 50), (50, 60), (60, 90)):
            inside = (np.degrees(elevation) >= low) & (np.degrees(elevation) < high) & \
                (tilt <= CentreNoise().max_tilt)
            if inside.sum() >= 5:
                figures[f'{prefix}_chief_ray_{low}_{high}deg_up_along_robust_std_mm'] = \
                    robust_std(along[inside]) * 1e3
                figures[f'{prefix}_chief_ray_{low}_{high}deg_up_across_robust_std_mm'] = \
                    robust_std(across[inside]) * 1e3
    figures['noise_frame_scatter_in_hold_mm_rms'] = float(np.sqrt(np.mean(np.square(
        scatter)))) * 1e3 if scatter else float('nan')
    return figures


def run(sweeps, seed=0, noise=None, frames_per_pose=4, flux_rays=20000, progress=None):
    """
    Run `sweeps` sweeps (tilted and level in turn) from `seed`; return (figures, rows).

    Each row: kind, elevation, poses, FULL frames and the Verdict per model.
    """
    noise = noise or CentreNoise()
    rng = np.random.default_rng(seed)
    runner = SweepRunner(frames_per_pose, flux_rays)
    rows, holds, scatter = [], [], []
    began = time.perf_counter()
    for index in range(sweeps):
        kind = KINDS[index % len(KINDS)]
        sweep = runner.sweep(kind, rng)
        if sweep is None:
            rows.append({'kind': kind, 'elevation_deg': float('nan'), 'poses': 0, 'frames': 0,
                         **{m: Verdict(False, float('nan'), 'no_poses', float('nan'), 0, 0,
                                       'no sky gave poses') for m in MODELS}})
            continue
        row = {'kind': kind, 'elevation_deg': sweep.sky.elevation_deg,
               'poses': len(sweep.poses), 'frames': sum(f.valid for f in sweep.frames),
               'coarse_error_deg': sweep.coarse_error_deg}
        for model in MODELS:
            row[model] = judge(runner, sweep, model, noise)
        if sweep.T_robot_world is not None:
            residuals = frame_residuals(sweep.frames, runner.model, runner.rig,
                                        sweep.T_robot_world)
            if residuals is not None:
                along, across, elevation, tilt, spread = hold_noise(residuals)
                holds.extend((kind, *values) for values in zip(along, across, elevation, tilt))
                scatter.append(spread)
        sweep.world = None
        rows.append(row)
        if progress:
            progress(index, row)
    figures = summary(rows, (holds, scatter))
    elapsed = time.perf_counter() - began
    figures['seconds_total'] = elapsed
    figures['seconds_per_sweep'] = elapsed / max(sweeps, 1)
    figures['seed'] = seed
    figures['frames_per_pose'] = frames_per_pose
    figures['flux_rays_per_band'] = flux_rays
    return figures, rows


def _print_row(index, row):
    """Print one sweep's line: its sun, poses, frames and each model's verdict."""
    verdicts = ' | '.join(
        f'{model}: {row[model].error_deg:6.3f} deg '
        + ('accepted' if row[model].accepted else row[model].flag) for model in MODELS)
    after = row['after']
    print(f"{index:4d} {row['kind']:6s} sun {row['elevation_deg']:5.1f} deg, {row['poses']:2d} "
          f"poses, {row['frames']:2d} FULL frames | {verdicts} | chi2 {after.chi2:.1f} for "
          f'{after.dof}', flush=True)


def main(args=None):
    """Parse arguments, run, print and optionally write the JSON figures."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--sweeps', type=int, default=200, help='sweeps to run (default 200)')
    parser.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    parser.add_argument('--frames', type=int, default=4,
                        help="frames per pose (default 4, lens_planner's observe_frames)")
    parser.add_argument('--flux-rays', type=int, default=20000,
                        help="the world's rays per spectral band (default 20000, its own)")
    parser.add_argument('--quiet', action='store_true', help='no line per sweep')
    add_json_option(parser)
    options = parser.parse_args(args)
    single_threaded_numerics()
    figures, _ = run(options.sweeps, options.seed, frames_per_pose=options.frames,
                     flux_rays=options.flux_rays, progress=None if options.quiet else _print_row)
    return report(figures, options.json, machine=True)


if __name__ == '__main__':
    raise SystemExit(main())
