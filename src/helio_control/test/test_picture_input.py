"""Picture input: formats, alpha, sensor_msgs/Image, and malformed input named in one line."""

import math

import cv2
from helio_control.picture_input import load_picture, picture_from_image_msg, PictureError
from helio_control.plan import plan_picture, PlanError, PlanOptions, PlanOptionsError
from helio_control.preview import main
import numpy as np
import pytest
from sensor_msgs.msg import Image


def checker(size=64):
    picture = np.full((size, size), 255, np.uint8)
    picture[: size // 2, : size // 2] = 0
    return picture


@pytest.mark.parametrize('suffix', ['.png', '.jpg', '.bmp', '.tif'])
def test_every_common_format_reads_as_the_same_grey_picture(tmp_path, suffix):
    path = str(tmp_path / f'picture{suffix}')
    assert cv2.imwrite(path, checker())
    picture = load_picture(path)
    assert (picture.width, picture.height) == (64, 64)
    assert picture.grey[5, 5] < 0.05 and picture.grey[60, 60] > 0.95


def test_alpha_is_flattened_onto_white(tmp_path):
    bgra = np.zeros((32, 32, 4), np.uint8)          # black everywhere
    bgra[:, :16, 3] = 255                           # opaque on the left only
    path = str(tmp_path / 'alpha.png')
    cv2.imwrite(path, bgra)
    grey = load_picture(path).grey
    assert np.allclose(grey[:, :16], 0.0) and np.allclose(grey[:, 16:], 1.0)


def test_sixteen_bit_and_colour_pictures_are_scaled_to_unit_grey(tmp_path):
    path = str(tmp_path / 'deep.png')
    cv2.imwrite(path, (checker().astype(np.uint16) * 257))
    assert load_picture(path).grey.max() == pytest.approx(1.0)
    colour = np.dstack([checker()] * 3)
    assert load_picture(colour).grey[60, 60] == pytest.approx(1.0)


def image_msg(array, encoding):
    msg = Image()
    msg.height, msg.width = array.shape[:2]
    msg.encoding = encoding
    msg.step = array.strides[0]
    msg.data = array.tobytes()
    return msg


def test_sensor_msgs_image_mono8_and_rgb8():
    grey = picture_from_image_msg(image_msg(checker(), 'mono8')).grey
    assert grey[5, 5] == 0.0 and grey[60, 60] == 1.0
    rgb = np.full((8, 8, 3), 255, np.uint8)
    rgb[:4, :, 1:] = 0                               # pure red in RGB order on top, white below
    red = picture_from_image_msg(image_msg(rgb, 'rgb8')).grey
    assert red[0, 0] == pytest.approx(0.299, abs=0.01)   # BT.601 weight of red
    assert red[7, 0] == pytest.approx(1.0)


def test_empty_or_unsupported_image_messages_are_named():
    with pytest.raises(PictureError, match='empty image'):
        picture_from_image_msg(Image())
    with pytest.raises(PictureError, match="unsupported image encoding 'yuv422'"):
        picture_from_image_msg(image_msg(np.zeros((4, 8), np.uint8), 'yuv422'))


def test_huge_pictures_are_decimated_with_a_warning(tmp_path):
    path = str(tmp_path / 'big.png')
    cv2.imwrite(path, cv2.resize(checker(), (2000, 1000), interpolation=cv2.INTER_NEAREST))
    picture = load_picture(path, max_pixels=200_000)
    assert picture.width * picture.height <= 200_000
    assert picture.original_size == (2000, 1000)
    assert 'decimated' in picture.warnings[0]


@pytest.mark.parametrize('make, message', [
    (lambda d: str(d / 'missing.png'), 'not found'),
    (lambda d: _write(d / 'empty.png', b''), 'empty (0 bytes)'),
    (lambda d: _write(d / 'noise.png', b'this is not a picture at all' * 10), 'OpenCV can read'),
    (lambda d: str(d), 'directory'),
])
def test_unusable_files_are_named(tmp_path, make, message):
    with pytest.raises(PictureError, match=message.split(' (')[0]):
        load_picture(make(tmp_path))


def _write(path, data):
    path.write_bytes(data)
    return str(path)


def test_empty_and_blank_pictures_are_refused():
    with pytest.raises(PictureError, match='empty picture'):
        load_picture(np.zeros((0, 10), np.uint8))
    with pytest.raises(PictureError, match='blank picture'):
        load_picture(np.full((50, 50), 255, np.uint8))
    with pytest.raises(PictureError, match='NaN'):
        load_picture(np.full((5, 5), np.nan, np.float32))


@pytest.mark.parametrize('changes, message', [
    ({'canvas_size': 0.0}, 'canvas_size must be > 0'),
    ({'canvas_size': -0.05}, 'canvas_size must be > 0'),
    ({'canvas_size': math.nan}, 'canvas_size must be finite'),
    ({'dot_radius': 0.0}, 'dot_radius must be > 0'),
    ({'dot_radius': math.inf}, 'dot_radius must be finite'),
    ({'canvas_size': 0.3}, 'larger than the rig can reach'),
    ({'offset_x': math.nan}, 'offset_x must be finite'),
    ({'n_p_target': 0}, 'n_p_target must be a whole number'),
    ({'feature_mode': 'sketch'}, 'feature_mode must be one of'),
])
def test_nonsense_sizes_and_options_are_named(changes, message):
    with pytest.raises(PlanOptionsError, match=message):
        plan_picture('sample:logo', PlanOptions(**changes))


def test_a_picture_too_narrow_for_one_dot_is_named():
    line = np.zeros((1, 400), np.uint8)
    line[0, ::2] = 255
    with pytest.raises(PlanError, match='too narrow'):
        plan_picture(line, PlanOptions())


@pytest.mark.parametrize('arguments, status, message', [
    (['MISSING.png'], 1, 'picture file not found'),
    (['sample:nothing'], 1, 'unknown sample picture'),
    (['sample:text', '--canvas-size', '0'], 2, 'canvas_size must be > 0'),
    (['sample:text', '--canvas-size', '-1'], 2, 'canvas_size must be > 0'),
    (['sample:text', '--dot-radius', 'nan'], 2, 'dot_radius must be finite'),
    (['sample:text', '--canvas-size', '0.5'], 2, 'larger than the rig can reach'),
])
def test_command_line_errors_are_one_line_without_traceback(tmp_path, capsys, arguments,
                                                            status, message):
    arguments = [a if a != 'MISSING.png' else str(tmp_path / a) for a in arguments]
    assert main(arguments + ['--out', str(tmp_path / 'out')]) == status
    error = capsys.readouterr().err
    assert error.count('\n') == 1 and error.startswith('error: ') and message in error
    assert 'Traceback' not in error


def test_blank_file_on_the_command_line(tmp_path, capsys):
    path = str(tmp_path / 'white.png')
    cv2.imwrite(path, np.full((40, 40), 255, np.uint8))
    assert main([path, '--out', str(tmp_path)]) == 1
    assert 'blank picture' in capsys.readouterr().err
