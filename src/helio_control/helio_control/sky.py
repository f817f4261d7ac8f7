"""
When the sun serves a canvas: the hours of a day, their windows and the best heading.

The core of ``helio sky`` and of the painter's refusal of a goal the sun cannot serve
(issue 30, item 7). No rclpy.

At an instant the sun **serves** the canvas when both hold:

1. **reach**: every point of a grid over the canvas (corners and edges included, spacing at
   most ``reach_spacing``) has a lens pose at the heating distance d_lp and at the retreat
   d_lp + delta d_lp: Eq 14 p_l = p_i - d_lp s0 and Eq 15 (the lens axis along -s0, both
   wrist solutions) through ``Rig.lens_pose_for_target``, by the rule the plan applies to
   every dot (``dot_layout.check_reach``);
2. **sweep**: the lens planner can estimate this sun (paper Sec. V-B, ``sun_sweep``): the sun
   stands at least ``min_elevation_deg`` up, at least ``min_sweep_poses`` of the sweep's
   candidate poses (its lens distances and tilts) and one of the spot search's (the
   acquisition's distances and tilts, aimed at the true sun) are reachable and show the
   RGB camera the spot, and with ``need_marker`` the whole marker, by the camera model
   (``sun_sweep.candidate_poses``, as the lens planner calls it). The painter calibrates
   robot-world before its first sweep, after which the lens planner no longer needs the
   marker (the default, ``need_marker`` false); a sweep before any robot-world
   calibration needs it (the rig found no such pose for suns below about 47 deg in front
   of the arm, issue 12).
   ``min_elevation_deg`` is what the geometry does not see: the lowest sun the simulated
   sweep estimated is 31 deg; at 26.5 deg the lens, tilted 64 deg to face the sun, cast a
   spot that reached the image border and no view was usable
   (test/test_sweep_over_suns.py). Below it no sweep is planned.

The sun's ray s0 in the robot frame (Eq 2, the way light travels) comes from the ephemeris
(``ephemeris.sun_position``, pysolar, apparent position) and the robot's heading h, the
compass azimuth of its x axis with z vertical (``ephemeris.ray_angles_from_sun``, the
mapping the simulated world places its sun with): the sun stands h - A counter-clockwise
from the robot's x axis for a compass azimuth A. Both checks depend on that ray alone.

Speed: a day and a scan of 24 headings ask for some 2,500 verdicts. Asked one pose at a
time the rig model takes about 0.1 ms a pose; ``reach_mask`` asks it for the whole grid at
once (``Rig.lens_poses_for_targets``, numpy), and the sweep's search discards the poses
that cannot pass (unreachable by ``Rig.inverse_many``, or out of the image by
``sun_sweep.in_view_many``) before the lens planner's own checks confirm the rest
(``SkyModel.candidate_count``). Tests hold both to
``dot_layout.check_reach`` and ``sun_sweep.candidate_poses`` (src/helio_control/test/
test_sky.py); the reasons printed come from the rig model itself.

A day is sampled every ``step`` seconds of the local day from sunrise to sunset (sunrise
and sunset: the sun's upper limb on the horizon, an apparent elevation of -0.2667 deg, found
to the second); a window is a run of served samples, its hours the samples times the step.
A painting begun in a window keeps its sun estimate (Eq 18 moves it with the sun) and can
go on while the reach column stays at 100 %.

API: ``SkySettings``, ``SkyModel(rig, settings)`` (``reach``, ``sweep``, ``verdict``),
``sun_ray_robot``, ``heading_from_ray``, ``local_day``, ``default_timezone``,
``sunrise_sunset``, ``sky_day``, ``heading_scan``, ``best_heading``, ``next_time``,
``sweep_refusal``, ``reach_refusal`` (a ``Refusal``), ``canvas_points``, ``reach_mask``,
``report_lines``, ``report_dict``.
"""

from dataclasses import dataclass, field, fields
import datetime
import inspect
import itertools
import math

from helio_control import sun_sweep
from helio_control.dot_layout import check_reach
from helio_control.picture_options import CANVAS_OPTIONS
from helio_control.plan import PlanOptions
from helio_optics.ephemeris import ray_angles_from_sun, Site, sun_position
from helio_optics.geometry import direction_from_angles, invert_transform, PinholeCamera
from helio_optics.geometry import transform_points
import numpy as np

SUN_RADIUS_DEG = 0.2667        # apparent semi-diameter of the sun: sunrise at the upper limb
UTC = datetime.timezone.utc


def _defaults(function):
    """Return the default values of `function`'s parameters by name."""
    return {name: parameter.default for name, parameter in
            inspect.signature(function).parameters.items()}


# the sweep's own defaults, read from it so that the search here keeps to them
_SEES = _defaults(sun_sweep.sees_marker_and_spot)
_CANDIDATES = _defaults(sun_sweep.candidate_poses)


class SkyError(ValueError):
    """Settings, dates or headings that describe no sky; the message names the problem."""


@dataclass(frozen=True)
class SkySettings:
    """
    What the sun must serve and how the lens planner finds it; SI units, degrees as named.

    Canvas: picture.yaml's (``canvas_size``, ``offset_x``, ``offset_y``); distances
    (``d_lp``, ``retreat``): the lens planner's defaults, which it owns. Sweep: the lens
    planner's defaults (lens_planner.yaml:
    ``marker_side``, ``view_margin``, ``panel_extent``, ``view_spacing``,
    ``marker_clearance``, ``sweep.tilts_deg``, ``sweep.distances``; the spot search's
    distances are d_lp plus ``acquisition_offsets``, its tilts ``acquisition_tilts_deg``,
    as in the lens planner's sweep_sun).
    Camera: the simulated RGB camera (640 x 480 px, 70 deg horizontal field of view).
    """

    canvas_size: float = PlanOptions.canvas_size      # the canvas: the picture options'
    offset_x: float = PlanOptions.offset_x
    offset_y: float = PlanOptions.offset_y
    d_lp: float = PlanOptions.d_lp
    retreat: float = PlanOptions.retreat
    reach_spacing: float = 0.01
    min_elevation_deg: float = 30.0
    need_marker: bool = False
    marker_side: float = 0.04
    view_margin: float = 30.0
    panel_extent: tuple = (-0.04, 0.16, -0.04, 0.16)
    view_spacing: float = 0.02
    marker_clearance: float = 0.05
    sweep_tilts_deg: tuple = (0.0, 5.0, 10.0)
    sweep_distances: tuple = (0.076, 0.082, 0.088)
    min_sweep_poses: int = 2
    acquisition_tilts_deg: tuple = (0.0, 15.0, 30.0)
    acquisition_offsets: tuple = (-0.016, -0.022, 0.03)
    camera_width: int = 640
    camera_height: int = 480
    camera_fov_deg: float = 70.0

    def __post_init__(self):
        """Raise SkyError naming the first setting that describes no canvas or sweep."""
        for name in ('canvas_size', 'd_lp', 'retreat', 'reach_spacing', 'marker_side',
                     'view_spacing'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise SkyError(f'{name} must be a finite number > 0, got {value!r}')
        for name in ('offset_x', 'offset_y', 'view_margin', 'marker_clearance'):
            if not math.isfinite(getattr(self, name)):
                raise SkyError(f'{name} must be finite, got {getattr(self, name)!r}')
        if not 0.0 <= self.min_elevation_deg < 90.0:
            raise SkyError(f'min_elevation_deg must be in [0, 90), got {self.min_elevation_deg}')
        if not 0.0 < self.camera_fov_deg < 180.0:
            raise SkyError(f'camera_fov_deg must be in (0, 180), got {self.camera_fov_deg}')
        if self.camera_width < 1 or self.camera_height < 1 or self.min_sweep_poses < 1:
            raise SkyError('camera_width, camera_height and min_sweep_poses must be >= 1')
        for name in ('sweep_distances', 'acquisition_distances', 'sweep_tilts_deg',
                     'acquisition_tilts_deg'):
            values = getattr(self, name)
            if not values or not all(math.isfinite(v) and v >= 0.0 for v in values):
                raise SkyError(f'{name} must be finite values >= 0, got {values!r}')

    @property
    def acquisition_distances(self):
        """Return the spot search's lens distances [m]: d_lp plus the offsets."""
        return tuple(self.d_lp + offset for offset in self.acquisition_offsets)

    @classmethod
    def from_plan_options(cls, options, **overrides):
        """Take the canvas, d_lp and retreat of PlanOptions (picture.yaml), then `overrides`."""
        canvas = {name: getattr(options, name) for name in CANVAS_OPTIONS}
        return cls(**{**canvas, **overrides})

    def camera(self):
        """Return the undistorted pinhole camera of the settings."""
        return PinholeCamera.from_fov(int(self.camera_width), int(self.camera_height),
                                      math.radians(self.camera_fov_deg))

    def to_dict(self):
        """Return the settings as JSON-ready values."""
        return {f.name: (list(getattr(self, f.name)) if isinstance(getattr(self, f.name), tuple)
                         else getattr(self, f.name)) for f in fields(self)}


def canvas_points(offset_x, offset_y, size, spacing):
    """
    Return world points (N, 2) [m] of a grid over the canvas square.

    The square [offset_x, offset_x + size] x [offset_y, offset_y + size] gets
    ceil(size / spacing) + 1 points a side, its corners and edges included (the plan's dots
    lie within it).
    """
    count = int(math.ceil(size / spacing - 1e-9)) + 1
    xs = offset_x + np.linspace(0.0, size, count)
    ys = offset_y + np.linspace(0.0, size, count)
    return np.array([[x, y] for x in xs for y in ys])


def sun_ray_robot(position, heading):
    """Return the unit sun ray s0 in the robot frame for a SunPosition and `heading` [rad]."""
    return direction_from_angles(*ray_angles_from_sun(position, heading))


def heading_from_ray(sun_ray, position):
    """
    Return the robot heading [rad, compass azimuth of its x axis] a sun ray implies.

    `sun_ray` is s0 in the robot frame (z vertical) at the instant the ephemeris gives
    `position` for: the sun stands h - A counter-clockwise from the robot's x axis, so
    h = atan2(-s0_y, -s0_x) + A.
    """
    ray = np.asarray(sun_ray, dtype=float).reshape(3)
    if math.hypot(ray[0], ray[1]) < 1e-9:
        raise SkyError('a sun at the zenith gives no heading')
    return (math.atan2(-ray[1], -ray[0]) + position.azimuth) % (2.0 * math.pi)


def reach_mask(rig, points, sun_ray, d_lp, retreat):
    """
    Return per world point (N, 2) [m] whether its dot is reachable, as ``check_reach`` says.

    The rule of ``check_reach`` for all points at once through
    ``Rig.lens_poses_for_targets`` (about a hundred times faster than point by point):
    Eq 14 p_l = p_i - d_lp s0, Eq 15 the lens axis along -s0, both wrist solutions (the one
    nearest the point's heading first), every joint limit, at d_lp and then at
    d_lp + retreat keeping the heating pose's yaw. Tests hold it to ``check_reach``.
    """
    ray = np.asarray(sun_ray, dtype=float).reshape(3)
    ray = ray / np.linalg.norm(ray)
    if not ray[2] < 0.0:
        raise SkyError(f'the sun ray {ray} does not point down: the sun is not up')
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    transform = rig.parameters.T_robot_world
    targets = np.column_stack([points, np.zeros(len(points))]) @ transform[:3, :3].T \
        + transform[:3, 3]
    near = rig.lens_poses_for_targets(targets, ray, d_lp)
    far = rig.lens_poses_for_targets(targets, ray, d_lp + retreat, preferred_yaws=near.yaws)
    return near.reachable & far.reachable


SWEEP_STATES = ('yes', 'low', 'no view', 'down')


@dataclass
class Verdict:
    """Whether the sun serves the canvas through one ray, and why not."""

    reach_share: float          # share of the canvas grid reachable (nan: not checked)
    reach_reason: str           # the first unreachable point's reason ('' when all reach)
    sweep_state: str            # SWEEP_STATES: possible, sun too low, no pose sees, sun down
    sweep_reason: str           # why no sweep ('' when it can)

    @property
    def sweep(self):
        """Return whether the sweep can estimate this sun."""
        return self.sweep_state == 'yes'

    @property
    def served(self):
        """Return whether every canvas point is reachable and the sweep can be made."""
        return self.sweep and self.reach_share == 1.0

    @property
    def reason(self):
        """Return why the sun does not serve ('' when it does)."""
        return '; '.join(r for r in (self.sweep_reason, self.reach_reason) if r)


class SkyModel:
    """The rig, the canvas and the sweep's view: whether a sun ray serves (see the module)."""

    def __init__(self, rig, settings=None):
        """Use `rig` (helio_optics Rig, its T_robot_world) and SkySettings."""
        self.rig = rig
        self.settings = settings or SkySettings()
        s = self.settings
        self.points = canvas_points(s.offset_x, s.offset_y, s.canvas_size, s.reach_spacing)
        self.camera = s.camera()
        # the lens planner's grid of panel points, nearest the canvas centre first: a pose
        # there is the likeliest to reach, and the verdicts (counts) do not depend on order
        centre = np.array([s.offset_x, s.offset_y]) + 0.5 * s.canvas_size
        self.view_points = sorted(
            sun_sweep.view_points(s.panel_extent, s.view_spacing, s.marker_clearance),
            key=lambda point: float(np.hypot(*(np.asarray(point) - centre))))
        self.T_robot_world = rig.parameters.T_robot_world

    def reach(self, sun_ray, points=None):
        """
        Return (share of `points` reachable, why the first unreachable one is not).

        `points` default to the canvas grid. The share comes from ``reach_mask``; the reason
        from ``dot_layout.check_reach`` (the rig model) for the first unreachable point.
        """
        points = self.points if points is None else np.asarray(points, dtype=float)
        s = self.settings
        mask = reach_mask(self.rig, points, sun_ray, s.d_lp, s.retreat)
        if mask.all():
            return 1.0, ''
        first = int(np.argmin(mask))
        reason = check_reach(points[first][None], self.rig, sun_ray, s.d_lp,
                             s.retreat).reasons[0]
        return float(mask.mean()), (
            f'{np.count_nonzero(~mask)} of {len(points)} canvas points out of reach, e.g. '
            f'({points[first][0] * 100:.1f}, {points[first][1] * 100:.1f}) cm '
            f'{reason or "(the rig model reaches it: report this disagreement)"}')

    def sweep(self, sun_ray):
        """Return (a SWEEP_STATES state for the sun of `sun_ray`, why no sweep or '')."""
        s = self.settings
        ray = np.asarray(sun_ray, dtype=float) / np.linalg.norm(sun_ray)
        elevation = math.degrees(math.asin(max(-1.0, min(1.0, -float(ray[2])))))
        if elevation < s.min_elevation_deg:
            return 'low', (f'the sun stands {elevation:.1f} deg up, below the lowest the '
                           f'sweep estimates ({s.min_elevation_deg:g} deg)')
        what = 'the marker and the spot' if s.need_marker else 'the spot'
        found = self.candidate_count(ray, s.sweep_distances, s.sweep_tilts_deg,
                                     s.min_sweep_poses)
        if found < s.min_sweep_poses:
            return 'no view', (f'{found} sweep pose(s) of the {s.min_sweep_poses} needed reach '
                               f'and show the camera {what}')
        if not self.candidate_count(ray, s.acquisition_distances, s.acquisition_tilts_deg, 1):
            return 'no view', f'no pose of the spot search reaches and shows the camera {what}'
        return 'yes', ''

    def candidate_count(self, ray, distances, tilts, enough):
        """
        Return how many poses ``sun_sweep.candidate_poses`` yields for `ray`, up to `enough`.

        The same poses (every view point, distance, tilt, turn and wrist solution), judged
        the same way: each must be reachable (``Rig.inverse_many``, which ``Rig.inverse``
        is for one pose) and pass ``sun_sweep.sees_marker_and_spot``. Before that, numpy
        discards at once the poses that cannot pass (unreachable, or ``_may_be_seen``: the
        spot, and with ``need_marker`` the marker, outside the image), so a sun that shows
        the camera nothing costs milliseconds instead of a second.
        """
        s = self.settings
        ray = np.asarray(ray, dtype=float) / np.linalg.norm(ray)
        targets = transform_points(self.T_robot_world, np.column_stack(
            [self.view_points, np.zeros(len(self.view_points))]))
        centres = np.concatenate([targets - distance * ray for distance in distances])
        headings = np.arctan2(centres[:, 1], centres[:, 0])
        found = 0
        for tilt in tilts:
            for turn in (_CANDIDATES['turns'] if tilt > 0.0 else (0.0,)):
                axis = sun_sweep.tilted_axis(ray, math.radians(tilt), math.radians(turn))
                for flip, offset in itertools.product((0.0, math.pi), _CANDIDATES['offsets']):
                    yaw, pitch = self.rig.yaw_pitch_for_axis(axis, headings + flip)
                    yaw = yaw + math.radians(offset)
                    solutions = self.rig.inverse_many(centres, yaw, pitch)
                    possible = solutions.reachable & self._may_be_seen(centres, yaw, pitch,
                                                                       ray)
                    for index in np.flatnonzero(possible):
                        if sun_sweep.sees_marker_and_spot(
                                self.rig, solutions.joints[index], ray, self.camera,
                                self.T_robot_world, s.marker_side, s.view_margin,
                                need_marker=s.need_marker):
                            found += 1
                            if found >= enough:
                                return found
        return found

    def _may_be_seen(self, centres, yaw, pitch, ray):
        """
        Return per lens pose whether it may pass ``sees_marker_and_spot``: a necessary test.

        Seen (``sun_sweep.in_view_many``) from the camera pose the lens pose implies
        (R_robot_lens = Rz(yaw) Ry(pitch) at the lens centre, then the rig's T_lens_rgb):
        the spot (the ray through the lens centre on the panel) in the image with the
        margin; with ``need_marker`` also the marker's corners, no more obliquely than
        ``sees_marker_and_spot``'s limit and with its smallest side in pixels.
        """
        s = self.settings
        cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
        zero = np.zeros_like(yaw)
        lens = np.stack([np.stack([cy * cp, -sy, cy * sp], -1),
                         np.stack([sy * cp, cy, sy * sp], -1),
                         np.stack([-sp, zero, cp], -1)], -2)          # Rz(yaw) Ry(pitch)
        T_lens_rgb = self.rig.parameters.T_lens_rgb
        T_world_robot = invert_transform(self.T_robot_world)
        T_world_rgb = np.broadcast_to(np.eye(4), (len(centres), 4, 4)).copy()
        T_world_rgb[:, :3, :3] = T_world_robot[:3, :3] @ lens @ T_lens_rgb[:3, :3]
        T_world_rgb[:, :3, 3] = (centres + lens @ T_lens_rgb[:3, 3]) @ T_world_robot[:3, :3].T \
            + T_world_robot[:3, 3]
        normal, plane = self.T_robot_world[:3, 2], self.T_robot_world[:3, 3]
        along = float(ray @ normal)
        distance = ((plane - centres) @ normal) / along if along < -1e-9 else \
            np.full(len(centres), -1.0)
        ok = distance > 0.0
        spots = transform_points(T_world_robot, centres + distance[:, None] * ray)

        def seen(points):         # rounding passes: the exact check decides
            return sun_sweep.in_view_many(self.camera, T_world_rgb, points, s.view_margin,
                                          tolerance=1e-6)
        ok &= seen(spots[:, None, :])[0]
        if not s.need_marker:
            return ok
        corners = sun_sweep.marker_corners(s.marker_side)
        in_image, pixels = seen(corners)
        ok &= in_image
        origin = T_world_rgb[:, :3, 3]
        to_camera = origin / np.linalg.norm(origin, axis=1)[:, None]     # marker at origin
        ok &= np.arccos(np.clip(to_camera[:, 2], -1.0, 1.0)) <= _SEES['max_view_angle'] + 1e-9
        sides = np.linalg.norm(pixels - np.roll(pixels, 1, axis=1), axis=2)
        ok &= sides.min(axis=1) >= _SEES['min_marker_pixels'] - 1e-9
        return ok

    def verdict(self, sun_ray, full=True):
        """
        Return the Verdict for a robot-frame sun ray.

        With `full` false (a heading scan) the reach is not checked when the sweep already
        fails (its share is then nan): served or not, at less cost.
        """
        state, sweep_reason = self.sweep(sun_ray)
        if not (full or state == 'yes'):
            return Verdict(math.nan, '', state, sweep_reason)
        share, why = self.reach(sun_ray)
        return Verdict(share, why, state, sweep_reason)


# ---------------------------------------------------------------------------- the day
def default_timezone(site):
    """
    Return the fixed UTC offset the site's longitude implies (15 deg an hour, rounded).

    That is the standard time of the site's nominal zone, without daylight saving: a user
    gives the zone by name (zoneinfo) or the offset for the clock on the wall.
    """
    longitude = ((site.longitude_deg + 180.0) % 360.0) - 180.0
    hours = int(round(longitude / 15.0))
    return datetime.timezone(datetime.timedelta(hours=hours))


def local_day(date, tz):
    """Return the UTC instants (start, end) of the local `date` in `tz` (23-25 h long)."""
    start = datetime.datetime.combine(date, datetime.time(0), tzinfo=tz)
    end = datetime.datetime.combine(date + datetime.timedelta(days=1), datetime.time(0),
                                    tzinfo=tz)
    return start.astimezone(UTC), end.astimezone(UTC)


def _above(site, when):
    """Return the sun's apparent elevation above the upper-limb horizon [deg] at `when`."""
    return math.degrees(sun_position(site, when).elevation) + SUN_RADIUS_DEG


def _crossing(site, early, late, tolerance=1.0):
    """Bisect the instant between `early` and `late` at which ``_above`` changes sign."""
    rising = _above(site, early) < 0.0
    while (late - early).total_seconds() > tolerance:
        middle = early + (late - early) / 2
        if (_above(site, middle) < 0.0) == rising:
            early = middle
        else:
            late = middle
    return early + (late - early) / 2


def sunrise_sunset(site, date, tz, coarse=600.0):
    """
    Return (sunrise, sunset) of the local `date` as UTC datetimes, to about a second.

    The sun's upper limb on the horizon (apparent elevation -0.2667 deg, pysolar's
    refraction). None for an event the day does not have (midnight sun, polar night, or
    a sun already up at midnight: sunrise None).
    """
    start, end = local_day(date, tz)
    step = datetime.timedelta(seconds=coarse)
    times = [start + k * step for k in range(int((end - start) / step) + 1)]
    if times[-1] < end:
        times.append(end)
    levels = [_above(site, when) for when in times]
    sunrise = sunset = None
    for (t0, a), (t1, b) in zip(zip(times, levels), zip(times[1:], levels[1:])):
        if a < 0.0 <= b and sunrise is None:
            sunrise = _crossing(site, t0, t1)
        elif a >= 0.0 > b:
            sunset = _crossing(site, t0, t1)
    return sunrise, sunset


@dataclass
class SkySample:
    """One instant of the day: the sun, and the verdict for the canvas."""

    when: datetime.datetime     # UTC
    elevation_deg: float        # apparent, above the horizon
    azimuth_deg: float          # compass, clockwise from north
    robot_azimuth_deg: float    # towards the sun, counter-clockwise from the robot's x axis
    verdict: Verdict = None

    @property
    def served(self):
        """Return whether the sun serves the canvas at this sample."""
        return self.verdict is not None and self.verdict.served


@dataclass
class SkyDay:
    """A day of samples for one heading, its windows and its hours."""

    site: Site
    date: datetime.date
    tz: datetime.tzinfo
    heading_deg: float
    step: float
    sunrise: datetime.datetime
    sunset: datetime.datetime
    samples: list = field(default_factory=list)

    @property
    def windows(self):
        """Return [(first, last)] UTC sample times of the runs of served samples."""
        runs, first, last = [], None, None
        for sample in self.samples:
            if sample.served:
                first = first or sample.when
                last = sample.when
            elif first is not None:
                runs.append((first, last))
                first = None
        if first is not None:
            runs.append((first, last))
        return runs

    @property
    def hours(self):
        """Return the served hours: served samples times the step."""
        return sum(sample.served for sample in self.samples) * self.step / 3600.0


def _sample_times(site, date, tz, step):
    """Return the UTC instants every `step` s of the local day from sunrise to sunset."""
    if not step > 0.0:
        raise SkyError(f'step must be > 0 s, got {step}')
    start, end = local_day(date, tz)
    sunrise, sunset = sunrise_sunset(site, date, tz)
    first = sunrise or start
    last = sunset or end
    delta = datetime.timedelta(seconds=step)
    times = []
    when = start
    while when < end:
        if first <= when <= last and (sunrise or sunset or _above(site, when) >= 0.0):
            times.append(when)
        when += delta
    return times, sunrise, sunset


def _positions(site, times):
    return [sun_position(site, when) for when in times]


def _day_from(model, site, date, tz, heading, step, times, positions, sunrise, sunset, full):
    samples = []
    for when, position in zip(times, positions):
        ray = sun_ray_robot(position, heading)
        towards = math.degrees(math.atan2(-ray[1], -ray[0])) % 360.0
        verdict = model.verdict(ray, full=full) if position.elevation > 0.0 else \
            Verdict(math.nan, '', 'down', 'the sun is not up')
        samples.append(SkySample(when, math.degrees(position.elevation),
                                 math.degrees(position.azimuth), towards, verdict))
    return SkyDay(site, date, tz, math.degrees(heading) % 360.0, step, sunrise, sunset,
                  samples)


def sky_day(model, site, date, tz, heading_deg, step=600.0):
    """
    Return the SkyDay of the local `date` (in `tz`) for a robot heading [deg].

    Every sample from sunrise to sunset gets the full Verdict (the reach share of the whole
    canvas grid, the sweep).
    """
    _check_heading(heading_deg)
    times, sunrise, sunset = _sample_times(site, date, tz, step)
    return _day_from(model, site, date, tz, math.radians(heading_deg), step, times,
                     _positions(site, times), sunrise, sunset, full=True)


def _check_heading(heading_deg):
    if not math.isfinite(heading_deg):
        raise SkyError(f'the heading must be a finite number of degrees, got {heading_deg}')


def heading_scan(model, site, date, tz, headings_deg, step=600.0):
    """
    Return [(heading [deg], served hours)] of the local `date` for each heading.

    The ephemeris is asked once per sample; each heading's verdicts are the scan's (served
    or not, ``SkyModel.verdict(full=False)``), the same as ``sky_day``'s.
    """
    times, sunrise, sunset = _sample_times(site, date, tz, step)
    positions = _positions(site, times)
    scan = []
    for heading_deg in headings_deg:
        _check_heading(heading_deg)
        day = _day_from(model, site, date, tz, math.radians(heading_deg), step, times,
                        positions, sunrise, sunset, full=False)
        scan.append((float(heading_deg) % 360.0, day.hours))
    return scan


def best_heading(scan, prefer=None):
    """
    Return the (heading, hours) of `scan` with the most hours.

    Among equals, the heading closest to `prefer` [deg] (the rig's present one: no turn for
    nothing), else the first.
    """
    if not scan:
        raise SkyError('no heading was scanned')
    most = max(hours for _, hours in scan)
    best = [(heading, hours) for heading, hours in scan if hours >= most - 1e-9]
    if prefer is None:
        return best[0]
    return min(best, key=lambda item: abs(math.remainder(item[0] - prefer, 360.0)))


# ---------------------------------------------------------------------------- the painter
def next_time(site, now, condition, step=600.0, horizon=48 * 3600.0):
    """
    Return the first instant now + k `step` (k >= 1, within `horizon` [s]) of `condition`.

    `condition(position)` judges the ephemeris' SunPosition at that instant; None when no
    sample within the horizon passes.
    """
    delta = datetime.timedelta(seconds=step)
    for k in range(1, int(horizon / step) + 1):
        instant = now + k * delta
        if condition(sun_position(site, instant)):
            return instant
    return None


@dataclass
class Refusal:
    """Why the sun cannot serve a painting now and, when known, the heading and next time."""

    text: str
    heading_deg: float = None             # the robot heading the sun estimate implies
    next_time: datetime.datetime = None   # UTC, when it serves next (None: not within reach)

    def __str__(self):
        """Return the text."""
        return self.text


def _at(instant, now):
    """Return 'HH:MM UTC (in X h)', with the date when it is another day."""
    text = instant.strftime('%H:%M UTC' if instant.date() == now.date() else
                            '%Y-%m-%d %H:%M UTC')
    return f'{text} (in {(instant - now).total_seconds() / 3600.0:.1f} h)'


def sweep_refusal(site, now, min_elevation_deg, step=600.0, horizon=48 * 3600.0):
    """
    Return a Refusal when no sun sweep can start at `now` (UTC), else None.

    The sweep needs the sun `min_elevation_deg` up (see the module). This asks the
    ephemeris only, so it holds whatever the robot's heading; the Refusal says when the sun
    stands that high next at the site (to the `step`).
    """
    elevation = math.degrees(sun_position(site, now).elevation)
    if elevation >= min_elevation_deg:
        return None
    minimum = math.radians(min_elevation_deg)
    later = next_time(site, now, lambda position: position.elevation >= minimum, step,
                      horizon)
    when = (f'at this site it stands that high next at {_at(later, now)}' if later else
            f'at this site it does not within {horizon / 3600.0:.0f} h')
    where = (f'it stands {elevation:.1f} deg up' if elevation >= 0.0 else
             f'it stands {-elevation:.1f} deg below the horizon')
    return Refusal(f'the sun cannot serve a painting now: {where} and the sun sweep needs '
                   f'{min_elevation_deg:g} deg; {when}; "helio sky" shows the hours the sun '
                   'serves the canvas', next_time=later)


def reach_refusal(rig, points, sun_ray, d_lp, retreat, site=None, now=None,
                  min_elevation_deg=0.0, step=600.0, horizon=48 * 3600.0, ray_time=None):
    """
    Return a Refusal when the sun reaches none of `points` now, else None.

    `points` are world (x, y) [m] (the goal's dots, or a grid over its canvas), `sun_ray`
    the sun estimate's s0 (robot frame) at `ray_time` (UTC, default `now`), judged by
    ``dot_layout.check_reach`` (Eqs 14-15, the heating and the retreat pose). With the
    `site` and `now` (UTC) the robot heading follows from the estimate and the ephemeris
    (``heading_from_ray``): the Refusal names it for ``helio sky --heading`` and says when
    every point is within reach next with the sun at least `min_elevation_deg` up (to the
    `step`, within the `horizon` [s]).
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if np.any(reach_mask(rig, points, sun_ray, d_lp, retreat)):
        return None
    result = check_reach(points, rig, sun_ray, d_lp, retreat)    # the rig model confirms
    if np.any(result.reachable):
        return None
    ray = np.asarray(sun_ray, dtype=float) / np.linalg.norm(sun_ray)
    elevation = math.degrees(math.asin(max(-1.0, min(1.0, -float(ray[2])))))
    towards = math.degrees(math.atan2(-ray[1], -ray[0])) % 360.0
    text = (f'the sun cannot serve this canvas now: none of its {len(points)} points is within '
            f'reach of the sun {elevation:.1f} deg up, {towards:.0f} deg from the robot x '
            f'axis ({result.reasons[0]})')
    if site is None or now is None or math.hypot(ray[0], ray[1]) < 1e-9:
        # no site, or a sun at the zenith: the heading cannot be told
        return Refusal(text + '; "helio sky" shows the hours the sun serves it')
    heading = heading_from_ray(ray, sun_position(site, ray_time or now))
    minimum = math.radians(min_elevation_deg)

    def served(position):
        return position.elevation > 0.0 and position.elevation >= minimum and bool(np.all(
            reach_mask(rig, points, sun_ray_robot(position, heading), d_lp, retreat)))
    later = next_time(site, now, served, step, horizon)
    when = (f'at this site all of it is within reach next at {_at(later, now)}' if later
            else f'at this site it is not within reach at any time of the next '
            f'{horizon / 3600.0:.0f} h')
    degrees = math.degrees(heading)
    return Refusal(f'{text}; the sun estimate puts the robot heading at {degrees:.0f} deg: '
                   f'"helio sky --heading {degrees:.0f}" shows the hours the sun serves it; '
                   f'{when}', heading_deg=degrees, next_time=later)


# ---------------------------------------------------------------------------- the report
def _local(when, tz):
    return when.astimezone(tz).strftime('%H:%M')


def _window_text(window, step, tz):
    first, last = window
    hours = ((last - first).total_seconds() + step) / 3600.0
    span = _local(first, tz) if first == last else f'{_local(first, tz)}-{_local(last, tz)}'
    return f'{span} ({hours:.1f} h)'


def _unserved_runs(day):
    """Return [(first, last, reason of the first)] of the runs of samples not served."""
    runs, previous = [], None
    for index, sample in enumerate(day.samples):
        if sample.served:
            continue
        if runs and previous == index - 1:
            runs[-1][1] = sample.when
        else:
            runs.append([sample.when, sample.when, sample.verdict.reason])
        previous = index
    return [tuple(run) for run in runs]


def report_lines(day, scan, best, settings, site_file='', tz_note=''):
    """
    Return the lines ``helio sky`` prints for a SkyDay, its heading scan and best heading.

    A header (site, date, time zone, heading, canvas, what served means), the table of the
    samples (local time, the sun's elevation and compass azimuth, its azimuth from the
    robot's x axis, the reach share, the sweep, * when served), the windows, why the other
    samples are not served (the first of each run), and the scan.
    """
    tz = day.tz
    site = day.site
    offset = day.samples[0].when.astimezone(tz).strftime('%Z') if day.samples else str(tz)
    sweep = ('the sweep (sun >= {:g} deg up, the marker and the spot in view: no robot-world '
             'calibration yet)' if settings.need_marker else
             'the sweep (sun >= {:g} deg up, the spot in view)').format(
                 settings.min_elevation_deg)
    lines = [
        f'site {site.latitude_deg:.4f} N, {site.longitude_deg:.4f} E, {site.elevation:.0f} m'
        + (f' ({site_file})' if site_file else '') + f', {day.date.isoformat()}, times '
        f'{offset}{tz_note}',
        f'rig heading {day.heading_deg:.0f} deg (the robot x axis, clockwise from north); '
        f'canvas {settings.canvas_size * 100:.1f} cm at ({settings.offset_x * 100:.1f}, '
        f'{settings.offset_y * 100:.1f}) cm from the marker, d_lp {settings.d_lp * 100:.1f} cm, '
        f'retreat {settings.retreat * 100:.1f} cm',
        'sunrise ' + (_local(day.sunrise, tz) if day.sunrise else '-') + ', sunset '
        + (_local(day.sunset, tz) if day.sunset else '-') + '; served (*): the whole '
        f'canvas within reach and {sweep}',
        '',
        ' time   sun elev  azimuth  from x   reach  sweep',
    ]
    for sample in day.samples:
        verdict = sample.verdict
        reach = '    -' if math.isnan(verdict.reach_share) else \
            f'{verdict.reach_share * 100:4.0f}%'
        lines.append((f'{_local(sample.when, tz)}  {sample.elevation_deg:9.1f}  '
                      f'{sample.azimuth_deg:7.0f}  {sample.robot_azimuth_deg:6.0f}   {reach}  '
                      f'{verdict.sweep_state:<7}' + (' *' if sample.served else '')).rstrip())
    lines.append('')
    windows = day.windows
    lines.append(f'served at heading {day.heading_deg:.0f} deg: ' + (', '.join(
        _window_text(window, day.step, tz) for window in windows)
        + (f', {day.hours:.1f} h in all' if len(windows) > 1 else '') if windows else 'never')
        + f' (samples every {day.step / 60.0:g} min)')
    runs = _unserved_runs(day)
    if runs:
        lines.append('not served (the first sample of each run says why):')
        for first, last, reason in runs:
            span = _local(first, tz) + ('' if first == last else f'-{_local(last, tz)}')
            lines.append(f'  {span}: {reason}')
    if scan:
        lines.append('hours by heading: ' + ', '.join(f'{heading:.0f}: {hours:.1f}'
                                                      for heading, hours in scan))
        lines.append(f'best heading {best[0]:.0f} deg: {best[1]:.1f} h'
                     + ('' if abs(math.remainder(best[0] - day.heading_deg, 360.0)) < 1e-6
                        else f' (heading {day.heading_deg:.0f} deg: {day.hours:.1f} h)'))
    return lines


def report_dict(day, scan, best, settings, site_file='', run_time=None):
    """Return the SkyDay, its scan and best heading as JSON-ready values (``--json``)."""
    def iso(when):
        return when.astimezone(UTC).isoformat() if when else None

    def finite(value):
        return None if value is None or not math.isfinite(value) else value
    return {
        'site': {f.name: getattr(day.site, f.name) for f in fields(day.site)},
        'site_file': site_file, 'date': day.date.isoformat(), 'heading_deg': day.heading_deg,
        'step_s': day.step, 'sunrise': iso(day.sunrise), 'sunset': iso(day.sunset),
        'settings': settings.to_dict(),
        'samples': [{'time': iso(sample.when),
                     'local_time': sample.when.astimezone(day.tz).isoformat(),
                     'elevation_deg': sample.elevation_deg, 'azimuth_deg': sample.azimuth_deg,
                     'robot_azimuth_deg': sample.robot_azimuth_deg,
                     'reach_share': finite(sample.verdict.reach_share),
                     'sweep': sample.verdict.sweep_state, 'served': sample.served,
                     'reason': sample.verdict.reason} for sample in day.samples],
        'windows': [{'start': iso(first), 'end': iso(last),
                     'hours': ((last - first).total_seconds() + day.step) / 3600.0}
                    for first, last in day.windows],
        'hours': day.hours,
        'scan': [{'heading_deg': heading, 'hours': hours} for heading, hours in scan],
        'best_heading': {'heading_deg': best[0], 'hours': best[1]} if best else None,
        'run_time_s': finite(run_time)}


__all__ = ['best_heading', 'canvas_points', 'default_timezone', 'heading_from_ray',
           'heading_scan', 'local_day', 'next_time', 'reach_refusal', 'Refusal',
           'SkyDay', 'SkyError', 'SkyModel', 'SkySample', 'SkySettings', 'sky_day',
           'sun_ray_robot', 'sunrise_sunset', 'sweep_refusal', 'Verdict', 'report_dict',
           'report_lines', 'reach_mask', 'SWEEP_STATES']
