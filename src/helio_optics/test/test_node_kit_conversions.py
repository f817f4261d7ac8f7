"""Tests of the kit's message conversions against hand-built messages and round trips."""

import math
import struct

from geometry_msgs.msg import PoseStamped
from helio_optics.geometry import homogeneous, PinholeCamera, rotation_x, rotation_y, rotation_z
from helio_optics.node_kit.conversions import (
    array_to_point, camera_from_info, camera_info_from_camera, ENCODINGS, image_to_numpy,
    ImageConversionError, matrix_to_pose, numpy_to_image, point_to_array, pose_to_matrix,
    restamped, serialized_image, serialized_pose_stamped, stamp_from_seconds,
    stamp_to_nanoseconds, stamp_to_seconds)
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Image


def random_array(encoding, height=5, width=7, seed=0):
    """Return a random array in the layout of `encoding`."""
    dtype, channels = ENCODINGS[encoding]
    rng = np.random.default_rng(seed)
    shape = (height, width) if channels == 1 else (height, width, channels)
    if dtype.kind == 'f':
        return rng.normal(25.0, 40.0, shape).astype(dtype)
    return rng.integers(0, np.iinfo(dtype).max, shape, endpoint=True).astype(dtype)


@pytest.mark.parametrize('encoding', sorted(ENCODINGS))
@pytest.mark.parametrize('big_endian', [False, True])
@pytest.mark.parametrize('padding', [0, 3])
def test_round_trip_every_encoding(encoding, big_endian, padding):
    array = random_array(encoding)
    row = array.shape[1] * array.itemsize * (array.shape[2] if array.ndim == 3 else 1)
    msg = numpy_to_image(array, encoding, is_bigendian=big_endian, step=row + padding)
    assert (msg.height, msg.width, msg.step) == (5, 7, row + padding)
    assert len(msg.data) == msg.step * msg.height
    back = image_to_numpy(msg)
    assert back.dtype == array.dtype.newbyteorder('=')
    np.testing.assert_array_equal(back, array)


def hand_built(encoding, rows, width, step, big_endian=False):
    """Build an Image message from raw row bytes without the module under test."""
    msg = Image()
    msg.height, msg.width, msg.step = len(rows), width, step
    msg.encoding, msg.is_bigendian = encoding, big_endian
    msg.data = b''.join(rows)
    return msg


def test_big_endian_16uc1_reads_the_right_values():
    values = [[258, 65535, 0], [1, 30000, 4660]]
    rows = [struct.pack('>3H', *r) for r in values]
    little = [struct.pack('<3H', *r) for r in values]
    big_msg = hand_built('16UC1', rows, 3, 6, big_endian=True)
    little_msg = hand_built('16UC1', little, 3, 6)
    np.testing.assert_array_equal(image_to_numpy(big_msg), values)
    np.testing.assert_array_equal(image_to_numpy(little_msg), values)


def test_big_endian_32fc1_and_padded_rows_ignore_the_padding_bytes():
    values = [[181.5, -3.25], [20.0, 1e3]]
    rows = [struct.pack('>2f', *r) + b'\xff\xee\xdd\xcc' for r in values]
    msg = hand_built('32FC1', rows, 2, 12, big_endian=True)
    np.testing.assert_array_equal(image_to_numpy(msg), np.array(values, dtype=np.float32))


def test_rgb_channel_order_is_kept():
    rows = [bytes([10, 20, 30, 40, 50, 60, 0])]  # two pixels plus one padding byte
    image = image_to_numpy(hand_built('rgb8', rows, 2, 7))
    np.testing.assert_array_equal(image, [[[10, 20, 30], [40, 50, 60]]])


def test_fast_path_is_a_read_only_view_and_copy_is_writable():
    msg = numpy_to_image(random_array('mono8'), 'mono8')
    view = image_to_numpy(msg)
    assert not view.flags.writeable
    copy = image_to_numpy(msg, copy=True)
    copy[0, 0] = 1
    assert copy.flags.writeable


def test_header_is_carried():
    msg = numpy_to_image(random_array('mono16'), 'mono16')
    msg.header.frame_id = 'thermal'
    again = numpy_to_image(image_to_numpy(msg), 'mono16', header=msg.header)
    assert again.header.frame_id == 'thermal'


@pytest.mark.parametrize('encoding', ['yuv422', 'bayer_rggb8', '', '16SC1'])
def test_unsupported_encoding_is_named(encoding):
    msg = hand_built(encoding, [b'\x00' * 4], 2, 4)
    with pytest.raises(ImageConversionError, match=repr(encoding).replace('[', r'\[')):
        image_to_numpy(msg)


def test_inconsistent_sizes_name_the_encoding_and_the_sizes():
    with pytest.raises(ImageConversionError, match=r'16UC1 .* 10 bytes, expected step 6 x '
                                                   r'height 2 = 12'):
        image_to_numpy(hand_built('16UC1', [b'\x00' * 6, b'\x00' * 4], 3, 6))
    with pytest.raises(ImageConversionError, match=r'rgb8 image step 5 is smaller'):
        image_to_numpy(hand_built('rgb8', [b'\x00' * 5], 2, 5))
    with pytest.raises(ImageConversionError, match='no pixels'):
        image_to_numpy(hand_built('mono8', [], 0, 0))


def test_wrong_array_for_encoding_is_rejected():
    with pytest.raises(ImageConversionError, match='16UC1 needs dtype uint16'):
        numpy_to_image(np.zeros((2, 2), np.uint8), '16UC1')
    with pytest.raises(ImageConversionError, match=r'rgb8 needs an array of shape'):
        numpy_to_image(np.zeros((2, 2), np.uint8), 'rgb8')
    with pytest.raises(ImageConversionError, match='step 1 is smaller'):
        numpy_to_image(np.zeros((2, 2), np.uint8), 'mono8', step=1)


def test_camera_info_round_trip_and_checks():
    camera = PinholeCamera(matrix=np.array([[500.0, 0.0, 320.0], [0.0, 510.0, 240.0],
                                            [0.0, 0.0, 1.0]]),
                           width=640, height=480, distortion=np.array([0.1, 0.01, 0.0, 0.0]))
    info = camera_info_from_camera(camera, frame_id='rgb')
    back = camera_from_info(info)
    assert info.distortion_model == 'plumb_bob' and len(info.d) == 5
    assert np.array_equal(back.matrix, camera.matrix)
    assert back.distortion.tolist() == [0.1, 0.01, 0.0, 0.0, 0.0]
    assert (back.width, back.height) == (640, 480)
    # the projection matrix P of an unrectified camera repeats K
    assert info.p[0] == 500.0 and info.p[5] == 510.0 and info.p[2] == 320.0
    bad = camera_info_from_camera(camera)
    bad.k = [0.0] * 9
    with pytest.raises(ValueError, match='intrinsic'):
        camera_from_info(bad)
    empty = camera_info_from_camera(camera)
    empty.width = 0
    with pytest.raises(ValueError, match='empty'):
        camera_from_info(empty)


@pytest.mark.parametrize('seconds', [0.0, 1.5, 1700000000.123456789, 2.0 ** 31 - 0.5])
def test_stamps_round_trip_to_the_nanosecond(seconds):
    stamp = stamp_from_seconds(seconds)
    assert 0 <= stamp.nanosec < 1_000_000_000
    assert stamp_to_nanoseconds(stamp) == round(seconds * 1e9)
    assert stamp_to_seconds(stamp) == pytest.approx(seconds, abs=1e-9)


@pytest.mark.parametrize('bad', [-1.0, math.nan, math.inf])
def test_a_stamp_from_nonsense_seconds_is_refused(bad):
    with pytest.raises(ValueError, match='finite seconds'):
        stamp_from_seconds(bad)


def test_pose_round_trip_matches_the_rotation_and_translation():
    transform = homogeneous(rotation_z(0.3) @ rotation_y(-0.7), [0.1, -0.2, 0.3])
    pose = matrix_to_pose(transform)
    assert pose.position.x == pytest.approx(0.1)
    norm = math.sqrt(pose.orientation.x ** 2 + pose.orientation.y ** 2 +
                     pose.orientation.z ** 2 + pose.orientation.w ** 2)
    assert norm == pytest.approx(1.0)
    assert np.allclose(pose_to_matrix(pose), transform, atol=1e-12)
    assert np.allclose(point_to_array(array_to_point([1.0, 2.0, 3.0])), [1.0, 2.0, 3.0])


@pytest.mark.parametrize('encoding', sorted(ENCODINGS))
@pytest.mark.parametrize('frame_id', ['', 'r', 'rgb', 'thermal', 'camera_optical_frame'])
@pytest.mark.parametrize('big_endian, padding', [(False, 0), (True, 2), (False, 5)])
def test_serialized_image_is_what_rclpy_serializes(encoding, frame_id, big_endian, padding):
    """The hand-written CDR against rclpy's serializer, every alignment of the strings."""
    array = random_array(encoding, height=4, width=3)
    row_bytes = array.nbytes // 4
    stamp = stamp_from_seconds(1234.000056789)
    message = numpy_to_image(array, encoding, is_bigendian=big_endian,
                             step=row_bytes + padding)
    message.header.stamp, message.header.frame_id = stamp, frame_id
    data = serialized_image(array, encoding, stamp, frame_id, is_bigendian=big_endian,
                            step=row_bytes + padding)
    expected = serialize_message(message)
    assert len(data) == len(expected)
    # CDR aligns each 4-byte field to 4 bytes from the end of the 4-byte encapsulation
    # header; the alignment gaps hold no data (Fast CDR leaves whatever was in its buffer)
    offset = 8 + 4 + len(frame_id) + 1        # past the stamp and the frame_id string
    gaps = [(offset, offset + -offset % 4)]   # height (uint32) is aligned
    offset += -offset % 4 + 8 + 4 + len(encoding) + 1 + 1   # encoding string, is_bigendian
    gaps.append((offset, offset + -offset % 4))             # step (uint32) is aligned
    masked = [bytearray(data), bytearray(expected)]
    for start, end in gaps:
        for buffer in masked:
            buffer[4 + start:4 + end] = bytes(end - start)
    assert masked[0] == masked[1]
    assert all(data[4 + start:4 + end] == bytes(end - start) for start, end in gaps)
    back = deserialize_message(data, Image)
    assert back.header.frame_id == frame_id and back.header.stamp == stamp
    assert np.array_equal(image_to_numpy(back), array)


# frame_id lengths 0-7 put the doubles after 0-7 bytes of padding: every alignment
@pytest.mark.parametrize('frame_id', ['', 'w', 'rg', 'rgb', 'base', 'world', 'robot_',
                                      'rgb_opt'])
def test_serialized_pose_stamped_is_what_rclpy_serializes(frame_id):
    """The hand-written CDR against rclpy's serializer, every alignment of the doubles."""
    rng = np.random.default_rng(len(frame_id))
    for _ in range(5):
        angles = rng.uniform(-3.0, 3.0, 3)
        rotation = rotation_z(angles[0]) @ rotation_y(angles[1]) @ rotation_x(angles[2])
        transform = homogeneous(rotation, rng.normal(size=3))
        stamp = stamp_from_seconds(rng.uniform(0.0, 1e6))
        message = PoseStamped()
        message.header.stamp, message.header.frame_id = stamp, frame_id
        message.pose = matrix_to_pose(transform)
        data = serialized_pose_stamped(transform, stamp, frame_id)
        expected = serialize_message(message)
        assert len(data) == len(expected)
        # the doubles are aligned to 8 bytes from the end of the encapsulation header; the
        # gap after the frame_id string holds no data
        start = 8 + 4 + len(frame_id) + 1
        end = start + -start % 8
        masked = [bytearray(data), bytearray(expected)]
        for buffer in masked:
            buffer[4 + start:4 + end] = bytes(end - start)
        assert masked[0] == masked[1] and data[4 + start:4 + end] == bytes(end - start)
        back = deserialize_message(data, PoseStamped)
        assert back == message
        assert np.allclose(pose_to_matrix(back.pose), transform)


def test_serialized_image_refuses_what_numpy_to_image_refuses():
    with pytest.raises(ImageConversionError, match='rgb8 needs dtype uint8'):
        serialized_image(np.zeros((2, 2, 3), np.uint16), 'rgb8', stamp_from_seconds(1.0))


def test_a_restamped_camera_info_or_clock_is_the_message_with_the_new_stamp():
    info = camera_info_from_camera(PinholeCamera.from_fov(160, 120, 0.8), None, 'thermal')
    clock = Clock()
    for message in (info, clock):
        template = serialize_message(message)
        for seconds in (0.0, 1.5, 86400.000000001, 2.0 ** 31 - 1.0):
            stamp = stamp_from_seconds(seconds)
            back = deserialize_message(restamped(template, stamp), type(message))
            if isinstance(message, Clock):
                assert back.clock == stamp
                message.clock = stamp
            else:
                assert back.header.stamp == stamp
                message.header.stamp = stamp
            assert back == message
    with pytest.raises(ValueError, match='little-endian CDR'):
        restamped(b'\x00\x00\x00\x00' + bytes(8), stamp_from_seconds(1.0))
