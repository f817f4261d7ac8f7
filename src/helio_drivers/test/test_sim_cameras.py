"""Simulated cameras: thermal read-out at pixel centres, RGB geometry against the pinhole model."""

from dataclasses import replace
import math

import cv2
from helio_drivers.sim_cameras import (celsius_to_centikelvin, centikelvin_to_celsius,
                                       RgbCamera, RgbSettings, ThermalCamera, ThermalSettings)
from helio_drivers.sim_wood import WoodPanel
from helio_optics.geometry import (intersect_plane, invert_transform, look_at,
                                   transform_points, transform_vectors)
import numpy as np
import pytest


def heated_panel():
    """Return a panel with a hot spot above the thermal camera's cap at (0.01, 0.005)."""
    panel = WoodPanel(extent=(-0.04, 0.06, -0.04, 0.06), centre=(0.01, 0.005))
    x, y = np.meshgrid(panel.x_centres, panel.y_centres)
    r2 = (x - 0.01) ** 2 + (y - 0.005) ** 2
    spot = 2.0 * 0.8 / (math.pi * 1.5e-3 ** 2) * np.exp(-2.0 * r2 / 1.5e-3 ** 2)
    for _ in range(40):
        panel.step(0.1, spot + 900.0, 900.0)
    return panel


def test_thermal_image_is_the_surface_field_at_pixel_centres_capped():
    panel = heated_panel()
    settings = ThermalSettings(noise_sigma=0.0)
    camera = ThermalCamera(settings)
    T_world_camera = look_at([-0.03, 0.0, 0.09], [0.01, 0.005, 0.0], up=(1.0, 0.0, 0.0))
    read_out = camera.temperatures(panel, T_world_camera)
    # Independent ray cast of every pixel centre.
    u, v = np.meshgrid(np.arange(settings.width), np.arange(settings.height))
    rays = camera.camera.pixel_rays(np.stack([u.ravel(), v.ravel()], axis=-1))
    origins = np.repeat(T_world_camera[:3, 3][None], len(rays), axis=0)
    points, _ = intersect_plane(origins, transform_vectors(T_world_camera, rays),
                                [0.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    field = panel.surface_temperature_at(points[:, 0], points[:, 1])
    expected = np.minimum(field, settings.cap).reshape(read_out.shape)
    assert read_out == pytest.approx(expected, abs=1e-9)
    assert read_out.max() == settings.cap and field.max() > settings.cap + 50.0
    assert 0 < np.count_nonzero(read_out >= settings.cap) < 200
    counts = camera.image(panel, T_world_camera)
    assert counts.dtype == np.uint16 and counts.shape == (120, 160)
    assert centikelvin_to_celsius(counts).max() == pytest.approx(settings.cap, abs=0.005)


def test_thermal_noise_has_the_asked_sigma_and_centikelvin_round_trips():
    panel = WoodPanel(extent=(-0.04, 0.06, -0.04, 0.06))
    camera = ThermalCamera(ThermalSettings(noise_sigma=0.2))
    pose = look_at([0.0, 0.0, 0.1], [0.0, 0.0, 0.0], up=(1.0, 0.0, 0.0))
    noisy = camera.temperatures(panel, pose, np.random.default_rng(3))
    assert np.std(noisy) == pytest.approx(0.2, rel=0.05)
    values = np.array([-10.0, 25.0, 180.9])
    assert centikelvin_to_celsius(celsius_to_centikelvin(values)) == pytest.approx(values,
                                                                                   abs=0.005)


def test_rgb_world_points_land_within_half_a_pixel_of_the_pinhole_projection():
    settings = RgbSettings(noise_sigma=0.0, blur_sigma=0.5, supersample=2)
    camera = RgbCamera((-0.04, 0.06, -0.04, 0.06), 2e-4, settings)
    T_world_camera = look_at([0.02, -0.07, 0.11], [0.0, 0.0, 0.0])
    image = camera.render(T_world_camera)
    gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    parameters = cv2.aruco.DetectorParameters()
    parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    detector = cv2.aruco.ArucoDetector(
        cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), parameters)
    corners, ids, _ = detector.detectMarkers(gray)
    assert ids is not None and list(ids.ravel()) == [0]
    half = 0.02
    world = np.array([[-half, half, 0.0], [half, half, 0.0], [half, -half, 0.0],
                      [-half, -half, 0.0]])
    expected = camera.camera.project(transform_points(invert_transform(T_world_camera), world))
    error = np.linalg.norm(corners[0][0] - expected, axis=1)
    print('marker corner error [px]:', np.round(error, 3))
    assert np.all(error < 0.5)


def test_char_darkens_the_rendered_wood_and_the_light_window_brightens_it():
    settings = RgbSettings(noise_sigma=0.0, blur_sigma=0.0)
    camera = RgbCamera((-0.04, 0.06, -0.04, 0.06), 2e-4, settings, marker_side=0.0)
    pose = look_at([0.03, 0.03, 0.10], [0.03, 0.03, 0.0], up=(0.0, 1.0, 0.0))
    centre = tuple(int(v) for v in np.round(camera.camera.project(
        transform_points(invert_transform(pose), [[0.03, 0.03, 0.0]]))[0]))
    bare = camera.render(pose)[centre[1], centre[0]].astype(float)
    char = np.zeros((500, 500))
    char[340:360, 340:360] = 1.0   # raster rows from y_min: (0.03, 0.03) is pixel (350, 350)
    camera.update_char(char, (340, 360, 340, 360))
    charred = camera.render(pose)[centre[1], centre[0]].astype(float)
    assert np.all(charred < 0.3 * bare)
    relative = np.full((20, 20), 10.0, np.float32)
    lit = camera.render(pose, (slice(340, 360), slice(340, 360), relative))
    assert np.all(lit[centre[1], centre[0]] > 2.0 * charred)
    again = camera.render(pose)
    assert np.array_equal(again[centre[1], centre[0]], charred.astype(np.uint8))
    assert replace(settings, width=320).camera().width == 320
