"""Ephemeris (pysolar) against the NREL SPA reference case, and the Eq 18 time update."""

import datetime
import math

from helio_optics.ephemeris import corrected_angles, corrected_direction, ray_angles_from_sun
from helio_optics.ephemeris import Site, sun_position, SunPath
from helio_optics.geometry import direction_from_angles
import numpy as np
import pytest

# NREL SPA (Reda & Andreas 2004) test case: 17 Oct 2003 12:30:30 local time (UTC-7),
# Golden CO; apparent zenith 50.11162 deg, azimuth 194.34024 deg.
SPA_SITE = Site(latitude_deg=39.742476, longitude_deg=-105.1786, elevation=1830.14,
                temperature=11.0, pressure=82000.0)
SPA_TIME = datetime.datetime(2003, 10, 17, 12, 30, 30,
                             tzinfo=datetime.timezone(datetime.timedelta(hours=-7)))


def test_nrel_spa_reference_case_within_a_hundredth_of_a_degree():
    position = sun_position(SPA_SITE, SPA_TIME)
    assert 90.0 - math.degrees(position.elevation) == pytest.approx(50.11162, abs=0.01)
    assert math.degrees(position.azimuth) == pytest.approx(194.34024, abs=0.01)


def test_naive_datetime_is_rejected_with_a_clear_error():
    with pytest.raises(ValueError, match='naive datetime'):
        sun_position(SPA_SITE, datetime.datetime(2003, 10, 17, 12, 30, 30))
    with pytest.raises(ValueError, match='latitude'):
        Site(latitude_deg=91.0, longitude_deg=0.0)


def test_eq18_update_matches_the_direct_sun_direction_later():
    heading = math.radians(37.0)  # compass azimuth of the robot's x axis (unknown to Eq 18)
    later = SPA_TIME + datetime.timedelta(minutes=25)
    anchor, now = sun_position(SPA_SITE, SPA_TIME), sun_position(SPA_SITE, later)
    phi0, theta0 = ray_angles_from_sun(anchor, heading)
    direct = ray_angles_from_sun(now, heading)
    updated = corrected_angles(phi0, theta0, anchor, now)
    assert updated[0] == pytest.approx(direct[0], abs=1e-12)
    assert math.remainder(updated[1] - direct[1], 2 * math.pi) == pytest.approx(0, abs=1e-12)
    # The sun moved measurably in 25 minutes, so the check is not vacuous.
    assert abs(now.azimuth - anchor.azimuth) > math.radians(3.0)
    np.testing.assert_allclose(corrected_direction(phi0, theta0, anchor, now),
                               direction_from_angles(*direct), atol=1e-12)


def test_ray_points_down_and_away_from_the_sun():
    # Sun due south at 40 deg elevation, robot x pointing north: the ray travels north
    # (+x) and down.
    from helio_optics.ephemeris import SunPosition
    phi0, theta0 = ray_angles_from_sun(SunPosition(math.radians(40.0), math.pi), 0.0)
    ray = direction_from_angles(phi0, theta0)
    np.testing.assert_allclose(ray, [math.cos(math.radians(40)), 0.0,
                                     -math.sin(math.radians(40))], atol=1e-12)


def test_angle_offsets_are_eq18_differences_wrapped_across_north():
    from helio_optics.ephemeris import angle_offsets, SunPosition
    before = SunPosition(math.radians(30.0), math.radians(359.5))
    after = SunPosition(math.radians(30.2), math.radians(0.5))     # one degree later, past N
    dphi, dtheta = angle_offsets(before, after)
    assert dphi == pytest.approx(math.radians(0.2), abs=1e-12)
    assert dtheta == pytest.approx(math.radians(-1.0), abs=1e-12)  # not +359 deg
    # the offsets move ray angles exactly as the direct ray angles at the later time
    heading = math.radians(12.0)
    phi0, theta0 = ray_angles_from_sun(before, heading)
    direct = ray_angles_from_sun(after, heading)
    np.testing.assert_allclose(direction_from_angles(phi0 + dphi, theta0 + dtheta),
                               direction_from_angles(*direct), atol=1e-12)


def _unit(position):
    cos_e = math.cos(position.elevation)
    return np.array([cos_e * math.sin(position.azimuth), cos_e * math.cos(position.azimuth),
                     math.sin(position.elevation)])


@pytest.mark.parametrize('site', [SPA_SITE, Site(-33.9, 151.2), Site(1.3, 103.8),
                                  Site(69.6, 18.9)], ids=['golden', 'sydney', 'equator',
                                                          'arctic'])
def test_sun_path_is_pysolar_within_1e7_rad_while_the_sun_is_up(site):
    """The interpolated path against pysolar itself at random instants over two days."""
    path = SunPath(site)
    rng = np.random.default_rng(7)
    start = datetime.datetime(2026, 6, 21, tzinfo=datetime.timezone.utc)
    errors, near_horizon = [], []
    for seconds in rng.uniform(0.0, 2 * 86400.0, 300):
        when = start + datetime.timedelta(seconds=float(seconds))
        exact = sun_position(site, when)
        gap = math.acos(min(1.0, float(_unit(exact) @ _unit(path.position(when)))))
        if exact.elevation > math.radians(2.0):
            errors.append(gap)
        elif exact.elevation > 0.0:
            near_horizon.append(gap)
    assert len(errors) > 50
    assert max(errors) < 1e-7
    assert max(near_horizon, default=0.0) < 1e-3       # refraction bends fast there
    # a knot per minute, each traced once: not a pysolar call per position
    assert path.exact_calls < 300 * 4


def test_sun_path_follows_a_clock_stepping_forward_with_four_calls_per_knot_at_most():
    path = SunPath(SPA_SITE, knot_spacing=60.0)
    for step in range(6000):     # ten minutes in 0.1 s steps
        position = path.position(SPA_TIME + datetime.timedelta(seconds=0.1 * step))
    assert path.exact_calls <= 10 + 4
    exact = sun_position(SPA_SITE, SPA_TIME + datetime.timedelta(seconds=599.9))
    assert position.elevation == pytest.approx(exact.elevation, abs=1e-7)
    assert position.azimuth == pytest.approx(exact.azimuth, abs=1e-7)


def test_sun_path_rejects_naive_times_and_bad_spacings():
    with pytest.raises(ValueError, match='naive datetime'):
        SunPath(SPA_SITE).position(datetime.datetime(2003, 10, 17, 12, 30, 30))
    with pytest.raises(ValueError, match='knot_spacing'):
        SunPath(SPA_SITE, knot_spacing=0.0)
    with pytest.raises(TypeError, match='Site'):
        SunPath((39.7, -105.2))
