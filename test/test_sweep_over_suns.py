"""
The sun sweep under suns from 25 to 75 deg elevation and from four azimuths (Sec. V-B).

For each sun the simulated world starts at another site, time and robot heading (its hidden
truth); every node runs as its own process, as in ``test_lens_planner.py``. The lens planner
calibrates robot-world, sweeps, and its estimate is compared with the world's true sun ray
(``sim/truth/sun_direction``) at the middle of the sweep. The controller's site file stays
Lausanne: the estimate must come from the spots, not from the ephemeris (at 08:10 in Munich
the controller's ephemeris puts the sun 3.6 deg lower than the world's).

Measured over seven runs (2 shared cores, load 2-10): 0.08-0.23 deg off at 26.3 deg up (08:10,
the sun 117 deg from the robot's x axis), 0.10-0.18 deg at 25.4 deg (18:24, 226 deg),
0.09-0.19 deg at 31 deg, 0.02-0.07 deg at 44 deg and 0.01-0.08 deg at 75 deg.

Before the sweep saw low suns, at 26 deg the acquisition found no spot at any of its 12
azimuth guesses. The cause, measured with SimWorld and SpotObserver offline and in this
graph: the lens tilts 64 deg to face the sun, and the wrist solution within the yaw servo's
+-90 deg often lowers the RGB camera to the panel's height (1.3 cm up, its sight line 88-90
deg off the panel normal). The acquisition took such poses because, the marker not being
needed once robot-world is calibrated, only the spot centre's projection was checked: the
panel was a sliver a few pixels high, the spot beside the dark beyond it (occluded, not
convex, not elliptical). Poses must now see the spot within 65 deg of the normal, and the
acquisition takes the squarest view; from the guess 27 deg off the sun the spot is found
(model centre 2 mm off, a coarse sun 0.9 deg off) and the sweep does the rest. Under load
two more things cost observations: frames measured while the arm moved entered the estimate
(now the planner names its frames by stamp), and the spot detector lacked joints at most
frames, so no kinematic camera pose (now it waits for the next joint state).

Low suns are not seen from every azimuth: from 285 to 60 deg off the robot's x axis a sun 25
deg up leaves the camera below the lens at every reachable pose (``test_sun_sweep.py``, the
lens planner's README); ``test_sweep_refuses_unseen_sun.py`` checks the sweep says so.
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
    ('lowest_east', 48.137, 11.575, '2026-06-21T08:10:00+02:00', 200.0),    # ~26 deg up
    ('low_east', 48.137, 11.575, '2026-06-21T08:40:00+02:00', 200.0),      # ~31 deg up
    ('mid_west', 48.137, 11.575, '2026-06-21T16:30:00+02:00', 20.0),       # ~44 deg up
    ('high_southeast', 30.0, 0.0, '2026-06-21T11:00:00+00:00', 290.0),     # ~75 deg up
    ('lowest_west', 48.137, 11.575, '2026-06-21T18:24:00+02:00', 142.5),   # ~25 deg up
]


@pytest.fixture(scope='module', params=SUNS, ids=[sun[0] for sun in SUNS])
def planner_under(request, tmp_path_factory):
    """Run a graph whose world has one of the suns; yield its Planner."""
    _, latitude, longitude, start, heading = request.param
    tmp_path = tmp_path_factory.mktemp(request.param[0])
    world = {'real_time_factor': 4.0, 'flux_rays': 20000, 'latitude_deg': latitude,
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
    assert 25.0 <= elevation <= 76.0
    assert error < 0.3
