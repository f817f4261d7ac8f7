"""
Convert sensor_msgs/Image to numpy arrays and back (the role cv_bridge plays elsewhere).

Supported encodings (sensor_msgs/image_encodings.hpp names):

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
This module imports sensor_msgs but not rclpy, so it is usable without ``rclpy.init``.
"""

import sys

import numpy as np
from sensor_msgs.msg import Image

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
    msg = Image()
    if header is not None:
        msg.header = header
    msg.height, msg.width, msg.step = height, width, step
    msg.encoding = encoding
    msg.is_bigendian = bool(is_bigendian)
    msg.data = rows.tobytes()
    return msg
