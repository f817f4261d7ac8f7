"""
A low sun the rig's camera cannot see is refused with the reason (Sec. V-B, issue 12).

26 deg up and along the robot's x axis (the world's robot heading 83.3 deg at 08:10 in
Munich): the lens tilts 64 deg to face it, and every pose within the lens yaw servo's +-90
deg puts the RGB camera below the lens, at the panel's height (the figures from the rig model
are in ``src/helio_control/test/test_sun_sweep.py``). The sweep must fail and say so, not
report a sun. Its own module: a graph per module, as ``test_sweep_over_suns.py``'s fixture
keeps its last graph until that module ends (two worlds on one /clock would mix).
"""

import math

from conftest import graph_of_processes
from helio_msgs.action import CalibrateWorld, SweepSun
from helio_optics.node_kit.conversions import point_to_array
from test_lens_planner import NODES, Planner, site_elsewhere_file


def test_a_low_sun_the_camera_cannot_see_fails_saying_why(tmp_path):
    world = {'real_time_factor': 4.0, 'flux_rays': 20000, 'latitude_deg': 48.137,
             'longitude_deg': 11.575, 'start_time': '2026-06-21T08:10:00+02:00',
             'robot_heading_deg': 83.3}
    site = {'site_file': site_elsewhere_file(tmp_path)}      # the controller: Lausanne
    overrides = {'sim_world': world, 'sun_estimator': site,
                 'lens_planner': {**site, 'calibration_dir': str(tmp_path / 'calibration')}}
    with graph_of_processes(tmp_path, NODES, overrides) as (_, graph):
        planner = Planner(graph)
        truth = point_to_array(planner.next_truth(planner.truth_sun).vector)
        azimuth = math.degrees(math.atan2(-truth[1], -truth[0]))
        assert abs(azimuth) < 5.0 and 25.0 < math.degrees(math.asin(-truth[2])) < 27.0
        calibration = planner.run(CalibrateWorld, 'calibrate_world',
                                  CalibrateWorld.Goal(apply=True))
        assert calibration.result.success, calibration.result.message
        result = planner.run(SweepSun, 'sweep_sun', SweepSun.Goal()).result
        print(f'\n{result.message}')
        assert not result.success
        assert ('cannot be seen at this elevation' in result.message
                or 'lens yaw servo cannot turn it' in result.message)
