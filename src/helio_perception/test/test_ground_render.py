"""Tests of the ground-plane renderer against PinholeCamera.project and cv2.aruco."""

import cv2
from helio_optics.geometry import (
    invert_transform, look_at, PinholeCamera, transform_points)
from helio_perception.ground_render import (
    aruco_dictionary, GroundEllipse, GroundRenderer, GroundTexture, make_panel_texture)
import numpy as np
import pytest

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
    dot = GroundEllipse(center=point[:2], semi_axes=(0.0012, 0.0012), value=255.0)
    dark = GroundTexture(image=np.zeros((4, 4), np.uint8), extent=(-1.0, 1.0, -1.0, 1.0))
    image = GroundRenderer(camera, supersample=4).render(
        T_world_camera, dark, [dot], background=0.0, dtype=np.float32)
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


def test_spot_area_in_pixels_matches_the_ellipse_area_seen_from_above():
    height = 0.2
    camera = PinholeCamera.from_fov(320, 240, np.radians(50))
    T_world_camera = look_at((0.0, 0.0, height), (0.0, 1e-9, 0.0))
    spot = GroundEllipse(center=(0.01, -0.005), semi_axes=(0.008, 0.005), angle=0.4)
    dark = GroundTexture(image=np.zeros((2, 2), np.uint8), extent=(-1.0, 1.0, -1.0, 1.0))
    image = GroundRenderer(camera, supersample=2).render(
        T_world_camera, dark, [spot], background=0.0, dtype=np.float32)
    focal = camera.matrix[0, 0]
    expected_pixels = spot.area * (focal / height) ** 2
    assert image.sum() / 255.0 == pytest.approx(expected_pixels, rel=0.01)


def test_exposure_blur_and_noise():
    texture = GroundTexture(image=np.full((2, 2), 100, np.uint8), extent=(-1.0, 1.0, -1.0, 1.0))
    renderer = GroundRenderer(CAMERA, supersample=1)
    pose = look_at((0.0, 0.0, 0.3), (0.001, 0.0, 0.0))
    bright = renderer.render(pose, texture, gain=3.0)
    assert np.all(bright == 255)  # 300 levels clip: saturation
    noisy = renderer.render(pose, texture, noise_sigma=5.0, rng=np.random.default_rng(3),
                            dtype=np.float32)
    assert noisy.mean() == pytest.approx(100.0, abs=0.2)
    assert noisy.std() == pytest.approx(5.0, rel=0.05)


def test_rays_that_miss_the_ground_get_the_background():
    texture = GroundTexture(image=np.full((2, 2), 200, np.uint8), extent=(-1.0, 1.0, -1.0, 1.0))
    looking_up = look_at((0.0, 0.0, 0.3), (0.0, 1e-9, 1.0))
    image = GroundRenderer(CAMERA, supersample=1).render(looking_up, texture, background=7.0)
    assert np.all(image == 7)


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
        expected = GroundRenderer(CAMERA).render(pose, ground)
        np.testing.assert_array_equal(reused.render(pose, ground), expected)
    # A pose changed in place (same array object) is seen as a new pose.
    pose = poses[0].copy()
    reused.render(pose, texture)
    pose[0, 3] += 0.01
    np.testing.assert_array_equal(reused.render(pose, texture),
                                  GroundRenderer(CAMERA).render(pose, texture))
