"""
Sheets to print at 1:1: the ground marker and a ChArUco calibration board (issue 29, item 6).

The marker a user prints must be the one the configuration describes (``spot_detector``'s
``marker.*``: dictionary, id, side): a printer driver's "fit to page" shrinks it by a few
per cent, which moves every pose the camera takes from it by as much. Each sheet is a page
(A4 or US letter) with the pattern at its true size, a 100 mm scale bar with centimetre
ticks to check the print with a ruler, and a line saying what to measure and where to enter
it. Written as PNG (its pixels per inch in the file, so viewers and printers know the
size) or PDF (the page size in points from the same pixels): print at 100 %.

No rclpy: ``helio print marker|board`` calls ``marker_sheet`` / ``board_sheet`` and
``write_sheet``.
"""

from dataclasses import dataclass
import os

import cv2
from helio_optics.calibration_board import BoardSpec
from helio_optics.ground_render import aruco_dictionary
import numpy as np

INCH = 0.0254                       # [m]
PAGES = {'a4': (0.210, 0.297), 'letter': (8.5 * INCH, 11.0 * INCH)}    # width, height [m]
SCALE_BAR = 0.100                   # [m]
MARGIN = 0.012                      # page margin printers leave blank [m]


@dataclass
class Sheet:
    """A page image (uint8, white 255) and what it holds, for the notes and the tests."""

    image: np.ndarray
    dpi: int
    scale_bar: tuple                # (column, row, length) of the 100 mm bar [px]
    text: list                      # the lines printed under the pattern


def pixels(length, dpi):
    """Return `length` [m] in pixels at `dpi`, rounded."""
    return int(round(length / INCH * dpi))


def _page(paper, dpi):
    if paper not in PAGES:
        raise ValueError(f'paper must be one of {sorted(PAGES)}, not {paper!r}')
    if not 72 <= dpi <= 2400:
        raise ValueError(f'dpi must be 72-2400, not {dpi}')
    width, height = PAGES[paper]
    return np.full((pixels(height, dpi), pixels(width, dpi)), 255, np.uint8)


def _scale_bar_and_text(page, dpi, top, lines):
    """Draw the 100 mm bar with 10 mm ticks at row `top` and `lines` under it; return the bar."""
    left = pixels(MARGIN + 0.01, dpi)
    length = pixels(SCALE_BAR, dpi)
    thick = max(2, pixels(0.0006, dpi))
    tick = pixels(0.004, dpi)
    page[top:top + thick, left:left + length + thick] = 0
    for k in range(11):
        x = left + pixels(k * SCALE_BAR / 10, dpi)
        height = 2 * tick if k in (0, 5, 10) else tick
        page[top - height:top + thick, x:x + thick] = 0
    scale = dpi / 300.0
    row = top + pixels(0.008, dpi)
    cv2.putText(page, '0', (left - pixels(0.001, dpi), row), cv2.FONT_HERSHEY_SIMPLEX,
                0.9 * scale, 0, max(1, int(2 * scale)), cv2.LINE_AA)
    cv2.putText(page, '100 mm', (left + length - pixels(0.01, dpi), row),
                cv2.FONT_HERSHEY_SIMPLEX, 0.9 * scale, 0, max(1, int(2 * scale)), cv2.LINE_AA)
    row += pixels(0.012, dpi)
    for line in lines:
        cv2.putText(page, line, (left, row), cv2.FONT_HERSHEY_SIMPLEX, 0.8 * scale, 0,
                    max(1, int(2 * scale)), cv2.LINE_AA)
        row += pixels(0.007, dpi)
    return left, top, length


def marker_sheet(side=0.04, marker_id=0, dictionary='DICT_4X4_50', paper='a4', dpi=600):
    """
    Return the Sheet of the ground marker: black square `side` [m], centred in the top half.

    The white around it is the page's own (the detector needs a quiet zone of at least one
    cell; the sheet keeps 15 mm clear all round).
    """
    page = _page(paper, dpi)
    widest = PAGES[paper][0] - 2 * (MARGIN + 0.015)
    if not 0.005 <= side <= widest:
        raise ValueError(f'side must be 5 to {widest * 1e3:.0f} mm (the {paper} page with 15 '
                         f'mm clear all round), not {side * 1e3:.1f} mm')
    size = pixels(side, dpi)
    marker = cv2.aruco.generateImageMarker(aruco_dictionary(dictionary), int(marker_id), size,
                                           1)
    column = (page.shape[1] - size) // 2
    row = pixels(MARGIN + 0.03, dpi)
    page[row:row + size, column:column + size] = marker
    lines = [f'ArUco {dictionary} id {marker_id}: black square {side * 1e3:.1f} mm',
             'Print at 100 % (not "fit to page"); check the bar with a ruler.',
             'Measure the black square; enter it as marker.side [m] in spot_detector.yaml',
             "(and the lens planner's marker_side). Matte paper, matte black: no gloss."]
    bar = _scale_bar_and_text(page, dpi, row + size + pixels(0.03, dpi), lines)
    return Sheet(page, dpi, bar, lines)


def board_sheet(squares=(7, 5), square=0.025, marker=0.018, dictionary='DICT_5X5_100',
                paper='a4', dpi=600):
    """
    Return the Sheet of a ChArUco board for a camera calibration.

    `squares` (columns, rows) of `square` [m], markers `marker` [m] of `dictionary` (not the
    ground marker's, so that neither is taken for the other).
    """
    spec = BoardSpec(squares, square, marker, dictionary)      # ValueError for a bad board
    columns, rows = spec.squares
    page = _page(paper, dpi)
    width, height = pixels(columns * square, dpi), pixels(rows * square, dpi)
    if width > page.shape[1] - 2 * pixels(MARGIN, dpi) or \
            height > 0.7 * page.shape[0]:
        raise ValueError(f'a {columns} x {rows} board of {square * 1e3:.1f} mm squares does '
                         f'not fit the {paper} page')
    image = spec.board().generateImage((width, height), marginSize=0, borderBits=1)
    column = (page.shape[1] - width) // 2
    row = pixels(MARGIN + 0.01, dpi)
    page[row:row + height, column:column + width] = image
    lines = [f'ChArUco {columns} x {rows}, {dictionary}: squares {square * 1e3:.1f} mm, '
             f'markers {marker * 1e3:.1f} mm',
             'Print at 100 % (not "fit to page"); check the bar with a ruler.',
             'Measure a square and a marker; lay the sheet flat on the panel.']
    bar = _scale_bar_and_text(page, dpi, row + height + pixels(0.025, dpi), lines)
    return Sheet(page, dpi, bar, lines)


def write_sheet(sheet, path):
    """Write `sheet` as PNG or PDF (by the extension of `path`) at its dpi; return the path."""
    from PIL import Image
    extension = os.path.splitext(path)[1].lower()
    if extension not in ('.png', '.pdf'):
        raise ValueError(f'write a .png or a .pdf, not {path!r}')
    image = Image.fromarray(sheet.image, mode='L')
    if extension == '.png':
        image.save(path, dpi=(sheet.dpi, sheet.dpi))
    else:
        image.save(path, resolution=float(sheet.dpi))
    return path
