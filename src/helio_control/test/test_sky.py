"""
helio sky (issue 30, item 7) against the rig model, the simulated world's sun and NREL's SPA.

The truths are independent of ``helio_control.sky``: reach from ``Rig.lens_pose_for_target``
point by point (Eqs 14-15), the sun from the simulated world's own ``Sun`` (its interpolated
ephemeris and heading), the sweep from ``sun_sweep.candidate_poses`` as the lens planner
calls it, sunrise from the NREL SPA report's test case.
"""

import datetime
import itertools
import math

from helio_control import sky, sun_sweep
from helio_control.dot_layout import check_reach
from helio_drivers.sim.sun import Sun
from helio_optics.ephemeris import Site, sun_position
from helio_optics.rig_kinematics import Rig, RigParameters
import numpy as np
from pysolar import solar
import pytest

SITE = Site(48.137, 11.575, 520.0)       # the simulated world's (sim_world.yaml)
HEADING = 200.0                          # its hidden robot_heading_deg
DAY = datetime.date(2026, 6, 21)
CEST = datetime.timezone(datetime.timedelta(hours=2))
UTC = datetime.timezone.utc
# a rig unlike the default in every offset the vectorised model uses: the lens off the pitch
# axis, the yaw axis off the flange's x axis, the marker turned, narrower servos
OTHER_RIG = Rig(RigParameters(lens_offset=(0.004, -0.003, -0.012),
                              yaw_axis_offset=(0.028, 0.006, -0.045),
                              yaw_limits=(math.radians(-75.0), math.radians(80.0)),
                              pitch_limits=(math.radians(-70.0), math.radians(85.0)),
                              world_in_robot=(0.16, -0.08, -0.13), world_yaw=0.35))


def rig_model_share(rig, points, ray, d_lp=0.082, retreat=0.03):
    """Return the share of world points whose heating and retreat poses the rig reaches."""
    T = rig.parameters.T_robot_world
    reached = 0
    for x, y in points:
        target = T[:3, :3] @ np.array([x, y, 0.0]) + T[:3, 3]
        near = rig.lens_pose_for_target(target, ray, d_lp)
        if near.x is not None:
            reached += rig.lens_pose_for_target(target, ray, d_lp + retreat,
                                                preferred_yaw=near.yaw).x is not None
    return reached / len(points)


def lens_planner_sees(rig, ray, settings, need_marker):
    """Return whether the lens planner's own search finds the sweep and a spot-search pose."""
    def count(distances, tilts, enough):
        return len(list(itertools.islice(sun_sweep.candidate_poses(
            rig, rig.parameters.T_robot_world, ray, settings.camera(), settings.marker_side,
            sun_sweep.view_points(), tuple(distances), tuple(tilts),
            margin=settings.view_margin, need_marker=need_marker), enough)))
    return (count(settings.sweep_distances, settings.sweep_tilts_deg, 2) >= 2
            and count(settings.acquisition_distances, settings.acquisition_tilts_deg, 1) == 1)


@pytest.fixture(scope='module')
def rig():
    return Rig()


@pytest.mark.parametrize('heading', [HEADING, 30.0])
def test_the_reach_agrees_with_the_rig_model_under_the_simulated_worlds_sun(rig, heading):
    model = sky.SkyModel(rig)
    day = sky.sky_day(model, SITE, DAY, CEST, heading, step=1800.0)
    world_sun = Sun(SITE, math.radians(heading), T_robot_world=rig.parameters.T_robot_world)
    shares = []
    for sample in day.samples:
        ray = world_sun.ray_robot(sample.when)
        elevation = math.degrees(math.asin(-ray[2]))
        assert elevation == pytest.approx(sample.elevation_deg, abs=1e-3)
        towards = math.degrees(math.atan2(-ray[1], -ray[0]))
        assert abs(math.remainder(towards - sample.robot_azimuth_deg, 360.0)) < 1e-3
        truth = rig_model_share(rig, model.points, ray)
        assert sample.verdict.reach_share == pytest.approx(truth, abs=1e-12), sample.when
        assert sample.served == (truth == 1.0 and sample.verdict.sweep)
        shares.append(truth)
    # the day has both: the whole canvas and part of it out of reach
    assert min(shares) < 0.95 and max(shares) == 1.0


def test_reach_mask_is_check_reach_over_many_suns_and_two_rigs(rig):
    rng = np.random.default_rng(7)
    points = sky.canvas_points(-0.02, -0.04, 0.2, 0.02)       # beyond the reach in places
    disagreements, unreachable = 0, 0
    for each in (rig, OTHER_RIG):
        for _ in range(30):
            ray = sun_sweep.sun_ray(math.radians(rng.uniform(2.0, 88.0)),
                                    math.radians(rng.uniform(0.0, 360.0)))
            truth = check_reach(points, each, ray, 0.082, 0.03).reachable
            disagreements += np.count_nonzero(sky.reach_mask(each, points, ray, 0.082, 0.03)
                                              != truth)
            unreachable += np.count_nonzero(~truth)
    assert disagreements == 0
    assert 0.1 * 60 * len(points) < unreachable < 0.9 * 60 * len(points)


@pytest.mark.parametrize('need_marker', [False, True])
def test_the_sweep_verdict_is_the_lens_planners_search(rig, need_marker):
    settings = sky.SkySettings(need_marker=need_marker)
    model = sky.SkyModel(rig, settings)
    world_sun = Sun(SITE, math.radians(HEADING))
    states = []
    for hour in (5.5, 7.0, 8.0, 9.0, 11.5, 14.0, 16.5):
        when = datetime.datetime(2026, 6, 21, tzinfo=UTC) + datetime.timedelta(hours=hour)
        ray = world_sun.ray_robot(when)
        state, _ = model.sweep(ray)
        elevation = math.degrees(math.asin(-ray[2]))
        expected = 'low' if elevation < settings.min_elevation_deg else \
            'yes' if lens_planner_sees(rig, ray, settings, need_marker) else 'no view'
        assert state == expected, (hour, elevation)
        states.append(state)
    assert {'low', 'yes'} <= set(states)
    if need_marker:    # the marker in view: no pose in front of the arm at midday (issue 12)
        assert 'no view' in states


def test_the_sweep_search_counts_as_candidate_poses_on_another_rig():
    rng = np.random.default_rng(3)
    for need_marker in (False, True):
        model = sky.SkyModel(OTHER_RIG, sky.SkySettings(need_marker=need_marker))
        for _ in range(4):
            ray = sun_sweep.sun_ray(math.radians(rng.uniform(30.0, 85.0)),
                                    math.radians(rng.uniform(0.0, 360.0)))
            truth = len(list(itertools.islice(sun_sweep.candidate_poses(
                OTHER_RIG, OTHER_RIG.parameters.T_robot_world, ray, model.camera, 0.04,
                sun_sweep.view_points(), (0.076, 0.082, 0.088), (0.0, 5.0, 10.0),
                margin=30.0, need_marker=need_marker), 3)))
            assert model.candidate_count(ray, (0.076, 0.082, 0.088), (0.0, 5.0, 10.0), 3) \
                == truth


def test_sunrise_and_sunset_are_nrel_spas():
    # NREL SPA report (Reda and Andreas, 2004), test case: Golden CO, 2003-10-17, UTC-7:
    # sunrise 06:12:43 and sunset 17:20:19 local time for the UT day of 17 October, whose
    # sunset (00:20:19 UT) is the local evening of the 16th; standard refraction (34')
    golden = Site(39.742476, -105.1786, 1830.14)
    mountain = datetime.timezone(datetime.timedelta(hours=-7))
    sunrise, _ = sky.sunrise_sunset(golden, datetime.date(2003, 10, 17), mountain)
    _, sunset = sky.sunrise_sunset(golden, datetime.date(2003, 10, 16), mountain)
    published_rise = datetime.datetime(2003, 10, 17, 6, 12, 43, tzinfo=mountain)
    published_set = datetime.datetime(2003, 10, 17, 0, 20, 19, tzinfo=UTC)
    assert abs((sunrise - published_rise).total_seconds()) < 30.0
    assert abs((sunset - published_set).total_seconds()) < 30.0


def test_the_day_is_sampled_from_sunrise_to_sunset_in_local_time(rig):
    day = sky.sky_day(sky.SkyModel(rig), SITE, DAY, CEST, HEADING, step=3600.0)
    assert day.sunrise <= day.samples[0].when and day.samples[-1].when <= day.sunset
    assert all(sample.when.astimezone(CEST).minute == 0 for sample in day.samples)
    assert day.samples[0].when - datetime.timedelta(hours=1) < day.sunrise
    # the pysolar elevation at each sample, asked directly
    for sample in day.samples:
        assert sample.elevation_deg == pytest.approx(solar.get_altitude(
            SITE.latitude_deg, SITE.longitude_deg, sample.when, elevation=SITE.elevation,
            temperature=SITE.temperature + 273.15, pressure=SITE.pressure), abs=1e-9)


def test_the_heading_scan_picks_a_heading_with_the_most_hours(rig):
    model = sky.SkyModel(rig)
    headings = list(range(0, 360, 30))
    scan = sky.heading_scan(model, SITE, DAY, CEST, headings, step=1800.0)
    best = sky.best_heading(scan)
    assert [heading for heading, _ in scan] == headings
    assert all(best[1] >= hours for _, hours in scan)
    assert best[1] > min(hours for _, hours in scan)          # the heading matters
    for heading, hours in scan[::3] + [best]:                 # the scan is the full day's
        assert sky.sky_day(model, SITE, DAY, CEST, heading, step=1800.0).hours == hours
    tied = [heading for heading, hours in scan if hours == best[1]]
    assert sky.best_heading(scan, prefer=tied[-1] + 5.0)[0] == tied[-1]


@pytest.mark.parametrize('heading', [0.0, 95.0, 200.0, 311.0])
def test_the_heading_follows_from_the_simulated_worlds_ray(heading):
    world_sun = Sun(SITE, math.radians(heading))
    for hour in (6, 10, 15):
        when = datetime.datetime(2026, 6, 21, hour, 17, tzinfo=UTC)
        found = math.degrees(sky.heading_from_ray(world_sun.ray_robot(when),
                                                  sun_position(SITE, when)))
        assert abs(math.remainder(found - heading, 360.0)) < 1e-3


def test_a_sun_too_low_for_the_sweep_is_refused_saying_when_it_is_high_enough():
    night = datetime.datetime(2026, 6, 21, 1, 0, tzinfo=UTC)
    refusal = sky.sweep_refusal(SITE, night, 30.0)
    assert 'helio sky' in str(refusal) and '30 deg' in str(refusal)
    later = refusal.next_time

    def altitude(when):
        return solar.get_altitude(SITE.latitude_deg, SITE.longitude_deg, when,
                                  elevation=SITE.elevation)
    assert altitude(later) >= 30.0 > altitude(later - datetime.timedelta(minutes=10))
    assert later.strftime('%H:%M UTC') in str(refusal)
    assert sky.sweep_refusal(SITE, later, 30.0) is None


def test_a_canvas_out_of_reach_is_refused_naming_the_heading_and_when(rig):
    now = datetime.datetime(2026, 6, 21, 12, 0, tzinfo=UTC)
    world_sun = Sun(SITE, math.radians(30.0))         # the sun behind the arm at midday
    points = [(0.05, 0.05), (0.05, 0.06)]
    assert rig_model_share(rig, points, world_sun.ray_robot(now)) == 0.0
    refusal = sky.reach_refusal(rig, points, world_sun.ray_robot(now), 0.082, 0.03, SITE,
                                now, min_elevation_deg=30.0)
    assert refusal.heading_deg == pytest.approx(30.0, abs=1e-3)
    assert 'helio sky --heading 30' in str(refusal)
    later = refusal.next_time
    assert later.strftime('%H:%M UTC') in str(refusal)
    assert rig_model_share(rig, points, world_sun.ray_robot(later)) == 1.0
    for k in range(1, int((later - now) / datetime.timedelta(minutes=10))):
        ray = world_sun.ray_robot(now + k * datetime.timedelta(minutes=10))
        assert rig_model_share(rig, points, ray) < 1.0 or -ray[2] < math.sin(math.radians(30))
    # one point within reach: the sun serves the goal, nothing is refused
    ray = world_sun.ray_robot(now)
    reachable = next(tuple(point) for point in sky.canvas_points(0.05, 0.05, 0.08, 0.01)
                     if rig_model_share(rig, [point], ray) == 1.0)
    assert sky.reach_refusal(rig, points + [reachable], ray, 0.082, 0.03, SITE, now) is None


def test_reports_say_the_windows_and_the_best_heading(rig):
    settings = sky.SkySettings()
    model = sky.SkyModel(rig, settings)
    scan = sky.heading_scan(model, SITE, DAY, CEST, [0.0, 90.0, 180.0, 270.0], step=3600.0)
    best = sky.best_heading(scan)
    day = sky.sky_day(model, SITE, DAY, CEST, 0.0, step=3600.0)
    text = '\n'.join(sky.report_lines(day, scan, best, settings))
    assert 'served at heading 0 deg: ' in text and f'best heading {best[0]:.0f} deg' in text
    assert len(day.samples) == sum(1 for line in text.splitlines() if line[:2].isdigit()
                                   and line[2] == ':' and len(line) > 40)
    data = sky.report_dict(day, scan, best, settings)
    assert data['hours'] == day.hours and len(data['samples']) == len(day.samples)
    assert data['windows'] and data['windows'][0]['start'] == day.windows[0][0].isoformat()


def test_a_sun_at_the_zenith_is_refused_without_a_heading(rig):
    now = datetime.datetime(2026, 6, 21, 12, 0, tzinfo=UTC)
    far = [(0.6, 0.6)]                     # half a metre beyond the arm's reach
    refusal = sky.reach_refusal(rig, far, [0.0, 0.0, -1.0], 0.082, 0.03, SITE, now)
    assert refusal.heading_deg is None and refusal.next_time is None
    assert "beyond the arm's reach" in str(refusal) and 'helio sky' in str(refusal)
