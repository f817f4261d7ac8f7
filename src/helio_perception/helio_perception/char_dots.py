"""
Charred dots measured at their targets, in an RGB frame or in a char map (issue 29, 3-4).

The painter's per-dot verdict measures an RGB frame, the run report the world's char map:
one measure for both (and for the dot-size calibration's test dots).

A dot is measured **per target**, not per connected dark region: dots 2 mm apart touch, and
their char is one region. The dark pixels around a target are given to the nearest of the
targets (a Voronoi cell: the target against its neighbours), within ``search_ratio`` of the
expected diameter of it; the dot is their area as an equivalent diameter ``2 sqrt(A / pi)``
and their centroid, world frame. Regions smaller than ``min_region`` of the expected area
(grain, noise) are left out.

In an RGB frame (``measure_in_image``), the ground around the target is resampled onto a
world grid of ``cell`` (the camera's model and pose, distortion included:
``GroundMapping.ground_to_pixels``; a top view, so the perspective does not bend the dot),
in linear light (the camera's response undone). A pixel is char where it is darker than
``dark_ratio`` of the bare wood's light around it: the ``reference_percentile`` of the
grid within ``reference_reach`` of the target. Char (sRGB 38, 30, 26: a linear reflectance
near 0.02) is 10-20 times darker than wood in the same light, so the ratio holds in the
lens shadow, in the defocused spot of the retreated lens (where bare wood saturates), and
over the wood's grain, which varies its light by tens of percent, not by factors.

The verdict (``DotMeasure.charred``): a dot at least ``min_diameter_ratio`` of the expected
diameter, its centre within ``max_offset_ratio`` of it from the target. Pure numpy/OpenCV:
no rclpy.
"""

from dataclasses import dataclass
import math

import cv2
from helio_perception.ground_plane import GroundMapping, response_table
import numpy as np


@dataclass(frozen=True)
class CharSettings:
    """How char is told from wood and a dot judged (spot_detector's ``verify.*``)."""

    cell: float = 1.0e-4              # the world grid an RGB frame is resampled on [m]
    dark_ratio: float = 0.6           # char: darker than this share of the bare wood [-]
    reference_reach: float = 0.006    # the bare wood's light is taken within this [m]
    reference_percentile: float = 90.0   # ... as this percentile of the grid's light [%]
    char_ratio: float = 0.05          # char's light / the bare wood's in the same light [-]
    edge_band: float = 1.0e-3         # the camera's blur: char measured this far around [m]
    search_ratio: float = 1.0         # a target's cell reaches this x the expected diameter
    min_region: float = 0.02          # dark regions under this x the expected area: noise
    min_diameter_ratio: float = 0.5   # charred: at least this x the expected diameter [-]
    max_offset_ratio: float = 0.5     # ... its centre within this x the expected diameter
    response: str = 'srgb'            # the camera's tone curve ('srgb' or 'linear')

    def __post_init__(self):
        """Refuse settings that cannot measure."""
        for name in ('cell', 'dark_ratio', 'reference_reach', 'search_ratio',
                     'min_diameter_ratio', 'max_offset_ratio'):
            if not getattr(self, name) > 0.0:
                raise ValueError(f'{name} must be > 0, got {getattr(self, name)}')
        if not 0.0 < self.reference_percentile <= 100.0:
            raise ValueError('reference_percentile must be in (0, 100]')


@dataclass
class DotMeasure:
    """One target's dot as measured (world frame, metres)."""

    charred: bool
    diameter: float           # equivalent diameter of the char in the target's cell [m]
    centre: tuple             # its centroid (x, y) [m] (NaN without char)
    expected: float           # the expected diameter it was judged against [m]
    reason: str = ''          # why it is not charred ('' when it is)
    offset: float = math.nan  # centre to target [m]

    def as_dict(self):
        """Return the measure as JSON values (journal, summary)."""
        return {'charred': bool(self.charred), 'diameter': _finite(self.diameter),
                'centre': [_finite(v) for v in self.centre], 'expected': float(self.expected),
                'reason': self.reason, 'offset': _finite(self.offset)}


def _finite(value):
    return float(value) if math.isfinite(value) else None


def measure_in_mask(dark, origin, cell, target, expected, neighbours=(), settings=None,
                    coverage=None, band=0):
    """
    Measure the dot of `target` in a boolean world grid `dark` (rows from y_min).

    `origin` is the world (x, y) of the grid's corner (pixel [0, 0]'s lower-left) [m], `cell`
    its pixel side [m], `expected` the expected diameter [m], `neighbours` (K, 2) the other
    targets near it (the plan's: their char is theirs). With `coverage` (the grid's char
    fraction per pixel, 0-1), the dot's area is its sum over the char regions grown by
    `band` pixels (a camera's blur spreads an edge over them), else their pixel count.
    Return a DotMeasure.
    """
    s = settings or CharSettings()
    dark = np.asarray(dark, dtype=bool)
    target = np.asarray(target, dtype=float).reshape(2)
    reach = s.search_ratio * expected
    # the window of the grid within reach of the target
    c0 = max(0, int(math.floor((target[0] - reach - origin[0]) / cell)))
    c1 = min(dark.shape[1], int(math.ceil((target[0] + reach - origin[0]) / cell)))
    r0 = max(0, int(math.floor((target[1] - reach - origin[1]) / cell)))
    r1 = min(dark.shape[0], int(math.ceil((target[1] + reach - origin[1]) / cell)))
    if c1 <= c0 or r1 <= r0:
        return DotMeasure(False, 0.0, (math.nan, math.nan), expected, 'target off the grid')
    xs = origin[0] + (np.arange(c0, c1) + 0.5) * cell
    ys = origin[1] + (np.arange(r0, r1) + 0.5) * cell
    dx, dy = xs[None, :] - target[0], ys[:, None] - target[1]
    distance = np.hypot(dx, dy)
    mine = distance <= reach
    others = np.asarray(neighbours, dtype=float).reshape(-1, 2)
    for other in others:
        if np.hypot(*(other - target)) > 1e-9:
            mine &= distance <= np.hypot(xs[None, :] - other[0], ys[:, None] - other[1])
    region = dark[r0:r1, c0:c1] & mine
    count, labels, stats, _ = cv2.connectedComponentsWithStats(region.astype(np.uint8),
                                                               connectivity=8)
    smallest = s.min_region * math.pi * (0.5 * expected) ** 2 / (cell * cell)
    keep = np.zeros(count, dtype=bool)
    keep[1:] = stats[1:, cv2.CC_STAT_AREA] >= smallest
    char = keep[labels]
    if not np.any(char):
        return DotMeasure(False, 0.0, (math.nan, math.nan), expected, 'no char at the target')
    weight = char.astype(float)
    if coverage is not None:
        grown = cv2.dilate(char.astype(np.uint8), cv2.getStructuringElement(
            cv2.MORPH_ELLIPSE, (2 * band + 1, 2 * band + 1))).astype(bool) & mine
        weight = np.where(grown, np.nan_to_num(coverage[r0:r1, c0:c1]), 0.0)
    area = float(np.sum(weight)) * cell * cell
    diameter = 2.0 * math.sqrt(area / math.pi)
    centre = (float(np.sum(weight * xs[None, :]) / np.sum(weight)),
              float(np.sum(weight * ys[:, None]) / np.sum(weight)))
    offset = float(np.hypot(centre[0] - target[0], centre[1] - target[1]))
    reason = ''
    if diameter < s.min_diameter_ratio * expected:
        reason = (f'char {diameter * 1e3:.2f} mm wide, under {s.min_diameter_ratio:g} x the '
                  f'expected {expected * 1e3:.2f} mm')
    elif offset > s.max_offset_ratio * expected:
        reason = f'char centred {offset * 1e3:.2f} mm off the target'
    return DotMeasure(not reason, diameter, centre, expected, reason, offset)


def ground_light(image, camera, T_world_camera, centre, half_width, cell, response='srgb'):
    """
    Return (light, origin): the linear light of a square of the ground seen in `image`.

    The square is centred on `centre` (world x, y) [m], `half_width` [m] each way, on a grid
    of `cell` [m] (rows from y_min, `origin` its lower-left corner); each grid point is
    projected into the image (`camera`, a PinholeCamera with its distortion, at
    `T_world_camera`) and the image's light there interpolated (the mean of its channels,
    `response` undone). NaN where the ground is out of the image.
    """
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f'an 8-bit image is needed, got {image.dtype.name}')
    linear = cv2.LUT(image, response_table(response))
    if linear.ndim == 3:
        linear = linear[:, :, :3].mean(axis=2)
    linear = np.ascontiguousarray(linear, dtype=np.float32)
    count = int(math.ceil(half_width / cell))
    origin = (centre[0] - count * cell, centre[1] - count * cell)
    axis = (np.arange(2 * count) + 0.5) * cell
    gx, gy = np.meshgrid(origin[0] + axis, origin[1] + axis)
    points = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    mapping = GroundMapping(camera, T_world_camera)
    pixels = mapping.ground_to_pixels(points).reshape(gx.shape + (2,)).astype(np.float32)
    light = cv2.remap(linear, pixels[..., 0], pixels[..., 1], cv2.INTER_LINEAR,
                      borderMode=cv2.BORDER_CONSTANT, borderValue=math.nan)
    inside = ((pixels[..., 0] >= 0) & (pixels[..., 0] <= camera.width - 1)
              & (pixels[..., 1] >= 0) & (pixels[..., 1] <= camera.height - 1))
    light[~inside] = math.nan
    return light, origin


def dark_of(light, origin, cell, target, settings=None):
    """Return the char mask of a `ground_light` grid: darker than the wood near `target`."""
    s = settings or CharSettings()
    count = light.shape[0]
    axis = origin[1] + (np.arange(count) + 0.5) * cell
    near = np.hypot(*np.meshgrid(origin[0] + (np.arange(light.shape[1]) + 0.5) * cell
                                 - target[0], axis - target[1])) <= s.reference_reach
    seen = light[near & np.isfinite(light)]
    if not seen.size:
        return None, math.nan
    wood = float(np.percentile(seen, s.reference_percentile))
    with np.errstate(invalid='ignore'):
        return light < s.dark_ratio * wood, wood


def measure_in_image(image, camera, T_world_camera, target, expected, neighbours=(),
                     settings=None):
    """
    Measure the dot of `target` (world x, y) [m] in an RGB (or mono) frame; a DotMeasure.

    `camera` and `T_world_camera` are the frame's camera model and pose, `expected` the
    expected diameter [m], `neighbours` the other targets near it.
    """
    s = settings or CharSettings()
    half = max(s.search_ratio * expected, s.reference_reach) + 2.0 * s.cell
    light, origin = ground_light(image, camera, T_world_camera, target, half, s.cell,
                                 s.response)
    core = light[light.shape[0] // 2 - 1:light.shape[0] // 2 + 1,
                 light.shape[1] // 2 - 1:light.shape[1] // 2 + 1]
    if not np.all(np.isfinite(core)):
        return DotMeasure(False, 0.0, (math.nan, math.nan), expected,
                          'the target is out of the image')
    dark, wood = dark_of(light, origin, s.cell, target, s)
    if not wood > 0.0:
        return DotMeasure(False, 0.0, (math.nan, math.nan), expected,
                          'no light on the wood around the target')
    # the char fraction of each grid pixel from its light, between the bare wood's (the
    # median of the pixels not dark around the target) and char's in that light: blurred
    # edges count by their share, as the camera's blur conserves the light
    bare = light[np.isfinite(light) & ~dark]
    level = float(np.median(bare)) if bare.size else wood
    with np.errstate(invalid='ignore'):
        coverage = np.clip((level - light) / (level * (1.0 - s.char_ratio)), None, 1.0)
    return measure_in_mask(dark, origin, s.cell, target, expected, neighbours, s, coverage,
                           int(round(s.edge_band / s.cell)))


def measure_targets_in_mask(dark, origin, cell, targets, expected, settings=None):
    """
    Measure every target's dot in one char map (the run report's per-target figures).

    `targets` (N, 2) [m]; `expected` one diameter or one per target [m]. Each target's
    neighbours are the others within twice its reach. Return N DotMeasures.
    """
    s = settings or CharSettings()
    targets = np.asarray(targets, dtype=float).reshape(-1, 2)
    expected = np.broadcast_to(np.asarray(expected, dtype=float), (len(targets),))
    measures = []
    for target, size in zip(targets, expected):
        near = targets[np.hypot(*(targets - target).T) <= 2.0 * s.search_ratio * size]
        measures.append(measure_in_mask(dark, origin, cell, target, float(size), near, s))
    return measures
