"""Simulated cameras: thermal read-out at pixel centres, RGB geometry against the pinhole model."""

from dataclasses import replace
import math

import cv2
from helio_drivers.sim.cameras import (celsius_to_centikelvin, centikelvin_to_celsius,
                                       NoisyReadOut, RgbCamera, RgbSettings, ThermalCamera,
                                       ThermalSettings)
from helio_drivers.sim.kernels import _count_below, bin_on_raster
from helio_drivers.sim.wood import WoodPanel
from helio_optics.geometry import (intersect_plane, invert_transform, look_at,
                                   transform_points, transform_vectors)
from helio_optics.ground_render import linear_to_srgb
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


def test_thermal_frames_kept_between_steps_and_re_centres_equal_a_fresh_cast():
    panel = heated_panel()
    settings = ThermalSettings(noise_sigma=0.0)
    kept = ThermalCamera(settings)
    T_world_camera = look_at([-0.03, 0.0, 0.09], [0.01, 0.005, 0.0], up=(1.0, 0.0, 0.0))
    kept.temperatures(panel, T_world_camera)
    spot = np.zeros(panel.cell_areas.shape)
    for _ in range(5):
        panel.step(0.1, spot + 900.0, 900.0)     # the field changes under a kept view
        fresh = ThermalCamera(settings).temperatures(panel, T_world_camera)
        assert np.array_equal(kept.temperatures(panel, T_world_camera), fresh)
    assert panel.follow((0.03, 0.01))            # the patch moves: the view is redone
    fresh = ThermalCamera(settings).temperatures(panel, T_world_camera)
    assert np.array_equal(kept.temperatures(panel, T_world_camera), fresh)
    moved = look_at([-0.02, 0.01, 0.09], [0.01, 0.005, 0.0], up=(1.0, 0.0, 0.0))
    fresh = ThermalCamera(settings).temperatures(panel, moved)
    assert np.array_equal(kept.temperatures(panel, moved), fresh)


@pytest.mark.parametrize('sigma', [0.0, 0.2])
def test_thermal_image_in_one_pass_equals_the_temperatures_encoded(sigma):
    # the compiled read-out against temperatures() then celsius_to_centikelvin, the same
    # noise drawn for both; a view half off the patch (far field) and above its cap
    panel = heated_panel()
    camera = ThermalCamera(ThermalSettings(noise_sigma=sigma))
    for pose in (look_at([-0.03, 0.0, 0.09], [0.01, 0.005, 0.0], up=(1.0, 0.0, 0.0)),
                 look_at([0.02, 0.05, 0.05], [0.06, 0.04, 0.0], up=(1.0, 0.0, 0.0))):
        # a new view (ground points searched per pixel), then the kept one (its sampler)
        counts = camera.image(panel, pose, np.random.default_rng(8))
        kept = camera.image(panel, pose, np.random.default_rng(8))
        expected = celsius_to_centikelvin(camera.temperatures(panel, pose,
                                                              np.random.default_rng(8)))
        assert np.array_equal(counts, expected) and np.array_equal(kept, expected)
    assert centikelvin_to_celsius(counts.min()) < 30.0


def test_the_walked_search_counts_what_numpys_searchsorted_counts_from_any_hint():
    # the patch's centres: fine cells in the middle, growing outwards (uneven spacing)
    centres = np.cumsum(np.concatenate([np.geomspace(2e-3, 1e-4, 30), np.full(40, 1e-4),
                                        np.geomspace(1e-4, 2e-3, 30)])) - 0.02
    rng = np.random.default_rng(3)
    values = np.concatenate([rng.uniform(-0.03, 0.03, 2000), centres, centres[::7] + 1e-12,
                             [-1.0, 1.0]])
    for value in values:
        expected = int(np.searchsorted(centres, value))
        for hint in (expected, expected - 1, expected + 2, 0, len(centres),
                     int(rng.integers(-5, len(centres) + 5))):
            assert _count_below(centres, value, hint) == expected, (value, hint)


def test_thermal_noise_differs_frame_to_frame():
    panel = WoodPanel(extent=(-0.04, 0.06, -0.04, 0.06))
    camera = ThermalCamera(ThermalSettings(noise_sigma=0.2))
    pose = look_at([0.0, 0.0, 0.1], [0.0, 0.0, 0.0], up=(1.0, 0.0, 0.0))
    rng = np.random.default_rng(5)
    frames = [camera.temperatures(panel, pose, rng) for _ in range(4)]
    differences = [np.std(a - b) for a, b in zip(frames, frames[1:])]
    # independent noise: the difference of two frames has sqrt(2) sigma
    assert differences == pytest.approx([0.2 * math.sqrt(2.0)] * 3, rel=0.05)


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
    # a linear tone curve: OpenCV's sub-pixel corners assume one (on sRGB frames they move
    # 0.6 px towards the dark side, which is what perception undoes)
    settings = RgbSettings(read_noise=0.0, full_well_electrons=0.0, blur_sigma=0.5,
                           supersample=2, tone_curve='linear')
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


def noise_free(**changes):
    """Return RgbSettings without sensor noise (and with `changes`)."""
    return replace(RgbSettings(), read_noise=0.0, full_well_electrons=0.0, **changes)


def test_char_darkens_the_rendered_wood_and_the_light_window_brightens_it():
    settings = noise_free(blur_sigma=0.0)
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
    lit = np.full((20, 20), 10.0, np.float32)
    brighter = camera.render(pose, (slice(340, 360), slice(340, 360), lit))
    assert np.all(brighter[centre[1], centre[0]] > 2.0 * charred)
    again = camera.render(pose)
    assert np.array_equal(again[centre[1], centre[0]], charred.astype(np.uint8))
    assert replace(settings, width=320).camera().width == 320


def test_the_light_is_albedo_times_sky_plus_direct_sun_and_a_cloud_leaves_the_sky():
    """
    Linear light = exposure x albedo x (sky + attenuation x direct) / (1 + sky), then sRGB.

    Issue 16's finding: a complete cloud made the frame black (the sky light was scaled
    with the direct sun); the sky must stay.
    """
    settings = noise_free(blur_sigma=0.0, vignetting=0.0, adc_bits=16)
    camera = RgbCamera((-0.04, 0.06, -0.04, 0.06), 2e-4, settings, marker_side=0.0)
    pose = look_at([0.01, 0.01, 0.12], [0.01, 0.01, 0.0], up=(0.0, 1.0, 0.0))
    centre = np.round(camera.camera.project(transform_points(
        invert_transform(pose), [[0.01, 0.01, 0.0]]))[0]).astype(int)
    albedo = camera._albedo.image[int(round((0.06 - 0.01) / 2e-4 - 0.5)),
                                  int(round((0.01 + 0.04) / 2e-4 - 0.5)), :3]
    sky = settings.diffuse_fraction
    for attenuation in (1.0, 0.3, 0.0):
        pixel = camera.render(pose, attenuation=attenuation)[centre[1], centre[0]]
        light = settings.exposure * albedo * (sky + attenuation) / (1 + sky)
        expected = 255 * linear_to_srgb(light)
        assert np.all(np.abs(pixel - expected) <= 1.5), (attenuation, pixel, expected)
    clear = camera.render(pose, attenuation=1.0).astype(float).mean()
    overcast = camera.render(pose, attenuation=0.0).astype(float).mean()
    assert overcast > 0.3 * clear   # sky light only: 11 % of the light, 36 % in sRGB levels
    # in the lens shadow (lit 0) only the sky is left
    shade = np.zeros((10, 10), np.float32)
    shaded = camera.render(pose, (slice(245, 255), slice(245, 255), shade), 1.0)
    expected = 255 * linear_to_srgb(settings.exposure * albedo * sky / (1 + sky))
    assert np.all(np.abs(shaded[centre[1], centre[0]] - expected) <= 1.5)


def test_a_marker_under_a_complete_cloud_is_still_found_by_aruco():
    camera = RgbCamera((-0.04, 0.06, -0.04, 0.06), 2e-4)
    T_world_camera = look_at([0.02, -0.07, 0.11], [0.0, 0.0, 0.0])
    for attenuation in (1.0, 0.0):
        gray = cv2.cvtColor(camera.render(T_world_camera, attenuation=attenuation,
                                          rng=np.random.default_rng(1)), cv2.COLOR_RGB2GRAY)
        detector = cv2.aruco.ArucoDetector(
            cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50),
            cv2.aruco.DetectorParameters())
        _, ids, _ = detector.detectMarkers(gray)
        assert ids is not None and list(ids.ravel()) == [0], attenuation


@pytest.mark.parametrize('supersample', [1, 2])
def test_kept_and_partly_redone_frames_equal_a_fresh_render(supersample):
    """The frame light kept between frames, char regions and the window: all exact."""
    extent = (-0.04, 0.06, -0.04, 0.06)
    settings = noise_free(blur_sigma=0.9, vignetting=0.2, supersample=supersample, width=320,
                          height=240)
    kept = RgbCamera(extent, 2e-4, settings)
    poses = [look_at([0.03, -0.04, 0.12], [0.02, 0.02, 0.0]),
             look_at([0.031, -0.04, 0.12], [0.02, 0.02, 0.0])]
    rows, cols = slice(280, 330), slice(290, 340)   # around (0.02, 0.02)
    lit = np.ones((50, 50), np.float32)
    lit[10:40, 10:40] = 0.0          # a shadow
    lit[24:27, 24:27] = 300.0        # and a focus
    char = np.zeros((500, 500))
    light = (rows, cols, lit)   # one window object: the world keeps it until a re-trace
    steps = [(poses[0], None, None, 1.0), (poses[0], light, None, 1.0),
             (poses[0], light, (300, 306, 310, 318), 1.0),    # char inside the window
             (poses[0], light, (300, 304, 300, 303), 1.0),
             (poses[0], light, (260, 262, 200, 230), 0.4),    # outside it, and a cloud
             (poses[1], light, (300, 310, 300, 318), 0.4),    # a move
             (poses[1], (rows, cols, lit * 0.5), None, 0.4),  # a new window
             (poses[1], None, None, 0.0)]
    for pose, light, box, attenuation in steps:
        if box is not None:
            r0, r1, c0, c1 = box
            char[r0:r1, c0:c1] = np.clip(char[r0:r1, c0:c1] + 0.6, 0, 1)
            kept.update_char(char, box)
        fresh = RgbCamera(extent, 2e-4, settings)
        fresh.update_char(char, (0, 500, 0, 500))
        frame = kept.render(pose, light, attenuation)
        expected = fresh.render(pose, light, attenuation)
        assert np.max(np.abs(frame.astype(int) - expected.astype(int))) <= 1
        assert np.mean(frame != expected) < 1e-3
    # the whole frame only at the start, on a cloud and after the move; the window's
    # changes and the char over their image regions alone
    assert kept.renders['whole'] == 4 and kept.renders['parts'] == 4
    assert kept.renders['light'] == 3
    # an unchanged scene is not rendered again: the sensor stage alone
    before = dict(kept.renders)
    kept.render(poses[1], None, 0.0)
    assert kept.renders == {**before, 'frames': before['frames'] + 1}


def test_linearised_read_out_has_the_exact_read_outs_mean_and_noise_per_level():
    # a ramp of light from black to 1.3 x full scale along the columns, all channels
    settings = RgbSettings(width=320, height=128)
    camera = RgbCamera((-0.04, 0.06, -0.04, 0.06), 2e-4, settings)
    webcam = camera._webcam
    read_out = NoisyReadOut(webcam, (settings.height, settings.width, 3), seed=3)
    light = np.repeat(np.linspace(0.0, 1.3, settings.width, dtype=np.float32)[None, :, None],
                      settings.height, axis=0).repeat(3, axis=2)
    exact_prepared, fast_prepared = webcam.prepare(light), read_out.prepare(light)
    rng = np.random.default_rng(4)
    exact = np.stack([webcam.expose(exact_prepared, rng) for _ in range(16)]).astype(float)
    fast = np.stack([read_out.expose(fast_prepared, rng) for _ in range(16)]).astype(float)
    # per column (one light level): 16 frames x 128 rows x 3 channels
    exact_mean, fast_mean = exact.mean(axis=(0, 1, 3)), fast.mean(axis=(0, 1, 3))
    exact_std, fast_std = exact.std(axis=(0, 1, 3)), fast.std(axis=(0, 1, 3))
    levels = np.linspace(0.0, 1.3, settings.width)
    # 8-bit levels; near black (under 1 % of full scale, where the sRGB curve bends most)
    # and just above full scale (the exact read-out dips below 255) up to half a level
    ordinary = (levels > 0.01) & ((levels < 0.995) | (levels > 1.02))
    assert np.abs(fast_mean - exact_mean)[ordinary].max() < 0.35
    assert np.abs(fast_mean - exact_mean).max() < 0.6
    noisy = (exact_std > 0.8) & ordinary
    assert noisy.sum() > 200
    assert np.abs(fast_std[noisy] / exact_std[noisy] - 1.0).max() < 0.08
    saturated = levels > 1.05
    assert np.all(fast[:, :, saturated] == 255) and np.all(exact[:, :, saturated] == 255)
    # no two frames alike
    assert np.abs(fast[0] - fast[1]).mean() > 0.5


def test_compiled_table_read_out_equals_the_numpy_and_opencv_passes_it_replaced():
    # the tables indexed by light x a per-pixel scale (the vignetting), written as numpy
    # passes: product, clip, + 0.5, cast; the frame as OpenCV's multiply and add of
    # level[index] and gain[index] x noise; light from below 0 to far above full scale
    settings = RgbSettings(width=96, height=64)
    camera = RgbCamera((-0.04, 0.06, -0.04, 0.06), 2e-4, settings)
    read_out = NoisyReadOut(camera._webcam, (settings.height, settings.width, 3), seed=3)
    rng = np.random.default_rng(5)
    light = rng.uniform(-0.1, 1.5, (settings.height, settings.width, 3)).astype(np.float32)
    light[0, 0] = np.nan
    scale = (rng.uniform(0.8, 1.0, light.shape[:2]) * read_out.index_scale()).astype(np.float32)
    for per_pixel in (scale, None):
        index = (np.multiply(light, per_pixel[:, :, None], dtype=np.float32)
                 if per_pixel is not None
                 else light * np.float32(read_out.index_scale()))
        index = np.nan_to_num(index, nan=0.0)
        np.clip(index, 0.0, float(read_out._last), out=index)
        index = (index + np.float32(0.5)).astype(np.intp)
        prepared = read_out.prepare(light, per_pixel)
        assert np.array_equal(prepared[0], read_out._level[index])
        assert np.array_equal(prepared[1], read_out._gain[index])
        # the same noise offset drawn for both (a generator of the same seed)
        frame = read_out.expose(prepared, np.random.default_rng(9))
        k, offset = (int(v) for v in np.random.default_rng(9).integers(
            0, (read_out.FRAMES, read_out._slack + 1)))
        noise = read_out._bank[k, offset:offset + light.size].reshape(light.shape)
        product = cv2.multiply(noise, read_out._gain[index], dtype=cv2.CV_32F)
        assert np.array_equal(frame, cv2.add(read_out._level[index], product,
                                             dtype=cv2.CV_8U))
    part = light[5:30, 7:50]    # a part of a frame (not contiguous)
    level, _ = read_out.prepare(part, scale[5:30, 7:50])
    assert np.array_equal(level, read_out.prepare(part.copy(), scale[5:30, 7:50].copy())[0])
    # a warp's padding channel after the colours is not read
    padded = np.concatenate([light, np.full(light.shape[:2] + (1,), np.nan, np.float32)],
                            axis=2)
    for got, expected in zip(read_out.prepare(padded[3:40], scale[3:40]),
                             read_out.prepare(light[3:40], scale[3:40])):
        assert np.array_equal(got, expected)
    with pytest.raises(ValueError, match='light must be'):
        read_out.prepare(light[:, :, :2])
    # written in place into a kept stage's parts, whole rows or not
    for rows, cols in ((slice(5, 30), slice(None)), (slice(5, 30), slice(7, 50))):
        kept = (np.zeros(light.shape, np.float32), np.zeros(light.shape, np.float32))
        views = (kept[0][rows, cols], kept[1][rows, cols])
        filled = read_out.prepare(light[rows, cols], scale[rows, cols], out=views)
        expected = read_out.prepare(light[rows, cols].copy(), scale[rows, cols].copy())
        assert filled is views
        assert np.array_equal(kept[0][rows, cols], expected[0])
        assert np.array_equal(kept[1][rows, cols], expected[1])
        assert not np.any(kept[0][:5]) and not np.any(kept[1][30:])


def test_rays_binned_on_the_raster_window_equal_numpys_histogram():
    rng = np.random.default_rng(12)
    points = rng.normal(0.07, 0.004, (20000, 2))
    points[:3] = np.nan
    power = rng.random(20000)
    origin, pixel, r0, c0, shape = (-0.04, -0.04), 2e-4, 520, 530, (60, 70)
    binned = np.zeros(shape)
    bin_on_raster(points, power, origin[0], origin[1], pixel, c0, r0, binned)
    x_edges = origin[0] + (c0 + np.arange(shape[1] + 1)) * pixel
    y_edges = origin[1] + (r0 + np.arange(shape[0] + 1)) * pixel
    keep = np.all(np.isfinite(points), axis=1)
    expected, _, _ = np.histogram2d(points[keep, 1], points[keep, 0], bins=(y_edges, x_edges),
                                    weights=power[keep])
    assert binned.sum() > 0.1 * power.sum()
    assert np.allclose(binned, expected, rtol=1e-12, atol=1e-12)


def test_ground_light_by_homography_equals_casting_every_pixel_ray():
    camera = RgbCamera((-0.04, 0.06, -0.04, 0.06), 2e-4, noise_free())
    texture = camera._albedo
    for pose in (look_at([0.02, -0.07, 0.11], [0.0, 0.0, 0.0]),
                 look_at([0.05, 0.03, 0.09], [0.03, 0.02, 0.0], up=(0.0, 1.0, 0.0))):
        warped = camera._radiance(pose, texture)
        cast = camera._renderer.radiance(pose, texture, background=0.0)[:, :, :3]
        difference = np.abs(warped - cast)
        # both sample bilinearly at their float coordinates, which round differently
        assert difference.mean() < 2e-3 and difference.max() < 0.05
        part = camera._radiance(pose, texture, rect=(100, 50, 300, 200))
        assert np.abs(part - warped[50:200, 100:300]).max() < 0.05
    # a camera that sees the horizon: nothing above it, the ground below it as cast
    pose = look_at([0.0, -0.15, 0.03], [0.0, 0.3, 0.0])
    assert camera._texture_homography(pose, texture)[1] is not None
    warped = camera._radiance(pose, texture)
    cast = camera._renderer.radiance(pose, texture, background=0.0)[:, :, :3]
    assert np.all(warped[:5] == 0.0) and np.abs(warped - cast).mean() < 2e-3
    rolled = look_at([0.0, -0.15, 0.03], [0.0, 0.3, 0.0], up=(0.4, 0.0, 1.0))
    warped = camera._radiance(rolled, texture)
    cast = camera._renderer.radiance(rolled, texture, background=0.0)[:, :, :3]
    assert np.all(warped[0, :5] == 0.0) and np.abs(warped - cast).mean() < 2e-3
