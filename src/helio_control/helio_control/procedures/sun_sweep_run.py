"""
The sun sweep procedure (paper Sec. V-B): find the spot, sweep poses, estimate the sun.

Without a sun estimate the spot is first acquired: the ephemeris' elevation at the site, a
ring of azimuth guesses; the first spot seen gives a coarse sun, its pose's lens model solved
for it (``sun_sweep.coarse_sun``). Then poses that change the geometry (``sun_sweep``), and
``estimate_sun`` on the spots of the sweep's holds.
"""

from dataclasses import dataclass
import datetime
import math

from helio_control import sun_sweep
from helio_control.procedures.lens_rig_port import GoalFailed
from helio_msgs.action import SweepSun
from helio_msgs.msg import SpotObservation
from helio_optics.ephemeris import sun_position
from helio_optics.geometry import transform_points
from helio_optics.node_kit.conversions import point_to_array, stamp_to_seconds
import numpy as np

# a sun at or below this elevation is refused as too low to paint (the spot search's
# elevation is the ephemeris' at the site)
MIN_SUN_ELEVATION = math.radians(5.0)
# The lens-panel distances of the spot search, as offsets from the heating distance [m],
# tried in this order for each azimuth guess (``sun_sweep.acquisition_poses``). The guess
# may be far off the sun, so no search pose holds the focus on the wood: every one lies more
# than ``safe_margin`` (1.5 cm) from the heating distance, where the spot of the 38 mm lens
# is 7.5-10 mm across (45-85 mm^2 against 1.5 mm^2 in focus: ``spot.spot_area_at``). First
# 1.6 and 2.2 cm nearer the panel, then the paper's heating-stop offset (Sec. IV-B:
# d_lp + 3 cm, a 16 mm spot) where those are out of reach or out of view.
ACQUISITION_D_LP_OFFSETS = (-0.016, -0.022, 0.03)
# at least this many sweep poses that show the marker and the spot make a sweep
MIN_SWEEP_POSES = 2


@dataclass
class Sweep:
    """What a sun sweep gave (``sweep``)."""

    response: object        # EstimateSun.Response
    planned: int
    used: int
    observations: int
    spots: list             # (image time [s], reported joints (5,), world centre (2,))
    start: float            # node clock [s]


def utc(seconds):
    """Return the UTC datetime of `seconds` since the epoch."""
    return datetime.datetime.fromtimestamp(seconds, tz=datetime.timezone.utc)


def valid_spot(message):
    """Return whether the spot detector found the spot in the image (any quality)."""
    return message.valid


def in_world(message):
    """Return whether a spot observation's centre is in the world (marker) frame."""
    return message.header.frame_id in ('', 'world')


async def sweep_sun(port, request, result):
    """Run a SweepSun goal: sweep, estimate the sun and use it."""
    sweep_run = await sweep(port, SweepSun.Feedback(), request.method,
                            request.poses or port.settings.sweep_count)
    result.estimate = sweep_run.response.estimate
    result.poses_used, result.observations = sweep_run.used, sweep_run.observations
    if not sweep_run.response.success:
        raise GoalFailed(f'estimate_sun after the sweep: {sweep_run.response.message}')
    port.use_sun(sweep_run.response.estimate)
    result.message = (f'{sweep_run.used} of {sweep_run.planned} sweep poses saw the spot, '
                      f'{sweep_run.observations} observations: {sweep_run.response.message}')


async def acquire(port, camera, report):
    """
    Find the spot with an unknown sun; return a coarse sun ray (robot frame) and the count.

    Returns (sun ray (3,), observations made).
    """
    settings = port.settings
    T_robot_world = port.rig.parameters.T_robot_world
    elevation = sun_position(port.site, utc(port.now())).elevation
    if elevation <= MIN_SUN_ELEVATION:
        raise GoalFailed(f'the sun stands {math.degrees(elevation):.1f} deg above the '
                         'horizon at this site and time: too low to paint')
    candidates = sun_sweep.acquisition_poses(
        port.rig, T_robot_world, elevation, camera, settings.marker_side,
        settings.view_points, math.radians(settings.acquire_step),
        tuple(port.heating_distance + offset for offset in ACQUISITION_D_LP_OFFSETS),
        margin=settings.view_margin, need_marker=not port.world_calibrated)
    if not candidates:
        raise GoalFailed('no pose to look for the spot: the view points are out of '
                         'reach or out of the camera view for this sun elevation')
    observations = 0
    for index, (azimuth, x) in enumerate(candidates):
        report(phase='acquiring', total=len(candidates), index=index)
        await port.move(x)
        seen = [m for m in await port.observe(settings.observe_frames, valid_spot)
                if in_world(m)]
        observations += len(seen)
        report(observations=observations)
        if not seen:
            continue
        # a coarse sun is enough to choose the sweep: this pose's spot solved for the sun by
        # the lens model (not the estimator's fit, whose reach leaves out a lens facing a
        # guessed sun; a twin sun is settled by the sweep)
        centres = transform_points(T_robot_world, [point_to_array(m.center) for m in seen])
        try:
            sun = sun_sweep.coarse_sun(port.spot_model, port.rig.forward(x).T_robot_lens,
                                       centres, T_robot_world[:3, 3], T_robot_world[:3, 2])
        except ValueError as error:
            port.log(f'azimuth guess {math.degrees(azimuth):.0f} deg: {error}', warning=True)
            continue
        up, around = (math.degrees(a) for a in sun_sweep.sun_angles(sun))
        port.log(f'spot found with the azimuth guess {math.degrees(azimuth):.0f} deg: '
                 f'a coarse sun {up:.2f} deg up, azimuth {around:.2f} deg (robot frame)')
        return sun, observations
    raise GoalFailed(f'the spot was not found at any of {len(candidates)} azimuth '
                     'guesses (clouds? the camera? the marker?)')


async def sweep(port, feedback, method, count, tilts=None):
    """
    Find the spot when there is no sun estimate, sweep `count` poses, estimate the sun.

    `tilts` [deg] of the lens axis off the sun (default the settings' ``sweep_tilts``).
    `feedback` gets the fields it has of phase, total, index and observations.

    Return a ``Sweep``: the estimate_sun response, the poses planned and used, the
    observations, the still valid spots of the sweep's holds (image time, reported
    joints, world centre) and when the sweep began (node clock).
    """
    settings = port.settings
    camera = await port.camera()
    T_robot_world = port.rig.parameters.T_robot_world
    observations = 0

    def report(**fields):
        for name, value in fields.items():
            if hasattr(feedback, name):
                setattr(feedback, name, value)
        port.feedback(feedback)

    if port.has_sun():
        sun = port.sun_ray()
    else:
        sun, observations = await acquire(port, camera, report)
    poses = sun_sweep.sweep_poses(port.rig, T_robot_world, sun, camera, settings.marker_side,
                                  settings.view_points, count,
                                  tuple(settings.sweep_tilts if tilts is None else tilts),
                                  tuple(settings.sweep_distances), settings.view_margin,
                                  need_marker=not port.world_calibrated)
    if len(poses) < MIN_SWEEP_POSES:
        raise GoalFailed(f'only {len(poses)} sweep poses show the marker and the spot')
    used, spots = 0, []
    for index, x in enumerate(poses):
        report(phase='sweeping', total=len(poses), index=index)
        await port.move(x)
        if index == 0:
            # the estimate is of the sweep's holds only: an acquisition pose far from the
            # focus casts a large spot whose centre the model misses by 2.5 mm at a 31 deg
            # sun (0.33 deg off the world's sun with it in the fit, 0.14-0.18 without)
            sweep_start = port.now()
        seen = await port.observe(settings.observe_frames, valid_spot)
        observations += len(seen)
        used += bool(seen)
        for message in seen:
            taken = stamp_to_seconds(message.header.stamp)
            lookup = port.joints_at(taken)
            if lookup and message.quality == SpotObservation.FULL and in_world(message):
                spots.append((taken, np.asarray(lookup.positions, dtype=float),
                              point_to_array(message.center)[:2]))
        report(observations=observations)
    report(phase='estimating')
    response = await port.estimate_sun(method, sweep_start)
    return Sweep(response, len(poses), used, observations, spots, sweep_start)
