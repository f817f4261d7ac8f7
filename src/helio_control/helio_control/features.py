"""
Feature extraction: which cells of the Eq 17 grid get a dot (paper Sec. IV-C, Fig. 9).

The picture is first resampled to a working image of ``oversample`` pixels per dot pitch
(``working_image``): features are found there, finer than the dots, and then put on the
grid. Modes:

- ``edges`` (paper, text/logos/symbols, Fig. 9 a-b): Canny edges (OpenCV), each edge pixel
  moved to its sub-pixel position along the gradient (Devernay's quadratic fit of the
  gradient magnitude), then every grid node within half a pitch of an edge point is taken
  and the node set thinned to one node wide (scikit-image ``skeletonize``).
- ``centerline`` (paper Fig. 9 c: strokes too narrow for two outlines): the dark strokes
  are thinned to their medial line by ``skimage.morphology.skeletonize``; each skeleton pixel
  is moved onto the ridge of the distance transform (sub-pixel), then nodes within half a
  pitch are taken and thinned as for edges.
- ``threshold`` (paper, the portrait of Fig. 9 d): median denoising, adaptive threshold
  (Gaussian local mean, block ``threshold_block_nodes`` pitches) OR Otsu's global threshold
  (so large dark areas stay filled), a morphological opening removing specks smaller than
  half a pitch; a node is burnt when at least half of its cell is dark.
- ``tones`` (beyond the paper): each node's darkness (1 - mean grey of its cell, raised to
  ``tone_gamma``) rendered as dot density by error diffusion (``halftone``).

``auto`` (``choose_mode``) looks at the working image: if more than 20 % of its pixels are
mid-grey (0.15..0.85 after a 3x3 median, so anti-aliased edges do not count) the picture
is a photograph: ``tones``. Otherwise it is two-level; the median stroke width (twice the
distance transform on the skeleton of the dark part) decides: narrower than 3 pitches,
``centerline`` (two outlines would nearly touch); else ``edges``.

Line modes also return their stroke points (sub-pixel, grid units) for the chamfer quality
figure; fill modes return the reference image the dots should reproduce.
"""

from dataclasses import dataclass, field

import cv2
from helio_control.halftone import error_diffusion
import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

FEATURE_MODES = ('edges', 'centerline', 'threshold', 'tones')
LINE_MODES = ('edges', 'centerline')
MID_GREY_FRACTION = 0.20     # auto: above this fraction of mid-grey pixels -> tones
MID_GREY_RANGE = (0.15, 0.85)
CENTERLINE_MAX_WIDTH = 3.0   # auto: strokes narrower than this many pitches -> centerline


@dataclass
class Features:
    """The grid cells that get a dot, and what the quality figure compares them with."""

    mode: str
    dots: np.ndarray                  # bool (n_v, n_u)
    darkness: np.ndarray              # float (n_v, n_u) in [0, 1], mean darkness per cell
    strokes: np.ndarray = None        # line modes: (M, 2) stroke points (u, v) [grid units]
    reference: np.ndarray = None      # working-resolution image the dots reproduce (1 white)
    notes: list = field(default_factory=list)


def working_image(grey, grid_shape, pixels_per_node, oversample):
    """
    Resample the picture so that each grid cell is `oversample` x `oversample` pixels.

    The part of the picture covered by the grid (n_u / omega_s by n_v / omega_s pixels,
    i.e. all of it but less than one pitch at the far edges) is resized with area averaging
    when shrinking and bilinear interpolation when enlarging.
    """
    rows, columns = grid_shape
    height = min(grey.shape[0], max(1, int(round(rows * pixels_per_node))))
    width = min(grey.shape[1], max(1, int(round(columns * pixels_per_node))))
    crop = grey[:height, :width]
    size = (columns * oversample, rows * oversample)
    shrinking = size[0] < width
    method = cv2.INTER_AREA if shrinking else cv2.INTER_LINEAR
    return cv2.resize(crop, size, interpolation=method)


def cell_means(image, oversample):
    """Mean of each oversample x oversample cell (grid resolution)."""
    rows, columns = image.shape[0] // oversample, image.shape[1] // oversample
    blocks = image[:rows * oversample, :columns * oversample]
    return blocks.reshape(rows, oversample, columns, oversample).mean(axis=(1, 3))


def to_grid_units(points_xy, oversample):
    """Working pixel centres (x, y) -> grid coordinates (u, v) (cell centres at integers)."""
    return (np.asarray(points_xy, dtype=float) + 0.5) / oversample - 0.5


def nodes_near(points_uv, tangents, grid_shape, oversample, radius=0.5, margin=None):
    """
    Boolean grid: nodes within `radius` (grid units) of the stroke.

    Each stroke point stands for a short piece of the stroke along its unit tangent, as long
    as the pixel it came from is wide in that direction (1 px along an axis, sqrt 2 px along
    a diagonal), so consecutive pieces join: the distance is taken to those pieces, not to
    the sample points (which would miss a line lying exactly half a pitch from a node).
    Nodes are taken within `radius` less `margin` (default a quarter of a working pixel, the
    stroke points' localisation error), so an error cannot push a dot beyond `radius`;
    where that leaves a stroke point without a node, its nearest node is added.
    """
    margin = 0.25 / oversample if margin is None else margin
    dots = np.zeros(grid_shape, dtype=bool)
    if len(points_uv) == 0:
        return dots
    rows, columns = grid_shape
    v, u = np.mgrid[0:rows, 0:columns]
    nodes = np.column_stack([u.ravel(), v.ravel()]).astype(float)
    half = 0.5 * (np.abs(tangents[:, 0]) + np.abs(tangents[:, 1])) / oversample
    reach = radius + float(np.max(half)) + 1e-9
    candidates = cKDTree(points_uv).query_ball_point(nodes, reach)
    node_index = np.repeat(np.arange(len(nodes)), [len(c) for c in candidates])
    if len(node_index) == 0:
        return dots
    point_index = np.concatenate([np.asarray(c, dtype=int) for c in candidates])
    offset = nodes[node_index] - points_uv[point_index]
    tangent = tangents[point_index]
    along = np.clip(np.sum(offset * tangent, axis=1), -half[point_index], half[point_index])
    distance = np.linalg.norm(offset - along[:, None] * tangent, axis=1)
    near = node_index[distance <= radius - margin + 1e-9]
    dots.ravel()[np.unique(near)] = True
    # Continuity: a stroke point farther than one pitch from every chosen node (the
    # stroke runs within `margin` of midway between node rows) gets its nearest node.
    chosen = np.flatnonzero(dots.ravel())
    if len(chosen):
        gap, _ = cKDTree(nodes[chosen]).query(points_uv)
        lonely = points_uv[gap > 1.0]
    else:
        lonely = points_uv
    if len(lonely):
        u_fill = np.clip(np.rint(lonely[:, 0]).astype(int), 0, columns - 1)
        v_fill = np.clip(np.rint(lonely[:, 1]).astype(int), 0, rows - 1)
        dots[v_fill, u_fill] = True
    return dots


def thin(dots):
    """One node wide lines (scikit-image skeletonize), keeping isolated single nodes."""
    from skimage.morphology import skeletonize

    if not dots.any():
        return dots
    return skeletonize(dots) | (dots & (ndimage.convolve(dots.astype(np.uint8), np.ones(
        (3, 3), np.uint8), mode='constant') == 1))


def subpixel_edges(image, low, high):
    """
    Canny edge pixels moved to their sub-pixel position (x, y) [working px]; and tangents.

    Devernay (1995): along the (quantised) gradient direction, the gradient magnitude at the
    edge pixel and its two neighbours is fitted by a parabola; its peak is the edge.
    """
    image8 = np.clip(image * 255.0 + 0.5, 0, 255).astype(np.uint8)
    blurred = cv2.GaussianBlur(image8, (5, 5), 1.0)
    edges = cv2.Canny(blurred, low, high, L2gradient=True)
    ys, xs = np.nonzero(edges)
    if len(xs) == 0:
        return np.zeros((0, 2)), np.zeros((0, 2))
    smooth = cv2.GaussianBlur(image.astype(np.float32), (5, 5), 1.0)
    gx = cv2.Sobel(smooth, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(smooth, cv2.CV_32F, 0, 1, ksize=3)
    magnitude = np.pad(np.hypot(gx, gy), 1, mode='edge')
    angle = np.arctan2(gy[ys, xs], gx[ys, xs])
    octant = np.round(angle / (np.pi / 4)).astype(int) % 4   # 0: x, 1: diag, 2: y, 3: anti
    steps = np.array([[1, 0], [1, 1], [0, 1], [-1, 1]])[octant]
    centre = magnitude[ys + 1, xs + 1]
    behind = magnitude[ys + 1 - steps[:, 1], xs + 1 - steps[:, 0]]
    ahead = magnitude[ys + 1 + steps[:, 1], xs + 1 + steps[:, 0]]
    curvature = behind - 2.0 * centre + ahead
    with np.errstate(divide='ignore', invalid='ignore'):
        offset = np.where(curvature < 0.0, 0.5 * (behind - ahead) / curvature, 0.0)
    offset = np.clip(offset, -0.5, 0.5)
    points = np.column_stack([xs, ys]).astype(float) + offset[:, None] * steps
    gradient = np.column_stack([gx[ys, xs], gy[ys, xs]]).astype(float)
    gradient /= np.maximum(np.linalg.norm(gradient, axis=1), 1e-12)[:, None]
    tangents = np.column_stack([-gradient[:, 1], gradient[:, 0]])
    return points, tangents


def subpixel_skeleton(mask, image, step=0.25):
    """
    Medial-line points (x, y) [working px] of a mask, refined across the stroke; tangents.

    ``skimage.morphology.skeletonize`` gives pixels on or next to the medial line (a stroke of
    even width has its medial line between two pixels). Each skeleton pixel is moved to the
    midpoint of the two places where the grey image crosses mid-grey along the stroke's
    normal (the direction to the nearest background pixel), found by bilinear sampling every
    `step` px: area-averaged or anti-aliased edges put that crossing within a small fraction
    of a pixel of the true outline. Moves are limited to one pixel.
    """
    from skimage.morphology import skeletonize

    skeleton = skeletonize(mask)
    ys, xs = np.nonzero(skeleton)
    if len(xs) == 0:
        return np.zeros((0, 2)), np.zeros((0, 2))
    distance, (iy, ix) = ndimage.distance_transform_edt(mask, return_indices=True)
    normal = np.column_stack([xs - ix[ys, xs], ys - iy[ys, xs]]).astype(float)
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-9)[:, None]
    reach = np.arange(0.0, float(np.max(distance[ys, xs])) + 2.0, step)
    crossings = []
    for sign in (1.0, -1.0):
        sample_x = xs[:, None] + sign * reach[None, :] * normal[:, 0:1]
        sample_y = ys[:, None] + sign * reach[None, :] * normal[:, 1:2]
        grey = ndimage.map_coordinates(image, [sample_y, sample_x], order=1, mode='nearest')
        bright = grey >= 0.5
        first = np.argmax(bright, axis=1)
        found = bright[np.arange(len(xs)), first] & (first > 0)
        before = grey[np.arange(len(xs)), np.maximum(first - 1, 0)]
        after = grey[np.arange(len(xs)), first]
        fraction = np.where(after > before, (0.5 - before) / np.maximum(after - before, 1e-9),
                            0.0)
        crossing = (np.maximum(first - 1, 0) + np.clip(fraction, 0.0, 1.0)) * step
        crossings.append(np.where(found, crossing, np.nan))
    offset = 0.5 * (crossings[0] - crossings[1])
    offset = np.clip(np.nan_to_num(offset, nan=0.0), -1.0, 1.0)
    points = np.column_stack([xs, ys]).astype(float) + offset[:, None] * normal
    return points, np.column_stack([-normal[:, 1], normal[:, 0]])


def dark_mask(image):
    """Dark part of a two-level picture: below mid-grey after a 3x3 median."""
    return cv2.medianBlur(np.clip(image * 255.0 + 0.5, 0, 255).astype(np.uint8), 3) < 128


def edge_features(image, grid_shape, oversample, options):
    """Mode ``edges``: Canny (paper), sub-pixel, nodes within half a pitch, thinned."""
    points, tangents = subpixel_edges(image, options.canny_low, options.canny_high)
    strokes = to_grid_units(points, oversample)
    dots = thin(nodes_near(strokes, tangents, grid_shape, oversample))
    return Features('edges', dots, 1.0 - cell_means(image, oversample), strokes=strokes,
                    reference=image)


def centerline_features(image, grid_shape, oversample, options):
    """Mode ``centerline``: medial line of the dark strokes (paper Fig. 9 c), thinned."""
    mask = dark_mask(image)
    points, tangents = subpixel_skeleton(mask, image)
    strokes = to_grid_units(points, oversample)
    dots = thin(nodes_near(strokes, tangents, grid_shape, oversample))
    return Features('centerline', dots, 1.0 - cell_means(image, oversample), strokes=strokes,
                    reference=image)


def threshold_features(image, grid_shape, oversample, options):
    """Mode ``threshold``: adaptive + Otsu threshold and denoising (paper, Fig. 9 d)."""
    image8 = np.clip(image * 255.0 + 0.5, 0, 255).astype(np.uint8)
    denoised = cv2.medianBlur(image8, 3 if oversample < 6 else 5)
    block = int(round(options.threshold_block_nodes * oversample)) | 1
    adaptive = cv2.adaptiveThreshold(denoised, 1, cv2.ADAPTIVE_THRESH_GAUSSIAN_C,
                                     cv2.THRESH_BINARY_INV, max(3, block),
                                     options.threshold_offset * 255.0)
    _, otsu = cv2.threshold(denoised, 0, 1, cv2.THRESH_BINARY_INV + cv2.THRESH_OTSU)
    binary = (adaptive | otsu).astype(np.uint8)
    speck = max(1, oversample // 2)
    binary = cv2.morphologyEx(binary, cv2.MORPH_OPEN, np.ones((speck, speck), np.uint8))
    dots = cell_means(binary.astype(float), oversample) >= 0.5
    reference = 1.0 - binary.astype(np.float32)
    return Features('threshold', dots, 1.0 - cell_means(image, oversample),
                    reference=reference)


def tone_features(image, grid_shape, oversample, options):
    """Mode ``tones``: darkness per node by error diffusion (``halftone``)."""
    darkness = np.clip(1.0 - cell_means(image, oversample), 0.0, 1.0) ** options.tone_gamma
    dots = error_diffusion(darkness, options.tone_kernel)
    return Features('tones', dots, darkness, reference=image)


def choose_mode(image, oversample):
    """Return (mode, reason): the documented ``auto`` rule (module docstring)."""
    image8 = np.clip(image * 255.0 + 0.5, 0, 255).astype(np.uint8)
    smoothed = cv2.medianBlur(image8, 3).astype(np.float32) / 255.0
    low, high = MID_GREY_RANGE
    mid = float(np.mean((smoothed > low) & (smoothed < high)))
    if mid > MID_GREY_FRACTION:
        return 'tones', (f'{mid:.0%} of the pixels are mid-grey (> {MID_GREY_FRACTION:.0%}): '
                         'a photograph')
    mask = dark_mask(image)
    if not mask.any():
        return 'tones', 'no dark strokes; light greys only'
    from skimage.morphology import skeletonize

    skeleton = skeletonize(mask)
    distance = ndimage.distance_transform_edt(mask)
    width = 2.0 * float(np.median(distance[skeleton])) / oversample
    if width < CENTERLINE_MAX_WIDTH:
        return 'centerline', (f'two-level picture, strokes {width:.1f} pitches wide '
                              f'(< {CENTERLINE_MAX_WIDTH:g}): medial lines')
    return 'edges', (f'two-level picture, strokes {width:.1f} pitches wide '
                     f'(>= {CENTERLINE_MAX_WIDTH:g}): outlines')


EXTRACTORS = {'edges': edge_features, 'centerline': centerline_features,
              'threshold': threshold_features, 'tones': tone_features}


def extract_features(image, grid_shape, oversample, options):
    """Run the feature mode of `options` (``auto`` resolved by ``choose_mode``)."""
    mode, notes = options.feature_mode, []
    if mode == 'auto':
        mode, reason = choose_mode(image, oversample)
        notes.append(f'auto chose {mode}: {reason}')
    features = EXTRACTORS[mode](image, grid_shape, oversample, options)
    features.notes[:0] = notes
    return features
