"""
The ground plane seen by the RGB camera: ArUco marker pose and pixel <-> ground mapping.

Paper Sec. III-C: a pixel ``i_p`` and a world point ``w_p`` satisfy ``s i_p = A [R | t] w_p``
(Eq 7); on the ground plane z_w = 0 this is the homography ``[x_w y_w 1]^T = (A [r1 r2 t])^-1
i_p s`` (Eq 8), and a ground point goes to the optics frame by ``T_o_l T_l_c T_c_w`` (Eq 9).
Here the camera pose comes from one ArUco marker (world frame = marker centre, marker x/y =
world x/y, z up, as cv2.aruco defines the marker frame), and the mapping uses
`geometry.PinholeCamera` (rays with OpenCV distortion) and the plane intersection of Eq 6, so
distortion is handled exactly; `GroundMapping.homography` gives Eq 8's matrix for
undistorted pixel coordinates.

Marker detection is the expensive step (about 20 ms at 1280x720 here), so `MarkerPoseTracker`
reuses the last pose while the joint states have not changed, re-detects in a region of
interest around the last corners when they have, and falls back to the whole frame.
"""

from dataclasses import dataclass, field
import math

import cv2
from helio_optics.geometry import (
    homogeneous, invert_transform, transform_points, transform_vectors)
from helio_optics.ground_render import aruco_dictionary, srgb8_to_linear_table
import numpy as np

RESPONSES = ('srgb', 'linear')


@dataclass
class MarkerPose:
    """
    A camera pose from the ArUco marker.

    `T_world_camera` maps rgb optical-frame points into the world; `corners` (4, 2) are the
    detected marker corners in pixels (cv2.aruco order: top-left, top-right, bottom-right,
    bottom-left of the marker image); `stamp` [s] of the image it was detected in;
    `reprojection_error` RMS [px]; `edge_width` the 10-90 % rise of its widest outer edge
    [px] (a sharp frame: about 2.6 optical blur sigmas; motion blur widens it).
    """

    T_world_camera: np.ndarray
    corners: np.ndarray
    stamp: float
    reprojection_error: float
    joints: np.ndarray = None
    edge_width: float = math.nan     # widest outer edge's 10-90 % rise [px] (NaN: unknown)

    @property
    def view_angle(self):
        """Return the angle [rad] between the marker's normal and its line to the camera."""
        return marker_view_angle(self.T_world_camera)

    @property
    def blur(self):
        """Return the edge width [px] (the frame's blur as the marker shows it)."""
        return self.edge_width


@dataclass
class MarkerResult:
    """The outcome of one detection attempt: a pose, or None with a reason."""

    pose: MarkerPose = None
    reason: str = ''
    detected_now: bool = False
    searched: str = ''  # 'cache', 'roi' or 'full'


def marker_object_points(side):
    """Return the marker corners in the world frame (4, 3) in cv2.aruco's order [m]."""
    h = side / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


class GroundMapping:
    """Map pixels to ground points (z = 0 of the world) and back for one camera pose."""

    def __init__(self, camera, T_world_camera):
        self.camera = camera
        self.T_world_camera = np.asarray(T_world_camera, dtype=float)
        self.T_camera_world = invert_transform(self.T_world_camera)
        self._undistorted = not np.any(np.asarray(camera.distortion))
        self._ground_from_pixel = np.linalg.inv(self.homography())
        self._ground_from_pixel_det = float(np.linalg.det(self._ground_from_pixel))
        self.cache = {}  # per-pose values of the users (e.g. the marker mask polygon)

    def pixels_to_ground(self, pixels):
        """
        Return world points (N, 3) on z = 0 seen at `pixels` (N, 2) (Eqs 7-8 with distortion).

        Pixels whose ray does not meet the ground in front of the camera get NaN. Without
        lens distortion this is Eq 8's inverse homography; with distortion the pixel rays of
        `PinholeCamera.pixel_rays` are intersected with the ground (Eq 6).
        """
        pixels = np.asarray(pixels, dtype=float).reshape(-1, 2)
        if self._undistorted:
            h = self._ground_from_pixel
            w = pixels @ h[2, :2] + h[2, 2]
            with np.errstate(divide='ignore', invalid='ignore'):
                x = (pixels @ h[0, :2] + h[0, 2]) / w
                y = (pixels @ h[1, :2] + h[1, 2]) / w
            # H [x y 1]^T = s [u v 1]^T with s the depth: w = 1 / s > 0 in front
            behind = ~(w > 0)
            out = np.stack([x, y, np.zeros_like(x)], axis=-1)
            out[behind] = np.nan
            return out
        rays = transform_vectors(self.T_world_camera, self.camera.pixel_rays(pixels))
        origin = self.T_world_camera[:3, 3]
        with np.errstate(divide='ignore', invalid='ignore'):
            scale = -origin[2] / rays[:, 2]
        scale = np.where((scale > 0) & np.isfinite(scale), scale, np.nan)
        return origin + scale[:, None] * rays

    def grid_to_ground(self, us, vs):
        """
        Return ground (x, y) [m] of the pixel grid us x vs as an array (len(vs), len(us), 2).

        The same mapping as `pixels_to_ground` (NaN off the ground), computed by outer
        products when there is no distortion (the per-frame spot measure uses it).
        """
        us, vs = np.asarray(us, dtype=float), np.asarray(vs, dtype=float)
        if not self._undistorted:
            grid = np.stack(np.meshgrid(us, vs), axis=-1).reshape(-1, 2)
            return self.pixels_to_ground(grid)[:, :2].reshape(len(vs), len(us), 2)
        h = self._ground_from_pixel
        w = np.add.outer(vs * h[2, 1] + h[2, 2], us * h[2, 0])
        out = np.empty(w.shape + (2,))
        with np.errstate(divide='ignore', invalid='ignore'):
            out[..., 0] = np.add.outer(vs * h[0, 1] + h[0, 2], us * h[0, 0]) / w
            out[..., 1] = np.add.outer(vs * h[1, 1] + h[1, 2], us * h[1, 0]) / w
        out[~(w > 0)] = np.nan
        return out

    def pixel_footprints(self, x0, x1, y0, y1):
        """
        Return ground centres (h, w, 2) [m] and areas (h, w) [m^2] of pixels x0..x1-1, y0..y1-1.

        Without distortion the area is Eq 8's Jacobian |det H^-1| / w^3 at the pixel centre
        (exact to second order in the pixel size); with distortion, the quadrilateral of the
        pixel's mapped corners. NaN where a pixel does not see the ground.
        """
        us, vs = np.arange(x0, x1, dtype=float), np.arange(y0, y1, dtype=float)
        if self._undistorted:
            h = self._ground_from_pixel
            w = np.add.outer(vs * h[2, 1] + h[2, 2], us * h[2, 0])
            centres = np.empty(w.shape + (2,))
            with np.errstate(divide='ignore', invalid='ignore'):
                inverse_w = 1.0 / w
                centres[..., 0] = np.add.outer(vs * h[0, 1] + h[0, 2], us * h[0, 0]) * inverse_w
                centres[..., 1] = np.add.outer(vs * h[1, 1] + h[1, 2], us * h[1, 0]) * inverse_w
                areas = abs(self._ground_from_pixel_det) * inverse_w ** 3
            behind = ~(w > 0)
            centres[behind] = np.nan
            areas[behind] = np.nan
            return centres, areas
        corners = self.grid_to_ground(np.arange(x0, x1 + 1) - 0.5, np.arange(y0, y1 + 1) - 0.5)
        a, b = corners[:-1, :-1], corners[:-1, 1:]
        c, d = corners[1:, 1:], corners[1:, :-1]
        ac, bd = c - a, d - b  # quadrilateral area from its diagonals: |ac x bd| / 2
        areas = 0.5 * np.abs(ac[..., 0] * bd[..., 1] - ac[..., 1] * bd[..., 0])
        return 0.25 * (a + b + c + d), areas

    def pixel_area(self, u, v):
        """Return the ground area [m^2] seen by one pixel centred at (u, v) (NaN if none)."""
        ground = self.pixels_to_ground([[u - 0.5, v], [u + 0.5, v], [u, v - 0.5], [u, v + 0.5]])
        du, dv = ground[1, :2] - ground[0, :2], ground[3, :2] - ground[2, :2]
        return float(abs(du[0] * dv[1] - du[1] * dv[0]))

    def ground_to_pixels(self, points):
        """Return the pixels (N, 2) of world points (N, 3) (Eq 7, with distortion)."""
        return self.camera.project(transform_points(self.T_camera_world, points))

    def homography(self):
        """
        Return Eq 8's 3x3 matrix H = A [r1 r2 t] (world (x, y, 1) -> undistorted pixel).

        Its inverse maps undistorted homogeneous pixels to ground points.
        """
        rt = self.T_camera_world
        return self.camera.matrix @ np.column_stack([rt[:3, 0], rt[:3, 1], rt[:3, 3]])

    def to_frame(self, points_world, T_frame_world):
        """Express world points in another frame (Eq 9: T_o_l T_l_c T_c_w composed)."""
        return transform_points(T_frame_world, points_world)


@dataclass
class MarkerConfig:
    """Marker and plausibility parameters (node parameters of spot_detector)."""

    dictionary: str = 'DICT_4X4_50'
    marker_id: int = 0
    side: float = 0.04               # black square side [m]
    max_reprojection_error: float = 1.5   # RMS [px]
    min_side_pixels: float = 20.0    # smallest plausible marker side in the image [px]
    min_distance: float = 0.03       # camera distance to the marker, plausible range [m]
    max_distance: float = 2.0
    # farther off the marker's normal, its pose misplaces the ground by up to millimetres
    # (docs/measurements/2026-11-27-marker-view-angle.md: 0.15 mm at 60 deg, 6 mm at 80 deg)
    max_view_angle_deg: float = 60.0
    roi_margin: float = 0.5          # ROI around the last corners, as a fraction of their size
    # re-detect first in that ROI (False: always in the whole frame, each image's pose then
    # depends on that image alone, as a replay that skips images needs)
    roi_search: bool = True
    joint_tolerance: float = 1e-4    # joints closer than this count as unchanged [rad]
    max_pose_age: float = 0.0        # re-detect after this long even if still [s] (0: never)
    # a marker not found with the joints still is searched for again only this often: a
    # whole-frame search that fails tries every scale (about 30 ms a frame here) [s] (0: every
    # frame)
    miss_retry_period: float = 1.0
    # a marker that the kinematic camera pose puts wholly outside the image, grown by this many
    # of its sides all round (the pose's error before a rig calibration), is not searched for:
    # a failed whole-frame search is most of a painting frame's cost (negative: always search)
    out_of_view_margin: float = 1.0
    refine_edges: bool = True        # corners from lines fitted to the marker's outer edges
    # the fine edge fit is repeated until its corners move less than 0.001 px, at most this
    # often: the result then does not depend on where the search started (ROI or frame)
    max_fine_passes: int = 8
    detect_max_width: int = 640      # wider images are downscaled for detection [px] (0: never)
    roi_side_pixels: int = 120       # ROI re-detection scales the marker to about this [px]
    response: str = 'srgb'           # the camera's tone curve: 'srgb' (webcams) or 'linear'
    max_edge_width: float = 4.5      # sharper frames: outer edges' 10-90 % rise up to this [px]
    max_clipped_fraction: float = 0.5  # over-exposed: more of the outline's white at full scale
    # the marker's edges' crossings lie within about 0.25 px (rms) of their lines; farther, the
    # corners are not trusted [px]
    max_edge_residual: float = 1.0
    # global levels tried when the adaptive threshold finds no marker (a lens shadow across
    # it): fractions of the frame's bright level (99th percentile, linear light); the black
    # in full sun and the white in the shadow lie 3-12 % of it apart for a printed marker
    shadow_levels: tuple = (0.025, 0.032, 0.04, 0.05, 0.063, 0.079, 0.1, 0.125)

    def __post_init__(self):
        """Refuse shadow levels outside (0, 1) and a non-positive edge residual limit."""
        self.shadow_levels = tuple(float(level) for level in self.shadow_levels)
        if not all(0.0 < level < 1.0 for level in self.shadow_levels):
            raise ValueError(f'shadow_levels must be fractions in (0, 1), got '
                             f'{self.shadow_levels}')
        if not self.max_edge_residual > 0.0:
            raise ValueError(f'max_edge_residual must be > 0 px, got {self.max_edge_residual}')
        if self.max_fine_passes < 1:
            raise ValueError(f'max_fine_passes must be >= 1, got {self.max_fine_passes}')


class MarkerDetector:
    """Detect one ArUco marker and compute the camera pose from it (cv2.aruco + IPPE)."""

    def __init__(self, config=None):
        self.config = config or MarkerConfig()
        parameters = cv2.aruco.DetectorParameters()
        parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        # The default (0.125) drops the marker in favour of a near-duplicate quad when the
        # white quiet zone around it makes a second nested contour; keep nested candidates
        # and choose below.
        parameters.minMarkerDistanceRate = 0.02
        # keep quads that touch the image border among the rejected candidates: a marker cut
        # by the border shows up there and is reported as partly visible
        parameters.minDistanceToBorder = 0
        self._detector = cv2.aruco.ArucoDetector(
            aruco_dictionary(self.config.dictionary), parameters)
        # the shadow levels' images are black and white already: one threshold window (the
        # detector keeps its own copy of the parameters) finds the outlines three did
        parameters.adaptiveThreshWinSizeMin = parameters.adaptiveThreshWinSizeMax = 3
        self._binary_detector = cv2.aruco.ArucoDetector(
            aruco_dictionary(self.config.dictionary), parameters)
        self._object = marker_object_points(self.config.side)
        self._to_linear = response_table(self.config.response)

    def detect(self, gray, camera, stamp=0.0, roi=None):
        """
        Detect the marker in a grey image (optionally only in roi = (x0, y0, x1, y1)).

        Return a MarkerResult: a pose or a reason (missing, partly visible, implausible).
        """
        offset = np.zeros(2)
        image = gray
        x0, y0, x1, y1 = 0, 0, gray.shape[1], gray.shape[0]
        if roi is not None:
            x0, y0, x1, y1 = roi
            image = gray[y0:y1, x0:x1]
            offset = np.array([x0, y0], dtype=float)
        image = self._linear8(image)
        # Coarse to fine: the adaptive threshold (windows up to 23 px) loses a marker whose
        # black border is wider than its window and finds a decoy quad inside the border,
        # so a larger scale is tried only when the smaller ones fail; a downscaled image
        # that misses a small marker is followed by the image at full resolution.
        limit = self.config.detect_max_width if roi is None else 2 * self.config.roi_side_pixels
        first = min(1.0, limit / image.shape[1]) if limit > 0 else 1.0
        scales = [first, first / 2, first / 4] + ([1.0] if first < 1.0 else [])
        wanted = self.config.marker_id
        seen, rejected_quads = set(), []
        for scale, small, binary in self._candidate_images(image, gray[y0:y1, x0:x1], scales):
            detector = self._binary_detector if binary else self._detector
            corners, ids, rejected = detector.detectMarkers(small)
            # pixel centres at integers: x_full = (x_small + 0.5) / scale - 0.5
            corners = [(c.reshape(-1, 2) + 0.5) / scale - 0.5 + offset for c in corners]
            rejected = [(c.reshape(-1, 2) + 0.5) / scale - 0.5 + offset for c in rejected]
            rejected_quads.extend(rejected)
            ids = [] if ids is None else [int(i) for i in ids.ravel()]
            seen.update(ids)
            # the marker's own outline has a black inside and a white outside all round
            found = [self.refine(gray, c.astype(float), camera, scale)
                     for c, i in zip(corners, ids) if i == wanted]
            found = [fit for fit in found if fit.contrast > 0]
            if found:
                fit = max(found, key=lambda item: item.contrast)
                best = fit.corners
                if not self.config.refine_edges:
                    best = min((c for c, i in zip(corners, ids) if i == wanted),
                               key=lambda c: np.abs(c - best).max()).astype(float)
                if fit.clipped_fraction > self.config.max_clipped_fraction:
                    return MarkerResult(reason=(
                        f'marker over-exposed: its white is at full scale along '
                        f'{100 * fit.clipped_fraction:.0f} % of its outline (the pose would '
                        'be biased: lower the exposure or gain)'))
                if fit.line_residual > self.config.max_edge_residual:
                    return MarkerResult(reason=(
                        f'marker edges not straight: their crossings lie {fit.line_residual:.2f}'
                        f' px (rms) from the fitted lines (> {self.config.max_edge_residual:g}'
                        ' px): a shadow or glare across them'))
                result = self.pose_from_corners(best, camera, stamp)
                if result.pose is not None:
                    result.pose.edge_width = fit.edge_width
                return result
        if any(_cut_marker_like(gray, c, self.config.min_side_pixels) for c in rejected_quads):
            return MarkerResult(reason=f'marker {wanted} partly visible (cut by the image '
                                'border)')
        if wanted in seen:
            return MarkerResult(reason=f'marker {wanted} implausible: no clean black-to-white '
                                'outline around the decoded quad')
        others = sorted(seen - {wanted})
        extra = f' (saw ids {others})' if others else ''
        return MarkerResult(reason=f'marker {wanted} not found{extra}')

    def _candidate_images(self, linear8, gray, scales):
        """
        Yield (scale, image, binary) for cv2.aruco: the adaptive threshold's, then shadow levels.

        First `linear8` at each of `scales` (cv2.aruco's adaptive threshold). Then, when the
        lens' shadow crosses the marker, the adaptive threshold marks the shadow's edge, which
        joins the black border to the shaded wood and leaves no quad; but a printed marker's
        black in full sun (ink x (sun + sky)) is still darker than its white in the shadow
        (paper x sky), so one global level between them gives the marker whole: `gray`
        thresholded at ``shadow_levels`` fractions of its bright level (99th percentile,
        linear light), at the first scale, darkest level first.
        """
        for scale in scales:
            if linear8.shape[1] * scale < 32 or linear8.shape[0] * scale < 32:
                continue
            yield scale, linear8 if scale == 1.0 else cv2.resize(
                linear8, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA), False
        scale = scales[0]
        gray = np.ascontiguousarray(gray)
        small = gray if scale == 1.0 else cv2.resize(gray, None, fx=scale, fy=scale,
                                                     interpolation=cv2.INTER_AREA)
        bright = float(self._to_linear[percentile_level(
            np.ascontiguousarray(small[::2, ::2]), None, 99.0)])
        tried = set()
        for fraction in self.config.shadow_levels:
            level = int(np.searchsorted(self._to_linear, fraction * bright))
            if level in tried or not 0 < level < 255:
                continue
            tried.add(level)
            yield scale, np.where(small >= level, 255, 0).astype(np.uint8), True

    def _linear8(self, image):
        """
        Return an 8-bit image of linear light, a dim one brightened (99th percentile at 128).

        cv2.aruco's adaptive threshold then sees the black border as the light has it: the
        sRGB curve brightens a thin, blurred black border (an oblique marker's far side)
        until it breaks up; and a dim scene (a cloud: sky light only) still spans the
        levels the threshold's constant needs.
        """
        image = np.ascontiguousarray(image)
        bright = float(self._to_linear[percentile_level(
            np.ascontiguousarray(image[::4, ::4]), None, 99.0)])
        gain = min(max(0.5 / max(bright, 1e-3), 1.0), 16.0)   # dim scenes only
        table = np.clip(np.rint(self._to_linear * (255.0 * gain)), 0, 255)
        return cv2.LUT(image, table.astype(np.uint8))

    def refine(self, gray, corners, camera, scale=1.0):
        """
        Refine detected corners on the full image: an EdgeFit.

        Corners found on an image downscaled by `scale` can be a few full-resolution pixels
        off, more than the fine refinement accepts: wide passes (as far as the downscaling
        can err, an eighth of the shortest side at most) until the corners settle, then the
        fine one. The reach across the edges grows
        with the marker (8 % of its shortest side, 2-8 px).
        """
        side = float(np.min(np.linalg.norm(corners - np.roll(corners, 1, axis=0), axis=1)))
        # within the border cell (1/6 side); in half pixels: the fit's fixed point moves by
        # up to 0.05 px with the reach (the profiles' sample grid), so a reach that followed
        # the start's size exactly would make the result depend on where the search began
        fine = float(np.clip(np.round(0.16 * side) / 2.0, 2.0, 8.0))
        coarse = max(fine, min(max(4.0, 2.5 / scale), 0.125 * side))
        for _ in range(3):   # wide passes until the corners settle (each re-centres the reach)
            nearer = refine_corners_from_edges(
                gray, corners, camera, samples=12, reach=coarse, step=0.5,
                to_linear=self._to_linear, max_shift=2.0 * coarse)
            if nearer.contrast <= 0:
                break
            moved = float(np.max(np.linalg.norm(nearer.corners - corners, axis=1)))
            corners = nearer.corners
            if moved < 0.5:
                break
        fit = refine_corners_from_edges(gray, corners, camera, reach=fine,
                                        to_linear=self._to_linear)
        # the fine pass again until it is a fixed point: one pass moves a corner by up to
        # 0.3 px on a slanted marker's short, blurred edges, then a few thousandths
        for _ in range(self.config.max_fine_passes - 1):
            again = refine_corners_from_edges(gray, fit.corners, camera, reach=fine,
                                              to_linear=self._to_linear)
            if again.contrast <= 0:
                break
            moved = float(np.max(np.linalg.norm(again.corners - fit.corners, axis=1)))
            fit = again
            if moved < 1e-3:
                break
        return fit

    def pose_from_corners(self, pixels, camera, stamp=0.0):
        """Solve the camera pose from the 4 marker corners (IPPE square) and check it."""
        config = self.config
        sides = np.linalg.norm(pixels - np.roll(pixels, 1, axis=0), axis=1)
        if sides.min() < config.min_side_pixels:
            return MarkerResult(reason=f'marker implausible: side {sides.min():.1f} px is '
                                f'below {config.min_side_pixels:.1f} px')
        # IPPE gives both planar solutions (OpenCV 5's is ~0.15 px off near fronto-parallel
        # views): refine each by Levenberg-Marquardt and keep the better one
        count, rvecs, tvecs, _ = cv2.solvePnPGeneric(
            self._object, pixels, camera.matrix, camera.distortion,
            flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if not count:
            return MarkerResult(reason='marker implausible: no pose solves its corners')
        best = None
        for rvec, tvec in zip(rvecs, tvecs):
            rvec, tvec = cv2.solvePnPRefineLM(self._object, pixels, camera.matrix,
                                              camera.distortion, rvec.copy(), tvec.copy())
            projected = cv2.projectPoints(self._object, rvec, tvec, camera.matrix,
                                          camera.distortion)[0].reshape(-1, 2)
            error = float(np.sqrt(np.mean(np.sum((projected - pixels) ** 2, axis=1))))
            if best is None or error < best[0]:
                best = (error, rvec, tvec)
        _, rvec, tvec = best
        rotation, _ = cv2.Rodrigues(rvec)
        T_camera_world = homogeneous(rotation, tvec.ravel())
        T_world_camera = invert_transform(T_camera_world)
        projected = camera.project(transform_points(T_camera_world, self._object))
        error = float(np.sqrt(np.mean(np.sum((projected - pixels) ** 2, axis=1))))
        distance = float(np.linalg.norm(tvec))
        height = T_world_camera[2, 3]
        view_angle = math.degrees(marker_view_angle(T_world_camera))
        if error > config.max_reprojection_error:
            reason = f'reprojection error {error:.2f} px > {config.max_reprojection_error} px'
        elif height <= 0:
            reason = f'camera below the ground plane (z = {height:.3f} m)'
        elif not config.min_distance <= distance <= config.max_distance:
            reason = (f'camera {distance:.3f} m from the marker, outside '
                      f'[{config.min_distance}, {config.max_distance}] m')
        elif view_angle > config.max_view_angle_deg:
            reason = (f'marker seen {view_angle:.0f} deg off its normal (> '
                      f'{config.max_view_angle_deg:g} deg): so slanted a view misplaces the '
                      'ground by up to millimetres')
        else:
            pose = MarkerPose(T_world_camera=T_world_camera, corners=pixels, stamp=stamp,
                              reprojection_error=error)
            return MarkerResult(pose=pose, detected_now=True)
        return MarkerResult(reason='marker pose implausible: ' + reason)


def marker_view_angle(T_world_camera):
    """
    Return the angle [rad] between the marker's normal (world z) and its line to the camera.

    The marker's centre is the world origin (Sec. III-A), so the line runs from the origin to
    the camera's position in the world frame. 0 is square on; near 90 deg the marker is seen
    edge-on and its pose (Eqs 7-8) no longer fixes the ground plane.
    """
    position = np.asarray(T_world_camera, dtype=float)[:3, 3]
    return math.atan2(math.hypot(position[0], position[1]), position[2])


def response_table(response):
    """
    Return the (256,) float32 table of linear light [0-1] for the camera's 8-bit levels.

    `response` 'srgb' (webcams: IEC 61966-2-1 tone curve) or 'linear' (level / 255).
    """
    if response == 'srgb':
        return srgb8_to_linear_table()
    if response == 'linear':
        return (np.arange(256) / 255.0).astype(np.float32)
    raise ValueError(f'camera response must be one of {RESPONSES}, got {response!r}')


@dataclass
class EdgeFit:
    """
    Marker corners from lines fitted to its outer edges (`refine_corners_from_edges`).

    `corners` (4, 2) [px]; `contrast` the smallest edge's mean linear step from inside to
    outside (0: the fit failed and `corners` are the input); `edge_width` the widest edge's
    median 10-90 % rise [px]; `clipped_fraction` the share of edge profiles whose white side
    is at the sensor's full scale (over-exposed) [-]; `line_residual` the largest rms
    distance of an edge's crossings from its fitted line [px].
    """

    corners: np.ndarray
    contrast: float = 0.0
    edge_width: float = math.nan
    clipped_fraction: float = 0.0
    line_residual: float = math.nan


def percentile_level(image, mask, percent):
    """Return the 8-bit level at `percent` of an 8-bit image's (masked) pixels (0 if none)."""
    counts = cv2.calcHist([image], [0], mask, [256], [0, 256]).ravel().cumsum()
    if counts[-1] <= 0:
        return 0
    return int(np.searchsorted(counts, percent / 100.0 * counts[-1]))


def refine_corners_from_edges(gray, corners, camera, samples=24, reach=3.0, step=0.25,
                              to_linear=None, min_contrast=0.03, max_shift=2.0):
    """
    Return an EdgeFit: the marker's corners from lines fitted to its outer edges.

    cv2.cornerSubPix pulls the corners of a blurred dark square inward (about 0.17 px here,
    which tilts the pose); the straight outer edges are unbiased: along each edge, away from
    the corners, the half-level crossing of the dark-to-light profile across the edge is
    found to sub-pixel, the points are undistorted (lines stay lines), a line is fitted to
    each edge and adjacent lines are intersected.

    The profiles are taken in LINEAR light (`to_linear`, a table of the camera's 8-bit
    levels, e.g. `response_table('srgb')`; None: level / 255): a blurred edge crosses half
    way between its dark and light sides where the edge is only in linear light; in sRGB
    levels the crossing sits 0.8 blur sigma on the dark side (the marker looks smaller and
    the camera farther away). `reach` [px] is how far across the given edge lines to look.

    The contrast is high for the real marker outline; the edge width grows with motion blur
    or defocus. Returns the input corners with contrast 0 if an edge is unusable or the
    result is more than `max_shift` px from the input.
    """
    corners = np.asarray(corners, dtype=float)
    table = response_table('linear') if to_linear is None else to_linear
    offsets = np.arange(-reach, reach + step / 2, step)
    starts, ends = corners, np.roll(corners, -1, axis=0)
    along = ends - starts
    lengths = np.linalg.norm(along, axis=1)
    if lengths.min() < 4 * reach + 8:
        return EdgeFit(corners)
    normals = np.stack([along[:, 1], -along[:, 0]], axis=1) / lengths[:, None]
    outward = np.sum(normals * ((starts + ends) / 2 - corners.mean(axis=0)), axis=1) < 0
    normals[outward] *= -1.0  # outward: from the black border to the white quiet zone
    t = np.linspace(0.15, 0.85, samples)
    base = starts[:, None, :] + t[None, :, None] * along[:, None, :]          # (4, S, 2)
    grid = base[:, :, None, :] + offsets[None, None, :, None] * normals[:, None, None, :]
    # linearise only the part of the image the profiles read (then interpolate linear light)
    height, width = gray.shape[:2]
    low = np.floor(grid.reshape(-1, 2).min(axis=0)).astype(int) - 1
    high = np.ceil(grid.reshape(-1, 2).max(axis=0)).astype(int) + 2
    x0, y0 = max(int(low[0]), 0), max(int(low[1]), 0)
    x1, y1 = min(int(high[0]), width), min(int(high[1]), height)
    if x1 - x0 < 2 or y1 - y0 < 2:
        return EdgeFit(corners)
    patch = cv2.LUT(np.ascontiguousarray(gray[y0:y1, x0:x1]), table)
    profiles = cv2.remap(patch, (grid[..., 0] - x0).reshape(4 * samples, -1).astype(np.float32),
                         (grid[..., 1] - y0).reshape(4 * samples, -1).astype(np.float32),
                         cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(float)
    dark, light = profiles[:, :3].mean(axis=1), profiles[:, -3:].mean(axis=1)
    rise = light - dark
    level = 0.5 * (dark + light)
    above = profiles >= level[:, None]
    first = np.argmax(above, axis=1)
    rows = np.arange(4 * samples)
    usable = above[rows, first] & (first > 0) & (rise >= min_contrast)
    first = np.maximum(first, 1)
    p0, p1 = profiles[rows, first - 1], profiles[rows, first]
    with np.errstate(divide='ignore', invalid='ignore'):
        crossing = offsets[first - 1] + step * (level - p0) / (p1 - p0)
        # 10-90 % rise: the normalised profile integrates to the distance from the 90 % side
        normalised = np.clip((profiles - dark[:, None]) / rise[:, None], 0.0, 1.0)
    # an over-exposed white side is clipped at full scale: its true level, hence the half
    # level, is unknown and the crossing moves towards the dark side (the marker looks
    # larger); counted, and refused by the detector above `max_clipped_fraction`
    clipped = profiles[:, -3:].mean(axis=1) >= 0.99 * float(table[-1])
    usable &= np.isfinite(crossing)
    widths = _rise_widths(normalised, step)
    # a profile with two steps (a shadow's edge or the spot's glare within reach of the
    # marker's edge) rises over a wider span than the frame's blur: its crossing is not the
    # edge's
    if np.any(usable):
        usable &= widths <= 1.6 * float(np.median(widths[usable])) + 0.3
    points = base.reshape(-1, 2) + crossing[:, None] * np.repeat(normals, samples, axis=0)
    usable = usable.reshape(4, samples)
    contrasts = rise.reshape(4, samples).mean(axis=1)
    if np.any(usable.sum(axis=1) < samples // 2):
        return EdgeFit(corners)
    edge_widths = [float(np.median(widths.reshape(4, samples)[i][usable[i]])) for i in range(4)]
    rays = camera.pixel_rays(np.where(np.isfinite(points), points, 0.0))  # unusable: unused
    normalised_points = (rays[:, :2] / rays[:, 2:3]).reshape(4, samples, 2)
    pixel_scale = float(camera.matrix[0, 0])   # normalised coordinates to pixels
    lines, residuals = [], []
    for i in range(4):
        fitted = _robust_line(normalised_points[i][usable[i]], pixel_scale, samples // 2)
        if fitted is None:
            return EdgeFit(corners)
        lines.append(fitted[:2])
        residuals.append(fitted[2])
    refined = []
    for i in range(4):
        (p, d), (q, e) = lines[(i - 1) % 4], lines[i]
        # corner i joins edge i-1 (from corner i-1) and edge i (to corner i+1)
        matrix = np.column_stack([d, -e])
        if abs(np.linalg.det(matrix)) < 1e-9:
            return EdgeFit(corners)
        s, _ = np.linalg.solve(matrix, q - p)
        x, y = p + s * d
        refined.append((x, y, 1.0))
    refined = camera.project(np.array(refined))
    if np.max(np.linalg.norm(refined - corners, axis=1)) > max_shift:
        return EdgeFit(corners)  # the fit disagrees with the detector: keep its corners
    return EdgeFit(refined, float(min(contrasts)), float(max(edge_widths)),
                   float(np.mean(clipped[usable.ravel()])), float(max(residuals)))


def _robust_line(points, pixel_scale, least, max_distance=0.15):
    """
    Fit a line to an edge's crossings, leaving out those off it; (point, direction, rms).

    Total least squares (SVD), then the points farther than `max_distance` px or four
    robust standard deviations (median absolute deviation) from the line are left out and
    the line fitted again, until none is; None when fewer than `least` points remain. The
    rms [px] is of the points kept.
    """
    keep = np.ones(len(points), bool)
    while True:
        if keep.sum() < max(least, 2):
            return None
        mean = points[keep].mean(axis=0)
        _, _, vt = np.linalg.svd(points[keep] - mean)
        normal = np.array([-vt[0][1], vt[0][0]])
        distances = np.abs((points - mean) @ normal) * pixel_scale
        spread = 1.4826 * float(np.median(distances[keep]))
        inside = distances <= max(max_distance, 4.0 * spread)
        if np.array_equal(inside & keep, keep):
            return mean, vt[0], float(np.sqrt(np.mean(distances[keep] ** 2)))
        keep &= inside


def _rise_widths(normalised, step):
    """
    Return the 10-90 % rise width [px] of each normalised edge profile (rows, 0 to 1).

    The crossings are interpolated on each profile's running maximum (monotone).
    """
    envelope = np.maximum.accumulate(normalised, axis=1)
    rows = np.arange(len(envelope))
    crossings = []
    for level in (0.1, 0.9):
        index = np.clip(np.argmax(envelope >= level, axis=1), 1, envelope.shape[1] - 1)
        before, after = envelope[rows, index - 1], envelope[rows, index]
        with np.errstate(divide='ignore', invalid='ignore'):
            fraction = np.clip((level - before) / (after - before), 0.0, 1.0)
        crossings.append((index - 1 + np.nan_to_num(fraction)) * step)
    return crossings[1] - crossings[0]


def _cut_marker_like(gray, quad, min_side):
    """Tell whether a rejected quad touches the image border and holds black and white cells."""
    if not _touches_border(quad, gray.shape, 3.0):
        return False
    if cv2.contourArea(quad.astype(np.float32)) < min_side * min_side:
        return False
    x, y, w, h = cv2.boundingRect(quad.astype(np.float32))
    x0, y0 = max(x, 0), max(y, 0)
    x1, y1 = min(x + w, gray.shape[1]), min(y + h, gray.shape[0])
    mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
    cv2.fillConvexPoly(mask, np.rint(quad - (x0, y0)).astype(np.int32), 1)
    _, deviation = cv2.meanStdDev(gray[y0:y1, x0:x1], mask=mask)
    return float(deviation[0, 0]) > 50.0  # binary cells; wood or a spot alone stay far below


def _touches_border(points, shape, margin):
    """Tell whether any point lies within `margin` px of the image border."""
    height, width = shape[:2]
    return bool(np.any((points < margin) | (points > np.array([width, height]) - 1 - margin)))


@dataclass
class MarkerPoseTracker:
    """
    Keep the camera pose from the marker across frames without re-detecting every time.

    Reuse the last pose while the joint states are unchanged (within `joint_tolerance`) and
    younger than `max_pose_age`; otherwise re-detect in a region of interest around the last
    corners, then in the whole frame. Without joint states the ROI is searched every frame.

    An image can be older than the joint states that arrive with it (the camera and the
    drivers are not synchronised), so a pose only becomes reusable when it was detected
    with the joints already still since the previous frame: the first frame after a move
    is detected again.

    The same holds for a marker out of view: not found with the joints still, it is not
    searched for again while they stay so, until ``miss_retry_period`` has passed (a shadow
    or a hand over it may have gone).
    """

    detector: MarkerDetector
    last: MarkerPose = None
    previous_joints: np.ndarray = None
    last_miss: tuple = None           # (joints, stamp, reason) of a marker not found, still
    counts: dict = field(default_factory=lambda: {'cache': 0, 'roi': 0, 'full': 0,
                                                  'failed': 0, 'miss_cache': 0,
                                                  'out_of_view': 0})

    def update(self, gray, camera, stamp, joints=None):
        """Return a MarkerResult for this image; `joints` the current joint positions."""
        config = self.detector.config
        joints = None if joints is None else np.asarray(joints, dtype=float)
        still = self._same(joints, self.previous_joints)
        self.previous_joints = joints
        if self.last is not None and self._same(joints, self.last.joints) \
                and (config.max_pose_age <= 0 or stamp - self.last.stamp <= config.max_pose_age):
            self.counts['cache'] += 1
            return MarkerResult(pose=self.last, searched='cache')
        if self.last_miss is not None:
            missed_joints, missed_at, reason = self.last_miss
            if self._same(joints, missed_joints) and 0.0 <= stamp - missed_at \
                    < config.miss_retry_period:
                self.counts['miss_cache'] += 1
                return MarkerResult(reason=reason, searched='cache')
            self.last_miss = None
        result = None
        if self.last is not None and config.roi_search:
            roi = self._roi(gray.shape)
            if roi is not None:
                result = self.detector.detect(gray, camera, stamp, roi)
                result.searched = 'roi'
        if result is None or result.pose is None:
            result = self.detector.detect(gray, camera, stamp)
            result.searched = 'full'
        if result.pose is None:
            self.counts['failed'] += 1
            if self.last is not None and 'not found' in result.reason:
                corners = self.last.corners
                size = np.max(corners.max(axis=0) - corners.min(axis=0))
                if _touches_border(corners, gray.shape, 0.25 * size):
                    result.reason = (f'marker {config.marker_id} partly visible or out of view '
                                     '(last seen at the image border)')
            if still and config.miss_retry_period > 0.0:
                self.last_miss = (joints, stamp, result.reason)
            return result
        self.counts[result.searched] += 1
        # None: not reusable (the joints moved since the last frame, or the frame is blurred)
        sharp = not result.pose.edge_width > config.max_edge_width
        result.pose.joints = joints if still and sharp else None
        self.last = result.pose
        return result

    def _same(self, a, b):
        """Tell whether two joint vectors are known and equal within the tolerance."""
        return a is not None and b is not None and a.shape == b.shape and \
            float(np.max(np.abs(a - b))) <= self.detector.config.joint_tolerance

    def forget(self):
        """Drop the cached pose (e.g. when the camera intrinsics change)."""
        self.last = None
        self.previous_joints = None
        self.last_miss = None

    def _roi(self, shape):
        corners = self.last.corners
        low, high = corners.min(axis=0), corners.max(axis=0)
        margin = self.detector.config.roi_margin * np.max(high - low)
        height, width = shape[:2]
        x0, y0 = np.maximum(np.floor(low - margin), 0).astype(int)
        x1 = int(min(np.ceil(high[0] + margin) + 1, width))
        y1 = int(min(np.ceil(high[1] + margin) + 1, height))
        if x1 - x0 < 16 or y1 - y0 < 16:
            return None
        return x0, y0, x1, y1
