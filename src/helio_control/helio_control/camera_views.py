"""
Where the arm holds the RGB camera to calibrate it over a ChArUco board (issue 29, item 5).

A camera calibration recovers the focal length only from views in which the board is
tilted against the image plane (square on, a longer focal length and a greater distance
give the same image), the principal point only from several tilts, and the distortion only
from corners near the image's edges and corners, where it moves them most. The camera is
rigid beside the lens (``rig_kinematics``: T_robot_rgb), so the views are poses of the
lens: its centre at several distances over points of the panel around the board, its axis
tilted 0 to 40 degrees off the vertical towards eight directions, with either wrist
solution. The wrist turns the lens about a vertical axis (yaw) and one horizontal axis
(pitch) only, so the board's normal, seen from the camera, always lies in one plane: the
camera tilts against the board about one axis (see ``helio_perception.camera_calibration``
for what that leaves unobservable).

Each candidate is checked with the rig model and the nominal camera before the arm moves:
reachable within the joint limits; the lens centre at least ``min_lens_height`` over the
panel (the heating distance 8.2 cm plus a margin: the focus stays off the paper); at least
``min_corners`` of the board's corners inside the image; the board tilted no more than
``max_view_angle`` against the image plane; its squares at least ``min_square_pixels``
and its markers' cells ``min_cell_pixels`` on their shortest side in the image (smaller
ones give their corners to the sampling and the detector cannot read the markers).

From the candidates ``plan_camera_views`` picks at most `count` greedily: each next view is
the one adding most to (a) the image cells its corners fall in that earlier views left empty
(a 6 x 4 grid, each corner counting 1 / (1 + corners the cell holds already)) plus (b) the
tilts chosen so far: 1 / (1 + the views already in its 10 degree bin of tilt against the
image plane, signed by the side the board leans to). The tilts spread over all the wrist
offers, each seen in several views: a plan of mostly steep views left the focal length
hanging on its one or two square-on views (dropping one moved it by 0.26 %).
No rclpy.
"""

from dataclasses import dataclass
import math

from helio_control.sun_sweep import tilted_axis
from helio_optics.calibration_board import world_corners
from helio_optics.geometry import invert_transform, transform_points
from helio_optics.rig_kinematics import UnreachableError
import numpy as np

GRID = (6, 4)        # image cells (columns, rows) the coverage is counted in


@dataclass
class CameraView:
    """A candidate pose: joints x (5,), the camera pose and the board corners it shows."""

    x: np.ndarray
    T_world_rgb: np.ndarray
    pixels: np.ndarray           # (K, 2) of the corners in view [px]
    normal: np.ndarray           # the board's normal (world up) in the camera frame
    distance: float              # lens height over the aimed point [m]
    tilt: float                  # lens axis off the vertical [rad]


def _shortest_side(pixels, grid, inside):
    """
    Return the shortest image distance [px] between neighbouring corners in view.

    `pixels` (N, 2) of the inner corners, row by row of `grid` (rows, columns); `inside`
    (N,) those in the image. A square foreshortened below a score of pixels gives its
    corners to the renderer's and the detector's sampling (0.2-0.3 px of error).
    """
    at = pixels.reshape(grid + (2,))
    seen = inside.reshape(grid)
    sides = [np.linalg.norm(at[:, 1:] - at[:, :-1], axis=2)[seen[:, 1:] & seen[:, :-1]],
             np.linalg.norm(at[1:] - at[:-1], axis=2)[seen[1:] & seen[:-1]]]
    sides = np.concatenate([side.ravel() for side in sides])
    return float(sides.min()) if sides.size else 0.0


def view_candidates(rig, camera, spec, centre, yaw=0.0, distances=(0.12, 0.145, 0.17, 0.195),
                    tilts_deg=(0.0, 15.0, 30.0, 40.0), azimuths=8, offsets=(0.0, 0.025, 0.05),
                    margin=10.0, min_corners=10, max_view_angle=math.radians(65.0),
                    min_square_pixels=18.0, min_cell_pixels=2.5, min_lens_height=0.1):
    """
    Return the CameraViews of the candidate lens poses (module docstring) that pass.

    `rig`: the rig model (``Rig`` of the rig file, its T_robot_world the best known);
    `camera`: the nominal PinholeCamera; the board `spec` (a BoardSpec) lies at `centre`
    (x, y) [m] turned by `yaw` [rad] on the panel. The lens stands over the board's centre
    and over points `offsets` [m] from it in eight directions; `margin` [px] keeps corners
    off the image border.
    """
    T_robot_world = rig.parameters.T_robot_world
    T_world_robot = invert_transform(T_robot_world)
    corners = world_corners(spec, centre, yaw)
    up = np.array([0.0, 0.0, 1.0])
    grid = (spec.squares[1] - 1, spec.squares[0] - 1)      # inner corners: rows, columns
    # a marker cell's side over a square's side: the cells must be readable
    cell = spec.marker / (spec.board().getDictionary().markerSize + 2) / spec.square
    centre3 = np.array([centre[0], centre[1], 0.0])
    points = [centre3]
    for offset in offsets:
        if offset > 0.0:
            points += [centre3 + offset * np.array([math.cos(a), math.sin(a), 0.0])
                       for a in np.arange(8) * math.pi / 4.0]
    views = []
    limit = np.array([camera.width, camera.height]) - margin
    for point in points:
        for tilt in (math.radians(t) for t in tilts_deg):
            for azimuth in np.arange(azimuths if tilt > 0.0 else 1) * 2.0 * math.pi / azimuths:
                axis = tilted_axis(np.array([0.0, 0.0, -1.0]), tilt, azimuth)
                for distance in distances:
                    lens = transform_points(T_robot_world, point) + distance * axis
                    if distance * axis[2] < min_lens_height:
                        continue
                    for turn in (0.0, math.pi):
                        yaw_lens, pitch = rig.yaw_pitch_for_axis(
                            axis, math.atan2(lens[1], lens[0]) + turn)
                        try:
                            x = rig.inverse(lens, yaw_lens, pitch)
                        except (UnreachableError, ValueError):
                            continue
                        T_world_rgb = T_world_robot @ rig.forward(x).T_robot_rgb
                        local = (corners - T_world_rgb[:3, 3]) @ T_world_rgb[:3, :3]
                        if np.any(local[:, 2] <= 0.0):
                            continue
                        pixels = camera.project(local)
                        inside = np.all((pixels >= margin) & (pixels <= limit), axis=1)
                        if np.count_nonzero(inside) < min_corners:
                            continue
                        normal = T_world_rgb[:3, :3].T @ up
                        if math.acos(min(1.0, abs(normal[2]))) > max_view_angle:
                            continue
                        shortest = _shortest_side(pixels, grid, inside)
                        if shortest < max(min_square_pixels, min_cell_pixels / cell):
                            continue
                        views.append(CameraView(
                            x=np.asarray(x, float), T_world_rgb=T_world_rgb,
                            pixels=pixels[inside], normal=normal, distance=float(distance),
                            tilt=float(tilt)))
    return views


def plan_camera_views(views, camera, count=25, tilt_bin=math.radians(10.0)):
    """
    Return at most `count` of the CameraViews `views`, picked greedily (module docstring).

    A view's score is the share of new image cells its corners fill (0..1) plus how few
    views chosen so far have its tilt against the image plane, within `tilt_bin`
    (1 / (1 + their number)): the tilts spread over all the candidates offer, each of them
    seen in several views (a fit that leans on one view leans on its noise).
    """
    columns, rows = GRID
    cells = []
    for view in views:
        u = np.clip((view.pixels[:, 0] / camera.width * columns).astype(int), 0, columns - 1)
        v = np.clip((view.pixels[:, 1] / camera.height * rows).astype(int), 0, rows - 1)
        cells.append(v * columns + u)
    normals = np.array([view.normal for view in views]).reshape(-1, 3)
    # the tilt, signed by the side the board leans to (the normals lie in about one plane)
    side = np.sign(normals[:, 1] + 1e-12)
    tilt = side * np.arccos(np.clip(np.abs(normals[:, 2]), 0.0, 1.0))
    bins = np.floor(tilt / tilt_bin).astype(int)
    cover = np.zeros(columns * rows)
    in_bin = {}
    chosen = []
    remaining = np.ones(len(views), bool)
    while np.any(remaining) and len(chosen) < count:
        gain = np.array([np.mean(1.0 / (1.0 + cover[c])) for c in cells])
        balance = np.array([1.0 / (1.0 + in_bin.get(b, 0)) for b in bins])
        score = gain + balance
        score[~remaining] = -np.inf
        best = int(np.argmax(score))
        chosen.append(best)
        remaining[best] = False
        np.add.at(cover, cells[best], 1.0)
        in_bin[bins[best]] = in_bin.get(bins[best], 0) + 1
    return [views[i] for i in chosen]


__all__ = ['CameraView', 'plan_camera_views', 'view_candidates']
