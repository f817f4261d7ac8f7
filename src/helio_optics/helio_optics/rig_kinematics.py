"""
The 5-DOF rig: Dobot arm, two-servo wrist, lens and camera mounts (paper Sec. II-B, Eqs 14-15).

Joints x in R^5 = (dobot_j1, dobot_j2, dobot_j3, lens_yaw, lens_pitch) [rad]. The Magician
keeps its flange level; the flange frame F sits at the flange point rotated by j1 about z.
The wrist hangs below it: a yaw servo about F's z axis (through ``yaw_axis_offset`` in F),
then a pitch servo about the yawed y axis (through ``pitch_axis_offset`` in the yaw frame),
then the lens centre O_l at ``lens_offset`` in the pitch frame. So the lens orientation is
zyx Tait-Bryan (alpha_l, beta_l, 0) of Eq 15 with alpha_l = j1 + lens_yaw and
beta_l = lens_pitch: R_robot_lens = Rz(alpha_l) Ry(beta_l), the lens axis (its +z, towards
the sun side) is (C alpha S beta, S alpha S beta, C beta). At j1 = 0 and zero wrist angles
the lens axes are aligned with the robot's. (The paper prints Eq 15 with the opposite sign
on the horizontal part, i.e. with its pitch measured the other way round.)

API
---
``RigParameters``: ``arm`` (DobotArmParameters), the three wrist offsets [m], servo limits
[rad], camera mounts ``T_lens_rgb`` / ``T_lens_thermal`` (optical frames whose axes meet
the lens axis at the focal point) and ``T_robot_world`` (where the ArUco marker / panel is
relative to the arm base). ``RigParameters.from_parameters(dict)`` reads the flat names of
``config/rig.yaml`` (``load_rig_parameters(path)`` reads that file); ``to_parameters()``
gives the same flat dict (for declaring ROS parameters).

``Rig(parameters)``:
- ``forward(x) -> RigPose`` with ``T_robot_flange``, ``T_robot_lens``, ``T_robot_rgb``,
  ``T_robot_thermal``, ``yaw``, ``pitch`` (alpha_l, beta_l).
- ``inverse(position, yaw, pitch, check_limits=True) -> x``: joints for the lens pose
  Omega = [p_l, alpha_l, beta_l, 0]; raises ``UnreachableError`` naming the joint (or the
  reach) and by how much.
- ``inverse_many(positions (N, 3), yaws (N,), pitches (N,), check_limits=True)
  -> RigSolutions``: the same closed form for N poses at once (numpy; ``inverse`` is this
  with N = 1): ``joints`` (N, 5), ``reachable`` (N,), ``failure`` (the first check failed:
  a reach code or a joint's index in ``limits()``), ``excess``, ``flange``.
- ``lens_pose_for_target(target, sun_direction, d_lp, preferred_yaw=None) -> LensTarget``:
  Eq 14 p_l = p_i - d_lp s0 and Eq 15 (alpha_l, beta_l) from a robot-frame target and sun
  ray; ``LensTarget`` has ``position``, ``yaw``, ``pitch``, ``d_lp``, ``x`` (joints, or None
  with ``reason`` when unreachable).
- ``lens_poses_for_targets(targets (N, 3), sun_direction, d_lp, preferred_yaws=None)
  -> LensTargets``: Eqs 14-15 for N targets at once (``lens_pose_for_target`` is this with
  N = 1); ``positions``, ``yaws``, ``pitches``, ``joints``, ``reachable``.
- ``yaw_pitch_for_axis(axis, preferred_yaw=None)``: Eq 15 alone, the solution closest to
  ``preferred_yaw`` (a number, or an array (N,) of them: arrays (N,) of yaws and pitches).

A non-finite number given to ``inverse``, ``lens_pose_for_target`` or
``yaw_pitch_for_axis`` (a NaN target, sun, axis or angle) raises ValueError naming the input,
instead of NaN joints with an empty reason.
"""

from dataclasses import dataclass, field, fields, replace
import math

from helio_optics.arm_kinematics import BEYOND_REACH, check_joint_limits, DobotArm
from helio_optics.arm_kinematics import DobotArmParameters, first_limit_failure, INSIDE_REACH
from helio_optics.arm_kinematics import JointLimit, limit_bounds, limit_error, REACHABLE
from helio_optics.arm_kinematics import UnreachableError
from helio_optics.config_files import config_path, read_parameter_section
from helio_optics.geometry import homogeneous, look_at, rotation_x, rotation_y, rotation_z
from helio_optics.geometry import unit
import numpy as np

JOINT_NAMES = ('dobot_j1', 'dobot_j2', 'dobot_j3', 'lens_yaw', 'lens_pitch')
# failure codes of Rig.inverse_many beyond the arm's (arm_kinematics); a limit is its index
ON_BASE_AXIS = -4         # the yaw axis cannot be placed: the lens is on the base axis
BEHIND_BASE_AXIS = -5     # the flange would stand behind the base axis
HEADING_MISMATCH = -6     # the arm's base joint disagrees with the rig's (numerical guard)

__all__ = ['JOINT_NAMES', 'LensTarget', 'LensTargets', 'Rig', 'RigParameters', 'RigPose',
           'RigSolutions', 'UnreachableError', 'camera_mount', 'default_rig_file', 'escape_lift',
           'load_rig_parameters', 'mount_rotation']


def _finite(name, value, size=None):
    """Return `value` as floats (shape (size,) when given); ValueError naming a non-finite one."""
    if size is None and isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f'{name} must be finite, got {value}')
        return value
    array = np.asarray(value, dtype=float)
    if size is not None:
        array = array.reshape(size)
    if not np.all(np.isfinite(array)):
        raise ValueError(f'{name} must be finite, got {array.tolist()}')
    return array if size is not None else float(array)


def camera_mount(position, focus_depth, up=(1.0, 0.0, 0.0)):
    """
    Return T_lens_camera of an optical frame at `position` (lens frame) aimed at the focus.

    The focus is the point (0, 0, -focus_depth) on the lens axis (paper Sec. II-B: lens and
    camera axes meet at the focal point).
    """
    return look_at(position, [0.0, 0.0, -focus_depth], up=up)


@dataclass(frozen=True)
class RigParameters:
    """Geometry and limits of the arm + wrist + lens + cameras; SI units, rad."""

    arm: DobotArmParameters = field(default_factory=DobotArmParameters)
    yaw_axis_offset: tuple = (0.03, 0.0, -0.04)     # yaw axis origin in the flange frame [m]
    pitch_axis_offset: tuple = (0.0, 0.0, -0.03)    # pitch axis origin in the yaw frame [m]
    lens_offset: tuple = (0.0, 0.0, 0.0)            # O_l in the pitch frame [m]
    yaw_limits: tuple = (math.radians(-90.0), math.radians(90.0))
    pitch_limits: tuple = (math.radians(-90.0), math.radians(90.0))
    rgb_position: tuple = (0.045, 0.0, 0.01)        # rgb optical centre in the lens frame [m]
    thermal_position: tuple = (-0.045, 0.0, 0.01)   # thermal optical centre, lens frame [m]
    camera_focus_depth: float = 0.082               # where the camera axes cross the lens
    #                                                 axis, below O_l [m] (d_lp default)
    world_in_robot: tuple = (0.145, -0.10, -0.14)    # marker centre in the robot frame [m]
    world_yaw: float = 0.0                          # marker x axis from the robot x [rad]
    # what a build gets wrong (issue 28; a rig calibration measures them, the rig file's
    # defaults are a perfect build): the true joint angle is scale * reported + offset (a
    # Dobot's zero after homing, a servo's neutral and travel); the lens tilted in its holder
    # (about x, then y of the pitch frame); each camera turned in its mount (Rz Ry Rx of
    # these angles after the aim at the focus, in its optical frame)
    joint_offsets: tuple = (0.0, 0.0, 0.0, 0.0, 0.0)     # [rad]
    joint_scales: tuple = (1.0, 1.0, 1.0, 1.0, 1.0)      # [-]
    lens_tilt: tuple = (0.0, 0.0)                        # [rad]
    rgb_rotation: tuple = (0.0, 0.0, 0.0)                # [rad]
    thermal_rotation: tuple = (0.0, 0.0, 0.0)            # [rad]

    @property
    def T_lens_rgb(self):  # noqa: N802 (the project's transform naming)
        """RGB optical frame in the lens holder frame (the lens frame of a perfect build)."""
        return camera_mount(self.rgb_position, self.camera_focus_depth) @ homogeneous(
            mount_rotation(self.rgb_rotation))

    @property
    def T_lens_thermal(self):  # noqa: N802
        """Thermal optical frame in the lens holder frame."""
        return camera_mount(self.thermal_position, self.camera_focus_depth) @ homogeneous(
            mount_rotation(self.thermal_rotation))

    def true_joints(self, x):
        """Return the true joint angles (..., 5) of reported joints x: scale * x + offset."""
        return np.asarray(x, dtype=float) * self.joint_scales + self.joint_offsets

    def reported_joints(self, x_true):
        """Return the joints the devices report (..., 5) for true angles (``true_joints``^-1)."""
        return (np.asarray(x_true, dtype=float) - self.joint_offsets) / self.joint_scales

    @property
    def T_robot_world(self):  # noqa: N802
        """World (marker, panel z = 0) frame in the robot frame; world z is vertical."""
        return homogeneous(rotation_z(self.world_yaw), self.world_in_robot)

    def limits(self):
        """Return the five joint limits in the order of x."""
        return self.arm.limits() + (JointLimit('lens_yaw', *self.yaw_limits),
                                    JointLimit('lens_pitch', *self.pitch_limits))

    def to_parameters(self):
        """Flat dict of floats and float lists, the names used in config/rig.yaml."""
        flat = {}
        for f in fields(self.arm):
            value = getattr(self.arm, f.name)
            flat['arm.' + f.name] = list(map(float, value)) if isinstance(value, tuple) \
                else float(value)
        for f in fields(self):
            if f.name == 'arm':
                continue
            value = getattr(self, f.name)
            flat[f.name] = list(map(float, value)) if isinstance(value, tuple) else float(value)
        return flat

    @classmethod
    def from_parameters(cls, flat):
        """Build from a flat dict (unknown names raise ValueError; missing ones default)."""
        arm_names = {f.name for f in fields(DobotArmParameters)}
        rig_names = {f.name for f in fields(cls)} - {'arm'}
        arm_values, rig_values = {}, {}
        for name, value in flat.items():
            if name.startswith('arm.') and name[4:] in arm_names:
                arm_values[name[4:]] = tuple(value) if isinstance(value, (list, tuple)) \
                    else float(value)
            elif name in rig_names:
                rig_values[name] = tuple(float(v) for v in value) \
                    if isinstance(value, (list, tuple)) else float(value)
            else:
                raise ValueError(f'unknown rig parameter {name!r}')
        return replace(cls(), arm=DobotArmParameters(**arm_values), **rig_values)


def mount_rotation(angles):
    """Return Rz(c) Ry(b) Rx(a) of a mount's small turn (a, b[, c]) [rad] (c = 0 if left out)."""
    a, b, c = (tuple(float(v) for v in angles) + (0.0, 0.0, 0.0))[:3]
    return rotation_z(c) @ rotation_y(b) @ rotation_x(a)


def escape_pitch(pitch, turn):
    """
    Return the lens pitch [rad] turned `turn` [rad] away from the pitch servo's nearer end.

    The wrist's escape when the arm cannot retreat, and the servo driver's on an emergency
    stop: the lens axis leaves the sun ray by `turn` (coma spreads the focus over the wood
    at 0.6 rad), whatever the sun, which neither knows for sure then.
    """
    return pitch - turn if pitch > 0.0 else pitch + turn


def escape_lift(arm, joints, lift, tries=4):
    """
    Return the arm joints (j1, j2, j3) [rad] that put the flange `lift` [m] straight above.

    The painter's retreat when the wrist cannot move (its driver dead or faulted): j1 stays
    and the Magician's linkage keeps the flange level, so the lens keeps its orientation and
    moves straight up, and the focus leaves the wood by the lift (3 cm spreads the spot over
    about a third of the lens' width, as the retreat along the sun ray does). `arm` is a
    DobotArm, `joints` its present j1..j3. The largest of `lift`, `lift` / 2, ... (`tries`
    halvings) within the joints' limits; UnreachableError naming the joint when none is.
    """
    flange = arm.forward(joints)
    error = None
    for attempt in range(tries):
        try:
            return arm.inverse(flange + [0.0, 0.0, lift / 2 ** attempt])
        except UnreachableError as failure:
            error = failure
    raise UnreachableError(f'no lift of the flange within {lift * 1000:.0f} mm: {error}',
                           joint=error.joint, excess=error.excess)


def default_rig_file():
    """Return the workspace's config/rig.yaml (see ``config_files``), or None when missing."""
    return config_path('rig.yaml', required=False)


def load_rig_parameters(path):
    """Read RigParameters from a ROS 2 parameter file (``/**: ros__parameters: rig: ...``)."""
    return RigParameters.from_parameters(read_parameter_section(path, 'rig'))


@dataclass
class RigPose:
    """Forward kinematics of the rig at one x (transforms map their frame into robot)."""

    T_robot_flange: np.ndarray
    T_robot_lens: np.ndarray
    T_robot_rgb: np.ndarray
    T_robot_thermal: np.ndarray
    yaw: float      # alpha_l [rad]
    pitch: float    # beta_l [rad]


@dataclass
class RigSolutions:
    """
    Joints for N lens poses (``Rig.inverse_many``) and the first check each one fails.

    ``failure`` per pose: ``REACHABLE``; ``ON_BASE_AXIS``, ``BEHIND_BASE_AXIS``,
    ``BEYOND_REACH``, ``INSIDE_REACH``, ``HEADING_MISMATCH`` (no closed-form solution:
    NaN joints); or the index in ``RigParameters.limits()`` of the first joint outside
    its limit. ``excess`` says by how much [m or rad], ``flange`` where the flange would be.
    """

    joints: np.ndarray      # (N, 5) [rad]
    failure: np.ndarray     # (N,) int
    excess: np.ndarray      # (N,) [m or rad]
    flange: np.ndarray      # (N, 3) [m], robot frame

    @property
    def reachable(self):
        """Return the mask (N,) of the poses every check passed."""
        return self.failure == REACHABLE


@dataclass
class LensTargets:
    """Lens poses Omega (Eqs 14-15) for N targets, their joints and whether they reach."""

    positions: np.ndarray   # (N, 3) p_l [m]
    yaws: np.ndarray        # (N,) alpha_l [rad] of the solution taken
    pitches: np.ndarray     # (N,) beta_l [rad]
    d_lp: float
    joints: np.ndarray      # (N, 5) [rad], NaN or out of limits where not reachable
    reachable: np.ndarray   # (N,) bool


@dataclass
class LensTarget:
    """A lens pose Omega (Eqs 14-15) and the joints that reach it (None when unreachable)."""

    position: np.ndarray
    yaw: float
    pitch: float
    d_lp: float
    x: np.ndarray = None
    reason: str = ''


class Rig:
    """Forward and inverse kinematics of the 5-DOF rig."""

    def __init__(self, parameters=None):
        """Use the given RigParameters, or the defaults of config/rig.yaml."""
        self.calibrations_applied = 0      # rig calibrations taken (``apply_calibration``)
        self.calibration_id = ''           # the last one's id
        self.set_parameters(parameters or RigParameters())

    def set_parameters(self, parameters):
        """Use new RigParameters (a rig calibration's) from now on."""
        self.parameters = parameters
        self.arm = DobotArm(self.parameters.arm)
        self._T_lens_rgb = self.parameters.T_lens_rgb
        self._T_lens_thermal = self.parameters.T_lens_thermal
        self._bounds_of = self._bounds = None
        p = self.parameters
        # a perfect build (the rig file's defaults) skips the build's terms
        self._built = (any(p.joint_offsets) or any(v != 1.0 for v in p.joint_scales)
                       or any(p.lens_tilt))
        self._tilt = homogeneous(mount_rotation(tuple(p.lens_tilt) + (0.0,)))

    def forward(self, x):
        """
        Return the RigPose at the reported joints x (5 values) [rad].

        The joints are made true first (``RigParameters.true_joints``); ``yaw`` and ``pitch``
        are the lens holder's. The lens frame is the holder's turned by ``lens_tilt``; the
        cameras are mounted on the holder.
        """
        p = self.parameters
        x = p.true_joints(np.asarray(x, dtype=float).reshape(5)) if self._built \
            else np.asarray(x, dtype=float).reshape(5)
        flange = self.arm.forward(x[:3])
        T_robot_flange = homogeneous(rotation_z(x[0]), flange)
        T_flange_yaw = homogeneous(rotation_z(x[3]), p.yaw_axis_offset)
        T_yaw_pitch = homogeneous(rotation_y(x[4]), p.pitch_axis_offset)
        T_pitch_lens = homogeneous(translation=p.lens_offset)
        T_robot_holder = T_robot_flange @ T_flange_yaw @ T_yaw_pitch @ T_pitch_lens
        T_robot_lens = T_robot_holder @ self._tilt if self._built else T_robot_holder
        return RigPose(T_robot_flange=T_robot_flange, T_robot_lens=T_robot_lens,
                       T_robot_rgb=T_robot_holder @ self._T_lens_rgb,
                       T_robot_thermal=T_robot_holder @ self._T_lens_thermal,
                       yaw=float(x[0] + x[3]), pitch=float(x[4]))

    def inverse(self, position, yaw, pitch, check_limits=True):
        """
        Joints x for the lens pose Omega = [position, yaw, pitch, 0] (robot frame, rad).

        ``inverse_many`` for one pose. Raises UnreachableError naming the joint (or the
        reach) and by how much.
        """
        position = _finite('lens position', position, 3)
        yaw, pitch = _finite('lens yaw', yaw), _finite('lens pitch', pitch)
        solutions = self.inverse_many(position[None], np.array([yaw]), np.array([pitch]),
                                      check_limits)
        if solutions.failure[0] != REACHABLE:
            raise self._unreachable(position, solutions, 0)
        return solutions.joints[0]

    def inverse_many(self, positions, yaws, pitches, check_limits=True):
        """
        Joints for N lens poses Omega = [p_l, alpha_l, beta_l, 0] of Eqs 14-15 (robot frame).

        `positions` (N, 3) [m], `yaws` and `pitches` (N,) [rad] of the lens holder. Closed
        form: the pitch- and lens-offsets are fixed by (yaw, pitch); the yaw-axis offset
        turns with j1, which is solved from the horizontal distance; the arm's
        ``inverse_many`` places the flange. The joints are the ones to command (reported:
        ``RigParameters.reported_joints`` of the true angles); the limits hold for them.
        A ``lens_tilt`` is left out: it turns the lens axis off the holder's by its angle,
        which moves the focus along the sun ray by f (1 / cos - 1), 0.03 mm at 1.5 deg, and
        not across it (the chief ray goes straight through the lens centre).
        Returns ``RigSolutions``: joints (N, 5) and per pose the first check it fails
        (``reachable`` its mask), by how much, and the flange position.
        """
        p = self.parameters
        positions = np.asarray(positions, dtype=float).reshape(-1, 3)
        yaws, pitches = np.asarray(yaws, dtype=float), np.asarray(pitches, dtype=float)
        lens, pitch_axis, a = p.lens_offset, p.pitch_axis_offset, p.yaw_axis_offset
        # v = pitch-axis offset + Ry(pitch) lens offset; q = flange + Rz(j1) a = p_l - Rz(yaw) v
        cos_pitch, sin_pitch = np.cos(pitches), np.sin(pitches)
        cos_yaw, sin_yaw = np.cos(yaws), np.sin(yaws)
        v0 = pitch_axis[0] + cos_pitch * lens[0] + sin_pitch * lens[2]
        v1 = pitch_axis[1] + lens[1]
        v2 = pitch_axis[2] - sin_pitch * lens[0] + cos_pitch * lens[2]
        q0 = positions[:, 0] - (cos_yaw * v0 - sin_yaw * v1)
        q1 = positions[:, 1] - (sin_yaw * v0 + cos_yaw * v1)
        horizontal = np.hypot(q0, q1)
        along = np.sqrt(np.maximum(horizontal ** 2 - a[1] ** 2, 0.0))  # = flange reach + a_x
        j1 = np.arctan2(q1, q0) - np.arctan2(a[1], along)
        reach = along - a[0]
        flange = np.empty((len(positions), 3))
        flange[:, 0] = reach * np.cos(j1)
        flange[:, 1] = reach * np.sin(j1)
        flange[:, 2] = positions[:, 2] - v2 - a[2]
        arm_joints, failure, excess = self.arm.inverse_many(flange, check_limits=False)
        # the checks in the order a pose fails them first: base axis, behind it, the arm
        on_axis = horizontal < abs(a[1]) + 1e-9
        behind = reach <= 0.0
        mismatch = np.abs(_remainder(arm_joints[:, 0] - j1)) > 1e-9
        unsolved = on_axis | behind | mismatch | (failure != REACHABLE)
        joints = np.empty((len(positions), 5))
        joints[:, 0] = j1
        joints[:, 1:3] = arm_joints[:, 1:]
        joints[:, 3] = _remainder(yaws - j1)
        joints[:, 4] = pitches
        if self._built:
            joints = p.reported_joints(joints)
        if unsolved.any():
            failure[mismatch & (failure == REACHABLE)] = HEADING_MISMATCH
            failure[behind] = BEHIND_BASE_AXIS
            excess[behind] = -reach[behind]
            failure[on_axis] = ON_BASE_AXIS
            excess[on_axis] = abs(a[1]) - horizontal[on_axis]
            joints[unsolved] = np.nan
        if check_limits:
            first_limit_failure(self._limit_bounds(), joints, failure, excess)
        return RigSolutions(joints=joints, failure=failure, excess=excess, flange=flange)

    def _limit_bounds(self):
        """Return the (lower, upper) arrays of the five joint limits [rad] (kept)."""
        if self._bounds_of is not self.parameters:
            self._bounds = limit_bounds(self.parameters.limits())
            self._bounds_of = self.parameters
        return self._bounds

    def _unreachable(self, position, solutions, index):
        """Return the UnreachableError of pose `index` of ``inverse_many``'s `solutions`."""
        failure, excess = solutions.failure[index], float(solutions.excess[index])
        if failure == ON_BASE_AXIS:
            horizontal = abs(self.parameters.yaw_axis_offset[1]) - excess
            return UnreachableError(
                f'lens position {position} lies on the arm base axis '
                f'(horizontal distance {horizontal * 1000:.1f} mm)', joint='reach',
                excess=excess)
        if failure == BEHIND_BASE_AXIS:
            return UnreachableError(
                f'lens position {position} needs the flange {excess * 1000:.1f} mm behind '
                'the base axis', joint='reach', excess=excess)
        if failure in (BEYOND_REACH, INSIDE_REACH):
            side = 'beyond' if failure == BEYOND_REACH else 'inside'
            return UnreachableError(
                f"target {solutions.flange[index]} is {side} the arm's reach by "
                f'{excess * 1000:.1f} mm', joint='reach', excess=excess)
        if failure == HEADING_MISMATCH:
            return UnreachableError('flange heading does not match the base joint', 'reach')
        limit = self.parameters.limits()[failure]
        return limit_error(limit, solutions.joints[index, failure])

    def set_world(self, world_in_robot, world_yaw):
        """
        Use a calibrated T_robot_world: the marker centre [m] and its yaw [rad], robot frame.

        The robot-world calibration (paper Sec. II-B) measures these at the start of each
        painting; the rig file's values are the starting guess.
        """
        position = tuple(float(v) for v in np.asarray(world_in_robot, dtype=float).ravel())
        if len(position) != 3 or not all(math.isfinite(v) for v in position) \
                or not math.isfinite(world_yaw):
            raise ValueError(f'world_in_robot must be 3 finite numbers and world_yaw finite, '
                             f'got {world_in_robot!r} and {world_yaw!r}')
        self.parameters = replace(self.parameters, world_in_robot=position,
                                  world_yaw=float(world_yaw))

    def apply_calibration(self, values, calibration_id=''):
        """
        Use a rig calibration's flat values ({name: value}, the names of config/rig.yaml).

        Unknown names raise ValueError; the names left out keep their present values.
        `calibration_id` names it: the attribute ``calibration_id`` says which one is in use.
        """
        flat = self.parameters.to_parameters()
        unknown = sorted(set(values) - set(flat))
        if unknown:
            raise ValueError(f'unknown rig parameters {unknown}')
        flat.update(values)
        self.set_parameters(RigParameters.from_parameters(flat))
        self.calibrations_applied += 1
        self.calibration_id = str(calibration_id)

    def check_limits(self, x):
        """Raise UnreachableError for the first joint of x outside its limits."""
        check_joint_limits(self.parameters.limits(), x)

    def yaw_pitch_for_axis(self, axis, preferred_yaw=None):
        """
        Eq 15: (alpha_l, beta_l) putting the lens axis along `axis` (robot frame, -s0).

        Of the two solutions (alpha, beta) and (alpha + pi, -beta) return the one whose
        servo yaw (alpha - j1, j1 unknown here: relative to `preferred_yaw`) is closest to
        `preferred_yaw` (default 0). A vertical axis keeps alpha = preferred_yaw. With an
        array of preferred yaws (N,), arrays (N,) of both angles, one per preferred yaw.
        """
        axis = _finite('lens axis', axis, 3)
        if not np.any(axis):
            raise ValueError('lens axis must not be the zero vector')
        if preferred_yaw is None:
            preferred_yaw = 0.0
        reference = np.asarray(preferred_yaw, dtype=float)
        if not np.all(np.isfinite(reference)):
            raise ValueError(f'preferred_yaw must be finite, got {reference.tolist()}')
        yaw, pitch = _yaw_pitch_for_axis(unit(axis), reference.reshape(-1))
        if reference.ndim == 0:
            return float(yaw[0]), float(pitch[0])
        return yaw.reshape(reference.shape), pitch.reshape(reference.shape)

    def lens_pose_for_target(self, target, sun_direction, d_lp, preferred_yaw=None):
        """
        Eqs 14-15: lens pose and joints that focus the sun ray onto `target` (robot frame).

        ``lens_poses_for_targets`` for one target; the result's ``x`` is None with
        ``reason`` (each wrist solution's UnreachableError) when neither is reachable.
        """
        _check_d_lp(d_lp)
        target = _finite('target', target, 3)
        if preferred_yaw is not None:
            preferred_yaw = np.array([_finite('preferred_yaw', preferred_yaw)])
        positions, yaws, pitches, solutions = self._lens_pose_solutions(
            target[None], _sun_ray(sun_direction), d_lp, preferred_yaw)
        position = positions[0]
        for index in (0, 1):
            if solutions.failure[index] == REACHABLE:
                return LensTarget(position=position, yaw=float(yaws[index]),
                                  pitch=float(pitches[index]), d_lp=d_lp,
                                  x=solutions.joints[index])
        reasons = [str(self._unreachable(position, solutions, index)) for index in (0, 1)]
        return LensTarget(position=position, yaw=float(yaws[0]), pitch=float(pitches[0]),
                          d_lp=d_lp, x=None, reason='; '.join(dict.fromkeys(reasons)))

    def lens_poses_for_targets(self, targets, sun_direction, d_lp, preferred_yaws=None):
        """
        Eqs 14-15 for N targets (N, 3) (robot frame) and one sun ray: ``LensTargets``.

        p_l = p_i - d_lp s0 (Eq 14), the lens axis along -s0 (Eq 15). Of the two wrist
        solutions (alpha, beta) and (alpha + pi, -beta), the one whose yaw is nearest the
        preferred yaw (default: the heading of p_l) is taken when reachable, else the other;
        ``reachable`` says whether either is. `preferred_yaws` (N,) [rad].
        """
        _check_d_lp(d_lp)
        targets = np.asarray(targets, dtype=float).reshape(-1, 3)
        if not np.all(np.isfinite(targets)):
            raise ValueError('targets must be finite')
        if preferred_yaws is not None:
            preferred_yaws = np.asarray(preferred_yaws, dtype=float).reshape(-1)
            if not np.all(np.isfinite(preferred_yaws)):
                raise ValueError('preferred_yaws must be finite')
        positions, yaws, pitches, solutions = self._lens_pose_solutions(
            targets, _sun_ray(sun_direction), d_lp, preferred_yaws)
        count = len(targets)
        first = solutions.failure[:count] == REACHABLE
        second = solutions.failure[count:] == REACHABLE
        return LensTargets(positions=positions, yaws=np.where(first, yaws[:count],
                                                              yaws[count:]),
                           pitches=np.where(first, pitches[:count], pitches[count:]),
                           d_lp=d_lp, joints=np.where(first[:, None],
                                                      solutions.joints[:count],
                                                      solutions.joints[count:]),
                           reachable=first | second)

    def _lens_pose_solutions(self, targets, s0, d_lp, preferred_yaws):
        """
        Return p_l (N, 3) and both wrist solutions' yaws, pitches (2N,) and RigSolutions.

        Eq 14 p_l = p_i - d_lp s0 for the unit ray `s0`; Eq 15 the lens axis along -s0,
        the solution nearest `preferred_yaws` (N,) (default: p_l's heading) in the first N
        rows, the other wrist solution (alpha + pi, -beta) in the last N.
        """
        positions = targets - d_lp * s0
        reference = np.arctan2(positions[:, 1], positions[:, 0]) if preferred_yaws is None \
            else preferred_yaws
        yaw, pitch = _yaw_pitch_for_axis(-s0, reference)
        yaws = np.concatenate([reference + _remainder(yaw - reference),
                               reference + _remainder(yaw + math.pi - reference)])
        pitches = np.concatenate([pitch, -pitch])
        solutions = self.inverse_many(np.concatenate([positions, positions]), yaws, pitches)
        return positions, yaws, pitches, solutions


def _check_d_lp(d_lp):
    """Raise ValueError unless the lens distance d_lp is finite and > 0 [m]."""
    if not (math.isfinite(d_lp) and d_lp > 0.0):
        raise ValueError(f'd_lp must be a finite value > 0 m, got {d_lp}')


def _sun_ray(sun_direction):
    """Return the unit sun ray s0 (3,); ValueError unless finite, non-zero and pointing down."""
    sun_direction = _finite('sun_direction', sun_direction, 3)
    if not np.any(sun_direction):
        raise ValueError('sun_direction must not be the zero vector')
    s0 = unit(sun_direction)
    if s0[2] >= 0.0:
        raise ValueError(f'the sun ray {s0} does not point down: the sun is not up')
    return s0


def _remainder(angle):
    """Return `angle` [rad] wrapped to [-pi, pi] as ``math.remainder(angle, 2 pi)`` does."""
    return angle - 2.0 * math.pi * np.round(angle / (2.0 * math.pi))


def _yaw_pitch_for_axis(axis, reference):
    """
    Eq 15 for one unit lens `axis` and references (N,) [rad]: yaws and pitches (N,).

    Per reference, of (alpha, beta) and (alpha + pi, -beta) the one whose yaw is nearest
    it, wrapped to within pi of it; a vertical axis keeps alpha = the reference.
    """
    horizontal = math.hypot(axis[0], axis[1])
    beta = math.atan2(horizontal, axis[2])
    if horizontal < 1e-12:
        return reference.copy(), np.full(reference.shape, beta)
    alpha = math.atan2(axis[1], axis[0])
    flip = np.abs(_remainder(alpha + math.pi - reference)) < np.abs(_remainder(alpha - reference))
    alpha = np.where(flip, alpha + math.pi, alpha)
    return reference + _remainder(alpha - reference), np.where(flip, -beta, beta)
