"""The sheets to print at 1:1: sizes read back from the files, patterns found by OpenCV."""

import re

import cv2
from helio_control.print_sheets import board_sheet, INCH, marker_sheet, write_sheet
from helio_optics.ground_render import aruco_dictionary
import numpy as np
from PIL import Image
import pytest


def detect(image, dictionary):
    detector = cv2.aruco.ArucoDetector(aruco_dictionary(dictionary))
    corners, ids, _ = detector.detectMarkers(image)
    return [c.reshape(4, 2) for c in corners], [] if ids is None else ids.ravel().tolist()


def bar_length(sheet):
    """Return the longest run of black pixels along the scale bar's row [px]."""
    column, row, _ = sheet.scale_bar
    black = sheet.image[row + 1, :] < 128
    runs, length = [], 0
    for value in black:
        length = length + 1 if value else 0
        runs.append(length)
    return max(runs)


@pytest.mark.parametrize('dpi', [300, 600])
def test_the_marker_prints_at_its_side_with_a_100_mm_bar(dpi):
    sheet = marker_sheet(side=0.04, marker_id=0, dpi=dpi)
    corners, ids = detect(sheet.image, 'DICT_4X4_50')
    assert ids == [0]
    # the detected outline's sides, in pixels, against 40 mm at this dpi
    quad = corners[0]
    sides = np.linalg.norm(quad - np.roll(quad, -1, axis=0), axis=1)
    assert np.all(np.abs(sides - 0.04 / INCH * dpi) <= 1.5), sides
    # the bar (and its thickness at the last tick) is 100 mm
    assert abs(bar_length(sheet) - 0.1 / INCH * dpi) <= 0.002 / INCH * dpi
    assert 'black square 40.0 mm' in sheet.text[0]


def test_the_files_say_their_size_png_by_its_dpi_pdf_by_its_page(tmp_path):
    sheet = marker_sheet(dpi=300)
    png = write_sheet(sheet, str(tmp_path / 'marker.png'))
    with Image.open(png) as image:
        assert image.info['dpi'] == pytest.approx((300, 300), abs=0.01)
        width_m = image.size[0] / image.info['dpi'][0] * INCH
    assert width_m == pytest.approx(0.210, abs=0.0002)          # A4
    pdf = write_sheet(sheet, str(tmp_path / 'marker.pdf'))
    with open(pdf, 'rb') as stream:
        box = re.search(rb'/MediaBox \[ *0 0 ([\d.]+) ([\d.]+) *\]', stream.read())
    # A4 in PostScript points (1/72 inch): 595.28 x 841.89
    assert float(box.group(1)) == pytest.approx(0.210 / INCH * 72, abs=0.5)
    assert float(box.group(2)) == pytest.approx(0.297 / INCH * 72, abs=0.5)
    with pytest.raises(ValueError, match='.png or a .pdf'):
        write_sheet(sheet, str(tmp_path / 'marker.jpg'))


def test_the_board_is_a_charuco_board_of_its_squares_and_no_ground_marker():
    dpi = 300
    sheet = board_sheet(squares=(7, 5), square=0.025, marker=0.018, dpi=dpi)
    board = cv2.aruco.CharucoBoard((7, 5), 0.025, 0.018, aruco_dictionary('DICT_5X5_100'))
    corners, ids, _, _ = cv2.aruco.CharucoDetector(board).detectBoard(sheet.image)
    assert ids is not None and len(ids) == 6 * 4          # every inner corner
    points = corners.reshape(-1, 2)[np.argsort(ids.ravel())].reshape(4, 6, 2)
    spacing = np.linalg.norm(np.diff(points, axis=1), axis=2)
    assert np.all(np.abs(spacing - 0.025 / INCH * dpi) <= 1.0), spacing
    assert detect(sheet.image, 'DICT_4X4_50')[1] == []     # never the ground marker


@pytest.mark.parametrize('call, words', [
    (lambda: marker_sheet(side=0.5), 'side must be 5 to'),
    (lambda: marker_sheet(paper='a3'), 'paper must be one of'),
    (lambda: marker_sheet(dpi=10), 'dpi must be 72-2400'),
    (lambda: marker_sheet(dictionary='DICT_NOPE'), 'unknown ArUco dictionary'),
    (lambda: board_sheet(squares=(2, 5)), 'at least 3 x 3'),
    (lambda: board_sheet(marker=0.03), 'smaller than the square'),
    (lambda: board_sheet(squares=(12, 9)), 'does not fit'),
])
def test_sheets_that_cannot_be_printed_are_refused_with_the_reason(call, words):
    with pytest.raises(ValueError, match=words):
        call()
