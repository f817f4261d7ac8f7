"""
The ChArUco calibration board: one definition for the sheet, the world and the detector.

A ChArUco board (OpenCV's aruco module) is a chessboard whose white squares hold ArUco
markers: each inner chessboard corner is identified by the markers around it, so a view
that shows only part of the board still gives corners with known board coordinates (a
plain chessboard must be seen whole). That suits a camera carried by the arm over a small
panel: the views that put the board's corners into the image's corners, where the lens
distortion shows, see only part of it.

``BoardSpec`` holds what a user prints and measures (``helio print board``): squares
(columns, rows), the square and marker sides [m] and the marker dictionary (not the ground
marker's, so that neither is taken for the other). Its board frame is OpenCV's: origin at
the board's top-left outer corner as printed, x to the right, y down the sheet, z into the
sheet; ``corner_points`` are the inner corners in that frame, indexed as the detector's
ids.

``draw_board`` prints a board onto a ``ground_render.GroundTexture`` (the simulated
panel) at any pose on the panel, with the print's ink and paper reflectances: each texture
pixel takes the ink's share of its area, so the board's edges are where the pose puts
them, not rounded to texture pixels.
"""

from dataclasses import dataclass
import math

import cv2
from helio_optics.ground_render import aruco_dictionary, linear_to_srgb, srgb_to_linear
import numpy as np


@dataclass(frozen=True)
class BoardSpec:
    """A ChArUco board as printed: squares (columns, rows), sides [m], marker dictionary."""

    squares: tuple = (7, 5)
    square: float = 0.025
    marker: float = 0.018
    dictionary: str = 'DICT_5X5_100'

    def __post_init__(self):
        """Refuse a board OpenCV cannot build or detect, naming the problem."""
        columns, rows = (int(v) for v in self.squares)
        if columns < 3 or rows < 3:
            raise ValueError(f'a ChArUco board needs at least 3 x 3 squares, not '
                             f'{columns} x {rows}')
        if not (math.isfinite(self.square) and self.square > 0.0):
            raise ValueError(f'the square side must be > 0 m, not {self.square}')
        if not 0.0 < self.marker < self.square:
            raise ValueError(f'the marker ({self.marker * 1e3:.1f} mm) must be smaller than '
                             f'the square ({self.square * 1e3:.1f} mm)')
        aruco_dictionary(self.dictionary)          # ValueError for an unknown name
        object.__setattr__(self, 'squares', (columns, rows))

    @property
    def size(self):
        """Return the board's (width, height) [m]: its outer squares' edges."""
        return self.squares[0] * self.square, self.squares[1] * self.square

    def board(self):
        """Return the cv2.aruco.CharucoBoard of this spec."""
        return cv2.aruco.CharucoBoard(self.squares, self.square, self.marker,
                                      aruco_dictionary(self.dictionary))

    def corner_points(self):
        """Return the inner corners (N, 3) in the board frame [m], row by row (the ids)."""
        return np.asarray(self.board().getChessboardCorners(), dtype=float).reshape(-1, 3)

    def image(self, pixels_per_square=64):
        """
        Return (image, pixels per square): the board as printed (uint8, 0 ink, 255 paper).

        At least `pixels_per_square` a square's side: OpenCV 5.0's ``generateImage`` fails
        for some sizes (its marker rectangle rounds outside the square): the next size up
        that works is taken.
        """
        board = self.board()
        for pixels in range(int(pixels_per_square), int(pixels_per_square) + 64):
            try:
                size = (self.squares[0] * pixels, self.squares[1] * pixels)
                return board.generateImage(size, marginSize=0, borderBits=1), pixels
            except cv2.error:
                continue
        raise ValueError(f'OpenCV draws no {self.squares} board near {pixels_per_square} px '
                         'per square')


def board_pose(centre, yaw):
    """
    Return T_world_board (4x4) of a board lying face up with its centre at world `centre`.

    `centre` (x, y) [m] on the panel (z = 0); `yaw` [rad] turns the board's x axis from the
    world x axis about the world z axis. Face up, the board's y axis (down the sheet) is
    the world's -y turned by `yaw`, and its z axis points into the panel.
    """
    c, s = math.cos(yaw), math.sin(yaw)
    T = np.eye(4)
    T[:3, :3] = [[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]]
    T[:3, 3] = [centre[0], centre[1], 0.0]
    return T


def board_centre_offset(spec):
    """Return the board-frame point (3,) at the board's centre [m]."""
    width, height = spec.size
    return np.array([0.5 * width, 0.5 * height, 0.0])


def world_corners(spec, centre, yaw):
    """Return the board's inner corners (N, 3) in the world frame for a board at a pose."""
    T = board_pose(centre, yaw)
    points = spec.corner_points() - board_centre_offset(spec)
    return points @ T[:3, :3].T + T[:3, 3]


def draw_board(texture, spec, centre, yaw=0.0, print_reflectance=(0.05, 0.85),
               paper_margin=0.004, supersample=4):
    """
    Print the board `spec` onto `texture` (8-bit sRGB GroundTexture) in place; return it.

    The board lies face up with its centre at world `centre` (x, y) [m], turned by `yaw`
    [rad] (``board_pose``), on white paper reaching `paper_margin` [m] beyond its outer
    squares (the detector needs a quiet zone). `print_reflectance` (ink, paper) is the
    print's linear reflectance, as the ground marker's (``ground_render.draw_marker``). Each
    texture pixel takes the ink's share of `supersample`^2 points of its area, mixed in
    linear light. ValueError when the sheet does not lie wholly on the texture.
    """
    ink, paper = (float(v) for v in print_reflectance)
    if not 0.0 <= ink < paper <= 1.0:
        raise ValueError(f'print_reflectance must be (ink, paper) with 0 <= ink < paper <= 1, '
                         f'got {print_reflectance}')
    width, height = spec.size
    half = np.array([0.5 * width + paper_margin, 0.5 * height + paper_margin])
    T = board_pose(centre, yaw)
    # the sheet's corners in the world: its bounding box of texture pixels
    corners = np.array([[sx * half[0], sy * half[1]] for sx in (-1, 1) for sy in (-1, 1)])
    world = corners @ T[:2, :2].T + T[:2, 3]
    x_min, x_max, y_min, y_max = texture.extent
    if (world[:, 0].min() < x_min or world[:, 0].max() > x_max or world[:, 1].min() < y_min
            or world[:, 1].max() > y_max):
        raise ValueError(f'the board sheet at {tuple(centre)} does not lie wholly on the '
                         f'panel {tuple(texture.extent)}')
    columns, rows = texture.texture_coordinates(world[:, 0], world[:, 1])
    c0, c1 = int(math.floor(columns.min())), int(math.ceil(columns.max())) + 1
    r0, r1 = int(math.floor(rows.min())), int(math.ceil(rows.max())) + 1
    c0, r0 = max(c0, 0), max(r0, 0)
    c1, r1 = min(c1, texture.image.shape[1]), min(r1, texture.image.shape[0])
    # sample points of each texture pixel, in the world, then in the board frame
    offsets = (np.arange(supersample) + 0.5) / supersample - 0.5
    cc = (np.arange(c0, c1)[:, None] + offsets[None, :]).ravel()
    rr = (np.arange(r0, r1)[:, None] + offsets[None, :]).ravel()
    x, _ = texture.world_of_texture(cc, 0)
    _, y = texture.world_of_texture(0, rr)
    dx, dy = x[None, :] - T[0, 3], y[:, None] - T[1, 3]
    bx = T[0, 0] * dx + T[1, 0] * dy + 0.5 * width       # R^T (p - t), then the centre
    by = T[0, 1] * dx + T[1, 1] * dy + 0.5 * height
    on_sheet = (np.abs(bx - 0.5 * width) <= half[0]) & (np.abs(by - 0.5 * height) <= half[1])
    pattern, pixels_per_square = spec.image()
    scale = pixels_per_square / spec.square
    u = np.floor(bx * scale).astype(int)
    v = np.floor(by * scale).astype(int)
    on_board = (u >= 0) & (u < pattern.shape[1]) & (v >= 0) & (v < pattern.shape[0])
    inked = on_board & (pattern[np.clip(v, 0, pattern.shape[0] - 1),
                                np.clip(u, 0, pattern.shape[1] - 1)] < 128)
    shape = (r1 - r0, supersample, c1 - c0, supersample)
    ink_share = inked.reshape(shape).mean(axis=(1, 3))
    sheet_share = on_sheet.reshape(shape).mean(axis=(1, 3))
    patch = texture.image[r0:r1, c0:c1].astype(np.float32) / 255.0
    underneath = srgb_to_linear(patch)
    printed = ink * ink_share + paper * (sheet_share - ink_share)
    if underneath.ndim == 3:
        sheet_share, printed = sheet_share[:, :, None], printed[:, :, None]
    linear = printed + (1.0 - sheet_share) * underneath
    texture.image[r0:r1, c0:c1] = np.rint(255.0 * linear_to_srgb(linear)).astype(np.uint8)
    return texture


__all__ = ['BoardSpec', 'board_centre_offset', 'board_pose', 'draw_board', 'world_corners']
