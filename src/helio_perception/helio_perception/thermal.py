"""
Thermal statistics for pyrolysis monitoring (paper Sec. IV-B, Fig. 8, Algorithm 1).

From one thermal image: the hottest reading T_max, N_p = the number of pixels at or above the
pyrolysis threshold T_p (the paper takes the camera's read-out cap, 180.9 degC, as T_p; a dot
is done when N_p >= 30 and the next starts when N_p is back to 0), the hottest pixel and
whether the reading sits at the camera cap (saturated: the true temperature may be higher).

Encodings (after `image_conversion.image_to_numpy`):

- ``16UC1``: FLIR Lepton radiometric (TLinear) centikelvin, degC = raw / 100 - 273.15;
- ``mono16``: a linear calibration degC = gain * raw + offset (parameters, gain > 0);
- ``32FC1``: degC directly (NaN pixels are ignored).

Integer images are never converted as a whole: T_p becomes the smallest raw count whose
temperature reaches it (evaluated with the same formula as the per-pixel conversion, so the
count is exactly a direct count on converted pixels) and T_max comes from the raw maximum.
"""

from dataclasses import dataclass
import math

import cv2
import numpy as np

CENTIKELVIN_GAIN = 0.01
KELVIN_OFFSET = -273.15
ENCODINGS = ('16UC1', 'mono16', '32FC1')


@dataclass
class ThermalConfig:
    """Parameters of thermal_monitor (degC unless stated)."""

    threshold: float = 180.9            # T_p, pyrolysis threshold for N_p [degC]
    camera_cap: float = 180.9           # read-out cap of the camera [degC]
    saturation_tolerance: float = 0.05  # T_max within this of the cap is saturated [K]
    mono16_gain: float = 0.01           # mono16 calibration: degC per count
    mono16_offset: float = -273.15      # mono16 calibration: degC at count 0


@dataclass
class ThermalStatistics:
    """One image's statistics (see ThermalStats.msg)."""

    t_max: float        # [degC]
    n_p: int            # pixels >= threshold [-]
    hottest_u: int      # column [px]
    hottest_v: int      # row [px]
    saturated: bool
    threshold: float    # [degC]
    camera_cap: float   # [degC]


def linear_calibration(encoding, config):
    """Return (gain, offset) of degC = gain * raw + offset for an integer encoding."""
    if encoding == '16UC1':
        return CENTIKELVIN_GAIN, KELVIN_OFFSET
    if encoding == 'mono16':
        return config.mono16_gain, config.mono16_offset
    raise ValueError(f'{encoding} has no linear calibration (expected 16UC1 or mono16)')


def raw_to_celsius(raw, encoding, config):
    """Convert raw counts (scalar or array) of an integer encoding to degC."""
    gain, offset = linear_calibration(encoding, config)
    raw = np.asarray(raw, dtype=np.float64)
    if encoding == '16UC1':
        return raw / 100.0 + offset  # centikelvin by definition
    return gain * raw + offset


def to_celsius(array, encoding, config):
    """Return the image in degC as float64 (NaN kept for 32FC1)."""
    if encoding == '32FC1':
        return np.asarray(array, dtype=np.float64)
    return raw_to_celsius(array, encoding, config)


def raw_threshold(threshold, encoding, config):
    """
    Return the smallest raw count whose temperature is >= threshold (gain > 0).

    Evaluated with `raw_to_celsius` itself, so a raw comparison equals a comparison of
    converted pixels, edge values included.
    """
    gain, offset = linear_calibration(encoding, config)
    if not gain > 0:
        raise ValueError(f'the {encoding} calibration gain must be > 0, got {gain}')
    raw = math.ceil((threshold - offset) / gain)
    while raw > 0 and raw_to_celsius(raw - 1, encoding, config) >= threshold:
        raw -= 1
    while raw_to_celsius(raw, encoding, config) < threshold:
        raw += 1
    return raw


class ThermalAnalyzer:
    """Compute ThermalStatistics; caches the raw threshold per encoding."""

    def __init__(self, config=None):
        self.config = config or ThermalConfig()
        self._raw_thresholds = {}

    def statistics(self, array, encoding):
        """Return ThermalStatistics of a (H, W) image of the given encoding."""
        config = self.config
        if encoding not in ENCODINGS:
            raise ValueError(f'thermal images must be one of {", ".join(ENCODINGS)}, '
                             f'got {encoding!r}')
        array = np.asarray(array)
        if array.ndim != 2 or array.size == 0:
            raise ValueError(f'a thermal image must be (H, W), got shape {array.shape}')
        if encoding == '32FC1':
            valid = array == array  # NaN marks invalid pixels
            if not valid.all():
                if not valid.any():
                    raise ValueError('the 32FC1 thermal image has no valid pixel (all NaN)')
                array = np.where(valid, array, -np.inf).astype(np.float32)
            _, top, _, (u, v) = cv2.minMaxLoc(array)
            t_max = float(top)
            n_p = int(np.count_nonzero(array >= np.float32(config.threshold)))
        else:
            if encoding not in self._raw_thresholds:
                self._raw_thresholds[encoding] = raw_threshold(config.threshold, encoding,
                                                               config)
            _, top, _, (u, v) = cv2.minMaxLoc(array)
            t_max = float(raw_to_celsius(top, encoding, config))
            n_p = int(np.count_nonzero(array >= self._raw_thresholds[encoding]))
        return ThermalStatistics(
            t_max=t_max, n_p=n_p, hottest_u=int(u), hottest_v=int(v),
            saturated=bool(t_max >= config.camera_cap - config.saturation_tolerance),
            threshold=config.threshold, camera_cap=config.camera_cap)
