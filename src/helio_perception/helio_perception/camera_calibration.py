"""
Camera calibration from ChArUco board views, and the camera_info file it writes (issue 29).

A USB webcam arrives uncalibrated: ``usb_cam`` publishes ``camera_info`` with K = 0 until
its ``camera_info_url`` names a calibration file, and ``spot_detector`` refuses K = 0 (every
ground point goes through the intrinsics, paper Eqs 7-9). This module turns frames of a
printed ChArUco board (``helio_optics.calibration_board.BoardSpec``) into that file:

- ``detect_board``: the board's inner corners in one frame (OpenCV's ``CharucoDetector``:
  ArUco markers first, the chessboard corners between them interpolated and refined to
  sub-pixel), with their board coordinates; a view with fewer than ``min_corners``
  corners, or whose corners all lie on one line, is refused with the reason.
- ``evenly_lit``: corners that the lens' shadow or its concentrated light cross are left
  out (they move by tenths of a pixel: enough to bias the focal length).
- ``calibrate``: ``cv2.calibrateCameraExtended`` over the views. Fitted: one focal length
  fx = fy (square pixels), the principal point cx, cy and the radial distortion k1, k2 of
  OpenCV's plumb_bob model; held: the tangential p1 = p2 = 0 and k3 = 0. Why: the rig's
  wrist tilts the camera against a board lying on the panel about one axis only (the lens
  pitch; ``helio_control.camera_views``), and views tilted about parallel axes cannot
  separate fx from fy, nor the principal point along the tilt from the tangential
  distortion and the tilt itself (Sturm and Maybank's critical motions for plane-based
  calibration): fitted free, fx and fy came out 0.2-0.5 % apart and cy 1-3 px off in the
  simulated rig. Webcam sensors have square pixels, and their decentring (tangential)
  distortion is a small fraction of a pixel; k3 matters only for wide-angle lenses and over
  a 70 degree field trades off with k1 and k2. ``square_pixels=False`` and
  ``tangential=True`` fit them for views that are free of that limit (a board held by
  hand). The fit starts from the camera's nominal intrinsics when given (a focal length
  from the field of view), else from OpenCV's own guess. Corners are then refused while
  any lies farther from its reprojection than ``corner_factor`` times the median corner's
  (a corner taken at the wrong place, a shadow's edge that ``evenly_lit`` missed), and the
  fit is redone without them; a view left with too few corners is refused with the reason.
- ``write_camera_info``/``read_camera_info``: the YAML of ``camera_calibration_parsers``
  (the format ``camera_info_manager`` and ``usb_cam``'s ``camera_info_url`` read):
  ``image_width``, ``image_height``, ``camera_name``, ``camera_matrix``,
  ``distortion_model`` (plumb_bob), ``distortion_coefficients``, ``rectification_matrix``
  (identity: a single camera) and ``projection_matrix`` ([K | 0]: rectified images keep the
  camera matrix). How the file was made is written as comments above it (the parsers read
  only their own keys).

No rclpy: ``helio calibrate camera`` (helio_control) collects the views, ``spot_detector``
reads the file (its ``camera_info_file`` parameter).
"""

from dataclasses import dataclass, field

import cv2
from helio_optics.geometry import PinholeCamera
from helio_optics.ground_render import srgb_to_linear
import numpy as np
import yaml

DISTORTION_MODEL = 'plumb_bob'


class BoardNotSeen(ValueError):
    """A frame that gives no usable view of the board; the message says why."""


@dataclass
class BoardView:
    """One frame's board corners: ids, image points (N, 2) [px], board points (N, 3) [m]."""

    ids: np.ndarray
    image_points: np.ndarray
    object_points: np.ndarray

    def __len__(self):
        """Return the number of corners."""
        return len(self.ids)


@dataclass
class CameraCalibration:
    """The fitted camera and how well it fits (see ``calibrate``)."""

    camera: PinholeCamera
    rms: float                          # RMS reprojection error over the views used [px]
    view_rms: list                      # per view used [px]
    used: list                          # indices (into the views given) used
    rejected: list = field(default_factory=list)    # (index, reason) of views left out
    sigmas: dict = field(default_factory=dict)      # one-sigma of each fitted term
    corners: int = 0                    # corners used
    corners_refused: int = 0            # corners left out (too far from the fit)

    def summary(self):
        """Return a line: the intrinsics, the distortion, the error and the views."""
        m, d = self.camera.matrix, self.camera.distortion
        return (f'fx {m[0, 0]:.2f} fy {m[1, 1]:.2f} cx {m[0, 2]:.2f} cy {m[1, 2]:.2f} px, '
                f'k1 {d[0]:.4f} k2 {d[1]:.4f} p1 {d[2]:.5f} p2 {d[3]:.5f}; reprojection '
                f'RMS {self.rms:.3f} px over {len(self.used)} views, {self.corners} corners'
                + (f' ({len(self.rejected)} views refused)' if self.rejected else '')
                + (f' ({self.corners_refused} corners refused)' if self.corners_refused
                   else ''))


def grey(image):
    """Return the 8-bit one-channel frame of an RGB (H, W, 3) or (H, W) uint8 image."""
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f'an 8-bit frame is needed, got {image.dtype.name}')
    if image.ndim == 3 and image.shape[2] in (3, 4):
        return cv2.cvtColor(image[:, :, :3], cv2.COLOR_RGB2GRAY)
    if image.ndim == 2:
        return image
    raise ValueError(f'a grey or RGB frame is needed, got shape {image.shape}')


def detect_board(image, spec, min_corners=8):
    """
    Return the BoardView of the board `spec` in `image` (grey or RGB uint8).

    Raises BoardNotSeen when fewer than `min_corners` corners are found or they lie on one
    line (such a view constrains no focal length).
    """
    board = spec.board()
    detector = cv2.aruco.CharucoDetector(board)
    corners, ids, _, _ = detector.detectBoard(grey(image))
    count = 0 if ids is None else len(ids)
    if count < min_corners:
        raise BoardNotSeen(f'{count} board corners found (at least {min_corners} needed)')
    ids = ids.ravel().astype(int)
    objects = spec.corner_points()[ids]
    columns = spec.squares[0] - 1
    rows, cols = ids // columns, ids % columns
    if len(set(rows.tolist())) < 2 or len(set(cols.tolist())) < 2:
        raise BoardNotSeen(f'the {count} corners found lie on one line of the board')
    return BoardView(ids=ids, image_points=corners.reshape(-1, 2).astype(float),
                     object_points=np.asarray(objects, dtype=float).reshape(-1, 3))


def evenly_lit(view, image, spec, min_ratio=0.6):
    """
    Return `view` without the corners whose surroundings are not evenly lit, and their count.

    The lens casts its shadow (sky light only: a tenth of the sunlit level) and its
    concentrated light onto the board. A shadow's edge or the bright spot across a corner
    pulls the sub-pixel corner off by a few tenths of a pixel, enough to bias the focal
    length by tenths of a per cent. Of the four squares around an inner corner two are
    black ink without a marker: their centres (mapped into the image by the view's
    homography) are read in linear light, and a corner whose two black squares differ by
    more than the ratio `min_ratio` is left out. `image` is the frame the view was found
    in (grey or RGB uint8, sRGB-encoded as webcams send).
    """
    if len(view) < 4:
        return view, 0
    homography, _ = cv2.findHomography(view.object_points[:, :2], view.image_points)
    if homography is None:
        return view, 0
    light = srgb_to_linear(grey(image).astype(np.float32) / 255.0)
    light = cv2.blur(light, (3, 3))
    columns = spec.squares[0] - 1
    rows, cols = view.ids // columns, view.ids % columns
    # the squares around inner corner (r, c) are (r, c), (r, c + 1), (r + 1, c), (r + 1, c + 1)
    # (row, column); OpenCV's board starts with a black square: black where their sum is even
    first = np.where((rows + cols) % 2 == 0, 0, 1)
    centres = []
    for offset in ((0, 0), (1, 1)):
        square_row = rows + offset[0]
        square_col = cols + np.where(first == 0, offset[1], 1 - offset[1])
        centres.append(np.stack([(square_col + 0.5) * spec.square,
                                 (square_row + 0.5) * spec.square], axis=1))
    levels = []
    height, width = light.shape
    for centre in centres:
        pixels = cv2.perspectiveTransform(centre.reshape(-1, 1, 2), homography).reshape(-1, 2)
        u = np.clip(np.rint(pixels[:, 0]).astype(int), 0, width - 1)
        v = np.clip(np.rint(pixels[:, 1]).astype(int), 0, height - 1)
        levels.append(light[v, u])
    low, high = np.minimum(*levels), np.maximum(*levels)
    even = low >= min_ratio * np.maximum(high, 1e-6)
    kept = BoardView(view.ids[even], view.image_points[even], view.object_points[even])
    return kept, int(np.count_nonzero(~even))


def _fit(views, size, guess, options):
    """
    One cv2.calibrateCameraExtended run over BoardViews.

    Returns (camera, rms, per-view rms, sigmas, per-view corner residuals [px]).
    """
    flags = cv2.CALIB_FIX_K3
    if options.get('square_pixels', True):
        flags |= cv2.CALIB_FIX_ASPECT_RATIO
    if not options.get('tangential', False):
        flags |= cv2.CALIB_ZERO_TANGENT_DIST
    matrix = distortion = None
    if guess is not None:
        flags |= cv2.CALIB_USE_INTRINSIC_GUESS
        matrix = np.array(guess.matrix, dtype=np.float64)
        distortion = np.zeros(5)
    objects = [v.object_points.astype(np.float32) for v in views]
    images = [v.image_points.astype(np.float32).reshape(-1, 1, 2) for v in views]
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    rms, matrix, distortion, rotations, translations, std_intrinsics, _, per_view = \
        cv2.calibrateCameraExtended(objects, images, size, matrix, distortion, flags=flags,
                                    criteria=criteria)
    residuals = []
    for points, image, rotation, translation in zip(objects, images, rotations, translations):
        projected, _ = cv2.projectPoints(points, rotation, translation, matrix, distortion)
        residuals.append(np.linalg.norm((projected - image).reshape(-1, 2), axis=1))
    std = np.asarray(std_intrinsics, dtype=float).ravel()
    names = ('fx', 'fy', 'cx', 'cy', 'k1', 'k2', 'p1', 'p2')
    sigmas = dict(zip(names, (float(v) for v in std[:8])))
    camera = PinholeCamera(matrix=np.asarray(matrix, dtype=float), width=int(size[0]),
                           height=int(size[1]),
                           distortion=np.asarray(distortion, dtype=float).ravel()[:5].copy())
    return (camera, float(rms), [float(v) for v in np.asarray(per_view).ravel()], sigmas,
            residuals)


def calibrate(views, size, guess=None, min_views=6, min_corners=6, corner_factor=3.0,
              min_corner_limit=0.15, rounds=5, **options):
    """
    Fit the camera to BoardViews `views` of images of `size` (width, height) [px].

    `guess`: a PinholeCamera to start from (the nominal intrinsics), or None. Corners are
    refused while any lies farther from its reprojection than `corner_factor` times the
    median corner's (at least `min_corner_limit` [px]), and the fit redone without them
    (at most `rounds` fits); a view left with fewer than `min_corners` corners is refused.
    `options`: ``square_pixels`` (default True: fx = fy), ``tangential`` (default False:
    p1 = p2 = 0). Returns a CameraCalibration; ValueError when fewer than `min_views` views
    remain.
    """
    views = list(views)
    keep = [np.ones(len(view), bool) for view in views]
    for _ in range(rounds):
        used = [i for i, mask in enumerate(keep) if np.count_nonzero(mask) >= min_corners]
        if len(used) < min_views:
            raise ValueError(f'{len(used)} board views with at least {min_corners} corners '
                             f'that fit (at least {min_views} needed)')
        subsets = [BoardView(views[i].ids[keep[i]], views[i].image_points[keep[i]],
                             views[i].object_points[keep[i]]) for i in used]
        camera, rms, view_rms, sigmas, residuals = _fit(subsets, tuple(size), guess, options)
        limit = max(min_corner_limit, corner_factor * float(np.median(np.concatenate(
            residuals))))
        changed = False
        for i, residual in zip(used, residuals):
            bad = residual > limit
            if np.any(bad):
                keep[i][np.flatnonzero(keep[i])[bad]] = False
                changed = True
        if not changed:
            break
    refused = sum(len(view) - np.count_nonzero(mask) for view, mask in zip(views, keep))
    rejected = [(i, f'{np.count_nonzero(keep[i])} of {len(views[i])} corners fit')
                for i in range(len(views)) if i not in used]
    return CameraCalibration(camera=camera, rms=rms, view_rms=view_rms, used=used,
                             rejected=rejected, sigmas=sigmas,
                             corners=sum(len(s) for s in subsets), corners_refused=int(refused))


# ---- the camera_info file -----------------------------------------------------------------

def camera_info_document(camera, camera_name):
    """Return camera_calibration_parsers' YAML tree of a PinholeCamera (plain numbers)."""
    matrix = np.asarray(camera.matrix, dtype=float)
    distortion = (list(np.asarray(camera.distortion, dtype=float).ravel()) + [0.0] * 5)[:5]
    projection = np.hstack([matrix, np.zeros((3, 1))])

    def block(rows, cols, values):
        return {'rows': rows, 'cols': cols, 'data': [float(v) for v in np.ravel(values)]}

    return {'image_width': int(camera.width), 'image_height': int(camera.height),
            'camera_name': str(camera_name),
            'camera_matrix': block(3, 3, matrix),
            'distortion_model': DISTORTION_MODEL,
            'distortion_coefficients': block(1, 5, distortion),
            'rectification_matrix': block(3, 3, np.eye(3)),
            'projection_matrix': block(3, 4, projection)}


def write_camera_info(path, camera, camera_name, comments=()):
    """Write the camera_info YAML of `camera` to `path`, `comments` as # lines above; return it."""
    text = ''.join(f'# {line}\n' for line in comments)
    text += yaml.safe_dump(camera_info_document(camera, camera_name), sort_keys=False,
                           default_flow_style=None)
    with open(path, 'w') as stream:
        stream.write(text)
    return path


def read_camera_info(path):
    """
    Return (PinholeCamera, camera name) of a camera_info YAML file.

    Raises ValueError naming the file and what is wrong with it (not that format, a
    distortion model other than plumb_bob, a camera matrix that is not one).
    """
    try:
        with open(path) as stream:
            document = yaml.safe_load(stream)
        width, height = int(document['image_width']), int(document['image_height'])
        matrix = np.asarray(document['camera_matrix']['data'], dtype=float).reshape(3, 3)
        model = document.get('distortion_model', DISTORTION_MODEL)
        distortion = np.asarray(document.get('distortion_coefficients', {}).get('data', []),
                                dtype=float).ravel()
        name = str(document.get('camera_name', ''))
    except (OSError, yaml.YAMLError, KeyError, TypeError, ValueError, AttributeError) as error:
        raise ValueError(f'{path}: not a camera_info file ({error})') from None
    if model not in (DISTORTION_MODEL, 'rational_polynomial') or len(distortion) > 8:
        raise ValueError(f'{path}: distortion model {model!r} with {len(distortion)} '
                         'coefficients (plumb_bob needed)')
    if (not np.all(np.isfinite(matrix)) or matrix[0, 0] <= 0.0 or matrix[1, 1] <= 0.0
            or matrix[2, 2] != 1.0 or width <= 0 or height <= 0):
        raise ValueError(f'{path}: not a calibrated camera matrix ({matrix.tolist()}, '
                         f'{width}x{height})')
    coefficients = np.zeros(5)
    coefficients[:min(5, len(distortion))] = distortion[:5]
    if not np.all(np.isfinite(coefficients)):
        raise ValueError(f'{path}: distortion coefficients are not finite')
    return PinholeCamera(matrix=matrix, width=width, height=height,
                         distortion=coefficients), name


def intrinsics_error(fitted, truth):
    """Return {fx, fy (relative), cx, cy [px], k1} errors of `fitted` against `truth`."""
    a, b = np.asarray(fitted.matrix, float), np.asarray(truth.matrix, float)
    return {'fx': a[0, 0] / b[0, 0] - 1.0, 'fy': a[1, 1] / b[1, 1] - 1.0,
            'cx': a[0, 2] - b[0, 2], 'cy': a[1, 2] - b[1, 2],
            'k1': float(fitted.distortion[0]) - float(truth.distortion[0])}
