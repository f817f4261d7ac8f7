"""
Thermal statistics for pyrolysis monitoring (paper Sec. IV-B, Fig. 8, Algorithm 1).

From one thermal image: the hottest reading T_max, N_p = the number of pixels at or above the
pyrolysis threshold T_p (the paper takes the camera's read-out cap, 180.9 degC, as T_p; a dot
is done when N_p >= 30 and the next starts when N_p is back to 0), the hottest pixel and
whether the reading sits at the camera cap (saturated: the true temperature may be higher).

Encodings (after `image_conversion.image_to_numpy`):

- ``16UC1``: FLIR Lepton radiometric (TLinear) centikelvin, degC = raw / 100 - 273.15;
- ``mono16``: a linear calibration degC = gain * raw + offset (parameters, gain > 0);
- ``32FC1``: degC directly.

Pixels that cannot be readings are ignored and counted: NaN and +-inf in 32FC1, and any
reading more than `cap_margin` above the camera's read-out cap (a camera that caps at
180.9 degC cannot read 382 degC: a stuck or dead pixel, e.g. 65535 cK). Arrays of either
byte order are read by value.

N_p for any camera range (issue 29): a camera whose read-out cap lies below T_p (a FLIR
Lepton 3.5 in high gain reads up to 140 degC) shows every pixel hotter than its cap at the
cap, so N_p counts the pixels at or above ``min(T_p, cap)`` (`ThermalConfig.counting_level`):
saturated pixels count, and the statistics' threshold is that level. The paper's rule (T_p =
the cap) is the case where both are equal. A cap below ``min_visible`` (default 100 degC:
below it the wood dries and does not char) cannot tell charring from warming, and is refused
at start (`camera_range_report`). How large a dot a given N_p target burns then depends on
the camera; the dot-size calibration (issue 29, item 3) measures it.

A frozen frame (`FreezeDetector`): a radiometric camera's pixels always differ by their
noise from one frame to the next, so a frame that repeats the last one bit for bit under a
newer stamp is the camera holding its output (a Lepton's flat-field correction, 0.3-1 s
every few minutes). A frame sent again under the same stamp (the simulated world's resend
while it waits) is not a freeze: it keeps the last frame's verdict.

Integer images are never converted as a whole: T_p becomes the smallest raw count whose
temperature reaches it (evaluated with the same formula as the per-pixel conversion, so the
count is exactly a direct count on converted pixels) and T_max comes from the raw maximum.
A reading counts as at T_p when it is within `THRESHOLD_ROUNDING` below it: a decimal T_p
and a decimal reading (238.9 degC = 51205 cK) differ by float rounding only.
"""

from dataclasses import dataclass
import math

import cv2
import numpy as np

CENTIKELVIN_GAIN = 0.01
KELVIN_OFFSET = -273.15
ENCODINGS = ('16UC1', 'mono16', '32FC1')
THRESHOLD_ROUNDING = 1e-4   # [K]: far below any thermal camera's resolution (10 mK)


@dataclass
class ThermalConfig:
    """Parameters of thermal_monitor (degC unless stated)."""

    threshold: float = 180.9            # T_p, pyrolysis threshold for N_p [degC]
    camera_cap: float = 180.9           # read-out cap of the camera [degC]
    saturation_tolerance: float = 0.05  # T_max within this of the cap is saturated [K]
    mono16_gain: float = 0.01           # mono16 calibration: degC per count
    mono16_offset: float = -273.15      # mono16 calibration: degC at count 0
    cap_margin: float = 1.0             # readings more than this above the cap are not [K]
    min_visible: float = 100.0          # a cap below this cannot see the charring [degC]

    @property
    def counting_level(self):
        """Return the level N_p counts from: T_p, or the cap when the camera reads less."""
        return min(self.threshold, self.camera_cap)


def camera_range_report(config):
    """
    Return a warning (or '') about the camera's range for N_p; ValueError if it is useless.

    A cap below ``min_visible`` saturates while the wood only warms: N_p would count the
    warm area, not the charring. A cap below T_p counts the saturated pixels instead.
    """
    if config.camera_cap < config.min_visible:
        raise ValueError(
            f'the thermal camera reads only up to {config.camera_cap:g} degC (camera_cap), '
            f'below {config.min_visible:g} degC (min_visible): it cannot tell charring wood '
            'from warm wood. Use a camera mode with a wider range (a Lepton 3.5 in low gain '
            'reads up to 400 degC; thermal_monitor camera_profile lepton35_low_gain)')
    if config.camera_cap < config.threshold:
        return (f'the thermal camera reads only up to {config.camera_cap:g} degC, below T_p '
                f'{config.threshold:g} degC: N_p counts its saturated pixels (at or above '
                f'{config.camera_cap:g} degC), so the dot an N_p target burns differs from the '
                "paper's; calibrate the dot size for this camera")
    return ''


class FreezeDetector:
    """Tell a frozen frame (the last one's pixels again under a newer stamp) from a live one."""

    def __init__(self):
        self._last = None            # (stamp, pixel bytes, verdict) of the last frame
        self.frozen_frames = 0       # frozen frames seen [-]

    def frozen(self, array, stamp):
        """Return whether `array` (the decoded image) at `stamp` [s] is a frozen frame."""
        pixels = np.ascontiguousarray(array).tobytes()
        last = self._last
        if last is not None and stamp == last[0]:
            return last[2]           # the same frame sent again: its verdict stands
        verdict = bool(last is not None and stamp > last[0] and pixels == last[1])
        self._last = (stamp, pixels, verdict)
        self.frozen_frames += verdict
        return verdict


@dataclass
class ThermalStatistics:
    """One image's statistics (see ThermalStats.msg)."""

    t_max: float        # [degC]
    n_p: int            # pixels >= threshold [-]
    hottest_u: int      # column [px]
    hottest_v: int      # row [px]
    saturated: bool
    threshold: float    # the level N_p counts from: min(T_p, cap) [degC]
    camera_cap: float   # [degC]
    ignored: int = 0    # pixels that are no reading (non-finite, above the cap) [-]
    window_n_p: int = 0            # pixels >= threshold inside the window mask [-]
    window_t_max: float = math.nan  # hottest reading inside it [degC] (NaN: no pixel)


def window_mask(mapping, shape, centre, radius):
    """
    Return the (H, W) bool mask of the pixels whose ground point lies within `radius`.

    `mapping` is the thermal camera's GroundMapping at the image's pose, `centre` the world
    (x, y) [m] of the window (the dot being heated): the painter counts N_p there only, so
    the previous dot's afterglow does not hold the next dot back (no cooling wait).
    """
    height, width = shape
    ground = mapping.grid_to_ground(np.arange(width), np.arange(height))
    with np.errstate(invalid='ignore'):
        return np.hypot(ground[..., 0] - centre[0], ground[..., 1] - centre[1]) <= radius


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
    converted pixels, edge values included; a count within THRESHOLD_ROUNDING below the
    threshold reaches it.
    """
    gain, offset = linear_calibration(encoding, config)
    if not gain > 0:
        raise ValueError(f'the {encoding} calibration gain must be > 0, got {gain}')
    threshold = threshold - THRESHOLD_ROUNDING
    raw = math.ceil((threshold - offset) / gain)
    while raw > 0 and raw_to_celsius(raw - 1, encoding, config) >= threshold:
        raw -= 1
    while raw_to_celsius(raw, encoding, config) < threshold:
        raw += 1
    return raw


class ThermalAnalyzer:
    """Compute ThermalStatistics; caches the raw thresholds per encoding."""

    def __init__(self, config=None):
        self.config = config or ThermalConfig()
        self._raw_thresholds = {}

    def statistics(self, array, encoding, window=None):
        """
        Return ThermalStatistics of a (H, W) image of the given encoding.

        `window`, a (H, W) bool mask (``window_mask``), adds N_p and T_max inside it.
        """
        config = self.config
        if encoding not in ENCODINGS:
            raise ValueError(f'thermal images must be one of {", ".join(ENCODINGS)}, '
                             f'got {encoding!r}')
        array = np.asarray(array)
        if array.ndim != 2 or array.size == 0:
            raise ValueError(f'a thermal image must be (H, W), got shape {array.shape}')
        implausible = config.camera_cap + config.cap_margin
        if encoding == '32FC1':
            if array.dtype.kind != 'f':
                raise ValueError(f'32FC1 needs a float array, got {array.dtype.name}')
            array = array.astype(np.float32, copy=False)   # native order, 32 bit
            valid = np.isfinite(array) & (array <= np.float32(implausible))
            ignored = int(array.size - np.count_nonzero(valid))
            if ignored:
                array = np.where(valid, array, -np.inf).astype(np.float32)
            level = np.float32(config.counting_level - THRESHOLD_ROUNDING)
        else:
            if array.dtype.kind not in 'ui' or array.dtype.itemsize != 2:
                raise ValueError(f'{encoding} needs a 16-bit integer array, got '
                                 f'{array.dtype.name}')
            array = array.astype(np.uint16, copy=False)   # native byte order, by value
            if encoding not in self._raw_thresholds:
                self._raw_thresholds[encoding] = (
                    raw_threshold(config.counting_level, encoding, config),
                    raw_threshold(implausible, encoding, config) + 1)
            level, too_hot = self._raw_thresholds[encoding]
            above = array >= too_hot
            ignored = int(np.count_nonzero(above))
            if ignored:
                array = np.where(above, 0, array).astype(np.uint16)
        n_p = int(np.count_nonzero(array >= level))
        if ignored == array.size:
            raise ValueError(f'the {encoding} thermal image has no plausible pixel (all '
                             f'non-finite or above {implausible:g} degC)')
        _, top, _, (u, v) = cv2.minMaxLoc(array)
        t_max = self._celsius(top, encoding)
        window_n_p, window_t_max = 0, math.nan
        if window is not None:
            if window.shape != array.shape:
                raise ValueError(f'the window mask is {window.shape}, the image {array.shape}')
            inside = array[window]
            if inside.size:
                window_n_p = int(np.count_nonzero(inside >= level))
                window_t_max = self._celsius(inside.max(), encoding)
        return ThermalStatistics(
            t_max=t_max, n_p=n_p, hottest_u=int(u), hottest_v=int(v),
            saturated=bool(t_max >= config.camera_cap - config.saturation_tolerance),
            threshold=config.counting_level, camera_cap=config.camera_cap, ignored=ignored,
            window_n_p=window_n_p, window_t_max=window_t_max)

    def _celsius(self, reading, encoding):
        """Return a reading of the encoding in degC."""
        if encoding == '32FC1':
            return float(reading)
        return float(raw_to_celsius(reading, encoding, self.config))
