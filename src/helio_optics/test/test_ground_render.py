"""Tests of the ground-plane renderer against PinholeCamera.project and cv2.aruco."""

import cv2
from helio_optics.geometry import (
    invert_transform, look_at, PinholeCamera, transform_points)
from helio_optics.ground_render import (
    aruco_dictionary, decode_srgb8, GroundEllipse, GroundRenderer, GroundTexture,
    linear_to_srgb, make_panel_texture, srgb_to_linear, Webcam, WebcamSettings)
import numpy as np
import pytest
from scipy.special import erf, erfinv

CAMERA = PinholeCamera.from_fov(320, 240, np.radians(60))
DISTORTED = PinholeCamera(matrix=CAMERA.matrix.copy(), width=320, height=240,
                          distortion=np.array([-0.12, 0.03, 0.001, -0.0015, 0.0]))


def intensity_centroid(image):
    """Return the intensity centroid (u, v) of a grey image [px]."""
    v, u = np.indices(image.shape)
    weight = image.astype(float)
    return np.array([(u * weight).sum(), (v * weight).sum()]) / weight.sum()


@pytest.mark.parametrize('camera', [CAMERA, DISTORTED], ids=['pinhole', 'distorted'])
@pytest.mark.parametrize('eye, target', [
    ((0.0, 0.0, 0.3), (0.001, 0.0, 0.0)),
    ((0.10, -0.15, 0.22), (0.02, 0.03, 0.0)),
    ((-0.12, 0.05, 0.18), (0.04, -0.02, 0.0)),
])
def test_a_world_point_lands_where_project_puts_it(camera, eye, target):
    T_world_camera = look_at(eye, target)
    point = np.array([target[0] + 0.01, target[1] - 0.008, 0.0])
    dot = GroundEllipse(center=point[:2], semi_axes=(0.0012, 0.0012), value=1.0)
    dark = GroundTexture(image=np.zeros((4, 4), np.uint8), extent=(-1.0, 1.0, -1.0, 1.0))
    image = GroundRenderer(camera, supersample=4).radiance(T_world_camera, dark, [dot])
    expected = camera.project(transform_points(invert_transform(T_world_camera), point))[0]
    # the centroid of a small disk's image is its centre's image up to perspective (tiny here)
    assert np.linalg.norm(intensity_centroid(image) - expected) < 0.5


def test_marker_corners_are_where_aruco_finds_them():
    side = 0.04
    texture = make_panel_texture(marker_side=side)
    camera = PinholeCamera.from_fov(640, 480, np.radians(60))
    T_world_camera = look_at((0.06, -0.1, 0.25), (0.0, 0.01, 0.0))
    image = GroundRenderer(camera, supersample=2).render(T_world_camera, texture)
    parameters = cv2.aruco.DetectorParameters()
    parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    detector = cv2.aruco.ArucoDetector(aruco_dictionary('DICT_4X4_50'), parameters)
    corners, ids, _ = detector.detectMarkers(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY))
    assert ids is not None and ids.ravel().tolist() == [0]
    # cv2.aruco's marker frame: corners TL, TR, BR, BL at (-s/2, s/2), (s/2, s/2), ...
    h = side / 2
    world = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]])
    expected = camera.project(transform_points(invert_transform(T_world_camera), world))
    assert np.max(np.linalg.norm(corners[0][0] - expected, axis=1)) < 0.5


def test_a_printed_marker_reflects_its_ink_and_paper_shares_in_linear_light():
    texture = make_panel_texture(marker_side=0.04, print_reflectance=(0.05, 0.85)).linearised()
    # world (x, y) -> texture pixel: the black border's middle and the quiet zone's
    black = texture.image[texture_pixel(texture, -0.019, 0.0)]
    white = texture.image[texture_pixel(texture, -0.0225, 0.0)]
    # 8-bit sRGB steps near these levels are under 1 % of the value
    assert np.allclose(black, 0.05, rtol=0.02) and np.allclose(white, 0.85, rtol=0.01)
    for bad in [(0.5, 0.4), (-0.1, 0.9), (0.05, 1.2)]:
        with pytest.raises(ValueError, match='print_reflectance'):
            make_panel_texture(print_reflectance=bad)


def texture_pixel(texture, x, y):
    """Return the (row, column) of the texture pixel holding the world point (x, y)."""
    column, row = texture.texture_coordinates(x, y)
    return int(round(row)), int(round(column))


def test_spot_area_in_pixels_matches_the_ellipse_area_seen_from_above():
    height = 0.2
    camera = PinholeCamera.from_fov(320, 240, np.radians(50))
    T_world_camera = look_at((0.0, 0.0, height), (0.0, 1e-9, 0.0))
    spot = GroundEllipse(center=(0.01, -0.005), semi_axes=(0.008, 0.005), angle=0.4, value=2.0)
    dark = GroundTexture(image=np.zeros((2, 2), np.uint8), extent=(-1.0, 1.0, -1.0, 1.0))
    image = GroundRenderer(camera, supersample=2).radiance(T_world_camera, dark, [spot])
    focal = camera.matrix[0, 0]
    expected_pixels = spot.area * (focal / height) ** 2
    assert image.sum() / 2.0 == pytest.approx(expected_pixels, rel=0.01)


def uniform_light(value, shape=(240, 320)):
    """Return a float32 image of one linear light value."""
    return np.full(shape, value, np.float32)


def test_the_srgb_tone_curve_round_trips_and_saturates():
    levels = np.arange(256) / 255.0
    np.testing.assert_allclose(linear_to_srgb(srgb_to_linear(levels)), levels, atol=1e-12)
    # IEC 61966-2-1's published points: linear 0.5 is sRGB 0.7354, 0.18 is 0.4614
    assert linear_to_srgb(0.5) == pytest.approx(0.7354, abs=1e-4)
    assert linear_to_srgb(0.18) == pytest.approx(0.4614, abs=1e-4)
    assert decode_srgb8(np.array([[0, 188, 255]], np.uint8))[0] == pytest.approx(
        [0.0, 0.5029, 1.0], abs=1e-4)
    texture = GroundTexture(image=np.full((2, 2), 100, np.uint8), extent=(-1.0, 1.0, -1.0, 1.0))
    renderer = GroundRenderer(CAMERA, supersample=1)
    pose = look_at((0.0, 0.0, 0.3), (0.001, 0.0, 0.0))
    assert np.all(np.abs(renderer.render(pose, texture).astype(int) - 100) <= 1)
    # exposure scales linear light: 2.2x the light of level 100 is level 145, not 220
    brighter = renderer.render(pose, texture, exposure=2.2)
    expected = 255 * linear_to_srgb(2.2 * srgb_to_linear(100 / 255))
    assert np.all(np.abs(brighter - expected) <= 1)
    assert np.all(renderer.render(pose, texture, exposure=8.0) == 255)  # saturation


def test_blur_happens_in_linear_light_before_the_tone_curve():
    """A blurred black-to-white step: sRGB of the Gaussian CDF, half level at 188, not 128."""
    sigma = 2.0
    light = np.zeros((40, 80), np.float32)
    light[:, 40:] = 1.0    # the step is at x = 39.5
    webcam = Webcam(WebcamSettings(blur_sigma=sigma, adc_bits=16), CAMERA)
    row = webcam.develop(light)[20].astype(float)
    x = np.arange(80) - 39.5
    expected = 255.0 * linear_to_srgb(0.5 * (1.0 + erf(x / (sigma * np.sqrt(2.0)))))
    assert np.max(np.abs(row[10:70] - expected[10:70])) <= 2.0  # sampled kernel, rounding
    # the grey-level midpoint (127.5) is where the light is 21 %: 0.79 sigma on the dark side
    crossing = np.interp(127.5, row[20:60], x[20:60])
    at_grey_midpoint = srgb_to_linear(0.5)
    assert crossing == pytest.approx(sigma * np.sqrt(2.0) * erfinv(2 * at_grey_midpoint - 1),
                                     abs=0.1)
    assert crossing < -0.75 * sigma


def test_noise_has_the_read_and_shot_variance_in_linear_light():
    settings = WebcamSettings(tone_curve='linear', read_noise=0.01, full_well_electrons=1000.0,
                              adc_bits=14)
    webcam = Webcam(settings, CAMERA)
    rng = np.random.default_rng(3)
    for light in (0.05, 0.25, 0.6):
        frame = webcam.sensor(uniform_light(light), rng).astype(float) / 255.0
        expected = np.sqrt(0.01 ** 2 + light / 1000.0)
        assert frame.mean() == pytest.approx(light, abs=0.003)
        # 8-bit rounding adds 1/12 level^2 of variance
        assert np.sqrt(frame.var() - 1.0 / 12 / 255 ** 2) == pytest.approx(expected, rel=0.05)
    # independent frames: crops of the bank at other offsets, so they differ
    first, second = (webcam.sensor(uniform_light(0.25), rng) for _ in range(2))
    assert np.mean(first != second) > 0.5


def test_vignetting_darkens_the_corners_by_the_set_fraction():
    settings = WebcamSettings(tone_curve='linear', vignetting=0.3, adc_bits=16)
    frame = Webcam(settings, CAMERA).develop(uniform_light(0.8)).astype(float)
    centre = frame[119:121, 159:161].mean()
    assert centre == pytest.approx(0.8 * 255, abs=1.0)
    assert frame[0, 0] == pytest.approx(0.7 * centre, abs=1.0)
    assert frame[0, 0] == frame.min()


def test_bayer_mosaic_and_demosaic_keep_flat_colours():
    colour = np.array([0.6, 0.3, 0.1], np.float32)
    light = np.broadcast_to(colour, (240, 320, 3)).copy()
    frame = Webcam(WebcamSettings(bayer=True), CAMERA).develop(light)
    expected = np.rint(255 * linear_to_srgb(colour))
    assert np.all(np.abs(frame[4:-4, 4:-4].astype(float) - expected) <= 1.0)
    red = np.zeros((240, 320, 3), np.float32)
    red[..., 0] = 0.5
    demosaiced = Webcam(WebcamSettings(bayer=True), CAMERA).develop(red)[10:-10, 10:-10]
    assert np.all(demosaiced[..., 0] >= 187) and np.all(demosaiced[..., 1:] == 0)
    with pytest.raises(ValueError, match='Bayer sensor needs RGB'):
        Webcam(WebcamSettings(bayer=True), CAMERA).develop(uniform_light(0.5))


def test_jpeg_keeps_a_smooth_frame_close_and_bad_settings_are_refused():
    u = np.linspace(0.0, 1.0, 320, dtype=np.float32)
    light = np.stack([np.tile(u, (240, 1)), np.tile(u[::-1], (240, 1)),
                      np.full((240, 320), 0.3, np.float32)], axis=-1)
    plain = Webcam(WebcamSettings(), CAMERA).develop(light).astype(float)
    jpeg = Webcam(WebcamSettings(jpeg_quality=90), CAMERA).develop(light).astype(float)
    assert 0 < np.abs(jpeg - plain).mean() < 1.5
    refused = [({'tone_curve': 'gamma'}, 'tone_curve'), ({'adc_bits': 20}, 'adc_bits'),
               ({'jpeg_quality': 101}, 'jpeg_quality'), ({'vignetting': 1.0}, 'vignetting'),
               ({'read_noise': -0.1}, 'read_noise')]
    for bad, match in refused:
        with pytest.raises(ValueError, match=match):
            WebcamSettings(**bad)


def test_rays_that_miss_the_ground_get_the_background():
    texture = GroundTexture(image=np.full((2, 2), 200, np.uint8), extent=(-1.0, 1.0, -1.0, 1.0))
    looking_up = look_at((0.0, 0.0, 0.3), (0.0, 1e-9, 1.0))
    light = GroundRenderer(CAMERA, supersample=1).radiance(looking_up, texture, background=0.07)
    assert np.all(light == np.float32(0.07))


def test_marker_placement_errors_are_clear():
    with pytest.raises(ValueError, match='pixel edges'):
        make_panel_texture(metres_per_pixel=3e-4)
    with pytest.raises(ValueError, match='do not fit'):
        make_panel_texture(extent=(-0.01, 0.1, -0.01, 0.1))
    with pytest.raises(ValueError, match='unknown ArUco dictionary'):
        aruco_dictionary('DICT_NOPE')


def test_reused_maps_never_go_stale():
    # One renderer across pose and texture changes must give what a fresh renderer gives.
    texture = make_panel_texture(extent=(-0.05, 0.15, -0.05, 0.15), metres_per_pixel=5e-4)
    shifted = GroundTexture(image=texture.image, extent=(-0.04, 0.16, -0.05, 0.15))
    poses = [look_at([0.05, -0.1, 0.2], [0.05, 0.05, 0.0]),
             look_at([0.06, -0.1, 0.2], [0.05, 0.05, 0.0])]
    reused = GroundRenderer(CAMERA)
    for pose, ground in [(poses[0], texture), (poses[1], texture), (poses[1], shifted),
                         (poses[0], texture)]:
        expected = GroundRenderer(CAMERA).radiance(pose, ground)
        np.testing.assert_array_equal(reused.radiance(pose, ground), expected)
    # A pose changed in place (same array object) is seen as a new pose.
    pose = poses[0].copy()
    reused.radiance(pose, texture)
    pose[0, 3] += 0.01
    np.testing.assert_array_equal(reused.radiance(pose, texture),
                                  GroundRenderer(CAMERA).radiance(pose, texture))


@pytest.mark.parametrize('supersample', [1, 2])
def test_a_part_of_the_frame_renders_as_the_same_part_of_the_whole(supersample):
    texture = make_panel_texture(metres_per_pixel=5e-4).linearised()
    renderer = GroundRenderer(CAMERA, supersample=supersample)
    pose = look_at([0.05, -0.1, 0.2], [0.05, 0.05, 0.0])
    whole = renderer.radiance(pose, texture)
    rect = (37, 21, 150, 99)
    part = renderer.radiance(pose, texture, rect=rect)
    np.testing.assert_array_equal(part, whole[21:99, 37:150])
    # optics on a part with a margin of context equal the whole frame's, inside the margin
    webcam = Webcam(WebcamSettings(blur_sigma=1.2, vignetting=0.2), CAMERA)
    m = webcam.blur_margin()
    wide = (rect[0] - m, rect[1] - m, rect[2] + m, rect[3] + m)
    inner = webcam.optics(renderer.radiance(pose, texture, rect=wide), wide)[m:-m, m:-m]
    np.testing.assert_allclose(inner, webcam.optics(whole)[21:99, 37:150], atol=1e-6)
