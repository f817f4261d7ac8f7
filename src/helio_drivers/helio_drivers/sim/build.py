"""
The rig as it was built, not as it was drawn (issue 28): the simulated world's hidden truth.

Every controller node believes ``config/rig.yaml``, the servo pulse constants and the
cameras' published intrinsics. A real rig differs from them by its build's tolerances: a
3D-printed wrist, hobby servos, a homed Dobot, cameras glued in place, a printed marker.
``draw_build(nominal, seed, scale)`` draws one such rig (``Build``) from ``Tolerances``
(half-widths of uniform draws; the sources are in SIMULATION.md, "The build"); ``ideal_build``
is the rig exactly as drawn. The world renders, moves and burns with the build; the
controller never sees it (it is published only on ``sim/truth/build`` and written as
``build.yaml`` beside ``canvas.png``).

What a build holds:

- ``rig``: the true RigParameters: every wrist and camera offset and the arm's links moved,
  the marker placed off the rig file's place (the user lays the panel down by eye), the lens
  tilted in its holder (``lens_tilt``), each camera turned in its mount (``rgb_rotation``,
  ``thermal_rotation``); its joints are the true angles (``BuiltJoints``);
- ``servos``: per wrist servo the true neutral pulse and microseconds per radian (the
  Maestro still reports the pulse it sends), and the play (deadband plus backlash) [rad];
- ``dobot_zero`` (j1, j2, j3) [rad]: true angle minus the angle the Dobot reports after
  homing; ``dobot_repeatability`` [m]: each move ends within about this of its target;
- ``rgb_camera``, ``thermal_camera``: the true intrinsics (focal length, centre, radial
  distortion) where the published camera_info holds the nominal ones (the user's calibration);
- ``marker_scale``: the printed marker's size over the nominal one.

``BuiltRig`` is the rig kinematics of a build (``Rig`` of the true parameters, whose aim
``lens_pose_for_target`` is refined numerically onto the tilted lens axis), ``BuiltJoints``
turns what the emulated devices report into the true joint angles.
"""

from dataclasses import asdict, dataclass, field, fields, replace
import math

from helio_drivers.maestro_protocol import ServoCalibration
from helio_optics.geometry import PinholeCamera
from helio_optics.rig_kinematics import Rig
import numpy as np

BUILDS = ('ideal', 'drawn')
WRIST_OFFSETS = ('yaw_axis_offset', 'pitch_axis_offset', 'lens_offset', 'rgb_position',
                 'thermal_position')
ARM_LINKS = ('rear_arm', 'forearm', 'tool_x', 'tool_z')


@dataclass(frozen=True)
class Tolerances:
    """
    Half-widths of a 3D-printed build's errors (uniform draws); sources in SIMULATION.md.

    ``draw_build``'s `scale` multiplies every one (1/3: a careful build, machined parts).
    """

    mount_offset: float = 0.0015                 # each wrist and camera offset, per axis [m]
    mount_angle: float = math.radians(1.5)       # lens tilt, camera turn, per axis [rad]
    servo_neutral_us: float = 25.0               # neutral pulse [us]
    servo_scale: float = 0.08                    # microseconds per radian, relative [-]
    servo_deadband_us: tuple = (2.0, 6.0)        # range of the deadband [us] (not scaled)
    servo_backlash: tuple = (math.radians(0.1), math.radians(0.4))   # range [rad] (not scaled)
    dobot_zero: float = math.radians(0.3)        # joint zero after homing [rad]
    dobot_link: float = 0.0005                   # each link length [m]
    dobot_repeatability: float = 0.0002          # the Magician's specification [m] (not scaled)
    camera_focal: float = 0.005                  # focal length, relative [-]
    rgb_centre_px: float = 4.0                   # principal point, per axis [px]
    thermal_centre_px: float = 1.0               # [px] (160 x 120 pixels)
    rgb_k1: float = 0.005                        # radial distortion k1 [-]
    thermal_k1: float = 0.005                    # [-]
    marker_scale: float = 0.005                  # printed size, relative [-]
    marker_offset: float = 0.003                 # the panel laid down by eye, per axis [m]
    marker_yaw: float = math.radians(0.6)        # [rad]


@dataclass(frozen=True)
class ServoBuild:
    """One wrist servo as built: what turns it, against what the controller believes."""

    name: str
    centre_us: float          # the pulse at which the joint angle is 0 [us]
    us_per_rad: float         # [us/rad]
    play: float               # deadband plus backlash: the shaft's free travel [rad]

    def calibration(self, channel):
        """Return the ServoCalibration of the true servo (the emulator turns pulses with it)."""
        return ServoCalibration(self.name, channel, us_per_rad=self.us_per_rad,
                                centre_pulse_us=self.centre_us)


@dataclass(frozen=True)
class CameraBuild:
    """A camera's true intrinsics, relative to the published (nominal) ones."""

    focal_scale: float = 1.0          # true focal length over the published one [-]
    centre_shift: tuple = (0.0, 0.0)  # true principal point minus the published one [px]
    k1: float = 0.0                   # the lens' true radial distortion [-]

    def true_camera(self, published):
        """Return the PinholeCamera the world renders with, from the published one."""
        matrix = np.array(published.matrix, dtype=float)
        matrix[0, 0] *= self.focal_scale
        matrix[1, 1] *= self.focal_scale
        matrix[0, 2] += self.centre_shift[0]
        matrix[1, 2] += self.centre_shift[1]
        distortion = np.zeros(5)
        distortion[0] = self.k1
        return PinholeCamera(matrix=matrix, width=published.width, height=published.height,
                             distortion=distortion)


@dataclass(frozen=True)
class Build:
    """One rig as built (see the module docstring); ``ideal`` when it is the rig file's."""

    name: str
    seed: int
    scale: float
    rig: object                     # RigParameters
    servos: tuple = ()
    dobot_zero: tuple = (0.0, 0.0, 0.0)
    dobot_repeatability: float = 0.0
    rgb_camera: CameraBuild = field(default_factory=CameraBuild)
    thermal_camera: CameraBuild = field(default_factory=CameraBuild)
    marker_scale: float = 1.0

    def servo(self, name):
        """Return the ServoBuild of `name` ('lens_yaw' or 'lens_pitch')."""
        for servo in self.servos:
            if servo.name == name:
                return servo
        raise KeyError(f'no servo {name!r} in the build')

    def to_dict(self):
        """Return the build as plain numbers (build.yaml, sim/truth/build): SI units, rad."""
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        values['rig'] = self.rig.to_parameters()
        values['servos'] = [asdict(servo) for servo in self.servos]
        for name in ('rgb_camera', 'thermal_camera'):
            values[name] = asdict(values[name])
        return _plain(values)


def _plain(value):
    """Return `value` with numpy numbers and tuples as Python floats, ints and lists."""
    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(item) for item in value]
    if isinstance(value, (bool, str, int)) and not isinstance(value, np.generic):
        return value
    return float(value)


def ideal_build(nominal, servo_centre_us=1500.0, servo_us_per_rad=2000.0 / math.pi):
    """Return the Build that is exactly the rig file and the nominal servo constants."""
    servos = tuple(ServoBuild(name, servo_centre_us, servo_us_per_rad, 0.0)
                   for name in ('lens_yaw', 'lens_pitch'))
    return Build(name='ideal', seed=0, scale=0.0, rig=nominal, servos=servos)


def draw_build(nominal, seed, scale=1.0, tolerances=None, servo_centre_us=1500.0,
               servo_us_per_rad=2000.0 / math.pi):
    """
    Draw a Build around the `nominal` RigParameters: each error uniform in its tolerance.

    `scale` multiplies the tolerances of the parts a builder makes (not the specified
    ones: the servos' deadband and backlash, the Dobot's repeatability); `seed` makes the
    draw reproducible.
    """
    if not (math.isfinite(scale) and scale >= 0.0):
        raise ValueError(f'build scale must be finite and >= 0, got {scale}')
    t = tolerances or Tolerances()
    rng = np.random.default_rng(seed)

    def uniform(half_width, size=None):
        return rng.uniform(-half_width * scale, half_width * scale, size)

    rig = {name: tuple(np.add(getattr(nominal, name), uniform(t.mount_offset, 3)))
           for name in WRIST_OFFSETS}
    arm = replace(nominal.arm, **{name: getattr(nominal.arm, name) + uniform(t.dobot_link)
                                  for name in ARM_LINKS})
    world = np.add(nominal.world_in_robot, uniform(t.marker_offset, 3) * [1.0, 1.0, 0.0])
    true_rig = replace(nominal, arm=arm, world_in_robot=tuple(world),
                       world_yaw=nominal.world_yaw + uniform(t.marker_yaw),
                       lens_tilt=tuple(uniform(t.mount_angle, 2)),
                       rgb_rotation=tuple(uniform(t.mount_angle, 3)),
                       thermal_rotation=tuple(uniform(t.mount_angle, 3)), **rig)
    servos = []
    for name in ('lens_yaw', 'lens_pitch'):
        deadband_us = rng.uniform(*t.servo_deadband_us)
        us_per_rad = servo_us_per_rad * (1.0 + uniform(t.servo_scale))
        servos.append(ServoBuild(name, servo_centre_us + uniform(t.servo_neutral_us),
                                 us_per_rad,
                                 deadband_us / us_per_rad + rng.uniform(*t.servo_backlash)))
    return Build(
        name='drawn', seed=int(seed), scale=float(scale), rig=true_rig, servos=tuple(servos),
        dobot_zero=tuple(uniform(t.dobot_zero, 3)),
        dobot_repeatability=t.dobot_repeatability,
        rgb_camera=CameraBuild(1.0 + uniform(t.camera_focal), tuple(uniform(t.rgb_centre_px, 2)),
                               uniform(t.rgb_k1)),
        thermal_camera=CameraBuild(1.0 + uniform(t.camera_focal),
                                   tuple(uniform(t.thermal_centre_px, 2)), uniform(t.thermal_k1)),
        marker_scale=1.0 + uniform(t.marker_scale))


class BuiltRig(Rig):
    """
    The kinematics of a Build: ``Rig`` of its true parameters, fed the TRUE joint angles.

    ``lens_pose_for_target`` refines Rig's closed form (which leaves the lens tilt out) with
    Newton steps until the TRUE lens centre and axis are the target's, so the world's truth
    (``truth.true_sun_focus_joints``) still aims its lens exactly.
    """

    def __init__(self, build):
        """Use the build's true RigParameters."""
        super().__init__(build.rig)
        self.build = build

    def lens_pose_for_target(self, target, sun_direction, d_lp, preferred_yaw=None):
        """Rig's Eqs 14-15, then the joints refined until the TRUE lens pose is the target's."""
        lens = super().lens_pose_for_target(target, sun_direction, d_lp, preferred_yaw)
        if lens.x is None or not any(self.parameters.lens_tilt):
            return lens
        wanted_axis = -np.asarray(sun_direction, float) / np.linalg.norm(sun_direction)
        x = np.array(lens.x, dtype=float)

        def error(joints):
            T = self.forward(joints).T_robot_lens
            return np.concatenate([T[:3, 3] - lens.position, np.cross(T[:3, 2], wanted_axis)])

        for _ in range(8):
            residual = error(x)
            if np.linalg.norm(residual) < 1e-10:
                break
            jacobian = np.empty((6, 5))
            for j in range(5):
                step = np.zeros(5)
                step[j] = 1e-7
                jacobian[:, j] = (error(x + step) - residual) / 1e-7
            x = x - np.linalg.lstsq(jacobian, residual, rcond=None)[0]
        return replace(lens, x=x)


def play(previous, commanded, width):
    """
    Return where a shaft with free travel `width` ends when its drive moves to `commanded`.

    The backlash (play) operator: the shaft stays unless the drive pushes it past half the
    play on either side. A servo's deadband acts the same way on its commands.
    """
    half = 0.5 * width
    return min(max(previous, commanded - half), commanded + half)


class BuiltJoints:
    """
    The true joint angles of a Build from what its emulated devices do.

    The Dobot's reported angles plus its zero offsets, and a repeatability error redrawn
    at each move (kept while the arm rests); each servo's angle from the pulse it is sent
    (the emulator turns it with the servo's true calibration) through its play.
    """

    def __init__(self, build, seed=0):
        """Hold the build and the play state of each servo."""
        self.build = build
        self._rng = np.random.default_rng(seed + 101)
        self._reach = 0.28        # the flange's typical distance from the shoulder [m]
        self._arm_at = None       # the reported arm joints of the last read
        self._scatter = np.zeros(3)
        self._shaft = {}

    def true_joints(self, arm, wrist):
        """
        Return x (5,) [rad]: `arm` the Dobot's reported j1..j3, `wrist` {servo: angle}.

        The wrist angles are those of the pulses sent, through the servos' true
        calibration (``ServoBuild.calibration``); each then goes through the servo's play.
        """
        arm = np.asarray(arm, dtype=float)[:3]
        if self.build.dobot_repeatability > 0.0 and (
                self._arm_at is None or np.any(arm != self._arm_at)):
            # moving: the move ends somewhere within the repeatability (one sigma a third)
            sigma = self.build.dobot_repeatability / 3.0 / self._reach
            self._scatter = self._rng.normal(0.0, sigma, 3)
            self._arm_at = arm.copy()
        true_arm = arm + np.asarray(self.build.dobot_zero) + self._scatter
        angles = []
        for name in ('lens_yaw', 'lens_pitch'):
            commanded = float(wrist[name])
            width = self.build.servo(name).play
            shaft = self._shaft.get(name, commanded)
            self._shaft[name] = shaft = play(shaft, commanded, width)
            angles.append(shaft)
        return np.concatenate([true_arm, angles])


def build_from_name(name, nominal, seed=0, scale=1.0, servo_centre_us=1500.0,
                    servo_us_per_rad=2000.0 / math.pi):
    """Return the Build `name` ('ideal' or 'drawn'); ValueError naming the choices."""
    if name == 'ideal':
        return ideal_build(nominal, servo_centre_us, servo_us_per_rad)
    if name == 'drawn':
        return draw_build(nominal, seed, scale, servo_centre_us=servo_centre_us,
                          servo_us_per_rad=servo_us_per_rad)
    raise ValueError(f"build must be one of {', '.join(BUILDS)}, got {name!r}")


__all__ = ['BUILDS', 'Build', 'build_from_name', 'BuiltJoints', 'BuiltRig', 'CameraBuild',
           'draw_build', 'ideal_build', 'play', 'ServoBuild', 'Tolerances']
