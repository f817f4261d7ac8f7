"""
Find the concentrated light spot in an RGB image and measure it on the ground plane.

Paper Sec. III-C: grey scale, binary threshold, contours, the outermost contour of the spot
mapped to the ground (Eqs 7-9), its ellipse and the Eq 10 features. The paper chose the
region of interest by hand because the marker's white cells are as bright as the spot; here
the candidates are filtered automatically:

1. the marker and its quiet zone (projected through the current marker pose) are masked out;
2. each remaining bright region must have a plausible ground area, be compact (its contour
   area close to its fitted ellipse's, and close to its convex hull's);
3. several survivors are disambiguated by the last observation (the spot moves little
   between frames); if that does not single one out the frame is reported ambiguous.

The chosen region is then measured at the half-way level between its local background and
its peak (the edge of a blurred spot, unbiased by the detection threshold), pixel by pixel
on the ground: each pixel contributes the ground area of its footprint, so the area, centre
and second moments (hence the ellipse) are exact in the world frame, perspective included.
"""

from dataclasses import dataclass, field

import cv2
from helio_optics import spot
from helio_optics.geometry import transform_points, transform_vectors
import numpy as np

THRESHOLD_MODES = ('fixed', 'otsu')
_KERNEL = np.ones((3, 3), np.uint8)


@dataclass
class SpotConfig:
    """Detection parameters (node parameters of spot_detector)."""

    threshold_mode: str = 'fixed'   # 'fixed' or 'otsu'
    threshold: float = 220.0        # grey level for 'fixed' [0-255]
    min_threshold: float = 100.0    # floor of the Otsu threshold [0-255]
    blur_kernel: int = 5            # Gaussian blur before thresholding, odd [px] (<= 1: none)
    min_pixels: int = 12            # smallest region [px]
    min_area: float = 2e-7          # smallest spot on the ground [m^2]
    max_area: float = 2e-3          # largest spot on the ground [m^2]
    min_fill: float = 0.8           # contour area / fitted ellipse area, lower bound [-]
    max_fill: float = 1.2           # upper bound [-]
    min_solidity: float = 0.9       # contour area / convex hull area [-]
    marker_margin: float = 0.008    # masked border around the marker's black square [m]
    max_jump: float = 0.02          # largest move from the last spot to be the same spot [m]
    expected_max_age: float = 2.0   # how long the last spot predicts the next [s]
    saturation_level: float = 250.0  # grey level counted as saturated [0-255]
    refine_margin: int = 4          # pixels around the region for the half-level measure [px]
    edge_band: int = 2              # band around the contour measured fractionally [px]


@dataclass
class SpotResult:
    """One light-spot observation (world frame unless stated); see SpotObservation.msg."""

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

    @property
    def eccentricity(self):
        """Return sqrt(1 - (b/a)^2) of the ellipse [-]."""
        if self.semi_major <= 0:
            return 0.0
        return float(np.sqrt(max(0.0, 1.0 - (self.semi_minor / self.semi_major) ** 2)))


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
    """Detect the light spot; keeps the last valid spot to predict the next one."""

    def __init__(self, config=None):
        self.config = config or SpotConfig()
        if self.config.threshold_mode not in THRESHOLD_MODES:
            raise ValueError(f'threshold_mode must be one of {THRESHOLD_MODES}, got '
                             f'{self.config.threshold_mode!r}')
        self.last_center = None
        self.last_stamp = None

    def detect(self, gray, mapping, marker_side=None, stamp=0.0):
        """
        Find and measure the spot in a grey image with a GroundMapping for this frame.

        `marker_side` [m] (the black square) enables the marker mask. Return a SpotResult.
        """
        config = self.config
        k = int(config.blur_kernel)
        blurred = cv2.GaussianBlur(gray, (k | 1, k | 1), 0) if k > 1 else gray
        if config.threshold_mode == 'otsu':
            level, binary = cv2.threshold(blurred, 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
            if level < config.min_threshold:
                _, binary = cv2.threshold(blurred, config.min_threshold, 255, cv2.THRESH_BINARY)
        else:
            _, binary = cv2.threshold(blurred, config.threshold, 255, cv2.THRESH_BINARY)
        if marker_side:
            key = ('marker_polygon', marker_side, config.marker_margin)
            if key not in mapping.cache:
                mapping.cache[key] = self._marker_polygon(mapping, marker_side)
            polygon = mapping.cache[key]
            if polygon is not None:
                cv2.fillConvexPoly(binary, polygon, 0)
        contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        candidates, rejected = self._filter(contours, mapping)
        result = SpotResult(candidates=len(candidates), rejected=rejected)
        if not candidates:
            detail = ', '.join(f'{n} {why}' for why, n in sorted(rejected.items()))
            result.reason = 'no spot' + (f' (bright regions rejected: {detail})' if detail
                                         else ': nothing above the threshold outside the marker')
            return result
        chosen = candidates[0] if len(candidates) == 1 else self._disambiguate(
            candidates, stamp)
        if chosen is None:
            result.reason = (f'ambiguous: {len(candidates)} spot candidates and no recent spot '
                             'to tell them apart')
            return result
        self._measure(gray, blurred, chosen, mapping, result)
        if result.valid:
            self.last_center, self.last_stamp = result.center[:2].copy(), stamp
        return result

    def _marker_polygon(self, mapping, side):
        h = side / 2.0 + self.config.marker_margin
        square = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
        in_camera = transform_points(mapping.T_camera_world, square)
        if np.any(in_camera[:, 2] <= 0):
            return None
        return np.rint(mapping.ground_to_pixels(square)).astype(np.int32)

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
                candidates.append((contour, centre, (cu, cv)))
        return candidates, rejected

    def _disambiguate(self, candidates, stamp):
        config = self.config
        if self.last_center is None or stamp - self.last_stamp > config.expected_max_age:
            return None
        near = [c for c in candidates
                if c[1] is not None
                and np.linalg.norm(c[1] - self.last_center) <= config.max_jump]
        return near[0] if len(near) == 1 else None

    def _measure(self, gray, blurred, chosen, mapping, result):
        """Measure the chosen region at its half level, pixel footprints on the ground."""
        config = self.config
        contour = chosen[0]
        height, width = gray.shape
        x, y, w, h = cv2.boundingRect(contour)
        m = int(config.refine_margin) + int(config.edge_band)
        x0, y0 = max(x - m, 0), max(y - m, 0)
        x1, y1 = min(x + w + m, width), min(y + h + m, height)
        roi = gray[y0:y1, x0:x1]
        region = np.zeros(roi.shape, np.uint8)
        cv2.drawContours(region, [contour], -1, 1, thickness=cv2.FILLED, offset=(-x0, -y0))
        near = cv2.dilate(region, _KERNEL, iterations=max(int(config.refine_margin) - 1, 1))
        # the spot is the region above the half level between its local background (the
        # ring around it) and its core: the edge of a blurred spot, unbiased along straight
        # edges
        background = cv2.mean(roi, mask=1 - near)[0] if near.size > np.count_nonzero(near) \
            else 0.0
        core = cv2.erode(region, _KERNEL, iterations=2)
        if cv2.countNonZero(core):
            top = cv2.mean(roi, mask=core)[0]
        else:
            top = float(cv2.minMaxLoc(blurred[y0:y1, x0:x1], mask=region)[1])
        contrast = max(top - background, 1.0)
        _, inside = cv2.threshold(roi, 0.5 * (background + top), 1, cv2.THRESH_BINARY)
        inside &= near
        count = cv2.countNonZero(inside)
        if count < config.min_pixels:
            result.reason = (f'spot too faint: {count} px above the half level between '
                             f'{background:.0f} and {top:.0f}')
            return
        # Blur moves the half-level contour inwards where it curves (by pi sigma^2 px^2 in
        # all, the curvature of a closed contour integrating to 2 pi): the light in a narrow
        # band around the contour counts as fractional coverage (I - background) / contrast.
        band_width = int(config.edge_band)
        if band_width > 0:
            band = cv2.dilate(inside, _KERNEL, iterations=band_width) \
                - cv2.erode(inside, _KERNEL, iterations=band_width)
            fraction = np.clip((roi.astype(np.float32) - np.float32(background))
                               * np.float32(1.0 / contrast), -0.5, 1.5)
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
        result.valid = True
        result.reason = ''
        result.center = np.array([center[0], center[1], 0.0])
        result.semi_major = float(2.0 * np.sqrt(max(eigenvalues[1], 0.0)))
        result.semi_minor = float(2.0 * np.sqrt(max(eigenvalues[0], 0.0)))
        result.orientation = orientation
        result.area = area
        result.contour = mapping.pixels_to_ground(outline + (x0, y0))
        result.contour[:, 2] = 0.0
        result.pixel_count = count
        saturated = cv2.countNonZero(cv2.inRange(roi, config.saturation_level, 255) & inside)
        result.saturated = bool(saturated > count // 2)
        moments = cv2.moments(inside, binaryImage=True)
        result.pixel_center = np.array([moments['m10'] / moments['m00'] + x0,
                                        moments['m01'] / moments['m00'] + y0])
