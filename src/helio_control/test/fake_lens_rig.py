"""
A model rig behind the lens planner's port (``LensRigPort``), for in-process procedure tests.

The rig's truth is known to the test that builds it: the true T_robot_world (the marker),
the true sun ray and the true lens, and optionally the true kinematics of a drawn build
(``helio_drivers.sim.build``). What the procedures get through the port is computed from
that truth with the project's pure geometry: marker poses are the true camera pose seen
from the true marker (``Rig.forward``, with measurement noise), spot centres where the true
lens model casts the spot (``SpotModel.centres``), spot areas the true lens' A_c
(``spot_area``), and estimate_sun answers with ``SunEstimator`` on the spots of the holds.
The procedures plan with the port's beliefs (``rig``, ``lens``, the sun estimate), which
start from the rig file. Nothing sleeps: the clock moves by a fixed step per move and frame.
"""

from dataclasses import replace
import datetime
import math
from types import SimpleNamespace

from helio_control import sun_sweep
from helio_control.lens_planner_parameters import code_defaults, declare_heating_distance
from helio_control.lens_planner_parameters import declare_settings
from helio_control.procedures.focal_calibration_run import scaled_lens
from helio_control.procedures.lens_rig_port import GoalCanceled, GoalFailed, LensRigPort
from helio_msgs.msg import SpotObservation
from helio_msgs.srv import EstimateSun
from helio_optics.config_files import config_path
from helio_optics.ephemeris import load_site
from helio_optics.focus_targeting import FocusTargeting
from helio_optics.geometry import invert_transform, PinholeCamera
from helio_optics.geometry import transform_points
from helio_optics.lens import load_lens_parameters
from helio_optics.node_kit.conversions import array_to_point, matrix_to_pose
from helio_optics.node_kit.conversions import stamp_from_seconds
from helio_optics.node_kit.joint_states import JointLookup
from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters, Rig
from helio_optics.spot import spot_area, SpotModel
from helio_optics.sun_estimation import Observation, SunEstimator
import numpy as np
from scipy.spatial.transform import Rotation

CAMERA = PinholeCamera.from_fov(640, 480, math.radians(70.0))   # the simulated RGB camera
# 2026-06-21 10:00 UTC at the sample site: the sun well up (checked in the tests)
START = datetime.datetime(2026, 6, 21, 10, 0, tzinfo=datetime.timezone.utc).timestamp()
MOVE_TIME = 1.0         # a move takes this long on the fake's clock [s]
FRAME_TIME = 0.1        # one camera frame [s]


def run(coroutine):
    """Run a procedure's coroutine to its end; the fake port never suspends it."""
    try:
        coroutine.send(None)
    except StopIteration as done:
        return done.value
    raise AssertionError('the procedure waited on something the fake port does not give')


def nominal_rig():
    """Return the rig file's parameters (the planner's prior)."""
    return load_rig_parameters(default_rig_file())


def moved_world(parameters, shift, turn_deg):
    """Return rig parameters with the marker moved by `shift` [m] and turned [deg]."""
    return replace(parameters,
                   world_in_robot=tuple(np.asarray(parameters.world_in_robot) + shift),
                   world_yaw=parameters.world_yaw + math.radians(turn_deg))


class FakeLensRig(LensRigPort):
    """
    The port over a model rig whose truth the test knows.

    `true_rig` (a ``Rig`` fed the TRUE joints, default the rig file's), `true_joints`
    (reported joints -> true angles, default the same), `true_sun` (robot frame, where light
    goes), `true_lens` (default the lens file's). The beliefs: `believed_rig` (default the
    rig file), `believed_sun` (a known estimate, or None), `world_calibrated`.
    `marker_noise` (position [m], angle [rad]) and `spot_noise` [m] per frame, from `seed`.
    `cancel_after` moves, the goal is canceled. Under `clouds` no spot is ever seen. The
    `settings` default to the lens planner's defaults.
    """

    def __init__(self, true_sun, true_rig=None, true_joints=None, true_lens=None,
                 believed_rig=None, believed_sun=None, world_calibrated=False,
                 settings=None, marker_noise=(0.0, 0.0), spot_noise=0.0, seed=0,
                 cancel_after=None, clouds=False, x_start=None):
        """Build the model and the planner's beliefs (see the class docstring)."""
        self.settings = settings or code_defaults(declare_settings)
        self.lens = load_lens_parameters(config_path('lens.yaml'))
        self.true_lens = true_lens or self.lens
        self.true_spot_model = SpotModel(self.true_lens)
        self.true_rig = true_rig or Rig(nominal_rig())
        self.true_joints = true_joints or (lambda x: np.asarray(x, dtype=float))
        self.true_sun = np.asarray(true_sun, dtype=float) / np.linalg.norm(true_sun)
        self.nominal_rig = nominal_rig()
        self.rig = Rig(believed_rig or self.nominal_rig)
        self.spot_model = SpotModel(self.lens)
        self.targeting = FocusTargeting(self.rig, self.lens, rays=1000)
        self.site = load_site(config_path('site.yaml'))
        self.heating_distance = code_defaults(declare_heating_distance)
        self.world_calibrated = world_calibrated
        self.sun = None if believed_sun is None else np.asarray(believed_sun, dtype=float)
        self.marker_noise, self.spot_noise = marker_noise, spot_noise
        self.rng = np.random.default_rng(seed)
        self.cancel_after, self.clouds = cancel_after, clouds
        self.time = START
        self.x = np.asarray(x_start if x_start is not None else [0.0, 0.3, 0.3, 0.0, 0.0],
                            dtype=float)
        self.moves, self.feedbacks, self.logs, self.saved = [], [], [], {}
        self.spots = []             # (image time, reported joints, world centre) of each frame
        self.placed_at = None       # (at_heating, alive) the focus said
        self.estimate_calls = []

    # ---- the truth --------------------------------------------------------------------------

    @property
    def T_true_robot_world(self):  # noqa: N802 (the project's transform naming)
        """Return the true T_robot_world (the marker)."""
        return self.true_rig.parameters.T_robot_world

    def true_pose(self, x=None):
        """Return the true RigPose of reported joints `x` (default the present ones)."""
        return self.true_rig.forward(self.true_joints(self.x if x is None else x))

    def true_spot_centre(self, x=None):
        """Return where the true lens casts the spot (world frame (3,)) at reported `x`."""
        T = self.T_true_robot_world
        centre = self.true_spot_model.centres(self.true_sun, self.true_pose(x).T_robot_lens,
                                              T[:3, 3], T[:3, 2])[0]
        return transform_points(invert_transform(T), centre)

    def _sees(self, x):
        """Tell whether the true camera sees the spot (and the marker) from joints x."""
        return not self.clouds and sun_sweep.sees_marker_and_spot(
            self.true_rig, self.true_joints(x), self.true_sun, CAMERA, self.T_true_robot_world,
            self.settings.marker_side, self.settings.view_margin, need_marker=False)

    def _sees_marker(self, x):
        T_world_rgb = invert_transform(self.T_true_robot_world) @ self.true_pose(x).T_robot_rgb
        return sun_sweep.in_view(CAMERA, T_world_rgb,
                                 sun_sweep.marker_corners(self.settings.marker_side),
                                 self.settings.view_margin)

    # ---- the port ---------------------------------------------------------------------------

    async def move(self, x):
        """Go to x at once (the clock moves on); GoalCanceled after `cancel_after` moves."""
        if self.cancel_after is not None and len(self.moves) >= self.cancel_after:
            raise GoalCanceled()
        self.x = np.asarray(x, dtype=float)
        self.moves.append(self.x.copy())
        self.time += MOVE_TIME
        return self.x.copy()

    async def observe(self, count, accept):
        """Return the accepted of `count` frames from the present pose."""
        area = centre = None
        if self._sees(self.x):
            centre = self.true_spot_centre()
            pose = self.true_pose()
            T = self.T_true_robot_world
            area = spot_area(self.true_lens, self.true_sun, pose.T_robot_lens, T[:3, 3],
                             T[:3, 2])
        marker = self._sees_marker(self.x)
        T_world_rgb = invert_transform(self.T_true_robot_world) @ self.true_pose().T_robot_rgb
        accepted = []
        for _ in range(count):
            self.time += FRAME_TIME
            message = SpotObservation()
            message.header.stamp = stamp_from_seconds(self.time)
            message.header.frame_id = 'world'
            if centre is not None:
                seen = centre + np.append(self.rng.normal(0.0, self.spot_noise, 2)
                                          if self.spot_noise else np.zeros(2), 0.0)
                message.valid, message.quality = True, SpotObservation.FULL
                message.center = array_to_point(seen)
                message.area = float(area)
                self.spots.append((self.time, self.x.copy(), seen))
            if marker:
                message.camera_pose_source = 'marker'
                message.camera_pose = matrix_to_pose(self._noisy(T_world_rgb))
            if accept(message):
                accepted.append(message)
        return accepted

    def _noisy(self, T):
        position, angle = self.marker_noise
        T = np.array(T)
        if position:
            T[:3, 3] += self.rng.normal(0.0, position, 3)
        if angle:
            T[:3, :3] = Rotation.from_rotvec(self.rng.normal(0.0, angle, 3)).as_matrix() \
                @ T[:3, :3]
        return T

    def joints_at(self, seconds):
        """Return the present joints (they do not change while the lens holds)."""
        return JointLookup(positions=self.x.copy())

    def present_joints(self):
        """Return the present joints."""
        return self.x.copy()

    async def camera(self):
        """Return the simulated RGB camera."""
        return CAMERA

    def now(self):
        """Return the fake's clock [s]."""
        return self.time

    def sun_ray(self):
        """Return the believed sun; GoalFailed without one."""
        if self.sun is None:
            raise GoalFailed('no sun estimate yet')
        return self.sun

    def has_sun(self):
        """Tell whether a sun is believed."""
        return self.sun is not None

    async def estimate_sun(self, method, since, rig_calibration=None):
        """Fit the sun (``SunEstimator``) to the spots imaged since `since`, believed rig."""
        self.estimate_calls.append((method, since, rig_calibration))
        T = self.rig.parameters.T_robot_world
        observations = [Observation.seen_on_the_world_plane(self.rig, T, centre, x)
                        for taken, x, centre in self.spots if taken > since]
        response = EstimateSun.Response()
        response.rig_calibration = rig_calibration or ''
        try:
            result = SunEstimator(self.lens).estimate(observations)
        except ValueError as error:
            response.success, response.message = False, f'estimation failed: {error}'
            return response
        response.estimate.direction.x, response.estimate.direction.y, \
            response.estimate.direction.z = (float(v) for v in result.direction)
        response.estimate.converged = bool(result.converged)
        response.success = result.trustworthy
        response.message = f'{len(observations)} observations: {result.reason or "fit"}'
        return response

    def use_sun(self, estimate):
        """Believe this sun estimate."""
        direction = estimate.direction
        self.sun = np.array([direction.x, direction.y, direction.z])

    def use_world(self, world_in_robot, world_yaw):
        """Believe this T_robot_world."""
        self.rig.set_world(world_in_robot, world_yaw)
        self.world_calibrated = True

    def use_rig(self, flat, identity):
        """Believe this rig calibration."""
        self.rig.apply_calibration(flat, identity)
        self.world_calibrated = True

    def use_rig_parameters(self, parameters):
        """Plan with these rig parameters."""
        self.rig.set_parameters(parameters)

    def use_focus(self, heating_distance, min_area, fit_rms_relative, samples):
        """Believe this heating distance; scale the lens model to it."""
        self.lens = scaled_lens(self.lens, heating_distance, self.heating_distance)
        self.spot_model = SpotModel(self.lens)
        self.targeting = FocusTargeting(self.rig, self.lens, rays=1000)
        self.heating_distance = heating_distance

    def save(self, name, tree, notes=None):
        """Keep the calibration in memory; return a path-like name."""
        self.saved[name] = (tree, notes)
        return f'memory:{name}'

    def feedback(self, message):
        """Keep a copy of the feedback's fields."""
        self.feedbacks.append(SimpleNamespace(**{
            name: getattr(message, name) for name in message.get_fields_and_field_types()}))

    def log(self, text, warning=False):
        """Keep the line."""
        self.logs.append((warning, text))

    async def in_background(self, function):
        """Compute it here."""
        return function()

    async def wait_for_inputs(self):
        """Nothing to wait for."""

    def client_alive(self):
        """No painter: no client."""
        return False

    def placed(self, at_heating, alive):
        """Keep what the focus said."""
        self.placed_at = (at_heating, alive)


def sun_at(elevation_deg, azimuth_deg):
    """Return the sun ray (robot frame) at this elevation and robot-frame azimuth."""
    return sun_sweep.sun_ray(math.radians(elevation_deg), math.radians(azimuth_deg))
