"""
Sample pictures made by the project, one per kind of target of paper Fig. 9.

``text`` (rendered "SUN", Fig. 9 a1: text), ``logo`` (a ring around a filled triangle,
Fig. 9 b1: a geometric logo), ``portrait`` (the grey "camera" photograph shipped by
scikit-image, Fig. 9 d1: a picture with many grey levels; CC0, Lav Varshney, per
``skimage.data.camera``'s licence note). The pictures are drawn in code, so tests, the
preview (``sample:text`` as PICTURE) and the benchmark need no file.

All three are uint8 greyscale, dark strokes on white (255), as a person would draw them.
"""

import cv2
import numpy as np

SAMPLE_NAMES = ('text', 'logo', 'portrait')


def text_picture(text='SUN', height=240, thickness=None):
    """Dark text on white, rendered with OpenCV's Hershey simplex font (paper Fig. 9 a1)."""
    font = cv2.FONT_HERSHEY_SIMPLEX
    thickness = thickness or max(1, height // 12)
    scale = cv2.getFontScaleFromHeight(font, int(height * 0.6), thickness)
    (width, text_height), baseline = cv2.getTextSize(text, font, scale, thickness)
    margin = height // 8
    picture = np.full((height, width + 2 * margin), 255, np.uint8)
    origin = (margin, (height + text_height) // 2)
    cv2.putText(picture, text, origin, font, scale, 0, thickness, cv2.LINE_AA)
    return picture


def logo_picture(size=400):
    """Draw a geometric logo: a thick ring around a filled triangle (paper Fig. 9 b1)."""
    picture = np.full((size, size), 255, np.uint8)
    centre = (size // 2, size // 2)
    cv2.circle(picture, centre, int(size * 0.42), 0, max(2, size // 16), cv2.LINE_AA)
    r = size * 0.26
    triangle = np.array([[centre[0] + r * np.sin(a), centre[1] - r * np.cos(a)]
                         for a in np.radians([0.0, 120.0, 240.0])])
    cv2.fillPoly(picture, [np.round(triangle * 16).astype(np.int32)], 0, cv2.LINE_AA, shift=4)
    return picture


def portrait_picture(size=256):
    """Return a grey photograph: scikit-image's CC0 'camera', resized (paper Fig. 9 d1)."""
    from skimage import data

    picture = data.camera()
    return cv2.resize(picture, (size, size), interpolation=cv2.INTER_AREA)


def sample_picture(name):
    """Return the named sample picture (one of SAMPLE_NAMES) as uint8 greyscale."""
    makers = {'text': text_picture, 'logo': logo_picture, 'portrait': portrait_picture}
    if name not in makers:
        raise KeyError(f'unknown sample picture {name!r} (samples: {", ".join(SAMPLE_NAMES)})')
    return makers[name]()
