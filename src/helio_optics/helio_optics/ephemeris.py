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

``SunPath(site, knot_spacing=60.0)``: the same positions, interpolated (a cubic through four
exact ones a ``knot_spacing`` apart, kept): ``SunPath.position(when)`` costs microseconds
instead of pysolar's milliseconds, within 1e-7 rad of ``sun_position`` while the sun is 2 deg
or more above the horizon (1e-3 rad below that, where refraction bends fast; tested). The
simulated world asks for the sun every step; this is what it uses.

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


def _check_aware(when):
    """Raise unless `when` is a timezone-aware datetime."""
    if not isinstance(when, datetime.datetime):
        raise TypeError(f'when must be a datetime.datetime, got {type(when).__name__}')
    if when.tzinfo is None or when.tzinfo.utcoffset(when) is None:
        raise ValueError(
            f'naive datetime {when.isoformat()}: give a timezone (e.g. tzinfo=timezone.utc)')


def sun_position(site, when):
    """Return the SunPosition at a timezone-aware datetime `when` (pysolar, with refraction)."""
    _check_aware(when)
    altitude = solar.get_altitude(site.latitude_deg, site.longitude_deg, when,
                                  elevation=site.elevation,
                                  temperature=site.temperature + 273.15,
                                  pressure=site.pressure)
    azimuth = solar.get_azimuth(site.latitude_deg, site.longitude_deg, when,
                                elevation=site.elevation)
    return SunPosition(elevation=math.radians(altitude),
                       azimuth=math.radians(azimuth) % (2.0 * math.pi))


class SunPath:
    """
    ``sun_position`` interpolated between exact positions every ``knot_spacing`` seconds.

    The sun's direction (east, north, up unit vector) at the knots k h (h the spacing,
    seconds since the Unix epoch) comes from ``sun_position``, once per knot; between knots
    k h <= t < (k + 1) h the direction is the cubic through knots k - 1 .. k + 2
    (Lagrange), normalised. The sun turns about 7.3e-5 rad/s, smoothly: the cubic's error
    is of order h^4 |d^4 s / dt^4| ~ 1e-7 rad at h = 60 s, far below the world's other
    errors (the rays' own sampling). Within a knot of the horizon, where pysolar's
    refraction term bends the elevation fast, the error grows (tested: below 1e-3 rad
    there, 3e-8 rad above 2 deg). The latest knots are kept (an instant's neighbours);
    a clock that jumps away only costs four exact positions.
    """

    KEPT_KNOTS = 16

    def __init__(self, site, knot_spacing=60.0):
        """Interpolate the sun at `site` (Site) between knots `knot_spacing` [s] apart."""
        if not isinstance(site, Site):
            raise TypeError('site must be a helio_optics.ephemeris.Site')
        if not 0.0 < knot_spacing <= 3600.0:
            raise ValueError(f'knot_spacing must be in (0, 3600] s, got {knot_spacing}')
        self.site = site
        self.knot_spacing = float(knot_spacing)
        self._knots = {}
        self.exact_calls = 0

    def _direction_at_knot(self, k):
        """Return the (east, north, up) unit vector of the sun at knot k (exact, kept)."""
        direction = self._knots.get(k)
        if direction is None:
            when = datetime.datetime.fromtimestamp(k * self.knot_spacing, datetime.timezone.utc)
            position = sun_position(self.site, when)
            self.exact_calls += 1
            cos_e = math.cos(position.elevation)
            direction = (cos_e * math.sin(position.azimuth), cos_e * math.cos(position.azimuth),
                         math.sin(position.elevation))
            if len(self._knots) >= self.KEPT_KNOTS:
                del self._knots[max(self._knots, key=lambda kept: abs(kept - k))]
            self._knots[k] = direction
        return direction

    def position(self, when):
        """Return the SunPosition at an aware datetime `when` (interpolated; see the class)."""
        _check_aware(when)
        t = when.timestamp() / self.knot_spacing
        k = math.floor(t)
        u = t - k         # in [0, 1) between knots k and k + 1
        # cubic Lagrange weights of the knots at -1, 0, 1, 2
        weights = (-u * (u - 1.0) * (u - 2.0) / 6.0, (u + 1.0) * (u - 1.0) * (u - 2.0) / 2.0,
                   -(u + 1.0) * u * (u - 2.0) / 2.0, (u + 1.0) * u * (u - 1.0) / 6.0)
        east = north = up = 0.0
        for offset, weight in zip((-1, 0, 1, 2), weights):
            e, n, z = self._direction_at_knot(k + offset)
            east += weight * e
            north += weight * n
            up += weight * z
        norm = math.sqrt(east * east + north * north + up * up)
        return SunPosition(elevation=math.asin(max(-1.0, min(1.0, up / norm))),
                           azimuth=math.atan2(east, north) % (2.0 * math.pi))


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
