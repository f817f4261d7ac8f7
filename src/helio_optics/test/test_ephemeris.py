"""Ephemeris (pysolar) against the NREL SPA reference case, and the Eq 18 time update."""

import datetime
import math

from helio_optics.ephemeris import corrected_angles, corrected_direction, ray_angles_from_sun
from helio_optics.ephemeris import Site, sun_position
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
