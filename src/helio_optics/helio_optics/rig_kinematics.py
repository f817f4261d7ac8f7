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
- ``lens_pose_for_target(target, sun_direction, d_lp, preferred_yaw=None) -> LensTarget``:
  Eq 14 p_l = p_i - d_lp s0 and Eq 15 (alpha_l, beta_l) from a robot-frame target and sun
  ray; ``LensTarget`` has ``position``, ``yaw``, ``pitch``, ``d_lp``, ``x`` (joints, or None
  with ``reason`` when unreachable).
- ``yaw_pitch_for_axis(axis, preferred_yaw=None)``: Eq 15 alone, the servo-reachable
  solution closest to ``preferred_yaw``.

A non-finite number given to ``inverse``, ``lens_pose_for_target`` or
``yaw_pitch_for_axis`` (a NaN target, sun, axis or angle) raises ValueError naming the input,
instead of NaN joints with an empty reason.
"""

from dataclasses import dataclass, field, fields, replace
import math

from helio_optics.arm_kinematics import check_joint_limits, DobotArm, DobotArmParameters
from helio_optics.arm_kinematics import JointLimit
from helio_optics.arm_kinematics import UnreachableError
from helio_optics.config_files import config_path, read_parameter_section
from helio_optics.geometry import homogeneous, look_at, rotation_y, rotation_z, unit
import numpy as np

JOINT_NAMES = ('dobot_j1', 'dobot_j2', 'dobot_j3', 'lens_yaw', 'lens_pitch')

__all__ = ['JOINT_NAMES', 'LensTarget', 'Rig', 'RigParameters', 'RigPose', 'UnreachableError',
           'camera_mount', 'default_rig_file', 'load_rig_parameters']


def _finite(name, value, size=None):
    """Return `value` as floats (shape (size,) when given); ValueError naming a non-finite one."""
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

    @property
    def T_lens_rgb(self):  # noqa: N802 (the project's transform naming)
        """RGB optical frame in the lens frame."""
        return camera_mount(self.rgb_position, self.camera_focus_depth)

    @property
    def T_lens_thermal(self):  # noqa: N802
        """Thermal optical frame in the lens frame."""
        return camera_mount(self.thermal_position, self.camera_focus_depth)

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


def escape_pitch(pitch, turn):
    """
    Return the lens pitch [rad] turned `turn` [rad] away from the pitch servo's nearer end.

    The wrist's escape when the arm cannot retreat, and the servo driver's on an emergency
    stop: the lens axis leaves the sun ray by `turn` (coma spreads the focus over the wood
    at 0.6 rad), whatever the sun, which neither knows for sure then.
    """
    return pitch - turn if pitch > 0.0 else pitch + turn


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
        self.parameters = parameters or RigParameters()
        self.arm = DobotArm(self.parameters.arm)
        self._T_lens_rgb = self.parameters.T_lens_rgb
        self._T_lens_thermal = self.parameters.T_lens_thermal

    def forward(self, x):
        """Return the RigPose at joints x (5 values) [rad]."""
        x = np.asarray(x, dtype=float).reshape(5)
        p = self.parameters
        flange = self.arm.forward(x[:3])
        T_robot_flange = homogeneous(rotation_z(x[0]), flange)
        T_flange_yaw = homogeneous(rotation_z(x[3]), p.yaw_axis_offset)
        T_yaw_pitch = homogeneous(rotation_y(x[4]), p.pitch_axis_offset)
        T_pitch_lens = homogeneous(translation=p.lens_offset)
        T_robot_lens = T_robot_flange @ T_flange_yaw @ T_yaw_pitch @ T_pitch_lens
        return RigPose(T_robot_flange=T_robot_flange, T_robot_lens=T_robot_lens,
                       T_robot_rgb=T_robot_lens @ self._T_lens_rgb,
                       T_robot_thermal=T_robot_lens @ self._T_lens_thermal,
                       yaw=float(x[0] + x[3]), pitch=float(x[4]))

    def inverse(self, position, yaw, pitch, check_limits=True):
        """
        Joints x for the lens pose Omega = [position, yaw, pitch, 0] (robot frame, rad).

        Closed form: the pitch- and lens-offsets are fixed by (yaw, pitch); the yaw-axis
        offset turns with j1, which is solved from the horizontal distance. Raises
        UnreachableError naming the joint (or the reach) and by how much.
        """
        p = self.parameters
        position = _finite('lens position', position, 3)
        yaw, pitch = _finite('lens yaw', yaw), _finite('lens pitch', pitch)
        rotation_yaw = rotation_z(yaw)
        # q = flange + Rz(j1) a, with a the yaw-axis offset in the flange frame.
        q = position - rotation_yaw @ (np.asarray(p.pitch_axis_offset, dtype=float)
                                       + rotation_y(pitch) @ np.asarray(p.lens_offset,
                                                                        dtype=float))
        a = np.asarray(p.yaw_axis_offset, dtype=float)
        horizontal = math.hypot(q[0], q[1])
        if horizontal < abs(a[1]) + 1e-9:
            raise UnreachableError(
                f'lens position {position} lies on the arm base axis '
                f'(horizontal distance {horizontal * 1000:.1f} mm)', joint='reach',
                excess=abs(a[1]) - horizontal)
        along = math.sqrt(horizontal ** 2 - a[1] ** 2)  # = flange reach + a_x
        j1 = math.atan2(q[1], q[0]) - math.atan2(a[1], along)
        reach = along - a[0]
        flange = np.array([reach * math.cos(j1), reach * math.sin(j1), q[2] - a[2]])
        if reach <= 0.0:
            raise UnreachableError(
                f'lens position {position} needs the flange {-reach * 1000:.1f} mm behind '
                'the base axis', joint='reach', excess=-reach)
        arm_joints = self.arm.inverse(flange, check_limits=False)
        if abs(math.remainder(arm_joints[0] - j1, 2.0 * math.pi)) > 1e-9:
            raise UnreachableError('flange heading does not match the base joint', 'reach')
        x = np.array([j1, arm_joints[1], arm_joints[2],
                      math.remainder(yaw - j1, 2.0 * math.pi), pitch])
        if check_limits:
            self.check_limits(x)
        return x

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

    def check_limits(self, x):
        """Raise UnreachableError for the first joint of x outside its limits."""
        check_joint_limits(self.parameters.limits(), x)

    def yaw_pitch_for_axis(self, axis, preferred_yaw=None):
        """
        Eq 15: (alpha_l, beta_l) putting the lens axis along `axis` (robot frame, -s0).

        Of the two solutions (alpha, beta) and (alpha + pi, -beta) return the one whose
        servo yaw (alpha - j1, j1 unknown here: relative to `preferred_yaw`) is closest to
        `preferred_yaw` (default 0). A vertical axis keeps alpha = preferred_yaw.
        """
        axis = _finite('lens axis', axis, 3)
        if not np.any(axis):
            raise ValueError('lens axis must not be the zero vector')
        axis = unit(axis)
        reference = 0.0 if preferred_yaw is None else _finite('preferred_yaw', preferred_yaw)
        horizontal = math.hypot(axis[0], axis[1])
        if horizontal < 1e-12:
            return reference, math.atan2(horizontal, axis[2])
        beta = math.atan2(horizontal, axis[2])
        alpha = math.atan2(axis[1], axis[0])
        other = alpha + math.pi
        if abs(math.remainder(other - reference, 2 * math.pi)) < \
                abs(math.remainder(alpha - reference, 2 * math.pi)):
            alpha, beta = other, -beta
        return reference + math.remainder(alpha - reference, 2 * math.pi), beta

    def lens_pose_for_target(self, target, sun_direction, d_lp, preferred_yaw=None):
        """
        Eqs 14-15: lens pose and joints that focus the sun ray onto `target` (robot frame).

        p_l = p_i - d_lp s0, the lens axis along -s0. Both wrist solutions are tried (the
        one nearest `preferred_yaw` first); the result's ``x`` is None with ``reason``
        when neither is reachable.
        """
        if not (math.isfinite(d_lp) and d_lp > 0.0):
            raise ValueError(f'd_lp must be a finite value > 0 m, got {d_lp}')
        target = _finite('target', target, 3)
        sun_direction = _finite('sun_direction', sun_direction, 3)
        if not np.any(sun_direction):
            raise ValueError('sun_direction must not be the zero vector')
        if preferred_yaw is not None:
            preferred_yaw = _finite('preferred_yaw', preferred_yaw)
        s0 = unit(sun_direction)
        if s0[2] >= 0.0:
            raise ValueError(f'the sun ray {s0} does not point down: the sun is not up')
        position = target - d_lp * s0
        heading = math.atan2(position[1], position[0])
        reference = heading if preferred_yaw is None else preferred_yaw
        yaw, pitch = self.yaw_pitch_for_axis(-s0, reference)
        reasons = []
        for alpha, beta in ((yaw, pitch), (yaw + math.pi, -pitch)):
            alpha = reference + math.remainder(alpha - reference, 2 * math.pi)
            try:
                x = self.inverse(position, alpha, beta)
            except UnreachableError as error:
                reasons.append(str(error))
                continue
            return LensTarget(position=position, yaw=alpha, pitch=beta, d_lp=d_lp, x=x)
        return LensTarget(position=position, yaw=yaw, pitch=pitch, d_lp=d_lp, x=None,
                          reason='; '.join(dict.fromkeys(reasons)))
