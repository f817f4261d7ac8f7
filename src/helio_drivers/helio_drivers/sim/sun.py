"""
The simulated sun and clouds (issue 6, item 1).

Position: ``helio_optics.ephemeris`` (pysolar; the one implementation the estimator uses for
Eq 18 too) for a site and the simulated instant, through its ``SunPath`` (exact positions a
minute apart, interpolated: microseconds a call instead of a millisecond, within 1e-7 rad);
the robot's heading (compass azimuth of its x axis, clockwise from north) is a hidden
parameter of the world: the estimator must find it from the light spot, nothing publishes it.
The sun ray s0 (the way light travels, paper Eq 2) in the robot frame comes from
``ephemeris.ray_angles_from_sun``; the world frame's orientation relative to the robot is the
rig's ``T_robot_world``.

Irradiance: the direct normal irradiance (DNI) times the cloud attenuation, a factor in
[0, 1] (1 clear). Clouds are a schedule of intervals [start, end) of simulated seconds
each with its attenuation, plus an optional seeded random process (alternating clear and
cloudy spells with exponential durations and a uniform attenuation), so a run is
reproducible for its seed. Where intervals overlap the darkest one wins. A cloud's edge
is sharp: the flux drops to its attenuation within one step.
"""

from dataclasses import dataclass
import math

from helio_optics.ephemeris import ray_angles_from_sun, Site, SunPath
from helio_optics.geometry import direction_from_angles
import numpy as np


@dataclass(frozen=True)
class CloudInterval:
    """A cloud over the sun from `start` to `end` [s of simulated time], DNI x attenuation."""

    start: float
    end: float
    attenuation: float

    def __post_init__(self):
        """Reject empty intervals and attenuations outside [0, 1]."""
        if not self.end > self.start:
            raise ValueError(f'cloud interval needs end > start, got [{self.start}, {self.end})')
        if not 0.0 <= self.attenuation <= 1.0:
            raise ValueError(f'cloud attenuation must be in [0, 1], got {self.attenuation}')


@dataclass(frozen=True)
class RandomClouds:
    """Seeded random clouds: mean clear / cloudy spell lengths [s], attenuation range."""

    seed: int = 0
    mean_clear: float = 300.0
    mean_cloudy: float = 30.0
    attenuation_range: tuple = (0.2, 0.7)

    def __post_init__(self):
        """Reject non-positive spell lengths and attenuations outside [0, 1]."""
        if not (self.mean_clear > 0.0 and self.mean_cloudy > 0.0):
            raise ValueError('mean_clear and mean_cloudy must be > 0 s')
        low, high = self.attenuation_range
        if not 0.0 <= low <= high <= 1.0:
            raise ValueError(f'attenuation_range must be within [0, 1], got {(low, high)}')

    def intervals(self, horizon):
        """Cloud intervals covering [0, horizon) seconds, the same for the same seed."""
        rng = np.random.default_rng(self.seed)
        t, result = 0.0, []
        while t < horizon:
            t += rng.exponential(self.mean_clear)
            length = rng.exponential(self.mean_cloudy)
            attenuation = rng.uniform(*self.attenuation_range)
            if t < horizon and length > 0.0:
                result.append(CloudInterval(t, t + length, attenuation))
            t += length
        return result


class CloudCover:
    """Attenuation of the direct sun over simulated time: schedule plus random clouds."""

    def __init__(self, schedule=(), random_clouds=None, horizon=86400.0):
        """Combine a schedule of CloudInterval with an optional RandomClouds process."""
        intervals = list(schedule)
        if random_clouds is not None:
            intervals += random_clouds.intervals(horizon)
        self.intervals = sorted(intervals, key=lambda c: c.start)

    @classmethod
    def from_flat(cls, flat, random_clouds=None):
        """Build from a flat list [start, end, attenuation, start, end, attenuation, ...]."""
        values = list(flat)
        if len(values) % 3:
            raise ValueError('cloud schedule needs triples (start_s, end_s, attenuation), '
                             f'got {len(values)} numbers')
        schedule = [CloudInterval(*map(float, values[i:i + 3]))
                    for i in range(0, len(values), 3)]
        return cls(schedule, random_clouds)

    def attenuation(self, time):
        """Factor on the DNI at simulated `time` [s]: 1 clear, the darkest cloud otherwise."""
        factor = 1.0
        for cloud in self.intervals:
            if cloud.start > time:
                break
            if time < cloud.end:
                factor = min(factor, cloud.attenuation)
        return factor


class Sun:
    """Where the sun is and how strong, seen from the robot and the panel."""

    def __init__(self, site, heading, dni=900.0, clouds=None, T_robot_world=None):
        """
        Place the sun for `site` (ephemeris.Site), robot `heading` [rad from north, clockwise].

        `dni` [W/m^2] is the clear-sky direct normal irradiance; `clouds` a CloudCover;
        `T_robot_world` the panel frame in the robot frame (default identity).
        """
        if not isinstance(site, Site):
            raise TypeError('site must be a helio_optics.ephemeris.Site')
        if not dni >= 0.0:
            raise ValueError(f'dni must be >= 0 W/m^2, got {dni}')
        self.site = site
        self.heading = float(heading)
        self.dni = float(dni)
        self.clouds = clouds or CloudCover()
        self.T_robot_world = np.eye(4) if T_robot_world is None else np.asarray(T_robot_world)
        self._path = SunPath(site)

    def position(self, when):
        """Return the sun elevation and compass azimuth [rad] at an aware datetime."""
        return self._path.position(when)

    def ray_robot(self, when):
        """Return the unit sun ray s0 (the way light travels) in the robot frame (Eq 2)."""
        return self.ray_robot_of(self.position(when))

    def ray_robot_of(self, position):
        """Return s0 in the robot frame for a sun `position` (from ``position``)."""
        phi0, theta0 = ray_angles_from_sun(position, self.heading)
        return direction_from_angles(phi0, theta0)

    def ray_world(self, when):
        """Return the unit sun ray s0 in the world (panel) frame."""
        return self.ray_world_of(self.position(when))

    def ray_world_of(self, position):
        """Return s0 in the world frame for a sun `position` (one ephemeris call for both)."""
        return self.T_robot_world[:3, :3].T @ self.ray_robot_of(position)

    def irradiance(self, when, time):
        """Return the DNI [W/m^2] at `when` and simulated `time` [s] (clouds); 0 at night."""
        if self.position(when).elevation <= 0.0:
            return 0.0
        return self.dni * self.clouds.attenuation(time)

    @staticmethod
    def is_up(ray):
        """Tell whether a sun ray comes down onto the horizontal panel."""
        return float(ray[2]) < -math.sin(math.radians(0.5))
