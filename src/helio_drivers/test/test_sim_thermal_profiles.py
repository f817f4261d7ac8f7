"""
The simulated world's thermal cameras by datasheet (issue 29, item 1).

Their range, radiometric error and encoding, and the flat-field correction's frozen frames.
"""

import math

from helio_drivers.sim.cameras import (centikelvin_to_celsius, FlatFieldCorrection,
                                       ThermalCamera, ThermalSettings)
from helio_drivers.sim.wood import WoodPanel
from helio_drivers.sim.world import SimSettings, SimWorld
from helio_optics.geometry import look_at
from helio_optics.thermal_cameras import thermal_camera
import numpy as np
import pytest


def test_a_profile_builds_the_datasheets_camera_with_an_error_within_half_its_accuracy():
    spec = thermal_camera('lepton35_high_gain')
    offsets, gains = [], []
    for seed in range(200):
        settings = ThermalSettings.from_spec(spec, seed)
        assert (settings.cap, settings.floor, settings.encoding) == (140.0, -10.0, 'mono16')
        assert settings.horizontal_fov == pytest.approx(math.radians(57.0))
        offsets.append(settings.offset_error)
        gains.append(settings.gain_error)
    assert max(map(abs, offsets)) <= 2.5 and max(map(abs, gains)) <= 0.025
    # drawn, not fixed: the errors spread over most of their range
    assert np.ptp(offsets) > 4.0 and np.ptp(gains) > 0.04
    assert ThermalSettings.from_spec(spec, 7) == ThermalSettings.from_spec(spec, 7)


def world_with(profile):
    """Return a world whose thermal camera is the datasheet's `profile`."""
    return SimWorld(SimSettings(thermal_profile=profile, seed=3))


def test_a_world_with_a_profile_publishes_the_profiles_camera_and_reads_through_its_error():
    world = world_with('lepton35_low_gain')
    truth = world.thermal_settings
    assert truth == ThermalSettings.from_spec(thermal_camera('lepton35_low_gain'), 3)
    assert world.published_cameras['thermal'].width == 160
    # a cold panel: every pixel seeing it reads ambient through the camera's error
    exact = world.thermal_temperatures(noise=False)
    ambient = world.panel.wood.ambient
    expected = ambient * (1.0 + truth.gain_error) + truth.offset_error
    assert np.median(exact) == pytest.approx(expected, abs=1e-9)


def test_a_hot_spot_saturates_at_the_high_gain_cap():
    panel = WoodPanel(extent=(-0.04, 0.06, -0.04, 0.06), centre=(0.01, 0.005))
    x, y = np.meshgrid(panel.x_centres, panel.y_centres)
    spot = 2.0 * 0.8 / (math.pi * 1.5e-3 ** 2) * np.exp(
        -2.0 * ((x - 0.01) ** 2 + (y - 0.005) ** 2) / 1.5e-3 ** 2)
    for _ in range(40):
        panel.step(0.1, spot + 900.0, 900.0)
    settings = ThermalSettings.from_spec(thermal_camera('lepton35_high_gain'), 0)
    camera = ThermalCamera(settings)
    pose = look_at([-0.03, 0.0, 0.09], [0.01, 0.005, 0.0], up=(1.0, 0.0, 0.0))
    readings = centikelvin_to_celsius(camera.image(panel, pose, np.random.default_rng(0)))
    exact = camera.temperatures(panel, pose, np.random.default_rng(0))
    assert readings.max() == pytest.approx(140.0, abs=0.005)
    # every pixel whose true field reads past the cap reads the cap, no more
    assert np.count_nonzero(readings >= 140.0 - 0.005) >= np.count_nonzero(exact >= 140.0) > 3
    assert panel.surface_temperature_at(np.array([0.01]), np.array([0.005]))[0] > 200.0


def test_flat_field_freezes_come_every_period_and_last_their_drawn_length():
    ffc = FlatFieldCorrection(period=10.0, shortest=0.3, longest=1.0, seed=4)
    times = np.arange(0.0, 100.0, 0.01)
    frozen = np.array([ffc.frozen(t) for t in times])
    starts = times[1:][frozen[1:] & ~frozen[:-1]]
    ends = times[1:][~frozen[1:] & frozen[:-1]]
    assert starts == pytest.approx(np.arange(10.0, 100.0, 10.0), abs=0.011)
    lengths = ends - starts[:len(ends)]
    assert np.all((lengths >= 0.3 - 0.011) & (lengths <= 1.0 + 0.011))
    assert np.ptp(lengths) > 0.2              # drawn, not all alike
    assert not any(FlatFieldCorrection(0.0, 0.3, 1.0).frozen(t) for t in times)
    for bad in ((-1.0, 0.3, 1.0), (10.0, 1.0, 0.3), (0.5, 0.3, 1.0)):
        with pytest.raises(ValueError):
            FlatFieldCorrection(*bad)


def test_a_frozen_world_camera_repeats_its_frame_bit_for_bit_and_a_live_one_never_does():
    settings = SimSettings(seed=1)
    world = SimWorld(settings)
    world.flat_field = FlatFieldCorrection(period=1.0, shortest=0.35, longest=0.35)
    frames = []
    while world.time < 3.0:
        world.step()
        frames.append((world.time, world.thermal_image().copy()))
    repeats = [t for (_, a), (t, b) in zip(frames, frames[1:]) if np.array_equal(a, b)]
    assert repeats and all((t % 1.0) < 0.35 + 1e-9 for t in repeats)
    assert all(t >= 1.0 for t in repeats)


def test_a_live_world_camera_never_repeats_a_frame_even_when_its_noise_crop_does():
    world = SimWorld(SimSettings(seed=2))
    world.thermal._noise.PAD = 0     # 4 noise crops: a still scene repeats a crop at once
    frames = [world.thermal_image().copy() for _ in range(60)]
    assert not any(np.array_equal(a, b) for a, b in zip(frames, frames[1:]))
