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
in linear light (the camera's response undone), one colour channel at a time. The dot is
measured in **one channel the bare wood does not clip**: from the retreated lens the
defocused spot (several suns) lies on the dot and its surroundings, and there the wood's
red, and most of its green, is at full scale (the simulated world: 99 % and 65 % of the
pixels around a dot); a dot's blurred edge darkens such a channel by less than its headroom
and is lost, which made the mean of the channels read dots 12-25 % small. A channel is
clipped when more than ``saturated_share`` of the reference pixels reach ``saturation`` of
full scale; of the others the brightest (the most contrast) is taken.

Char is found as pixels darker than ``dark_ratio`` of the bare wood's light around the target (the
``reference_percentile`` of the grid within ``reference_reach``); char (sRGB 38, 30, 26: a linear
reflectance near 0.02) is 10-20 times darker than wood in the same light. A dark region is the
dot's when it is dark in the mean of the channels too (the unclipped channel shows the ray-traced
spot's shades, which the clipped ones hide), centred within ``max_offset_ratio`` of the expected
diameter of the target and nearer it than half way to a neighbour (a neighbour's blurred edge
spills over the cells' border), and reaches half of char's contrast to the wood around it. Around
them, beyond the camera's blur (``edge_band``), a ring ``ring_width`` wide gives the bare wood's
light *at the dot* (its median: the spot's light and the grain vary by tens of percent over
millimetres). Each pixel's char fraction is then its darkening between that light and char's
(``char_ratio`` of it), and a pixel is char where that fraction is at least one half: the char
map's own rule (char >= 0.5), which a blur that conserves light leaves on a disc's edge. A dot too
small for the blur to leave its core dark (its smoothed fraction below ``core_contrast``: under
~1.4 mm from the retreated lens, 0.3 x 0.67 mm pixels) has no such edge; its area is the sum of the
fractions over its blurred region instead (the light a blur conserves).

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
    dark_ratio: float = 0.6           # char found: darker than this share of the wood [-]
    reference_reach: float = 0.006    # the bare wood's light is taken within this [m]
    reference_percentile: float = 90.0   # ... as this percentile of the grid's light [%]
    char_ratio: float = 0.05          # char's light / the bare wood's in the same light [-]
    edge_band: float = 1.0e-3         # the camera's blur: char measured this far around [m]
    ring_width: float = 0.6e-3        # the bare wood's light at the dot: a ring this wide [m]
    core_contrast: float = 0.7        # a core this dark: the half-contrast edge; else summed
    saturation: float = 0.97          # a channel reading this share of full scale clips [-]
    saturated_share: float = 0.02     # ... in more than this share of the wood: not used
    search_ratio: float = 1.0         # a target's cell reaches this x the expected diameter
    min_region: float = 0.02          # dark regions under this x the expected area: noise
    min_diameter_ratio: float = 0.5   # charred: at least this x the expected diameter [-]
    max_offset_ratio: float = 0.5     # ... its centre within this x the expected diameter
    response: str = 'srgb'            # the camera's tone curve ('srgb' or 'linear')

    def __post_init__(self):
        """Refuse settings that cannot measure."""
        for name in ('cell', 'dark_ratio', 'reference_reach', 'search_ratio',
                     'min_diameter_ratio', 'max_offset_ratio', 'ring_width', 'core_contrast',
                     'saturation'):
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


def measure_in_mask(dark, origin, cell, target, expected, neighbours=(), settings=None):
    """
    Measure the dot of `target` in a boolean world grid `dark` (rows from y_min).

    `origin` is the world (x, y) of the grid's corner (pixel [0, 0]'s lower-left) [m], `cell`
    its pixel side [m], `expected` the expected diameter [m], `neighbours` (K, 2) the other
    targets near it (the plan's: their char is theirs). The dot's area is its pixels' count.
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
    area = float(np.sum(weight)) * cell * cell
    diameter = 2.0 * math.sqrt(area / math.pi)
    centre = (float(np.sum(weight * xs[None, :]) / np.sum(weight)),
              float(np.sum(weight * ys[:, None]) / np.sum(weight)))
    return _judged(diameter, centre, target, expected, s)


def ground_light(image, camera, T_world_camera, centre, half_width, cell, response='srgb',
                 each_channel=False):
    """
    Return (light, origin): the linear light of a square of the ground seen in `image`.

    The square is centred on `centre` (world x, y) [m], `half_width` [m] each way, on a grid
    of `cell` [m] (rows from y_min, `origin` its lower-left corner); each grid point is
    projected into the image (`camera`, a PinholeCamera with its distortion, at
    `T_world_camera`) and the image's light there interpolated (the mean of its channels,
    `response` undone; with `each_channel`, (h, w, channels) of them). NaN where the ground
    is out of the image.
    """
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f'an 8-bit image is needed, got {image.dtype.name}')
    linear = cv2.LUT(image, response_table(response))
    if linear.ndim == 3:
        linear = linear[:, :, :3] if each_channel else linear[:, :, :3].mean(axis=2)
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
    return (light[:, :, None] if each_channel and light.ndim == 2 else light), origin


def dark_of(light, origin, cell, target, settings=None):
    """Return the char mask of a `ground_light` grid: darker than the wood near `target`."""
    s = settings or CharSettings()
    near = _distance_grid(light.shape, origin, cell, target) <= s.reference_reach
    seen = light[near & np.isfinite(light)]
    if not seen.size:
        return None, math.nan
    wood = float(np.percentile(seen, s.reference_percentile))
    with np.errstate(invalid='ignore'):
        return light < s.dark_ratio * wood, wood


def _distance_grid(shape, origin, cell, target):
    """Return each grid pixel's distance to `target` [m] (rows from y_min)."""
    xs = origin[0] + (np.arange(shape[1]) + 0.5) * cell
    ys = origin[1] + (np.arange(shape[0]) + 0.5) * cell
    return np.hypot(xs[None, :] - target[0], ys[:, None] - target[1])


def unclipped_light(image, camera, T_world_camera, target, half_width, settings=None):
    """
    Return (light, origin, channel, mean): the light of a channel the wood does not clip.

    `mean` is the mean of the channels (where char is found, ``measure_in_light``).

    Each channel of `image` is resampled (``ground_light``); a channel is clipped when more
    than ``saturated_share`` of the pixels within ``reference_reach`` of `target` read
    ``saturation`` of full scale or more. Of the channels not clipped, the one whose wood is
    brightest (its ``reference_percentile``); all clipped: the least clipped. A mono frame
    has its one channel (None).
    """
    s = settings or CharSettings()
    lights, origin = ground_light(image, camera, T_world_camera, target, half_width, s.cell,
                                  s.response, each_channel=True)
    near = _distance_grid(lights.shape[:2], origin, s.cell, target) <= s.reference_reach
    best = None
    for channel in range(lights.shape[2]):
        light = np.ascontiguousarray(lights[:, :, channel])
        seen = light[near & np.isfinite(light)]
        if not seen.size:
            return light, origin, channel, light
        clipped = float(np.mean(seen >= s.saturation))
        key = (clipped > s.saturated_share, clipped if clipped > s.saturated_share else 0.0,
               -float(np.percentile(seen, s.reference_percentile)))
        if best is None or key < best[0]:
            best = (key, light, channel)
    mean = np.ascontiguousarray(np.mean(lights, axis=2), dtype=np.float32)
    return best[1], origin, (None if lights.shape[2] == 1 else best[2]), mean


def measure_in_light(light, origin, target, expected, neighbours=(), settings=None,
                     detect=None):
    """
    Measure the dot of `target` in a `ground_light` grid (linear light, rows from y_min).

    The dark regions within the target's cell (against `neighbours`) centred near it (see
    the module); the bare wood's light in a ring around them beyond ``edge_band``; each
    pixel's char fraction between that and char's light; the dot is the pixels of fraction
    >= 0.5 when its smoothed core reaches ``core_contrast``, else the sum of the fractions
    within ``edge_band`` of its darker half. Return a
    DotMeasure (judged as ``measure_in_mask`` judges). `detect`: a grid the regions must be
    dark in too (the mean of the channels: a clipped channel hides the spot's shades).
    """
    s = settings or CharSettings()
    cell = s.cell
    target = np.asarray(target, dtype=float).reshape(2)
    dark, wood = dark_of(light, origin, cell, target, s)
    if not wood > 0.0:
        return DotMeasure(False, 0.0, (math.nan, math.nan), expected,
                          'no light on the wood around the target')
    distance = _distance_grid(light.shape, origin, cell, target)
    xs = origin[0] + (np.arange(light.shape[1]) + 0.5) * cell
    ys = origin[1] + (np.arange(light.shape[0]) + 0.5) * cell
    others = [other for other in np.asarray(neighbours, dtype=float).reshape(-1, 2)
              if np.hypot(*(other - target)) > 1e-9]
    mine = distance <= s.search_ratio * expected
    for other in others:
        mine &= distance <= np.hypot(xs[None, :] - other[0], ys[:, None] - other[1])
    count, labels, stats, centroids = cv2.connectedComponentsWithStats(
        (dark & mine).astype(np.uint8), connectivity=8)
    smallest = s.min_region * math.pi * (0.5 * expected) ** 2 / (cell * cell)
    keep = np.zeros(count, dtype=bool)
    keep[1:] = stats[1:, cv2.CC_STAT_AREA] >= smallest
    if detect is not None:      # dark there too: char, not a shade a clipped channel hides
        seen, _ = dark_of(detect, origin, cell, target, s)
        if seen is not None:
            found = np.zeros(count, dtype=bool)
            found[np.unique(labels[seen])] = True
            keep &= found
    # a dot's region is centred near its target: a neighbour's blurred edge spilling over
    # the cell's border is centred on that border
    at = np.column_stack([origin[0] + (centroids[:, 0] + 0.5) * cell,
                          origin[1] + (centroids[:, 1] + 0.5) * cell])
    to_target = np.hypot(*(at - target).T)
    keep &= to_target <= s.max_offset_ratio * expected
    for other in others:
        keep &= to_target <= 0.5 * np.hypot(*(at - other).T)
    finite = np.isfinite(light)
    band = int(round(s.edge_band / cell))
    bare = finite & ~dark
    fallback = float(np.median(light[bare])) if np.any(bare) else float(np.nanmax(light))
    # char, not a shade of the spot's or the grain's: half as dark as the wood around it
    for label in np.nonzero(keep)[0]:
        region = labels == label
        level = _ring_level(light, region, band, s.ring_width / cell, bare, fallback)
        keep[label] = float(np.min(light[region])) <= level * (1.0 - 0.5 * (1.0 - s.char_ratio))
    char = keep[labels]
    if not np.any(char):
        return DotMeasure(False, 0.0, (math.nan, math.nan), expected, 'no char at the target')
    grown = _grown(char, band) & mine & finite
    level = _ring_level(light, char, band, s.ring_width / cell, bare, fallback)
    with np.errstate(invalid='ignore'):
        fraction = np.where(grown, np.minimum((level - light) / (level * (1.0 - s.char_ratio)),
                                              1.0), 0.0)
    smooth = cv2.GaussianBlur(fraction.astype(np.float32), (0, 0),
                              max(1.5e-4 / cell, 0.5))
    if float(np.max(smooth[grown])) >= s.core_contrast:
        weight = (grown & (fraction >= 0.5)).astype(float)
    else:
        # the light a blur conserves, around the dot's darkest part only (not the spot's
        # shades it touches)
        core = char & (smooth >= 0.5 * float(np.max(smooth[char])))
        weight = np.where(_grown(core, band) & grown, fraction, 0.0)
    total = float(np.sum(weight))
    if not total > 0.0:
        return DotMeasure(False, 0.0, (math.nan, math.nan), expected, 'no char at the target')
    diameter = 2.0 * math.sqrt(total * cell * cell / math.pi)
    centre = (float(np.sum(weight * xs[None, :]) / total),
              float(np.sum(weight * ys[:, None]) / total))
    return _judged(diameter, centre, target, expected, s)


def _ring_level(light, region, band, width, bare, fallback):
    """Return the median light of the bare pixels `band` to `band` + `width` px around `region`."""
    inner = _grown(region, band)
    ring = _grown(region, band + int(round(width))) & ~inner & bare
    return float(np.median(light[ring])) if np.count_nonzero(ring) >= 8 else fallback


def _grown(mask, pixels):
    """Return `mask` grown by a disc of `pixels` radius."""
    if pixels <= 0:
        return mask.copy()
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * pixels + 1, 2 * pixels + 1))
    return cv2.dilate(mask.astype(np.uint8), disc).astype(bool)


def _judged(diameter, centre, target, expected, s):
    """Return the DotMeasure of a measured dot: charred when big enough and on target."""
    offset = float(np.hypot(centre[0] - target[0], centre[1] - target[1]))
    reason = ''
    if diameter < s.min_diameter_ratio * expected:
        reason = (f'char {diameter * 1e3:.2f} mm wide, under {s.min_diameter_ratio:g} x the '
                  f'expected {expected * 1e3:.2f} mm')
    elif offset > s.max_offset_ratio * expected:
        reason = f'char centred {offset * 1e3:.2f} mm off the target'
    return DotMeasure(not reason, diameter, centre, expected, reason, offset)


def measure_in_image(image, camera, T_world_camera, target, expected, neighbours=(),
                     settings=None):
    """
    Measure the dot of `target` (world x, y) [m] in an RGB (or mono) frame; a DotMeasure.

    `camera` and `T_world_camera` are the frame's camera model and pose, `expected` the
    expected diameter [m], `neighbours` the other targets near it. The light is the
    channel the wood does not clip (``unclipped_light``), measured by ``measure_in_light``.
    """
    s = settings or CharSettings()
    half = max(s.search_ratio * expected, s.reference_reach) + 2.0 * s.cell
    light, origin, _, mean = unclipped_light(image, camera, T_world_camera, target, half, s)
    core = light[light.shape[0] // 2 - 1:light.shape[0] // 2 + 1,
                 light.shape[1] // 2 - 1:light.shape[1] // 2 + 1]
    if not np.all(np.isfinite(core)):
        return DotMeasure(False, 0.0, (math.nan, math.nan), expected,
                          'the target is out of the image')
    return measure_in_light(light, origin, target, expected, neighbours, s, detect=mean)


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
