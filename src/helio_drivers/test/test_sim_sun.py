"""Simulated sun, clouds and clock against pysolar and their own definitions."""

import datetime
import math

from helio_drivers.sim.clock import Lockstep, Pacer, SimClock
from helio_drivers.sim.sun import CloudCover, CloudInterval, RandomClouds, Sun
from helio_optics.ephemeris import Site
from helio_optics.geometry import homogeneous, rotation_z
import numpy as np
from pysolar import solar
import pytest

SITE = Site(latitude_deg=48.137, longitude_deg=11.575, elevation=520.0)
CEST = datetime.timezone(datetime.timedelta(hours=2))
START = datetime.datetime(2026, 6, 21, 9, 30, tzinfo=CEST)


def pysolar_ray_enu(when):
    """Sun ray (east, north, up), computed directly from pysolar's altitude and azimuth."""
    altitude = math.radians(solar.get_altitude(SITE.latitude_deg, SITE.longitude_deg, when,
                                               elevation=SITE.elevation,
                                               temperature=SITE.temperature + 273.15,
                                               pressure=SITE.pressure))
    azimuth = math.radians(solar.get_azimuth(SITE.latitude_deg, SITE.longitude_deg, when,
                                             elevation=SITE.elevation))
    towards = np.array([math.sin(azimuth) * math.cos(altitude),
                        math.cos(azimuth) * math.cos(altitude), math.sin(altitude)])
    return -towards


def enu_to_robot(vector, heading):
    """Robot x points at compass `heading` (clockwise from north), z up, y = z cross x."""
    x_axis = np.array([math.sin(heading), math.cos(heading), 0.0])
    y_axis = np.cross([0.0, 0.0, 1.0], x_axis)
    return np.array([vector @ x_axis, vector @ y_axis, vector[2]])


@pytest.mark.parametrize('heading_deg', [0.0, 37.0, 200.0])
def test_sun_moves_as_pysolar_says_over_a_simulated_hour(heading_deg):
    heading = math.radians(heading_deg)
    world_yaw = math.radians(25.0)
    T_robot_world = homogeneous(rotation_z(world_yaw), (0.1, -0.1, -0.13))
    sun = Sun(SITE, heading, T_robot_world=T_robot_world)
    clock = SimClock(START)
    angles = []
    for _ in range(7):  # every 10 minutes over an hour
        when = clock.datetime()
        expected_robot = enu_to_robot(pysolar_ray_enu(when), heading)
        assert sun.ray_robot(when) == pytest.approx(expected_robot, abs=1e-6)
        expected_world = rotation_z(world_yaw).T @ expected_robot
        assert sun.ray_world(when) == pytest.approx(expected_world, abs=1e-6)
        angles.append(sun.ray_robot(when))
        clock.advance(600.0)
    moved = math.degrees(math.acos(np.clip(angles[0] @ angles[-1], -1.0, 1.0)))
    print(f'sun moved {moved:.2f} deg over the simulated hour')
    assert 10.0 < moved < 20.0  # about 15 deg/h of hour angle, projected


def test_heading_turns_the_ray_in_the_robot_frame_only_about_the_vertical():
    when = START
    a = Sun(SITE, 0.0).ray_robot(when)
    b = Sun(SITE, math.radians(90.0)).ray_robot(when)
    assert a[2] == pytest.approx(b[2])
    turned = math.atan2(b[1], b[0]) - math.atan2(a[1], a[0])
    assert math.remainder(turned, 2 * math.pi) == pytest.approx(math.radians(90.0), abs=1e-9)


def test_schedule_attenuates_inside_intervals_and_the_darkest_wins():
    clouds = CloudCover([CloudInterval(10.0, 20.0, 0.3), CloudInterval(15.0, 30.0, 0.6)])
    assert clouds.attenuation(9.99) == 1.0
    assert clouds.attenuation(10.0) == 0.3
    assert clouds.attenuation(16.0) == 0.3
    assert clouds.attenuation(25.0) == 0.6
    assert clouds.attenuation(30.0) == 1.0
    sun = Sun(SITE, 0.0, dni=900.0, clouds=clouds)
    assert sun.irradiance(START, 12.0) == pytest.approx(270.0)
    assert sun.irradiance(START, 40.0) == pytest.approx(900.0)
    night = datetime.datetime(2026, 6, 21, 1, 0, tzinfo=datetime.timezone.utc)
    assert sun.irradiance(night, 40.0) == 0.0


def test_random_clouds_are_reproducible_for_a_seed_and_have_the_asked_statistics():
    process = RandomClouds(seed=7, mean_clear=100.0, mean_cloudy=20.0)
    first, again = process.intervals(20000.0), process.intervals(20000.0)
    other = RandomClouds(seed=8, mean_clear=100.0, mean_cloudy=20.0).intervals(20000.0)
    assert first == again and first != other
    lengths = np.array([c.end - c.start for c in first])
    assert lengths.mean() == pytest.approx(20.0, rel=0.25)
    assert all(0.2 <= c.attenuation <= 0.7 for c in first)
    cover = CloudCover(random_clouds=process, horizon=20000.0)
    times = np.arange(0.0, 20000.0, 1.0)
    cloudy = np.mean([cover.attenuation(t) < 1.0 for t in times])
    assert cloudy == pytest.approx(20.0 / 120.0, abs=0.06)


def test_bad_cloud_and_sun_parameters_are_refused():
    with pytest.raises(ValueError, match='end > start'):
        CloudInterval(5.0, 5.0, 0.5)
    with pytest.raises(ValueError, match='attenuation'):
        CloudInterval(0.0, 5.0, 1.5)
    with pytest.raises(ValueError, match='triples'):
        CloudCover.from_flat([0.0, 1.0])
    with pytest.raises(ValueError, match='dni'):
        Sun(SITE, 0.0, dni=-1.0)


def test_clock_advances_only_when_stepped_and_maps_to_dates():
    clock = SimClock(START)
    assert clock() == 0.0
    clock.advance(0.25)
    clock.advance(0.25)
    assert clock() == 0.5
    # /clock carries the absolute simulated instant (Unix epoch), for the Eq 18 ephemeris
    epoch = datetime.datetime(1970, 1, 1, tzinfo=datetime.timezone.utc)
    assert clock.nanoseconds() == (START - epoch) // datetime.timedelta(microseconds=1) * 1000 \
        + 500_000_000
    assert clock.datetime() == START + datetime.timedelta(seconds=0.5)
    with pytest.raises(ValueError):
        clock.advance(0.0)
    with pytest.raises(ValueError, match='timezone'):
        SimClock(datetime.datetime(2026, 6, 21, 9, 30))


def test_pacer_holds_the_real_time_factor_and_reports_it():
    pacer = Pacer(real_time_factor=10.0)
    assert pacer.delay(100.0, 0.0) == 0.0
    # one simulated second at 10x is due 0.1 wall seconds later
    assert pacer.delay(100.02, 1.0) == pytest.approx(0.08)
    assert pacer.delay(100.2, 1.0) == 0.0
    assert pacer.achieved(100.2, 2.0) == pytest.approx(10.0)
    assert Pacer(real_time_factor=0.0).delay(5.0, 3.0) == 0.0


def test_a_new_real_time_factor_paces_from_the_present_on():
    pacer = Pacer(real_time_factor=0.0)
    assert pacer.delay(100.0, 0.0) == 0.0 and pacer.delay(100.1, 50.0) == 0.0
    pacer.set_real_time_factor(2.0)
    assert pacer.delay(100.1, 50.0) == 0.0          # anchored now, not at the start
    assert pacer.delay(100.1, 51.0) == pytest.approx(0.5)
    assert pacer.achieved(101.1, 52.0) == pytest.approx(52.0 / 1.1)


def test_a_pacer_behind_catches_up_only_within_max_lag():
    # 1x, one step of 0.1 s took 0.3 s of wall time: 0.2 s behind
    catching = Pacer(real_time_factor=1.0, max_lag=0.5)
    never = Pacer(real_time_factor=1.0, max_lag=0.0)
    for pacer in (catching, never):
        assert pacer.delay(100.0, 0.0) == 0.0
        assert pacer.delay(100.3, 0.1) == 0.0                   # late: step at once
    # the next step is due at 100.2 on the old anchor: the one that catches up steps at once,
    # the other counts from where it is (0.1 s of wall time for 0.1 s simulated)
    assert catching.delay(100.3, 0.2) == 0.0
    assert never.delay(100.3, 0.2) == pytest.approx(0.1)


def test_lockstep_holds_the_world_at_most_lead_ahead_of_its_consumer_and_not_forever():
    lockstep = Lockstep(lead=0.35, timeout=1.0)
    assert not lockstep.hold(100.0, 0.0)           # no consumer yet: free running
    assert not lockstep.left_behind(100.0)         # (not paced: there is none to wait for)
    lockstep.seen(10.0, wall_now=5.0)
    assert not lockstep.hold(10.35, 5.1)           # within the lead
    assert lockstep.hold(10.36, 5.1)               # ahead of it: wait
    lockstep.seen(9.0, wall_now=5.2)               # a late answer does not move it back,
    lockstep.seen(10.0, wall_now=5.9)              # and neither is an answer to the same
    assert lockstep.hold(10.36, 5.3)               # frame again progress: silent from 5.0
    assert not lockstep.left_behind(5.95) and lockstep.left_behind(6.05)
    assert not lockstep.hold(10.36, 6.3)           # silent for more than 1 s wall: go on
    assert lockstep.left_behind(6.3)               # (the node paces itself at real time)
    lockstep.seen(10.3, wall_now=6.4)              # answering again: held again
    assert not lockstep.left_behind(6.5)
    assert lockstep.hold(10.7, 6.5) and not lockstep.hold(10.6, 6.5)
    with pytest.raises(ValueError):
        Lockstep(lead=0.0)


def test_lockstep_waits_for_the_slowest_of_several_sources_and_leaves_a_silent_one():
    lockstep = Lockstep(lead=0.2, timeout=1.0)
    lockstep.seen(10.0, wall_now=0.0, source='thermal')
    lockstep.seen(10.0, wall_now=0.0, source='dobot')
    lockstep.seen(9.7, wall_now=0.0, source='servo')
    assert lockstep.holding(10.0, 0.1) == ['servo']    # 0.3 s behind the world
    assert lockstep.holding(9.85, 0.1) == []
    lockstep.seen(9.9, wall_now=0.2, source='servo')
    assert lockstep.holding(10.1, 0.3) == []           # every source within the lead
    lockstep.seen(10.2, wall_now=0.3, source='servo')
    assert lockstep.holding(10.25, 0.3) == ['dobot', 'thermal']
    # the Dobot unplugged: it alone goes silent and is left behind after the timeout
    for wall in (0.5, 0.9, 1.1):
        lockstep.seen(10.3, wall_now=wall, source='thermal')
        lockstep.seen(10.3, wall_now=wall, source='servo')
    assert lockstep.holding(10.4, 0.9) == ['dobot'] and not lockstep.left_behind(0.9)
    assert lockstep.holding(10.4, 1.1) == [] and lockstep.silent(1.1) == ['dobot']
    lockstep.seen(10.4, wall_now=1.2, source='dobot', lead=0.15)   # back, with its own lead
    assert 'dobot' not in lockstep.holding(10.5, 1.2)
    assert 'dobot' in lockstep.holding(10.56, 1.2)
    lockstep.seen(10.4, wall_now=1.2, source='dobot')     # plugged back in: held again
    assert not lockstep.left_behind(1.2) and lockstep.holding(10.7, 1.2) == ['dobot', 'servo',
                                                                             'thermal']


def test_a_source_that_says_it_is_done_is_no_longer_waited_for():
    lockstep = Lockstep(lead=0.2, timeout=1.5)
    lockstep.seen(10.0, wall_now=0.0, source='lens/heating', lead=0.05)
    assert lockstep.holding(10.1, 0.1) == ['lens/heating']   # past its own lead: held
    lockstep.forget('lens/heating')                          # 'clear': nothing to watch
    assert lockstep.holding(12.0, 0.2) == [] and not lockstep.left_behind(5.0)
    lockstep.seen(12.0, wall_now=0.3, source='lens/heating')  # heating again: held again,
    assert lockstep.holding(12.25, 0.3) == ['lens/heating']  # at the default lead now
    lockstep.forget('never heard')                           # forgetting nothing is fine
