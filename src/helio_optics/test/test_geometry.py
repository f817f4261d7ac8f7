"""Geometry helpers against independent truth: OpenCV, closed forms and round trips."""

import math

import cv2
from helio_optics import geometry
import numpy as np
import pytest


def random_rotation(rng):
    q = rng.normal(size=4)
    return geometry.matrix_from_quaternion(q / np.linalg.norm(q))


def test_rotation_about_z_turns_x_into_y():
    np.testing.assert_allclose(geometry.rotation_z(math.pi / 2) @ [1, 0, 0], [0, 1, 0],
                               atol=1e-15)
    np.testing.assert_allclose(geometry.rotation_x(math.pi / 2) @ [0, 1, 0], [0, 0, 1],
                               atol=1e-15)
    np.testing.assert_allclose(geometry.rotation_y(math.pi / 2) @ [0, 0, 1], [1, 0, 0],
                               atol=1e-15)


def test_quaternion_round_trip_and_opencv_rodrigues_agree():
    rng = np.random.default_rng(1)
    for _ in range(200):
        rotation = random_rotation(rng)
        q = geometry.quaternion_from_matrix(rotation)
        np.testing.assert_allclose(geometry.matrix_from_quaternion(q), rotation, atol=1e-12)
        # Independent: the rotation angle from OpenCV's Rodrigues vector equals 2 acos(w).
        rvec, _ = cv2.Rodrigues(rotation)
        assert np.linalg.norm(rvec) == pytest.approx(2 * math.acos(min(1.0, q[3])), abs=1e-7)


def test_invert_transform_composes_to_identity():
    rng = np.random.default_rng(2)
    transform = geometry.homogeneous(random_rotation(rng), rng.normal(size=3))
    np.testing.assert_allclose(transform @ geometry.invert_transform(transform), np.eye(4),
                               atol=1e-12)
    np.testing.assert_allclose(geometry.invert_transform(transform), np.linalg.inv(transform),
                               atol=1e-12)


def test_direction_angles_round_trip():
    rng = np.random.default_rng(3)
    polar = rng.uniform(0.01, math.pi - 0.01, 500)
    azimuth = rng.uniform(0.0, 2 * math.pi, 500)
    back_polar, back_azimuth = geometry.angles_from_direction(
        geometry.direction_from_angles(polar, azimuth))
    np.testing.assert_allclose(back_polar, polar, atol=1e-12)
    np.testing.assert_allclose(np.cos(back_azimuth - azimuth), 1.0, atol=1e-12)


def test_intersect_plane_matches_closed_form():
    # A ray from (0, 0, h) with direction (sin a, 0, -cos a) hits z = 0 at x = h tan a.
    h, a = 0.08, math.radians(30)
    points, scale = geometry.intersect_plane([[0, 0, h]], [[math.sin(a), 0, -math.cos(a)]],
                                             [0, 0, 0], [0, 0, 1])
    np.testing.assert_allclose(points[0], [h * math.tan(a), 0, 0], atol=1e-15)
    assert scale[0] == pytest.approx(h / math.cos(a))
    parallel, _ = geometry.intersect_plane([[0, 0, 1]], [[1, 0, 0]], [0, 0, 0], [0, 0, 1])
    assert np.all(np.isnan(parallel))


def test_projection_matches_opencv_with_distortion():
    rng = np.random.default_rng(4)
    camera = geometry.PinholeCamera(
        matrix=np.array([[600.0, 0.0, 321.5], [0.0, 605.0, 238.0], [0.0, 0.0, 1.0]]),
        width=640, height=480, distortion=np.array([-0.12, 0.05, 0.001, -0.0005, 0.01]))
    points = np.column_stack([rng.uniform(-0.1, 0.1, 100), rng.uniform(-0.08, 0.08, 100),
                              rng.uniform(0.15, 0.4, 100)])
    expected, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), camera.matrix,
                                    camera.distortion)
    np.testing.assert_allclose(camera.project(points), expected.reshape(-1, 2), atol=1e-9)
    # Back-projection: the ray through each pixel passes through its point.
    rays = camera.pixel_rays(camera.project(points))
    np.testing.assert_allclose(rays, geometry.unit(points), atol=1e-9)


def test_look_at_points_the_optical_axis_at_the_target():
    pose = geometry.look_at([0.1, -0.05, 0.3], [0.05, 0.05, 0.0])
    camera_in_world = geometry.transform_vectors(pose, [0, 0, 1])
    np.testing.assert_allclose(camera_in_world, geometry.unit([-0.05, 0.1, -0.3]), atol=1e-12)
    np.testing.assert_allclose(pose[:3, :3].T @ pose[:3, :3], np.eye(3), atol=1e-12)
    assert np.linalg.det(pose[:3, :3]) == pytest.approx(1.0)


def test_look_at_keeps_the_image_upright():
    # Looking horizontally along +x with z up: the image's down axis (+y) is world -z and
    # its right axis (+x) is world -y, as for a person facing +x.
    pose = geometry.look_at([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], up=(0.0, 0.0, 1.0))
    np.testing.assert_allclose(pose[:3, 1], [0.0, 0.0, -1.0], atol=1e-12)
    np.testing.assert_allclose(pose[:3, 0], [0.0, -1.0, 0.0], atol=1e-12)
    # Tilted down at a point on the ground: image down still has a negative z component,
    # and a point above the target projects above the image centre (smaller row).
    pose = geometry.look_at([0.0, -0.2, 0.3], [0.0, 0.0, 0.0])
    assert pose[2, 1] < 0.0
    camera = geometry.PinholeCamera.from_fov(640, 480, math.radians(60))
    above = geometry.transform_points(geometry.invert_transform(pose), [0.0, 0.0, 0.02])
    assert camera.project(above)[0, 1] < camera.matrix[1, 2]
