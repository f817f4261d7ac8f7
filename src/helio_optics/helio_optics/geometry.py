"""
Rigid-body geometry, frames and the pinhole camera: the one implementation every package uses.

Conventions (DESIGN.md "Frames and units"): SI units, right-handed frames, a transform
``T_a_b`` (4x4) maps points expressed in frame ``b`` into frame ``a``:
``p_a = T_a_b @ p_b``. Quaternions are ``(x, y, z, w)`` as in geometry_msgs. Point arrays are
``(N, 3)``; single points may be given as ``(3,)``.
"""

from dataclasses import dataclass, field

import numpy as np


def rotation_x(angle):
    """Rotation matrix about x by `angle` [rad]."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rotation_y(angle):
    """Rotation matrix about y by `angle` [rad]."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_z(angle):
    """Rotation matrix about z by `angle` [rad]."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def homogeneous(rotation=None, translation=None):
    """4x4 transform from a 3x3 rotation (default identity) and a translation (default 0)."""
    transform = np.eye(4)
    if rotation is not None:
        transform[:3, :3] = rotation
    if translation is not None:
        transform[:3, 3] = np.asarray(translation, dtype=float).reshape(3)
    return transform


def invert_transform(transform):
    """Inverse of a rigid 4x4 transform (R^T, -R^T t), exact for rotations."""
    rotation = transform[:3, :3]
    inverse = np.eye(4)
    inverse[:3, :3] = rotation.T
    inverse[:3, 3] = -rotation.T @ transform[:3, 3]
    return inverse


def transform_points(transform, points):
    """Apply a 4x4 rigid transform to points of shape (N, 3) or (3,)."""
    points = np.asarray(points, dtype=float)
    return points @ transform[:3, :3].T + transform[:3, 3]


def transform_vectors(transform, vectors):
    """Rotate free vectors (directions) of shape (N, 3) or (3,) by a 4x4 transform."""
    return np.asarray(vectors, dtype=float) @ transform[:3, :3].T


def unit(vectors):
    """Normalise vectors along the last axis; raise on a zero vector."""
    vectors = np.asarray(vectors, dtype=float)
    norms = np.linalg.norm(vectors, axis=-1, keepdims=True)
    if np.any(norms == 0.0):
        raise ValueError('cannot normalise a zero vector')
    return vectors / norms


def quaternion_from_matrix(rotation):
    """Return the unit quaternion (x, y, z, w), w >= 0, of a rotation (Shepperd's method)."""
    m = np.asarray(rotation, dtype=float)
    trace = np.trace(m)
    if trace > 0.0:
        s = 2.0 * np.sqrt(trace + 1.0)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, s / 4]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4, (m[1, 0] - m[0, 1]) / s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def matrix_from_quaternion(quaternion):
    """3x3 rotation matrix of a quaternion (x, y, z, w); the quaternion is normalised first."""
    x, y, z, w = unit(quaternion)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def direction_from_angles(polar, azimuth):
    """Return [sin(phi)cos(theta), sin(phi)sin(theta), cos(phi)] (paper Eq 2)."""
    polar, azimuth = np.asarray(polar, dtype=float), np.asarray(azimuth, dtype=float)
    return np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth),
                     np.cos(polar) * np.ones_like(azimuth)], axis=-1)


def angles_from_direction(direction):
    """Inverse of direction_from_angles: (polar in [0, pi], azimuth in [0, 2 pi))."""
    d = unit(direction)
    polar = np.arccos(np.clip(d[..., 2], -1.0, 1.0))
    azimuth = np.mod(np.arctan2(d[..., 1], d[..., 0]), 2.0 * np.pi)
    return polar, azimuth


def intersect_plane(origins, directions, plane_point, plane_normal):
    """
    Intersect rays p = o + K d with a plane (paper Eq 6, K from (p - p_g0) . n_g = 0).

    Returns (points (N, 3), K (N,)). Rays parallel to the plane get NaN.
    """
    origins = np.atleast_2d(np.asarray(origins, dtype=float))
    directions = np.atleast_2d(np.asarray(directions, dtype=float))
    normal = np.asarray(plane_normal, dtype=float)
    denominator = directions @ normal
    with np.errstate(divide='ignore', invalid='ignore'):
        scale = ((np.asarray(plane_point, dtype=float) - origins) @ normal) / denominator
    scale = np.where(np.abs(denominator) < 1e-15, np.nan, scale)
    return origins + scale[:, None] * directions, scale


@dataclass
class PinholeCamera:
    """
    Pinhole camera with OpenCV's distortion model (paper Eq 7: s p_i = A [R | t] p_w).

    `matrix` is the intrinsic matrix A (3x3, pixels); `distortion` the OpenCV coefficients
    (k1, k2, p1, p2[, k3]); the camera looks along +z of its optical frame, x right, y down.
    """

    matrix: np.ndarray
    width: int
    height: int
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(5))

    @classmethod
    def from_fov(cls, width, height, horizontal_fov):
        """Make an undistorted camera with square pixels and this horizontal field of view."""
        focal = 0.5 * width / np.tan(0.5 * horizontal_fov)
        matrix = np.array([[focal, 0.0, (width - 1) / 2.0],
                           [0.0, focal, (height - 1) / 2.0],
                           [0.0, 0.0, 1.0]])
        return cls(matrix=matrix, width=width, height=height)

    def project(self, points_camera):
        """Pixels (N, 2) of points (N, 3) in the optical frame, with distortion."""
        p = np.atleast_2d(np.asarray(points_camera, dtype=float))
        x, y = p[:, 0] / p[:, 2], p[:, 1] / p[:, 2]
        x, y = self._distort(x, y)
        fx, fy, cx, cy = self.matrix[0, 0], self.matrix[1, 1], self.matrix[0, 2], self.matrix[1, 2]
        return np.stack([fx * x + self.matrix[0, 1] * y + cx, fy * y + cy], axis=-1)

    def pixel_rays(self, pixels, iterations=20):
        """Return unit rays (N, 3) in the optical frame through pixels (N, 2), undistorted."""
        pixels = np.atleast_2d(np.asarray(pixels, dtype=float))
        fx, fy, cx, cy = self.matrix[0, 0], self.matrix[1, 1], self.matrix[0, 2], self.matrix[1, 2]
        yd = (pixels[:, 1] - cy) / fy
        xd = (pixels[:, 0] - cx - self.matrix[0, 1] * yd) / fx
        x, y = xd.copy(), yd.copy()
        if np.any(self.distortion):
            for _ in range(iterations):  # fixed-point inversion, as cv2.undistortPoints
                xx, yy = self._distort(x, y)
                x, y = x + (xd - xx), y + (yd - yy)
        return unit(np.stack([x, y, np.ones_like(x)], axis=-1))

    def _distort(self, x, y):
        k = np.zeros(5)
        k[:len(self.distortion)] = np.asarray(self.distortion, dtype=float)[:5]
        k1, k2, p1, p2, k3 = k
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
        return (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)


def look_at(eye, target, up=(0.0, 0.0, 1.0)):
    """
    Pose T_world_camera of an optical frame at `eye` whose +z looks at `target`.

    The image's y axis (down) is as close as possible to -`up`.
    """
    eye, target = np.asarray(eye, dtype=float), np.asarray(target, dtype=float)
    z_axis = unit(target - eye)
    # Right-handed optical frame with y = -up (projected): x = y cross z = z cross up.
    x_axis = np.cross(z_axis, np.asarray(up, dtype=float))
    if np.linalg.norm(x_axis) < 1e-9:
        x_axis = np.cross(z_axis, [0.0, 1.0, 0.0])
    x_axis = unit(x_axis)
    y_axis = np.cross(z_axis, x_axis)
    return homogeneous(np.column_stack([x_axis, y_axis, z_axis]), eye)
