"""
Message conversions in both directions, written once for every helio package.

- ``image_to_numpy`` / ``numpy_to_image``: sensor_msgs/Image <-> numpy arrays (the role
  cv_bridge plays elsewhere; table below); ``serialized_image``: the same Image as the
  serialised bytes a publisher sends (for frames published many times a second);
  ``restamped``: a serialised stamped message (CameraInfo, Clock) with a new stamp.
- ``camera_from_info`` / ``camera_info_from_camera``: sensor_msgs/CameraInfo <->
  ``helio_optics.geometry.PinholeCamera`` (plumb_bob distortion).
- ``stamp_to_seconds`` / ``stamp_to_nanoseconds`` / ``stamp_from_seconds``:
  builtin_interfaces/Time <-> float seconds or integer nanoseconds.
- ``point_to_array`` / ``array_to_point`` (geometry_msgs/Point or Vector3) and
  ``pose_to_matrix`` / ``matrix_to_pose`` (geometry_msgs/Pose <-> 4x4 transform).

Supported image encodings (sensor_msgs/image_encodings.hpp names):

==========  =======  ========  ====================================
encoding    dtype    channels  notes
==========  =======  ========  ====================================
rgb8        uint8    3
bgr8        uint8    3
rgba8       uint8    4
bgra8       uint8    4
mono8       uint8    1         returned as (H, W)
8UC1        uint8    1         returned as (H, W)
mono16      uint16   1         returned as (H, W)
16UC1       uint16   1         thermal centikelvin (FLIR Lepton)
32FC1       float32  1         e.g. thermal degC
==========  =======  ========  ====================================

Rows may be padded (``step`` larger than ``width * bytes per pixel``) and multi-byte data may
be big-endian (``is_bigendian``); `image_to_numpy` always returns native byte order. Anything
unsupported or inconsistent raises `ImageConversionError` naming the encoding and the sizes.
This module imports message packages but not rclpy, so it is usable without ``rclpy.init``.
"""

import math
import struct
import sys

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Pose
from helio_optics.geometry import homogeneous, matrix_from_quaternion, PinholeCamera
from helio_optics.geometry import quaternion_from_matrix
import numpy as np
from sensor_msgs.msg import CameraInfo, Image

# encoding -> (numpy dtype with no byte order, channels)
ENCODINGS = {
    'rgb8': (np.dtype(np.uint8), 3),
    'bgr8': (np.dtype(np.uint8), 3),
    'rgba8': (np.dtype(np.uint8), 4),
    'bgra8': (np.dtype(np.uint8), 4),
    'mono8': (np.dtype(np.uint8), 1),
    '8UC1': (np.dtype(np.uint8), 1),
    'mono16': (np.dtype(np.uint16), 1),
    '16UC1': (np.dtype(np.uint16), 1),
    '32FC1': (np.dtype(np.float32), 1),
}


_NATIVE_ORDER = '<' if sys.byteorder == 'little' else '>'


class ImageConversionError(ValueError):
    """An Image message that cannot be converted (unsupported or inconsistent)."""


def encoding_layout(encoding):
    """Return (dtype, channels) of a supported encoding; raise ImageConversionError otherwise."""
    try:
        return ENCODINGS[encoding]
    except KeyError:
        raise ImageConversionError(
            f'unsupported image encoding {encoding!r} '
            f'(supported: {", ".join(sorted(ENCODINGS))})') from None


def image_to_numpy(msg, copy=False):
    """
    Return the pixels of a sensor_msgs/Image as an array of shape (H, W) or (H, W, C).

    The array has native byte order. Without `copy` it is a read-only view of the message
    buffer whenever no byte swap is needed (the fast path for large images).
    """
    encoding = msg.encoding
    dtype, channels = encoding_layout(encoding)
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    row_bytes = width * channels * dtype.itemsize
    data = msg.data
    size = len(data)
    if height == 0 or width == 0:
        raise ImageConversionError(
            f'{encoding} image has no pixels (height {height}, width {width})')
    if step < row_bytes:
        raise ImageConversionError(
            f'{encoding} image step {step} is smaller than width {width} x {channels} '
            f'channel(s) x {dtype.itemsize} byte(s) = {row_bytes}')
    if size != step * height:
        raise ImageConversionError(
            f'{encoding} image data has {size} bytes, expected step {step} x height {height}'
            f' = {step * height}')
    buffer = np.frombuffer(data, dtype=np.uint8)
    rows = buffer.reshape(height, step)[:, :row_bytes]
    if step != row_bytes:
        rows = np.ascontiguousarray(rows)  # drop the row padding (this copies)
    order = '>' if msg.is_bigendian else '<'
    array = rows.view(dtype.newbyteorder(order))
    array = array.reshape((height, width, channels) if channels > 1 else (height, width))
    if dtype.itemsize > 1 and order != _NATIVE_ORDER:
        array = array.astype(dtype)  # swap to native byte order (this copies)
    elif copy:
        array = array.copy()
    elif array.flags.writeable:
        array.flags.writeable = False
    return array


def numpy_to_image(array, encoding, header=None, is_bigendian=False, step=None):
    """
    Make a sensor_msgs/Image from an array of shape (H, W) or (H, W, C).

    The array's dtype must match the encoding (e.g. uint16 for 16UC1). `step` (bytes per
    row) defaults to the packed row size; a larger value pads each row with zeros.
    `is_bigendian` writes multi-byte samples big-endian.
    """
    height, width, step, rows = _image_rows(array, encoding, is_bigendian, step)
    msg = Image()
    if header is not None:
        msg.header = header
    msg.height, msg.width, msg.step = height, width, step
    msg.encoding = encoding
    msg.is_bigendian = bool(is_bigendian)
    msg.data = rows.tobytes()
    return msg


def serialized_image(array, encoding, stamp, frame_id='', is_bigendian=False, step=None):
    """
    Return ``numpy_to_image``'s sensor_msgs/Image serialised, for ``Publisher.publish(bytes)``.

    The bytes ``rclpy.serialization.serialize_message`` gives for the message (tested):
    CDR, little endian, each field aligned to its size from the end of the 4-byte
    encapsulation header. Publishing them skips building the message's Python object and
    its conversion to C: a third of the publish of a 640 x 480 rgb8 frame (0.26 of
    0.76 ms, measured with a subscriber in another process). `stamp` is a
    builtin_interfaces/Time.
    """
    if sys.byteorder != 'little':
        raise RuntimeError('serialized_image writes little-endian CDR on little-endian hosts '
                           'only; publish numpy_to_image() instead')
    height, width, step, rows = _image_rows(array, encoding, is_bigendian, step)
    writer = _CdrWriter()
    writer.add(_CDR_TIME, stamp.sec, stamp.nanosec)
    writer.add_string(frame_id)
    writer.add('<II', height, width)
    writer.add_string(encoding)
    writer.add('<B', 1 if is_bigendian else 0)
    writer.add('<II', step, rows.nbytes)
    writer.parts.append(rows.data)      # contiguous (_image_rows)
    return b''.join(writer.parts)


def serialized_pose_stamped(transform, stamp, frame_id=''):
    """
    Return the geometry_msgs/PoseStamped of a 4x4 rigid transform, serialised.

    The bytes ``rclpy.serialization.serialize_message`` gives for the message of
    ``matrix_to_pose`` (tested), written directly as ``serialized_image`` writes its
    Image: a pose that changes every frame (a camera on the moving arm) costs a fifth of
    building the message and serialising it (0.15 ms). `stamp` is a
    builtin_interfaces/Time.
    """
    if sys.byteorder != 'little':
        raise RuntimeError('serialized_pose_stamped writes little-endian CDR on little-endian '
                           'hosts only; publish a PoseStamped instead')
    transform = np.asarray(transform, dtype=float)
    writer = _CdrWriter()
    writer.add(_CDR_TIME, stamp.sec, stamp.nanosec)
    writer.add_string(frame_id)
    writer.add('<ddd', *(float(v) for v in transform[:3, 3]))
    writer.add('<dddd', *(float(v) for v in quaternion_from_matrix(transform[:3, :3])))
    return b''.join(writer.parts)


def restamped(serialized, stamp):
    """
    Return a serialised message whose first field is its stamp, with `stamp` there instead.

    For messages published often that change only their stamp (a sensor_msgs/CameraInfo
    or any message that begins with a std_msgs/Header, a rosgraph_msgs/Clock): serialise
    once (``rclpy.serialization.serialize_message``), restamp per publication (a
    ``Publisher.publish(bytes)``). `stamp` is a builtin_interfaces/Time; ValueError for
    bytes that are not little-endian CDR.
    """
    if bytes(serialized[:4]) != _CdrWriter.HEADER or len(serialized) < 12:
        raise ValueError('restamped needs a little-endian CDR message beginning with a stamp')
    return b''.join((serialized[:4], struct.pack(_CDR_TIME, stamp.sec, stamp.nanosec),
                     serialized[12:]))


_CDR_TIME = '<iI'     # builtin_interfaces/Time: int32 sec, uint32 nanosec


class _CdrWriter:
    """The parts of a little-endian CDR (XCDR1) message, fields aligned to their sizes."""

    HEADER = b'\x00\x01\x00\x00'     # CDR_LE encapsulation, no options

    def __init__(self):
        self.parts = [self.HEADER]
        self._offset = 0       # from the end of the encapsulation header

    def add(self, layout, *values):
        """Add `values` packed by struct `layout` (one field size: 1, 4 or 8 bytes)."""
        size = struct.calcsize(layout[1:2])
        padding = -self._offset % size
        data = b'\0' * padding + struct.pack(layout, *values)
        self.parts.append(data)
        self._offset += len(data)

    def add_string(self, text):
        """Add a CDR string: its length with the terminating NUL, the UTF-8 bytes, NUL."""
        data = text.encode('utf-8') + b'\0'
        self.add('<I', len(data))
        self.parts.append(data)
        self._offset += len(data)


def _image_rows(array, encoding, is_bigendian=False, step=None):
    """Return (height, width, step, rows (H, step) uint8) of an image array; see numpy_to_image."""
    dtype, channels = encoding_layout(encoding)
    array = np.asarray(array)
    expected = '(H, W)' if channels == 1 else f'(H, W, {channels})'
    shape_ok = (array.ndim == 2 and channels == 1) or \
        (array.ndim == 3 and array.shape[2] == channels) or \
        (array.ndim == 3 and channels == 1 and array.shape[2] == 1)
    if not shape_ok:
        raise ImageConversionError(
            f'{encoding} needs an array of shape {expected}, got {array.shape}')
    if array.dtype != dtype:
        raise ImageConversionError(
            f'{encoding} needs dtype {dtype.name}, got {array.dtype.name}')
    height, width = array.shape[:2]
    if height == 0 or width == 0:
        raise ImageConversionError(f'{encoding} array has no pixels: shape {array.shape}')
    row_bytes = width * channels * dtype.itemsize
    step = row_bytes if step is None else int(step)
    if step < row_bytes:
        raise ImageConversionError(
            f'{encoding} step {step} is smaller than the row size {row_bytes}')
    target = dtype.newbyteorder('>' if is_bigendian else '<')
    rows = np.ascontiguousarray(array, dtype=target).view(np.uint8).reshape(height, row_bytes)
    if step > row_bytes:
        padded = np.zeros((height, step), dtype=np.uint8)
        padded[:, :row_bytes] = rows
        rows = padded
    return height, width, step, rows


# ---- CameraInfo ------------------------------------------------------------------------------

def camera_from_info(msg):
    """
    Make a PinholeCamera from a sensor_msgs/CameraInfo; raise ValueError if it is not valid.

    Checks the intrinsic matrix k (positive focal lengths, k[8] = 1) and the size; the first
    five distortion coefficients are used as OpenCV's plumb_bob (k1, k2, p1, p2, k3).
    """
    matrix = np.asarray(msg.k, dtype=float).reshape(3, 3)
    if not np.all(np.isfinite(matrix)) or matrix[0, 0] <= 0 or matrix[1, 1] <= 0 \
            or matrix[2, 2] != 1.0:
        raise ValueError(f'camera matrix is not a valid intrinsic matrix: {matrix.tolist()}')
    width, height = int(msg.width), int(msg.height)
    if width <= 0 or height <= 0:
        raise ValueError(f'camera size {width}x{height} is empty')
    distortion = np.zeros(5)
    d = np.asarray(msg.d, dtype=float).ravel()[:5]
    if not np.all(np.isfinite(d)):
        raise ValueError(f'distortion coefficients are not finite: {d.tolist()}')
    distortion[:len(d)] = d
    return PinholeCamera(matrix=matrix, width=width, height=height, distortion=distortion)


def camera_info_from_camera(camera, stamp=None, frame_id=''):
    """Return the sensor_msgs/CameraInfo of a PinholeCamera (plumb_bob, no rectification)."""
    info = CameraInfo()
    if stamp is not None:
        info.header.stamp = stamp
    info.header.frame_id = frame_id
    info.width, info.height = int(camera.width), int(camera.height)
    info.distortion_model = 'plumb_bob'
    distortion = [float(v) for v in np.asarray(camera.distortion).ravel()]
    info.d = (distortion + [0.0] * 5)[:5]
    matrix = np.asarray(camera.matrix, dtype=float)
    info.k = [float(v) for v in matrix.ravel()]
    info.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    info.p = [float(matrix[0, 0]), float(matrix[0, 1]), float(matrix[0, 2]), 0.0,
              0.0, float(matrix[1, 1]), float(matrix[1, 2]), 0.0,
              0.0, 0.0, 1.0, 0.0]
    return info


# ---- stamps ----------------------------------------------------------------------------------

def stamp_to_nanoseconds(stamp):
    """Return a builtin_interfaces/Time as integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def stamp_to_seconds(stamp):
    """Return a builtin_interfaces/Time as float seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def stamp_from_seconds(seconds):
    """Return builtin_interfaces/Time for `seconds` (finite, >= 0) [s]."""
    if not (math.isfinite(seconds) and seconds >= 0.0):
        raise ValueError(f'a stamp needs finite seconds >= 0, got {seconds!r}')
    nanoseconds = int(round(seconds * 1e9))
    return Time(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)


# ---- points and poses --------------------------------------------------------------------------

def point_to_array(point):
    """Return a geometry_msgs/Point (or Vector3) as an array (3,)."""
    return np.array([point.x, point.y, point.z], dtype=float)


def array_to_point(values, point_type=Point):
    """Return a geometry_msgs/Point (or `point_type`, e.g. Vector3) from 3 numbers."""
    x, y, z = (float(v) for v in np.asarray(values, dtype=float).reshape(3))
    return point_type(x=x, y=y, z=z)


def pose_to_matrix(pose):
    """Return the 4x4 transform of a geometry_msgs/Pose (child frame into parent frame)."""
    q = pose.orientation
    rotation = matrix_from_quaternion([q.x, q.y, q.z, q.w])
    return homogeneous(rotation, point_to_array(pose.position))


def matrix_to_pose(transform):
    """Return the geometry_msgs/Pose of a 4x4 rigid transform."""
    transform = np.asarray(transform, dtype=float)
    pose = Pose()
    pose.position = array_to_point(transform[:3, 3])
    x, y, z, w = (float(v) for v in quaternion_from_matrix(transform[:3, :3]))
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = x, y, z, w
    return pose
