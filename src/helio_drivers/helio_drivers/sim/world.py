"""
The simulated world, without ROS: sun, lens flux, wood, cameras, clock and canvas (issue 6).

``SimWorld`` ties the parts together. Each ``step()`` advances the simulated clock by
``step``, reads where the rig truly is (the hosted emulators, or any callable returning
x in R^5), traces the sun through the lens at that pose (re-traced only when something moved),
heats the wood and chars it. ``thermal_image()`` and ``rgb_image()`` render the cameras at
their poses on the end effector; ``canvas_image()`` and ``charred_dots()`` give the painting
and its ground truth, ``canvas_picture()`` the burnt panel as a person sees it;
``write_outputs(dir)`` writes ``canvas.png`` (the picture), ``canvas_mask.png`` (the char
map), ``dots.csv`` and ``build.yaml`` (the rig as built, ``sim.build``: a drawn build's
geometry, servos, camera intrinsics and marker print differ from what the controller
believes, as a real rig's do).

Nothing here tells the controller what it wants to know: the robot's heading, the sun and
the lens focus are only visible through the images, as on the real rig.
"""

import contextlib
from dataclasses import dataclass, field, fields, replace
import datetime
import math
import os

import cv2
from helio_drivers.sim.build import BuiltRig, ideal_build
from helio_drivers.sim.cameras import (FlatFieldCorrection, light_window, RgbCamera, RgbSettings,
                                       ThermalCamera, ThermalSettings)
from helio_drivers.sim.clock import SimClock
from helio_drivers.sim.flux import irradiance_on_cells, lens_pose_in_world, LensFlux
from helio_drivers.sim.kernels import char_canvas
from helio_drivers.sim.sun import CloudCover, RandomClouds, Sun
from helio_drivers.sim.wood import GridParameters, WoodPanel, WoodParameters
from helio_optics.calibration_board import BoardSpec
from helio_optics.ephemeris import Site
from helio_optics.geometry import invert_transform
from helio_optics.lens import LensParameters
from helio_optics.node_kit.process_tuning import keep_large_buffers
from helio_optics.rig_kinematics import RigParameters
from helio_optics.thermal_cameras import thermal_camera
import numpy as np
import yaml


@dataclass(frozen=True)
class SimSettings:
    """Everything about the world that is not the rig geometry (see config/sim_world.yaml)."""

    latitude_deg: float = 48.137
    longitude_deg: float = 11.575
    elevation: float = 520.0
    start_time: str = '2026-06-21T10:00:00+02:00'   # ISO 8601 with its UTC offset
    robot_heading_deg: float = 200.0     # hidden: compass azimuth of the robot's x axis
    dni: float = 900.0                   # clear-sky direct normal irradiance [W/m^2]
    cloud_schedule: tuple = ()           # flat (start_s, end_s, attenuation) triples
    random_clouds: bool = False
    cloud_seed: int = 0
    cloud_mean_clear: float = 300.0
    cloud_mean_cloudy: float = 30.0
    cloud_attenuation_range: tuple = (0.2, 0.7)
    step: float = 0.1                  # simulated time per step [s]
    seed: int = 0                        # camera noise
    lens: LensParameters = field(default_factory=lambda: LensParameters(
        focal_length=0.081, aperture_diameter=0.038, transmission=0.92))   # tuned
    flux_rays: int = 20000
    flux_rays_moving: int = 2500         # per band while the lens keeps moving
    beam_spread: float = 0.004           # lens optical errors, Gaussian sigma [rad] (tuned)
    wood: WoodParameters = field(default_factory=WoodParameters)
    grid: GridParameters = field(default_factory=GridParameters)
    panel_extent: tuple = (-0.04, 0.16, -0.04, 0.16)   # x_min, x_max, y_min, y_max [m]
    marker_side: float = 0.04
    marker_id: int = 0
    marker_dictionary: str = 'DICT_4X4_50'
    # a laser print on office paper: in full sun its black is still darker than its white in
    # the lens shadow (sky light only), by a factor of about 2 (an ideal print: 0, 1)
    marker_print_reflectance: tuple = (0.05, 0.85)   # (ink, paper), linear [-]
    # a printed ChArUco board for the camera calibration (issue 29, item 5), printed as the
    # marker is: its centre x, y [m] and yaw [rad] on the panel, () for none (the default:
    # the panel as before); squares (columns, rows), their side and the markers' [m]
    board_pose: tuple = ()
    board_squares: tuple = (7, 5)
    board_square: float = 0.014
    board_marker: float = 0.0105
    board_dictionary: str = 'DICT_5X5_100'
    rgb: RgbSettings = field(default_factory=RgbSettings)
    thermal: ThermalSettings = field(default_factory=ThermalSettings)
    # a datasheet's thermal camera (helio_optics.thermal_cameras: 'paper',
    # 'lepton35_high_gain', 'lepton35_low_gain') in place of `thermal`; '': `thermal` as given
    thermal_profile: str = ''
    # the flat-field correction's period of either [s] (< 0: the camera's own): a test's
    # freezes come every few seconds instead of every 3 minutes
    thermal_ffc_period: float = -1.0

    def thermal_settings(self):
        """Return the thermal camera's settings: the profile's (its error from `seed`)."""
        settings = self.thermal if not self.thermal_profile else ThermalSettings.from_spec(
            thermal_camera(self.thermal_profile), self.seed)
        if self.thermal_ffc_period >= 0.0:
            settings = replace(settings, ffc_period=float(self.thermal_ffc_period))
        return settings

    def start_datetime(self):
        """Return the start as an aware datetime (ValueError if the offset is missing)."""
        when = datetime.datetime.fromisoformat(self.start_time)
        if when.utcoffset() is None:
            raise ValueError(f'start_time {self.start_time!r} needs a UTC offset, '
                             'e.g. 2026-06-21T10:00:00+02:00')
        return when

    def board(self):
        """Return (BoardSpec, centre (x, y), yaw) of the printed board, or None (no board)."""
        if not self.board_pose:
            return None
        if len(self.board_pose) != 3:
            raise ValueError(f'board_pose must be [x, y, yaw] (m, m, rad) or empty, got '
                             f'{list(self.board_pose)}')
        spec = BoardSpec(tuple(int(v) for v in self.board_squares), float(self.board_square),
                         float(self.board_marker), self.board_dictionary)
        x, y, yaw = (float(v) for v in self.board_pose)
        return spec, (x, y), yaw

    def cloud_cover(self):
        """Return the CloudCover of the schedule and the optional random process."""
        process = None
        if self.random_clouds:
            process = RandomClouds(seed=self.cloud_seed, mean_clear=self.cloud_mean_clear,
                                   mean_cloudy=self.cloud_mean_cloudy,
                                   attenuation_range=tuple(self.cloud_attenuation_range))
        return CloudCover.from_flat(self.cloud_schedule, process)


@dataclass
class CharredDot:
    """One charred dot of the canvas (ground truth): centroid and size in the world frame."""

    x: float          # [m]
    y: float          # [m]
    diameter: float   # equivalent diameter 2 sqrt(area / pi) [m]
    area: float       # [m^2]


def charred_dots_of(mask, origin, cell, minimum_area=0.05e-6):
    """
    Return the CharredDots of a char mask: connected regions, centroid and size (world).

    `mask` (rows from y_min) is true where the wood is charred, `origin` the world (x, y) of
    its corner [m], `cell` its pixel side [m]; regions under `minimum_area` [m^2] are left
    out. A subscriber of ``sim/canvas`` (row 0 at y_max) flips it first.
    """
    count, _, stats, centroids = cv2.connectedComponentsWithStats(
        np.asarray(mask).astype(np.uint8), connectivity=8)
    dots = []
    for label in range(1, count):
        area = stats[label, cv2.CC_STAT_AREA] * cell * cell
        if area < minimum_area:
            continue
        column, row = centroids[label]
        dots.append(CharredDot(x=float(origin[0] + (column + 0.5) * cell),
                               y=float(origin[1] + (row + 0.5) * cell),
                               diameter=float(2.0 * math.sqrt(area / math.pi)),
                               area=float(area)))
    return dots


def settings_from_flat(flat, base=None):
    """
    Build SimSettings from flat names ('dni', 'wood.density', 'lens.aperture_diameter', ...).

    Unknown names raise ValueError; angles in the flat form are as named (deg where '_deg').
    """
    base = base or SimSettings()
    groups = {'lens': base.lens, 'wood': base.wood, 'grid': base.grid, 'rgb': base.rgb,
              'thermal': base.thermal}
    top, nested = {}, {name: {} for name in groups}
    top_names = {f.name for f in fields(SimSettings)} - set(groups)
    for name, value in flat.items():
        group, _, leaf = name.partition('.')
        if leaf and group in groups:
            names = {f.name for f in fields(groups[group])}
            if leaf not in names:
                raise ValueError(f'unknown sim parameter {name!r}')
            nested[group][leaf] = value
        elif name in top_names:
            top[name] = tuple(value) if isinstance(value, list) else value
        else:
            raise ValueError(f'unknown sim parameter {name!r}')
    for group, values in nested.items():
        if values:
            top[group] = replace(groups[group], **values)
    return replace(base, **top)


def flat_settings(settings):
    """Return the flat name -> value dict of SimSettings (inverse of settings_from_flat)."""
    flat = {}
    for f in fields(SimSettings):
        value = getattr(settings, f.name)
        if f.name in ('lens', 'wood', 'grid', 'rgb', 'thermal'):
            for g in fields(value):
                flat[f'{f.name}.{g.name}'] = getattr(value, g.name)
        else:
            flat[f.name] = list(value) if isinstance(value, tuple) else value
    return flat


class SimWorld:
    """The simulated world; see the module docstring."""

    def __init__(self, settings=None, rig_parameters=None, joints=None, build=None):
        """
        Build the world. `joints` is a callable returning x (5,) [rad] at the clock's time.

        Without it, set the joints with ``set_joints`` (tests) or host the emulators on the
        world's clock (``SimDevices(world.clock)``) and attach their ``joint_positions`` with
        ``attach_joint_source``. `build` (``sim.build.Build``) is the rig as built: its
        geometry, mounts, camera intrinsics and marker print; default the ideal build of
        `rig_parameters` (exactly the rig file).
        """
        # its 0.3-4 MB arrays, allocated and freed every step and frame, are reused from the
        # heap, not page-faulted in anew (a tridiagonal product 1.1 -> 0.3 ms:
        # docs/measurements/simulation-speed-history.md)
        keep_large_buffers()
        self.settings = settings or SimSettings()
        s = self.settings
        if not s.step > 0.0:
            raise ValueError(f'step must be > 0 s, got {s.step}')
        self.clock = SimClock(s.start_datetime())
        if build is not None and rig_parameters is not None:
            raise ValueError('give the world a build or rig parameters, not both')
        self.build = build or ideal_build(rig_parameters or RigParameters())
        self.rig = BuiltRig(self.build)
        self.T_robot_world = self.rig.parameters.T_robot_world
        self.T_world_robot = invert_transform(self.T_robot_world)
        self.site = Site(s.latitude_deg, s.longitude_deg, s.elevation)
        self.sun = Sun(self.site, math.radians(s.robot_heading_deg), s.dni, s.cloud_cover(),
                       self.T_robot_world)
        self.flux = LensFlux(s.lens, rays=s.flux_rays, seed=s.seed, beam_spread=s.beam_spread,
                             moving_rays=s.flux_rays_moving)
        self.panel = WoodPanel(s.wood, s.grid, s.panel_extent)
        # the cameras' camera_info: the intrinsics the user's calibration gave (nominal);
        # the images are rendered with the build's true ones
        self.thermal_settings = s.thermal_settings()
        self.published_cameras = {'rgb': s.rgb.camera(),
                                  'thermal': self.thermal_settings.camera()}
        self.thermal = ThermalCamera(
            self.thermal_settings, seed=s.seed,
            camera=self.build.thermal_camera.true_camera(self.published_cameras['thermal']))
        thermal = self.thermal_settings
        self.flat_field = FlatFieldCorrection(thermal.ffc_period, thermal.ffc_freeze_min,
                                              thermal.ffc_freeze_max, seed=s.seed)
        self._last_thermal = None    # the last thermal image: repeated while frozen
        self.thermal_stuck = False   # a hung camera: its last frame, until this is false
        self.rgb = RgbCamera(self.panel.extent, s.grid.fine_cell, s.rgb, s.marker_side,
                             s.marker_id, s.marker_dictionary, seed=s.seed,
                             print_reflectance=s.marker_print_reflectance,
                             camera=self.build.rgb_camera.true_camera(
                                 self.published_cameras['rgb']),
                             marker_scale=self.build.marker_scale, board=s.board())
        self._rng = np.random.default_rng(s.seed)
        self._joints_source = joints
        self._holding_joints = self._joints_held = False     # one_instant
        self._x = np.array([0.0, math.radians(30.0), math.radians(30.0), 0.0, 0.0])
        self._sun_ray = None
        self._sun_ray_time = -math.inf
        self._dni = 0.0
        self._field = None
        self._irradiance_key = None
        self._unit_irradiance = None
        self._light_key = None
        self._light = None
        self._pose_key = None
        self._pose = None
        self._lens_pose_key = None
        self._T_world_lens = None
        self._camera_pose_key = None
        self._camera_poses = None
        self.steps = 0
        self._refresh()

    # ------------------------------------------------------------------ state
    @property
    def time(self):
        """Return the simulated seconds since the start."""
        return self.clock()

    def attach_joint_source(self, source):
        """Read the joints from `source()` -> x (5,) [rad] from now on (e.g. the emulators)."""
        if not callable(source):
            raise TypeError(f'the joint source must be callable, got {type(source).__name__}')
        self._joints_source = source

    def set_joints(self, x):
        """Put the rig at x (5,) [rad] (when no joint source is attached)."""
        self._x = np.asarray(x, dtype=float).reshape(5).copy()

    def joint_positions(self):
        """Return x (5,) [rad] of the rig now (within ``one_instant``: as first read there)."""
        if self._joints_source is not None and not self._joints_held:
            self._x = np.asarray(self._joints_source(), dtype=float).reshape(5)
            self._joints_held = self._holding_joints
        return self._x.copy()

    @contextlib.contextmanager
    def one_instant(self):
        """
        Read the joint source once for all that the block does: a step and its outputs.

        The step's flux and the frames and truths published after it are then of one
        instant of the devices (a command the emulators take meanwhile counts from the next
        step on), and the emulators are read once a step instead of three to five times.
        """
        self._holding_joints, self._joints_held = True, False
        try:
            yield self
        finally:
            self._holding_joints = self._joints_held = False

    def pose(self):
        """Return the RigPose (robot-frame transforms) at the present joints."""
        x = self.joint_positions()
        key = x.tobytes()
        if key != self._pose_key:  # the arm is still most of the time
            self._pose = self.rig.forward(x)
            self._pose_key = key
        return self._pose

    def camera_poses(self):
        """Return (T_world_rgb, T_world_thermal) at the present joints."""
        pose = self.pose()
        if self._camera_pose_key != self._pose_key:     # once per pose
            self._camera_poses = (self.T_world_robot @ pose.T_robot_rgb,
                                  self.T_world_robot @ pose.T_robot_thermal)
            self._camera_pose_key = self._pose_key
        return tuple(T.copy() for T in self._camera_poses)

    def sun_ray_world(self):
        """Return the true sun ray s0 in the world frame now (for tests and the demo only)."""
        return self.sun.ray_world(self.clock.datetime())

    def dni_now(self):
        """Return the direct normal irradiance now, clouds included [W/m^2]."""
        return self._dni

    def peak_irradiance(self):
        """Return the highest irradiance on a cell of the heat patch now [W/m^2] (0 before)."""
        if self._unit_irradiance is None:
            return 0.0
        return float(self._dni * np.max(self._unit_irradiance))

    @property
    def flux_field(self):
        """Return the FluxField (per unit DNI) of the present lens pose."""
        return self._field

    def set_cloud_schedule(self, flat):
        """
        Replace the cloud schedule (flat start_s, end_s, attenuation triples) from now on.

        The random clouds of the settings stay; ValueError for a malformed schedule.
        """
        settings = replace(self.settings, cloud_schedule=tuple(float(v) for v in flat))
        self.sun.clouds = settings.cloud_cover()
        self.settings = settings

    # ------------------------------------------------------------------ dynamics
    def _refresh(self):
        """Update sun, lens field and irradiance for the present time and joints."""
        now = self.clock()
        when = self.clock.datetime()
        # the sun turns 7e-5 rad/s: a new ray each simulated second, under the flux's
        # angle tolerance (a ray that changed every step would cost a comparison per step)
        if now - self._sun_ray_time >= 1.0 or self._sun_ray is None:
            position = self.sun.position(when)
            self._sun_ray = self.sun.ray_world_of(position)
            self._sun_ray_time = now
            self._sun_up = position.elevation > 0.0
        self._dni = self.sun.dni * self.sun.clouds.attenuation(now) if self._sun_up else 0.0
        pose_key = self._pose_key
        pose = self.pose()
        moving = pose_key is not None and self._pose_key != pose_key   # since the last step
        if self._lens_pose_key != self._pose_key:
            self._T_world_lens = lens_pose_in_world(self.T_robot_world, pose.T_robot_lens)
            self._lens_pose_key = self._pose_key
        T_world_lens = self._T_world_lens
        self._field = self.flux.field(T_world_lens, self._sun_ray, moving=moving)
        centroid = self._field.centroid()
        self.panel.follow(centroid)
        key = (self.flux.fields, tuple(self.panel.centre))
        if key != self._irradiance_key:
            self._unit_irradiance = irradiance_on_cells(self._field, self.panel.x_edges,
                                                        self.panel.y_edges, 1.0)
            self._irradiance_key = key

    def step(self):
        """Advance the world by one step of ``step`` simulated seconds."""
        dt = self.settings.step
        self.clock.advance(dt)
        self._refresh()
        self.panel.step(dt, self._dni * self._unit_irradiance,
                        self._dni * self._field.direct)
        self.steps += 1

    def run(self, duration):
        """Step until `duration` more simulated seconds have passed."""
        end = self.clock() + duration - 1e-9
        while self.clock() < end:
            self.step()

    # ------------------------------------------------------------------ sensors
    def thermal_temperatures(self, noise=True):
        """Return the thermal camera's read-out [degC] (H, W) at its present pose."""
        _, T_world_thermal = self.camera_poses()
        camera = self.thermal if noise else ThermalCamera(
            replace(self.thermal_settings, noise_sigma=0.0))
        return camera.temperatures(self.panel, T_world_thermal, self._rng)

    def thermal_image(self):
        """
        Return the thermal image, centikelvin (H, W) uint16, with noise.

        While a flat-field correction freezes the camera, or while it is stuck
        (``thermal_stuck``), the last image again (the same array: a frozen output repeats
        its last frame bit for bit).
        """
        last = self._last_thermal
        if last is not None and (self.thermal_stuck or self.flat_field.frozen(self.time)):
            return last
        _, T_world_thermal = self.camera_poses()
        image = self.thermal.image(self.panel, T_world_thermal, self._rng)
        # a live camera never repeats a frame bit for bit (a thermal monitor would take it
        # for a frozen one): a still scene whose noise crop came up again (once in 4356
        # frames of the noise bank) is read out again with another
        while (last is not None and self.thermal.settings.noise_sigma > 0.0
               and np.array_equal(image, last)):
            image = self.thermal.image(self.panel, T_world_thermal, self._rng)
        self._last_thermal = image
        return image

    def rgb_image(self):
        """Return the RGB image (H, W, 3) uint8 at the camera's present pose."""
        return self.stage_rgb_frame()()

    def stage_rgb_frame(self):
        """
        Take the RGB camera's frame now; return it to develop (``cameras.DevelopingFrame``).

        Call the returned frame for the image, here or on another thread while the world
        steps on (``RgbCamera.stage``): the image is the one ``rgb_image`` gives now.
        """
        T_world_rgb, _ = self.camera_poses()
        field = self._field
        if self.flux.fields != self._light_key:  # the lit window changes only with a new field
            window = self._light_window(field)
            self._light = None if window is None else light_window(
                field, self.panel.raster_shape, self.panel.raster_origin,
                self.panel.grid.fine_cell, window)
            self._light_key = self.flux.fields
        self.rgb.update_char(self.panel.char, self.panel.take_char_changes())
        attenuation = self._dni / max(self.sun.dni, 1e-9)   # clouds dim the direct sun only
        return self.rgb.stage(T_world_rgb, self._light, attenuation, self._rng)

    def _light_window(self, field):
        """Return the panel box holding the lens shadow and the focused spot."""
        s0 = field.sun_ray
        if s0[2] >= 0.0:
            return None
        centre = field.lens_centre[:2] + (-field.lens_centre[2] / s0[2]) * s0[:2]
        reach = field.aperture_radius / max(abs(s0[2]), 0.2) + 0.004
        boxes = [(centre[0] - reach, centre[0] + reach, centre[1] - reach, centre[1] + reach)]
        if field.points.size:
            lo, hi = field.bounds()
            boxes.append((lo[0] - 0.002, hi[0] + 0.002, lo[1] - 0.002, hi[1] + 0.002))
        return (min(b[0] for b in boxes), max(b[1] for b in boxes),
                min(b[2] for b in boxes), max(b[3] for b in boxes))

    # ------------------------------------------------------------------ canvas
    def canvas_image(self):
        """Return the char map as a top-view mono8 image (255 bare, 0 char; row 0 at y_max)."""
        image = np.empty(self.panel.char.shape, np.uint8)
        char_canvas(self.panel.char, image)
        return image

    def canvas_picture(self):
        """
        Return the burnt panel as a person sees it: (H, W, 3) uint8 sRGB RGB, row 0 at y_max.

        Top view, one square pixel per char raster pixel: the RGB camera's wood, marker and
        char colours (``RgbCamera.top_view``) under even white light.
        """
        return self.rgb.top_view(self.panel.char)

    def charred_dots(self, minimum_area=0.05e-6):
        """Return the CharredDots: connected charred regions, centroid and size (world)."""
        return charred_dots_of(self.panel.charred_mask(), self.panel.raster_origin,
                               self.panel.grid.fine_cell, minimum_area)

    def write_outputs(self, directory):
        """
        Write canvas.png, canvas_mask.png, dots.csv, build.yaml; return (canvas.png, dots.csv).

        canvas.png is the burnt panel as a person sees it (``canvas_picture``),
        canvas_mask.png the char map as data (``canvas_image``: 255 bare, 0 charred), both
        top views of the same pixels; dots.csv the charred dots (ground truth); build.yaml
        the rig as built (``sim.build.Build.to_dict``: hidden truth, as dots.csv).
        """
        os.makedirs(directory, exist_ok=True)
        with open(os.path.join(directory, 'build.yaml'), 'w') as stream:
            stream.write('# the simulated rig as built (helio_drivers.sim.build): hidden from '
                         'every controller node; SI units, rad\n')
            yaml.safe_dump(self.build.to_dict(), stream, sort_keys=False)
        png = os.path.join(directory, 'canvas.png')
        mask = os.path.join(directory, 'canvas_mask.png')
        for path, image in ((png, cv2.cvtColor(self.canvas_picture(), cv2.COLOR_RGB2BGR)),
                            (mask, self.canvas_image())):
            if not cv2.imwrite(path, image):
                raise OSError(f'could not write {path}')
        csv = os.path.join(directory, 'dots.csv')
        x_min, x_max, y_min, y_max = self.panel.extent
        with open(csv, 'w') as stream:
            stream.write(f'# charred dots (char fraction >= {self.panel.wood.charred_fraction}) '
                         f'in the world frame; canvas.png and canvas_mask.png span x '
                         f'{x_min:.4f}..{x_max:.4f} m, '
                         f'y {y_min:.4f}..{y_max:.4f} m, {self.panel.grid.fine_cell:.6f} m/px, '
                         'row 0 at y_max\n')
            stream.write('x_m,y_m,diameter_m,area_m2\n')
            for dot in self.charred_dots():
                stream.write(f'{dot.x:.6f},{dot.y:.6f},{dot.diameter:.6f},{dot.area:.9f}\n')
        return png, csv
