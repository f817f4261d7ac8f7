"""
The sun sweep under suns from 31 to 75 deg elevation and from three azimuths (Sec. V-B).

For each sun the simulated world starts at another site, time and robot heading (its hidden
truth); every node runs as its own process, as in ``test_lens_planner.py``. The lens planner
calibrates robot-world, sweeps, and its estimate is compared with the world's true sun ray
(``sim/truth/sun_direction``) at the middle of the sweep. The controller's site file stays
Lausanne: the estimate must come from the spots, not from the ephemeris.

Issue 12 asks for 25 deg. At 26.5 deg (same site, 08:10) the lens is tilted 64 deg to face
the sun and the acquisition finds no usable view at any of its 12 azimuth guesses: the
refusals are mostly "marker partly visible or out of view" and "spot cut by the image
border" (the coma of the tilted lens reaches the border), some "no spot" and a few "not
elliptical"; relaxing the shape gates (min_fill 0.6, min_solidity 0.75) changes nothing.
The sweep fails there, saying so. 31 deg is the lowest sun tested.
"""

import math

from conftest import graph_of_processes
from helio_msgs.action import CalibrateWorld, SweepSun
from helio_optics.node_kit.conversions import point_to_array, stamp_to_seconds
import pytest
from test_lens_planner import angle_deg, NODES, Planner, site_elsewhere_file

# (name, world latitude [deg], longitude [deg], start time, robot heading [deg]): the
# elevation and the azimuth from the robot's x axis the world's ephemeris gives then
SUNS = [
    ('low_east', 48.137, 11.575, '2026-06-21T08:40:00+02:00', 200.0),      # ~31 deg up
    ('mid_west', 48.137, 11.575, '2026-06-21T16:30:00+02:00', 20.0),       # ~44 deg up
    ('high_southeast', 30.0, 0.0, '2026-06-21T11:00:00+00:00', 290.0),     # ~75 deg up
]


@pytest.fixture(scope='module', params=SUNS, ids=[sun[0] for sun in SUNS])
def planner_under(request, tmp_path_factory):
    """Run a graph whose world has one of the suns; yield its Planner."""
    _, latitude, longitude, start, heading = request.param
    tmp_path = tmp_path_factory.mktemp(request.param[0])
    # free: in lockstep with every consumer of the world (issue 31)
    world = {'real_time_factor': 0.0, 'flux_rays': 20000, 'latitude_deg': latitude,
             'longitude_deg': longitude, 'start_time': start, 'robot_heading_deg': heading}
    site = {'site_file': site_elsewhere_file(tmp_path)}      # the controller: Lausanne
    overrides = {'sim_world': world, 'sun_estimator': site,
                 'lens_planner': {**site, 'calibration_dir': str(tmp_path / 'calibration')}}
    with graph_of_processes(tmp_path, NODES, overrides) as (_, graph):
        yield Planner(graph)


def test_the_sweep_finds_the_true_sun(planner_under):
    planner = planner_under
    truth_sun = planner.truth_sun
    calibration = planner.run(CalibrateWorld, 'calibrate_world', CalibrateWorld.Goal(apply=True))
    assert calibration.result.success, calibration.result.message
    began = stamp_to_seconds(planner.next_truth(truth_sun).header.stamp)
    result = planner.run(SweepSun, 'sweep_sun', SweepSun.Goal()).result
    assert result.success, result.message
    ended = stamp_to_seconds(planner.next_truth(truth_sun).header.stamp)
    truth = planner.truth_at(truth_sun, 0.5 * (began + ended))
    true_ray = point_to_array(truth.vector)
    # the ray points from the sun to the ground: the sun stands -ray above the robot's plane
    elevation = math.degrees(math.asin(-true_ray[2] / math.hypot(*true_ray)))
    error = angle_deg(point_to_array(result.estimate.direction), true_ray)
    print(f'\nsun {elevation:.1f} deg up: {result.message}\nagainst the world: {error:.3f} deg')
    assert 30.0 <= elevation <= 76.0
    assert error < 0.3
