"""
Sun position from pysolar and the time update of the estimate (paper Sec. IV-C, Eq 18).

API
---
``Site(latitude_deg, longitude_deg, elevation=0.0, temperature=12.0,
pressure=101325.0)``: where the robot stands (degrees north/east; height above sea
level [m]; air temperature and pressure for refraction).

``sun_position(site, when) -> SunPosition(elevation, azimuth)``: the apparent sun
elevation above the horizon and the azimuth clockwise from north, both [rad], for a
timezone-aware ``datetime`` (a naive one raises ``ValueError``: the hour would be a guess).

``corrected_angles(phi0, theta0, anchor, now) -> (phi0_t, theta0_t)``: Eq 18,
theta_hat_t = theta_hat + (theta_c^t - theta_c^t0), for the ray angles of Eq 2 (s0 points
from the sun down). With the robot's z axis vertical, the ray polar angle is
phi0 = pi/2 + elevation, and the ray azimuth counter-clockwise from the robot's x axis
changes by minus the change of the compass azimuth (clockwise from north), so
phi0_t = phi0 + (e_t - e_t0), theta0_t = theta0 - (A_t - A_t0) (mod 2 pi).

``corrected_direction(phi0, theta0, anchor, now)``: the robot-frame unit ray s0 at time t.

``angle_offsets(anchor, now) -> (dphi, dtheta)``: the change Eq 18 adds to the ray angles
between two sun positions (dtheta wrapped to [-pi, pi)); the sun estimator moves each
observation of a sweep to one reference time with it (``sun_estimation.Observation``'s
``angle_offset``).

``ray_angles_from_sun(position, heading)``: the ray angles (phi0, theta0) for a sun
position and a robot heading (the compass azimuth of the robot's x axis, clockwise from
north [rad]); the simulated world uses it to place its sun from the same ephemeris.
"""

from dataclasses import dataclass
import datetime
import math

from helio_optics.config_files import read_parameter_section
from helio_optics.geometry import direction_from_angles
from pysolar import solar


@dataclass(frozen=True)
class Site:
    """Geographic site of the robot (WGS84 degrees, metres, degC, Pa)."""

    latitude_deg: float
    longitude_deg: float
    elevation: float = 0.0
    temperature: float = 12.0
    pressure: float = 101325.0

    def __post_init__(self):
        """Reject coordinates outside the globe."""
        if not -90.0 <= self.latitude_deg <= 90.0:
            raise ValueError(f'latitude must be in [-90, 90] deg, got {self.latitude_deg}')
        if not -180.0 <= self.longitude_deg <= 360.0:
            raise ValueError(f'longitude must be in [-180, 360] deg, got {self.longitude_deg}')


def load_site(path):
    """Read the Site from a ROS 2 parameter file's ``site`` section (config/site.yaml)."""
    flat = read_parameter_section(path, 'site')
    names = set(Site.__dataclass_fields__)
    unknown = sorted(set(flat) - names)
    if unknown:
        raise ValueError(f'{path}: unknown site parameter(s) {unknown}; known: {sorted(names)}')
    return Site(**{name: float(value) for name, value in flat.items()})


@dataclass(frozen=True)
class SunPosition:
    """Apparent sun position: elevation above the horizon, azimuth clockwise from north [rad]."""

    elevation: float
    azimuth: float


def sun_position(site, when):
    """Return the SunPosition at a timezone-aware datetime `when` (pysolar, with refraction)."""
    if not isinstance(when, datetime.datetime):
        raise TypeError(f'when must be a datetime.datetime, got {type(when).__name__}')
    if when.tzinfo is None or when.tzinfo.utcoffset(when) is None:
        raise ValueError(
            f'naive datetime {when.isoformat()}: give a timezone (e.g. tzinfo=timezone.utc)')
    altitude = solar.get_altitude(site.latitude_deg, site.longitude_deg, when,
                                  elevation=site.elevation,
                                  temperature=site.temperature + 273.15,
                                  pressure=site.pressure)
    azimuth = solar.get_azimuth(site.latitude_deg, site.longitude_deg, when,
                                elevation=site.elevation)
    return SunPosition(elevation=math.radians(altitude),
                       azimuth=math.radians(azimuth) % (2.0 * math.pi))


def angle_offsets(anchor, now):
    """Eq 18's change of the ray angles (dphi, dtheta) [rad] from SunPosition `anchor` to `now`."""
    dtheta = -(now.azimuth - anchor.azimuth)
    return now.elevation - anchor.elevation, math.remainder(dtheta, 2.0 * math.pi)


def corrected_angles(phi0, theta0, anchor, now):
    """Eq 18: ray angles (phi0, theta0) [rad] at `now` from an estimate made at `anchor`."""
    dphi, dtheta = angle_offsets(anchor, now)
    return phi0 + dphi, (theta0 + dtheta) % (2.0 * math.pi)


def corrected_direction(phi0, theta0, anchor, now):
    """Robot-frame unit ray s0 at `now` (Eqs 2 and 18)."""
    return direction_from_angles(*corrected_angles(phi0, theta0, anchor, now))


def ray_angles_from_sun(position, heading):
    """
    Return ray angles (phi0, theta0) [rad] seen from a robot whose x axis has `heading`.

    `heading` is the compass azimuth of the robot's x axis (clockwise from north) [rad];
    the robot's z axis is vertical.
    """
    phi0 = 0.5 * math.pi + position.elevation
    towards_sun = heading - position.azimuth  # counter-clockwise from the robot's x axis
    return phi0, (towards_sun + math.pi) % (2.0 * math.pi)
