"""
Find the concentrated light spot in an RGB image and measure it on the ground plane.

Paper Sec. III-C: grey scale, binary threshold, contours, the outermost contour of the spot
mapped to the ground (Eqs 7-9), its ellipse and the Eq 10 features. The paper chose the
region of interest by hand because the marker's white cells are as bright as the spot; here
the candidates are filtered automatically:

1. the marker, its quiet zone and the white paper sheet it is printed on (the bright region
   connected to the quiet zone, found once per marker pose) are masked out;
2. the threshold follows the frame ('auto': a multiple of the bright end of the frame's
   diffuse light, capped at the fixed level), so an unsaturated spot is still a candidate;
3. each remaining bright region must have a plausible ground area, be compact (its contour
   area close to its fitted ellipse's, and close to its convex hull's);
4. several survivors: one carrying `dominance` times the light of each other one is the
   spot (a lens reflection is much fainter than the focus), else the one nearest the last
   spot when it is clearly the nearest, else the frame is reported ambiguous.

The chosen region is then measured in LINEAR light (the camera's tone curve undone by a
table, `response`) at the half-way level between its local background and its peak (the
edge of a blurred spot, unbiased by the detection threshold and by the sRGB curve), pixel by
pixel on the ground: each pixel contributes the ground area of its footprint, so the area,
centre and second moments (hence the ellipse) are exact in the world frame, perspective
included. Its quality says whether the measure is complete (see SpotObservation.msg): cut by
the image border, occluded (its outline borders something much darker than its background,
or the masked marker sheet), or blurred (set by the observer from the marker's edges).
"""

from dataclasses import dataclass, field

import cv2
from helio_optics import spot
from helio_optics.geometry import transform_points, transform_vectors
from helio_perception.ground_plane import percentile_level, response_table, RESPONSES
import numpy as np

THRESHOLD_MODES = ('auto', 'fixed', 'otsu')
# SpotObservation.quality (helio_msgs): the same numbers
QUALITY_NONE, QUALITY_FULL, QUALITY_CUT_BY_BORDER, QUALITY_OCCLUDED, QUALITY_BLURRED = range(5)
QUALITY_NAMES = {QUALITY_NONE: 'none', QUALITY_FULL: 'full',
                 QUALITY_CUT_BY_BORDER: 'cut by the image border', QUALITY_OCCLUDED: 'occluded',
                 QUALITY_BLURRED: 'blurred'}
_KERNEL = np.ones((3, 3), np.uint8)


@dataclass
class SpotConfig:
    """Detection parameters (node parameters of spot_detector)."""

    threshold_mode: str = 'auto'    # 'auto', 'fixed' or 'otsu'
    threshold: float = 220.0        # grey level for 'fixed', the ceiling of 'auto' [0-255]
    relative_threshold: float = 1.5  # 'auto': this x the frame's bright diffuse light [-]
    min_threshold: float = 100.0    # floor of 'auto' and of the Otsu threshold [0-255]
    blur_kernel: int = 5            # Gaussian blur before thresholding, odd [px] (<= 1: none)
    min_pixels: int = 12            # smallest region [px]
    min_area: float = 2e-7          # smallest spot on the ground [m^2]
    max_area: float = 2e-3          # largest spot on the ground [m^2]
    min_fill: float = 0.8           # contour area / fitted ellipse area, lower bound [-]
    max_fill: float = 1.2           # upper bound [-]
    min_solidity: float = 0.9       # contour area / convex hull area [-]
    marker_margin: float = 0.008    # masked border around the marker's black square [m]
    sheet_level: float = 0.6        # marker paper: brighter than this x its quiet zone [-]
    max_jump: float = 0.02          # largest move from the last spot to be the same spot [m]
    expected_max_age: float = 2.0   # how long the last spot predicts the next [s]
    dominance: float = 4.0          # light ratio that singles out one candidate [-] (0: off)
    saturation_level: float = 250.0  # grey level counted as saturated [0-255]
    refine_margin: int = 4          # pixels around the region for the half-level measure [px]
    edge_band: int = 2              # band around the contour measured fractionally [px]
    border_margin: int = 2          # a spot this close to the image border is cut [px]
    occlusion_level: float = 0.5    # outline neighbours darker than this x background [-]
    max_occluded_fraction: float = 0.1  # occluded when more of the outline borders them [-]
    response: str = 'srgb'          # the camera's tone curve: 'srgb' or 'linear'


@dataclass
class SpotResult:
    """
    One light-spot observation (world frame unless stated); see SpotObservation.msg.

    `measured`: a spot was found and measured (the ellipse fields hold its measure);
    `quality` one of QUALITY_*; `valid` = measured with quality FULL.
    """

    valid: bool = False
    reason: str = ''
    center: np.ndarray = field(default_factory=lambda: np.zeros(3))
    semi_major: float = 0.0
    semi_minor: float = 0.0
    orientation: float = 0.0        # world x to major axis [rad]
    area: float = 0.0               # [m^2]
    contour: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    pixel_count: int = 0
    saturated: bool = False
    pixel_center: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))
    candidates: int = 0
    rejected: dict = field(default_factory=dict)
    measured: bool = False
    quality: int = QUALITY_NONE
    quality_reason: str = ''
    threshold: float = float('nan')  # the grey level the candidates were cut at [0-255]

    @property
    def eccentricity(self):
        """Return sqrt(1 - (b/a)^2) of the ellipse [-]."""
        if self.semi_major <= 0:
            return 0.0
        return float(np.sqrt(max(0.0, 1.0 - (self.semi_minor / self.semi_major) ** 2)))

    def degrade(self, quality, reason):
        """Mark a measured spot as not complete: `quality` with its reason; not valid."""
        if self.quality in (QUALITY_NONE, QUALITY_FULL):
            self.quality, self.quality_reason = quality, reason
        self.valid = False
        if self.measured:
            self.reason = f'spot {QUALITY_NAMES[self.quality]}: {self.quality_reason}'


@dataclass
class SpotFeatures:
    """Eq 10 features y = [Pi, Theta] and the Sec. V-B orientation/shape features."""

    frame: str
    pi: float
    theta: float
    axis_angle: float
    eccentricity: float


def position_features(result, T_frame_world=None, frame='world'):
    """
    Compute Eq 10's y = [Pi, Theta] from the ellipse centre in a frame.

    Eq 10 itself is `helio_optics.spot.position_features` (one implementation); this adds
    the change of frame (Eq 9) and the major-axis angle.

    With `T_frame_world` (e.g. T_optics_world, Eq 9) the centre and major axis are expressed
    in that frame first; otherwise in the world frame. Pi = sqrt(xc^2 + yc^2) [m],
    Theta = atan2(yc, xc) [rad], axis_angle = angle of the major axis in the frame's x-y
    plane [rad].
    """
    center = np.asarray(result.center, dtype=float)
    axis = np.array([np.cos(result.orientation), np.sin(result.orientation), 0.0])
    if T_frame_world is not None:
        center = transform_points(T_frame_world, center)
        axis = transform_vectors(T_frame_world, axis)
    else:
        frame = 'world'
    pi, theta = spot.position_features(center[:2])
    return SpotFeatures(frame=frame, pi=float(pi), theta=float(theta),
                        axis_angle=float(np.arctan2(axis[1], axis[0])),
                        eccentricity=result.eccentricity)


def to_gray(image, channel_order='rgb'):
    """Return an 8-bit grey image from mono8 (H, W), rgb/bgr (H, W, 3) or rgba/bgra (H, W, 4)."""
    if image.dtype != np.uint8:
        raise ValueError(f'spot detection needs 8-bit images, got {image.dtype.name}')
    if image.ndim == 2:
        return image
    codes = {('rgb', 3): cv2.COLOR_RGB2GRAY, ('bgr', 3): cv2.COLOR_BGR2GRAY,
             ('rgb', 4): cv2.COLOR_RGBA2GRAY, ('bgr', 4): cv2.COLOR_BGRA2GRAY}
    code = codes.get((channel_order, image.shape[2]))
    if code is None:
        raise ValueError(f'cannot make grey from {image.shape[2]} {channel_order} channels')
    return cv2.cvtColor(image, code)


class SpotDetector:
    """Detect the light spot; keeps the last measured spot to predict the next one."""

    def __init__(self, config=None):
        self.config = config or SpotConfig()
        if self.config.threshold_mode not in THRESHOLD_MODES:
            raise ValueError(f'threshold_mode must be one of {THRESHOLD_MODES}, got '
                             f'{self.config.threshold_mode!r}')
        if self.config.response not in RESPONSES:
            raise ValueError(f'response must be one of {RESPONSES}, got '
                             f'{self.config.response!r}')
        self.to_linear = response_table(self.config.response)
        self.last_center = None
        self.last_stamp = None

    def detect(self, gray, mapping, marker_side=None, stamp=0.0):
        """
        Find and measure the spot in a grey image with a GroundMapping for this frame.

        `marker_side` [m] (the black square) enables the marker and sheet mask. Return a
        SpotResult (its `quality` says whether the measure is complete).
        """
        config = self.config
        k = int(config.blur_kernel)
        blurred = cv2.GaussianBlur(gray, (k | 1, k | 1), 0) if k > 1 else gray
        masked = self.marker_mask(gray, mapping, marker_side) if marker_side else None
        reference = self.reference_light(blurred, None if masked is None else masked[1])
        if config.threshold_mode == 'otsu':
            level, binary = cv2.threshold(blurred, 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
            if level < config.min_threshold:
                level, binary = cv2.threshold(blurred, config.min_threshold, 255,
                                              cv2.THRESH_BINARY)
        else:
            level = config.threshold if config.threshold_mode == 'fixed' \
                else self.auto_threshold(reference)
            _, binary = cv2.threshold(blurred, level, 255, cv2.THRESH_BINARY)
        if masked is not None:
            cv2.bitwise_and(binary, masked[1], dst=binary)
        contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        candidates, rejected = self._filter(contours, mapping)
        result = SpotResult(candidates=len(candidates), rejected=rejected, threshold=level)
        if not candidates:
            detail = ', '.join(f'{n} {why}' for why, n in sorted(rejected.items()))
            result.reason = 'no spot' + (f' (bright regions rejected: {detail})' if detail
                                         else ': nothing above the threshold outside the marker')
            return result
        chosen = candidates[0] if len(candidates) == 1 else self._disambiguate(
            candidates, blurred, reference, stamp)
        if chosen is None:
            result.reason = (f'ambiguous: {len(candidates)} spot candidates, none '
                             f'{config.dominance:g}x brighter than the others and no recent '
                             'spot to tell them apart')
            return result
        self._measure(gray, blurred, chosen, mapping, None if masked is None else masked[0],
                      result)
        if result.measured:
            self.last_center, self.last_stamp = result.center[:2].copy(), stamp
        return result

    def reference_light(self, blurred, keep=None):
        """
        Return the bright end of the frame's diffuse light: the 95th percentile [linear].

        Sampled every 8th pixel outside the marker mask (`keep` 255 where not masked). The
        spot covers far less than 5 % of a frame, so this is the brightest lit panel (or
        whatever else fills the view), not the spot.
        """
        sample = np.ascontiguousarray(blurred[::8, ::8])
        mask = None if keep is None else np.ascontiguousarray(keep[::8, ::8])
        return float(self.to_linear[percentile_level(sample, mask, 95.0)])

    def auto_threshold(self, reference):
        """
        Return the 'auto' grey level: `relative_threshold` x the reference light.

        In linear light (the tone curve undone), clamped to [min_threshold, threshold]: the
        fixed level when the scene is bright, lower for an unsaturated spot on a dim panel.
        """
        config = self.config
        level = float(np.searchsorted(self.to_linear, config.relative_threshold * reference))
        return float(min(max(level, config.min_threshold), config.threshold))

    def marker_mask(self, gray, mapping, side):
        """
        Return (masked, keep) uint8 images of the marker and its paper, or None (not seen).

        `masked` is 1 on the marker's black square with `marker_margin` around it and on its
        white sheet: the region brighter than `sheet_level` x the quiet zone's light that is
        connected to the quiet zone (grown by 2 px for the blur). `keep` is 255 elsewhere.
        Found once per marker pose (cached in the mapping): the panel must be darker than
        the paper; if the bright region covers half the frame it is not taken as the sheet.
        """
        config = self.config
        key = ('marker_mask', side, config.marker_margin, config.sheet_level)
        if key not in mapping.cache:
            mapping.cache[key] = self._marker_mask(gray, mapping, side)
        return mapping.cache[key]

    def _marker_mask(self, gray, mapping, side):
        config = self.config
        polygon = _ground_square_pixels(mapping, side / 2.0 + config.marker_margin)
        if polygon is None:
            return None
        masked = np.zeros(gray.shape, np.uint8)
        cv2.fillConvexPoly(masked, np.rint(polygon).astype(np.int32), 1)
        if config.sheet_level > 0:
            sheet = self._sheet(gray, mapping, side)
            if sheet is not None:
                masked |= sheet
        return masked, (1 - masked) * np.uint8(255)

    def _sheet(self, gray, mapping, side):
        """Return the marker's paper sheet (uint8 0/1 image) or None."""
        inner = _ground_square_pixels(mapping, side / 2.0 + 0.0007)
        outer = _ground_square_pixels(mapping, side / 2.0 + 0.0022)
        if inner is None or outer is None:
            return None
        ring = np.zeros(gray.shape, np.uint8)
        cv2.fillConvexPoly(ring, np.rint(outer).astype(np.int32), 1)
        cv2.fillConvexPoly(ring, np.rint(inner).astype(np.int32), 0)
        levels = gray[ring > 0]
        if levels.size < 8:
            return None
        white = float(self.to_linear[int(np.median(levels))])
        level = int(np.searchsorted(self.to_linear, self.config.sheet_level * white))
        bright = (gray >= max(level, 1)).astype(np.uint8)
        fill = np.zeros((gray.shape[0] + 2, gray.shape[1] + 2), np.uint8)
        seeds = np.argwhere((ring > 0) & (bright > 0))
        for v, u in seeds[::max(len(seeds) // 32, 1)]:
            if not fill[v + 1, u + 1]:
                cv2.floodFill(bright, fill, (int(u), int(v)), 1, 0, 0,
                              4 | cv2.FLOODFILL_MASK_ONLY | (1 << 8))
        sheet = fill[1:-1, 1:-1]
        if np.count_nonzero(sheet) > 0.5 * sheet.size:
            return None  # the panel is as bright as the paper: no sheet to tell apart
        return cv2.dilate(sheet, _KERNEL, iterations=2)

    def _filter(self, contours, mapping):
        config = self.config
        shapes, rejected = [], {}

        def reject(why):
            rejected[why] = rejected.get(why, 0) + 1

        for contour in contours:
            if len(contour) < 5:
                continue
            pixels = cv2.contourArea(contour)
            if pixels < config.min_pixels:
                continue
            (cu, cv), axes, _ = cv2.fitEllipse(contour)
            ellipse_pixels = np.pi * axes[0] * axes[1] / 4.0
            fill = pixels / ellipse_pixels if ellipse_pixels > 0 else 0.0
            if not config.min_fill <= fill <= config.max_fill:
                reject('not elliptical')
                continue
            hull = cv2.contourArea(cv2.convexHull(contour))
            if hull <= 0 or pixels / hull < config.min_solidity:
                reject('not convex')
                continue
            shapes.append((contour, cu, cv, pixels))
        candidates = []
        for contour, cu, cv, pixels in shapes:
            # ground area of the region from the ground area of one pixel at its centre
            area = pixels * mapping.pixel_area(cu, cv)
            if not np.isfinite(area):
                reject('off the ground')
            elif area < config.min_area:
                reject('too small')
            elif area > config.max_area:
                reject('too large')
            else:
                centre = mapping.pixels_to_ground([[cu, cv]])[0, :2] if len(shapes) > 1 \
                    else None
                candidates.append((contour, centre, (cu, cv), area))
        return candidates, rejected

    def _disambiguate(self, candidates, blurred, reference, stamp):
        """
        Return the candidate that is the spot, or None.

        One carrying `dominance` times the light of every other one (ground area times mean
        linear light above the reference light; a lens reflection is much fainter than the
        focus); else the one nearest the last spot if it is within `max_jump` and every
        other one is more than twice as far.
        """
        config = self.config
        if config.dominance > 0:
            light = np.array([area * max(self._mean_light(blurred, contour) - reference,
                                         1e-6)
                              for contour, _, _, area in candidates])
            order = np.argsort(light)[::-1]
            if light[order[0]] >= config.dominance * light[order[1]]:
                return candidates[order[0]]
        if self.last_center is None or stamp - self.last_stamp > config.expected_max_age:
            return None
        distances = np.array([np.linalg.norm(c[1] - self.last_center) if c[1] is not None
                              else np.inf for c in candidates])
        order = np.argsort(distances)
        if distances[order[0]] <= config.max_jump and \
                distances[order[1]] > 2.0 * distances[order[0]]:
            return candidates[order[0]]
        return None

    def _mean_light(self, blurred, contour):
        """Return the mean linear light inside a contour (of the blurred grey image)."""
        x, y, w, h = cv2.boundingRect(contour)
        region = np.zeros((h, w), np.uint8)
        cv2.drawContours(region, [contour], -1, 1, thickness=cv2.FILLED, offset=(-x, -y))
        patch = cv2.LUT(np.ascontiguousarray(blurred[y:y + h, x:x + w]), self.to_linear)
        return float(cv2.mean(patch, mask=region)[0])

    def _measure(self, gray, blurred, chosen, mapping, masked, result):
        """Measure the chosen region at its half level (linear light), footprints on ground."""
        config = self.config
        contour = chosen[0]
        height, width = gray.shape
        x, y, w, h = cv2.boundingRect(contour)
        # a defocused or blurred spot's halo reaches past the thresholded region, more so
        # the larger the spot: the ring that gives the background starts beyond it
        halo = max(2, int(round(0.5 * np.sqrt(cv2.contourArea(contour) / np.pi))))
        m = int(config.refine_margin) + int(config.edge_band) + 2 + halo
        x0, y0 = max(x - m, 0), max(y - m, 0)
        x1, y1 = min(x + w + m, width), min(y + h + m, height)
        roi8 = gray[y0:y1, x0:x1]
        roi = cv2.LUT(np.ascontiguousarray(roi8), self.to_linear)
        region = np.zeros(roi.shape, np.uint8)
        cv2.drawContours(region, [contour], -1, 1, thickness=cv2.FILLED, offset=(-x0, -y0))
        near = _grow(region, max(int(config.refine_margin) - 1, 1) + halo)
        # the spot is the region above the half level between its local background (the
        # ring around it) and its core, in linear light: the edge of a blurred spot,
        # unbiased along straight edges
        ring = (1 - near) if masked is None else (1 - near) & (1 - masked[y0:y1, x0:x1])
        # the median: the ring may reach past the lens shadow's edge in a grazing view
        background = float(self.to_linear[percentile_level(roi8, ring, 50.0)]) \
            if cv2.countNonZero(ring) else 0.0
        core = _shrink(region, 2)
        if cv2.countNonZero(core):
            top = cv2.mean(roi, mask=core)[0]
        else:
            top = float(self.to_linear[int(cv2.minMaxLoc(blurred[y0:y1, x0:x1],
                                                         mask=region)[1])])
        contrast = max(top - background, 1e-3)
        half = 0.5 * (background + top)
        inside = (roi > np.float32(half)).astype(np.uint8) & near
        # only what is connected to the chosen region (not a neighbour's edge in reach)
        count, labels = cv2.connectedComponents(inside, connectivity=8)
        if count > 2:   # background and more than one piece
            own = np.zeros(count, np.uint8)
            own[labels[(region > 0) & (inside > 0)]] = 1
            own[0] = 0
            inside = own[labels]
        count = cv2.countNonZero(inside)
        if count < config.min_pixels:
            result.reason = (f'spot too faint: {count} px above the half level between '
                             f'{background:.3f} and {top:.3f} (linear)')
            return
        # Blur moves the half-level contour inwards where it curves (by pi sigma^2 px^2 in
        # all, the curvature of a closed contour integrating to 2 pi): the light in a narrow
        # band around the contour counts as fractional coverage (I - background) / contrast.
        band_width = int(config.edge_band)
        if band_width > 0:
            band = _grow(inside, band_width) - _shrink(inside, band_width)
            fraction = np.clip((roi - np.float32(background)) * np.float32(1.0 / contrast),
                               -0.5, 1.5)
            coverage = np.where(band > 0, fraction, inside.astype(np.float32))
        else:
            coverage = inside.astype(np.float32)
        outline, _ = cv2.findContours(inside, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        outline = max(outline, key=cv2.contourArea).reshape(-1, 2)
        # every pixel's ground centre and footprint area (Eqs 7-8)
        centres, footprint = mapping.pixel_footprints(x0, x1, y0, y1)
        if np.isnan(footprint).any():
            result.reason = 'spot not on the ground plane (rays miss it)'
            return
        weights = (footprint * coverage).ravel()
        points = centres.reshape(-1, 2)
        area = float(weights.sum())
        if not area > 0:
            result.reason = 'spot has no area on the ground'
            return
        center = weights @ points / area
        offsets = points - center
        covariance = (offsets * weights[:, None]).T @ offsets / area
        # a pixel's own extent adds its second moment (a square of area s^2: s^2 / 12)
        covariance += np.eye(2) * float(weights @ footprint.ravel()) / area / 12.0
        eigenvalues, eigenvectors = np.linalg.eigh(covariance)
        major = eigenvectors[:, 1]
        orientation = float(np.arctan2(major[1], major[0]))
        if orientation <= -np.pi / 2:
            orientation += np.pi
        elif orientation > np.pi / 2:
            orientation -= np.pi
        result.measured = result.valid = True
        result.quality, result.reason = QUALITY_FULL, ''
        result.center = np.array([center[0], center[1], 0.0])
        result.semi_major = float(2.0 * np.sqrt(max(eigenvalues[1], 0.0)))
        result.semi_minor = float(2.0 * np.sqrt(max(eigenvalues[0], 0.0)))
        result.orientation = orientation
        result.area = area
        result.contour = mapping.pixels_to_ground(outline + (x0, y0))
        result.contour[:, 2] = 0.0
        result.pixel_count = count
        saturated = cv2.countNonZero(cv2.inRange(roi8, config.saturation_level, 255) & inside)
        result.saturated = bool(saturated > count // 2)
        moments = cv2.moments(inside, binaryImage=True)
        result.pixel_center = np.array([moments['m10'] / moments['m00'] + x0,
                                        moments['m01'] / moments['m00'] + y0])
        self._judge(roi, inside, background, masked, (x0, y0, x1, y1), gray.shape, result)

    def _judge(self, roi, inside, background, masked, box, shape, result):
        """Set the quality of a measured spot: cut by the border, occluded, or full."""
        config = self.config
        x0, y0, x1, y1 = box
        grown = _grow(inside, int(config.edge_band) + 1)
        gx, gy, gw, gh = cv2.boundingRect(grown)
        margin = int(config.border_margin)
        if gx + x0 < margin or gy + y0 < margin or gx + gw + x0 > shape[1] - margin \
                or gy + gh + y0 > shape[0] - margin:
            result.degrade(QUALITY_CUT_BY_BORDER, 'its light reaches the image border')
            return
        if masked is not None and np.any(grown & masked[y0:y1, x0:x1]):
            result.degrade(QUALITY_OCCLUDED, 'it touches the masked marker sheet')
            return
        # the outline's neighbours, 2-4 px out, are at least as bright as the background
        # (the lens shadow the spot sits in, plus the spot's own halo) unless something
        # borders part of the spot: an object in front, a char mark (whose dark wood also
        # shrinks the spot's light on that side)
        near_outline = _grow(inside, 2)
        outside = _grow(near_outline, 2) - near_outline
        levels = roi[outside > 0]
        if levels.size == 0 or not background > 0:
            return
        dark = float(np.mean(levels < np.float32(config.occlusion_level * background)))
        if dark > config.max_occluded_fraction:
            result.degrade(QUALITY_OCCLUDED, f'{100 * dark:.0f} % of its outline borders '
                           f'something darker than {config.occlusion_level:g} x its '
                           'background')


def _grow(mask, pixels):
    """Return `mask` dilated by `pixels` (a square: as many 3x3 dilations, in one pass)."""
    return cv2.dilate(mask, _square(pixels))


def _shrink(mask, pixels):
    """Return `mask` eroded by `pixels` (a square: as many 3x3 erosions, in one pass)."""
    return cv2.erode(mask, _square(pixels))


def _square(pixels, _kernels={}):
    """Return the (2 pixels + 1) square structuring element (kept)."""
    if pixels not in _kernels:
        _kernels[pixels] = np.ones((2 * pixels + 1, 2 * pixels + 1), np.uint8)
    return _kernels[pixels]


def _ground_square_pixels(mapping, half):
    """Return the pixels (4, 2) of the ground square of half side `half` [m] at the origin."""
    square = np.array([[-half, half, 0.0], [half, half, 0.0], [half, -half, 0.0],
                       [-half, -half, 0.0]])
    in_camera = transform_points(mapping.T_camera_world, square)
    if np.any(in_camera[:, 2] <= 0):
        return None
    return mapping.ground_to_pixels(square)
