"""
The target picture I_t of paper Sec. IV-C, read from a file, an array or a sensor_msgs/Image.

Every source becomes a ``Picture``: greyscale float32 in [0, 1] (0 black, 1 white), alpha
flattened onto white (a transparent pixel is bare wood), with the name it came from and
any warnings (e.g. decimation). Sources:

- a path to any picture OpenCV reads (PNG, JPEG, BMP, TIFF, ...), 8 or 16 bit, grey,
  colour or with alpha;
- ``sample:NAME`` for a picture made by ``helio_control.samples`` (text, logo, portrait);
- a numpy array (H x W grey, H x W x 3 BGR, H x W x 4 BGRA; uint8, uint16 or float in
  [0, 1]);
- a ``sensor_msgs/Image`` through ``picture_from_image_msg`` (the one place that imports a
  message converter, lazily).

Pictures larger than ``MAX_PIXELS`` (40 megapixels) are decimated by an integer factor on
reading with a warning: a 40 cm canvas of 1 mm dots needs 400 x 400 pixels, so nothing a
dot can show is lost. Problems raise ``PictureError`` with a message naming the problem
(missing or unreadable file, empty, blank, unsupported array).
"""

from dataclasses import dataclass, field
import math
import os

import cv2
import numpy as np

MAX_PIXELS = 40_000_000        # decimate above this many pixels (documented in the README)
BLANK_CONTRAST = 2.0 / 255.0   # a picture whose 1st..99th percentile spread is below this
SAMPLE_PREFIX = 'sample:'


class PictureError(ValueError):
    """A picture that cannot be used; the message names the problem."""


@dataclass
class Picture:
    """Greyscale target picture: float32 in [0, 1], 1 = white (bare wood)."""

    grey: np.ndarray
    name: str = 'array'
    original_size: tuple = (0, 0)     # (width, height) before any decimation [px]
    warnings: list = field(default_factory=list)

    @property
    def width(self):
        """Width x_b of the picture [px]."""
        return int(self.grey.shape[1])

    @property
    def height(self):
        """Height y_b of the picture [px]."""
        return int(self.grey.shape[0])


def load_picture(source, name=None, max_pixels=MAX_PIXELS):
    """
    Return a Picture from a path, ``sample:NAME``, a numpy array or an existing Picture.

    Raise PictureError naming the problem: missing/unreadable file, empty or blank picture,
    an array of the wrong shape or type.
    """
    if isinstance(source, Picture):
        return source
    if isinstance(source, np.ndarray):
        return picture_from_array(source, name or 'array', max_pixels)
    if isinstance(source, (str, os.PathLike)):
        text = os.fspath(source)
        if text.startswith(SAMPLE_PREFIX):
            from helio_control.samples import sample_picture

            try:
                array = sample_picture(text[len(SAMPLE_PREFIX):])
            except KeyError as error:
                raise PictureError(error.args[0]) from None
            return picture_from_array(array, text, max_pixels)
        return read_picture_file(text, max_pixels)
    if hasattr(source, 'encoding') and hasattr(source, 'data'):
        return picture_from_image_msg(source, max_pixels=max_pixels)
    raise PictureError(f'cannot read a picture from a {type(source).__name__}')


def read_picture_file(path, max_pixels=MAX_PIXELS):
    """Read a picture file with OpenCV; decimate huge ones; raise PictureError on problems."""
    if not os.path.exists(path):
        raise PictureError(f'picture file not found: {path}')
    if os.path.isdir(path):
        raise PictureError(f'picture path is a directory, not a file: {path}')
    if os.path.getsize(path) == 0:
        raise PictureError(f'picture file is empty (0 bytes): {path}')
    try:
        with open(path, 'rb') as stream:
            raw = np.frombuffer(stream.read(), np.uint8)
    except OSError as error:
        raise PictureError(f'cannot read picture file {path}: {error.strerror}') from None
    width, height = _header_size(raw)
    warnings = []
    flags = cv2.IMREAD_UNCHANGED
    factor = _decimation(width, height, max_pixels)
    if factor > 1:
        reduced = {2: cv2.IMREAD_REDUCED_COLOR_2, 4: cv2.IMREAD_REDUCED_COLOR_4,
                   8: cv2.IMREAD_REDUCED_COLOR_8}
        flags = reduced[min(8, 1 << (factor - 1).bit_length())]
    try:
        array = cv2.imdecode(raw, flags)
    except cv2.error as error:
        raise PictureError(f'OpenCV cannot decode {path}: {str(error).strip()}') from None
    if array is None:
        raise PictureError(f'not a picture OpenCV can read (unknown or damaged format): {path}')
    if factor > 1:
        warnings.append(f'{path}: {width}x{height} px is above {max_pixels} px; read '
                        f'decimated to {array.shape[1]}x{array.shape[0]} px')
    picture = picture_from_array(array, path, max_pixels)
    picture.original_size = (width or array.shape[1] * factor, height or array.shape[0] * factor)
    picture.warnings[:0] = warnings
    return picture


def _header_size(raw):
    """Return (width, height) from a PNG header, else (0, 0): known before decoding."""
    if raw.size >= 24 and bytes(raw[:8]) == b'\x89PNG\r\n\x1a\n':
        width = int.from_bytes(bytes(raw[16:20]), 'big')
        return width, int.from_bytes(bytes(raw[20:24]), 'big')
    return 0, 0


def _decimation(width, height, max_pixels):
    if width * height <= max_pixels:
        return 1
    return int(math.ceil(math.sqrt(width * height / max_pixels)))


def picture_from_array(array, name='array', max_pixels=MAX_PIXELS):
    """
    Return a Picture from an H x W (grey), H x W x 3 (BGR) or H x W x 4 (BGRA) array.

    Integer arrays are scaled by their type's maximum (uint8 255, uint16 65535); float
    arrays must lie in [0, 1]. Alpha is flattened onto white. Above `max_pixels` the array
    is decimated (area average) with a warning.
    """
    array = np.asarray(array)
    if array.size == 0 or array.ndim < 2 or 0 in array.shape[:2]:
        raise PictureError(f'{name}: empty picture (shape {array.shape})')
    if array.ndim == 3 and array.shape[2] == 1:
        array = array[:, :, 0]
    if array.ndim not in (2, 3) or (array.ndim == 3 and array.shape[2] not in (3, 4)):
        raise PictureError(f'{name}: a picture must be H x W, H x W x 3 or H x W x 4, '
                           f'got shape {array.shape}')
    if array.dtype == np.bool_:
        array = array.astype(np.float32)
    if np.issubdtype(array.dtype, np.integer):
        scale = float(np.iinfo(array.dtype).max)
        values = array.astype(np.float32) / scale
    elif np.issubdtype(array.dtype, np.floating):
        values = array.astype(np.float32)
        if not np.all(np.isfinite(values)):
            raise PictureError(f'{name}: picture has NaN or infinite pixels')
        if values.min() < 0.0 or values.max() > 1.0:
            raise PictureError(f'{name}: float pixels must lie in [0, 1], got '
                               f'{values.min():g}..{values.max():g}')
    else:
        raise PictureError(f'{name}: unsupported pixel type {array.dtype}')
    warnings = []
    height, width = values.shape[:2]
    factor = _decimation(width, height, max_pixels)
    if factor > 1:
        values = cv2.resize(values, (max(1, width // factor), max(1, height // factor)),
                            interpolation=cv2.INTER_AREA)
        warnings.append(f'{name}: {width}x{height} px is above {max_pixels} px; decimated '
                        f'by {factor} to {values.shape[1]}x{values.shape[0]} px')
    grey = _to_grey(values)
    _check_not_blank(grey, name)
    return Picture(grey=np.ascontiguousarray(grey, dtype=np.float32), name=name,
                   original_size=(width, height), warnings=warnings)


def _to_grey(values):
    if values.ndim == 2:
        return values
    colour = values[:, :, :3]
    grey = cv2.cvtColor(np.ascontiguousarray(colour), cv2.COLOR_BGR2GRAY)
    if values.shape[2] == 4:
        alpha = values[:, :, 3]
        grey = alpha * grey + (1.0 - alpha)   # flattened onto white
    return grey


def _check_not_blank(grey, name):
    low, high = np.percentile(grey, [1.0, 99.0]) if grey.size > 100 else (grey.min(),
                                                                          grey.max())
    if high - low < BLANK_CONTRAST and grey.max() - grey.min() < BLANK_CONTRAST:
        raise PictureError(f'{name}: blank picture (every pixel is {float(grey.mean()):.3f} '
                           'of white): nothing to paint')


def picture_from_image_msg(msg, name='sensor_msgs/Image', max_pixels=MAX_PIXELS):
    """
    Return a Picture from a sensor_msgs/Image (rgb8, bgr8, rgba8, bgra8, mono8, mono16, ...).

    The message converter is imported here only (``image_to_numpy``; the lead's refactor
    moves it to ``helio_optics.node_kit.conversions``: repoint this one import).
    """
    from helio_optics.node_kit.conversions import image_to_numpy

    if msg.width == 0 or msg.height == 0:
        raise PictureError(f'{name}: empty image ({msg.width}x{msg.height})')
    try:
        array = image_to_numpy(msg)
    except ValueError as error:
        raise PictureError(f'{name}: {error}') from None
    if msg.encoding in ('rgb8', 'rgba8'):
        code = cv2.COLOR_RGB2BGR if msg.encoding == 'rgb8' else cv2.COLOR_RGBA2BGRA
        array = cv2.cvtColor(array, code)
    return picture_from_array(array, name, max_pixels)
