"""The ChArUco board as printed onto a panel texture lies where its pose says (issue 29)."""

import math

import cv2
from helio_optics.calibration_board import BoardSpec, draw_board, world_corners
from helio_optics.ground_render import make_panel_texture
import numpy as np
import pytest

EXTENT = (-0.04, 0.16, -0.04, 0.16)


@pytest.mark.parametrize('yaw', [0.0, math.radians(30.0)])
def test_the_printed_boards_corners_are_where_its_pose_puts_them(yaw):
    spec = BoardSpec((7, 5), 0.014, 0.0105)
    texture = make_panel_texture(extent=EXTENT, metres_per_pixel=2e-4)
    centre = (0.07, 0.08)
    draw_board(texture, spec, centre, yaw)
    detector = cv2.aruco.CharucoDetector(spec.board())
    corners, ids, _, _ = detector.detectBoard(cv2.cvtColor(texture.image, cv2.COLOR_RGB2GRAY))
    assert ids is not None and len(ids) == 24                 # every inner corner read
    ids = ids.ravel()
    truth = world_corners(spec, centre, yaw)[ids]
    column, row = texture.texture_coordinates(truth[:, 0], truth[:, 1])
    error = np.linalg.norm(corners.reshape(-1, 2) - np.stack([column, row], axis=1), axis=1)
    assert error.max() < (0.01 if yaw == 0.0 else 0.15)      # texture pixels (0.2 mm)


def test_a_board_off_the_panel_and_a_board_opencv_cannot_build_are_refused():
    texture = make_panel_texture(extent=EXTENT, metres_per_pixel=2e-4)
    with pytest.raises(ValueError, match='does not lie wholly on the panel'):
        draw_board(texture, BoardSpec(), (0.15, 0.15))
    with pytest.raises(ValueError, match='must be smaller than the square'):
        BoardSpec((7, 5), 0.01, 0.012)
    with pytest.raises(ValueError, match='at least 3 x 3'):
        BoardSpec((2, 5))
    image, pixels = BoardSpec((9, 6), 0.011, 0.008).image(64)    # 64 px: OpenCV 5.0 fails
    assert pixels > 64 and image.shape == (6 * pixels, 9 * pixels)
