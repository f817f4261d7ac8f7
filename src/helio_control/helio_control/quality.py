"""
How well the dots reproduce the picture: the quality figure of a plan.

- Line modes (``edges``, ``centerline``): the symmetric chamfer distance [mm] between the
  dot centres and the picture's strokes (the sub-pixel feature points) at canvas scale:
  the mean of (mean distance from each dot to the nearest stroke point) and (mean distance
  from each stroke point to the nearest dot). 0 is perfect; a dot pitch of 2 mm gives
  about 0.3-0.6 mm for clean line art. Reported with both directed parts.
- Fill modes (``threshold``, ``tones``): the structural similarity (SSIM, Wang et al. 2004,
  scikit-image) between the dot rendering and the target, both blurred by a Gaussian of
  one dot pitch (as seen from a distance where dots merge). The target is the picture
  itself for ``tones`` and the thresholded picture for ``threshold``. The rendering draws
  each dot as a black disc of diameter r_p * sqrt(N_p / N_p target) (area grows with N_p,
  paper Fig. 8 d) on white. 1 is perfect.
"""

import math

import cv2
import numpy as np
from scipy.spatial import cKDTree


def chamfer_mm(dots_uv, strokes_uv, pitch):
    """Symmetric chamfer distance [mm] between dots and stroke points (both grid units)."""
    dots_uv = np.asarray(dots_uv, dtype=float).reshape(-1, 2)
    strokes_uv = np.asarray(strokes_uv, dtype=float).reshape(-1, 2)
    if len(dots_uv) == 0 or len(strokes_uv) == 0:
        return {'chamfer_mm': math.inf, 'dots_to_strokes_mm': math.inf,
                'strokes_to_dots_mm': math.inf}
    to_strokes, _ = cKDTree(strokes_uv).query(dots_uv)
    to_dots, _ = cKDTree(dots_uv).query(strokes_uv)
    scale = pitch * 1e3
    forward, backward = float(np.mean(to_strokes)) * scale, float(np.mean(to_dots)) * scale
    return {'chamfer_mm': 0.5 * (forward + backward), 'dots_to_strokes_mm': forward,
            'strokes_to_dots_mm': backward}


def render_dots(dots_uv, shape, oversample, sizes=None):
    """
    White image (working resolution, 1 = white) with each dot a black disc.

    `dots_uv` are grid coordinates; a dot's diameter is one pitch (oversample pixels) times
    `sizes` (default 1), drawn anti-aliased with sub-pixel centres.
    """
    canvas = np.full(shape, 255, np.uint8)
    sizes = np.ones(len(dots_uv)) if sizes is None else np.asarray(sizes, dtype=float)
    shift = 4
    for (u, v), size in zip(np.asarray(dots_uv, dtype=float).reshape(-1, 2), sizes):
        centre = (int(round(((u + 0.5) * oversample - 0.5) * (1 << shift))),
                  int(round(((v + 0.5) * oversample - 0.5) * (1 << shift))))
        radius = int(round(0.5 * oversample * size * (1 << shift)))
        cv2.circle(canvas, centre, radius, 0, -1, cv2.LINE_AA, shift)
    return canvas.astype(np.float32) / 255.0


def blurred(image, oversample):
    """Gaussian blur of one dot pitch (sigma = oversample pixels)."""
    return cv2.GaussianBlur(image.astype(np.float32), (0, 0), float(oversample))


def ssim_of_dots(dots_uv, reference, oversample, sizes=None):
    """SSIM between the blurred dot rendering and the blurred reference (working scale)."""
    from skimage.metrics import structural_similarity

    rendering = render_dots(dots_uv, reference.shape, oversample, sizes)
    return float(structural_similarity(blurred(rendering, oversample),
                                       blurred(reference, oversample), data_range=1.0))
