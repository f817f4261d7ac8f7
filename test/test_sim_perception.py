"""helio_perception reads the simulated cameras as the physics put things there."""

from helio_drivers.sim.truth import true_sun_focus_joints
from helio_drivers.sim.world import SimSettings, SimWorld
from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters
from helio_perception.ground_plane import GroundMapping
from helio_perception.spot_detection import SpotDetector, to_gray
from helio_perception.thermal import ThermalAnalyzer
import numpy as np
import pytest


@pytest.fixture(scope='module')
def world():
    """Return one world shared by the tests of this module."""
    return SimWorld(SimSettings(flux_rays=30000), load_rig_parameters(default_rig_file()))


@pytest.mark.parametrize('target', [(0.07, 0.07), (0.05, 0.09)])
def test_spot_detector_finds_the_rendered_spot_where_the_ray_tracer_put_it(world, target):
    world.set_joints(true_sun_focus_joints(world, target, 0.082))
    world.step()
    image = world.rgb_image()
    T_world_rgb, _ = world.camera_poses()
    result = SpotDetector().detect(to_gray(image), GroundMapping(world.rgb.camera, T_world_rgb),
                                   marker_side=world.settings.marker_side)
    assert result.valid, result.reason
    traced = world.flux_field.centroid()
    error = np.linalg.norm(result.center[:2] - traced)
    print(f'spot detected {error * 1e3:.3f} mm from the traced centroid')
    assert error < 0.3e-3


def test_thermal_monitor_statistics_match_the_simulated_field(world):
    world.set_joints(true_sun_focus_joints(world, (0.08, 0.06), 0.082))
    world.run(6.0)
    image = world.thermal_image()
    stats = ThermalAnalyzer().statistics(image, '16UC1')
    field = world.thermal_temperatures(noise=False)
    cap = world.settings.thermal.cap
    assert stats.saturated and stats.t_max == pytest.approx(cap, abs=0.01)
    # the read-out noise (0.05 K) may move a pixel right at the cap across it
    assert abs(stats.n_p - np.count_nonzero(field >= cap - 1e-9)) <= 2
    assert stats.n_p > 0
