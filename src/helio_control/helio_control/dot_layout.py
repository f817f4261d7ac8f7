"""
From feature pixels to world dots: paper Eq 17, canvas bounds, spacing and reach.

The scaling of Eq 17, the canvas bounds, the dot spacing, and the rig's reach for a given
sun.

Eq 17: omega_s = l_w / (max(x_b, y_b) r_p). The picture (x_b x y_b pixels) is scaled by
omega_s so that its larger side has l_w / r_p pixels: one feature pixel per dot pitch r_p
(the paper's r_p = 0.2 cm is the width of a charred dot at N_p = 30, so dots one pitch apart
touch without overlapping). Feature pixel (u, v) then maps to the world point

    w_p = [u r_p + d_x, v r_p + d_y, 0]        (v_axis = 'paper', as printed)
    w_p = [u r_p + d_x, (n_v - 1 - v) r_p + d_y, 0]   (v_axis = 'flip', the default)

in metres, world frame = the ArUco marker centre, z up. The image's v axis points down;
world y (x to the right, z towards a viewer above the panel) points up. The paper's mapping
therefore burns the picture mirrored top-to-bottom for a viewer above the panel; 'flip'
puts the picture's top row at the largest y so it reads the right way round from above
(as ``sim_world``'s canvas.png shows it: row 0 at y_max). Both keep the dots inside
[d_x, d_x + l_w) x [d_y, d_y + l_w).

The grid has n_u = floor(x_b omega_s) by n_v = floor(y_b omega_s) cells (the larger side
floor(l_w / r_p)); node (u, v) stands for the picture region [u, u + 1) x [v, v + 1) /
omega_s, i.e. its centre is at picture pixel coordinate (u + 0.5) / omega_s.

Reach (paper Sec. IV-A, Eqs 14-15): each dot is checked at the heating distance d_lp and
at the retreat distance d_lp + delta d_lp through ``helio_optics.rig_kinematics.Rig``;
unreachable dots are returned with the rig's reason, never dropped silently.
"""

from dataclasses import dataclass
import math

import numpy as np
from scipy.spatial import cKDTree

SPACING_SLACK = 1e-9   # [m] floating-point slack of the no-overlap check


@dataclass(frozen=True)
class DotGrid:
    """The feature grid of Eq 17 for one picture and one canvas."""

    picture_width: int      # x_b [px]
    picture_height: int     # y_b [px]
    canvas_size: float      # l_w [m]
    dot_pitch: float        # r_p [m]
    offset_x: float         # d_x [m]
    offset_y: float         # d_y [m]
    v_axis: str = 'flip'

    @property
    def omega_s(self):
        """Eq 17 scaling factor: feature pixels per picture pixel."""
        return self.canvas_size / (max(self.picture_width, self.picture_height) * self.dot_pitch)

    @property
    def pixels_per_node(self):
        """Picture pixels per feature pixel (1 / omega_s)."""
        return 1.0 / self.omega_s

    @property
    def shape(self):
        """(n_v, n_u): feature image rows and columns."""
        return (int(math.floor(self.picture_height * self.omega_s + 1e-9)),
                int(math.floor(self.picture_width * self.omega_s + 1e-9)))

    def world(self, uv):
        """Map feature pixels uv (N x 2, columns u, v) to world x, y [m] by Eq 17."""
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        x = uv[:, 0] * self.dot_pitch + self.offset_x
        if self.v_axis == 'paper':
            y = uv[:, 1] * self.dot_pitch + self.offset_y
        else:
            y = (self.shape[0] - 1 - uv[:, 1]) * self.dot_pitch + self.offset_y
        return np.column_stack([x, y])


def grid_for_picture(width, height, options):
    """Return the DotGrid of a picture of width x height px under PlanOptions."""
    return DotGrid(int(width), int(height), float(options.canvas_size),
                   float(options.dot_radius), float(options.offset_x),
                   float(options.offset_y), options.v_axis)


def outside_canvas(points, options):
    """Boolean mask of world points (N x 2) whose centre lies outside the canvas square."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    low = np.array([options.offset_x, options.offset_y]) - 1e-12
    high = low + options.canvas_size + 2e-12
    return np.any((points < low) | (points > high), axis=1)


def too_close(points, pitch, slack=SPACING_SLACK):
    """
    Find the points closer than `pitch` to an earlier point (greedy, in input order).

    Returns {index: index of the earlier point it is too close to}.

    The paper's no-overlap requirement: keeping the returned points out leaves no two dots
    closer than the pitch (within `slack`).
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(points) < 2:
        return {}
    tree = cKDTree(points)
    pairs = tree.query_pairs(pitch - slack, output_type='ndarray')
    if len(pairs) == 0:
        return {}
    neighbours = {}
    for i, j in pairs:
        neighbours.setdefault(int(max(i, j)), []).append(int(min(i, j)))
    removed = {}
    for index in sorted(neighbours):
        kept = [j for j in neighbours[index] if j not in removed]
        if kept:
            removed[index] = kept[0]
    return removed


def min_spacing(points):
    """Smallest distance between two of the points (inf for fewer than two) [m]."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(points) < 2:
        return math.inf
    distances, _ = cKDTree(points).query(points, k=2)
    return float(distances[:, 1].min())


@dataclass
class ReachResult:
    """Joints at the heating and retreat poses of each dot, and why a dot is unreachable."""

    joints_heat: np.ndarray       # N x 5 [rad], NaN rows when unreachable
    joints_retreat: np.ndarray    # N x 5 [rad]
    reasons: list                 # '' when reachable

    @property
    def reachable(self):
        """Boolean mask of the reachable dots."""
        return np.array([not reason for reason in self.reasons], dtype=bool)


def check_reach(points, rig, sun_ray_robot, d_lp, retreat):
    """
    Eqs 14-15 for every world point at d_lp and d_lp + retreat; joints and reasons.

    The world point p maps to the robot frame by ``rig.parameters.T_robot_world``; the lens
    pose comes from ``rig.lens_pose_for_target`` with the sun ray s0 (robot frame, pointing
    down). The retreat pose keeps the yaw solution of the heating pose when it can.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    transform = rig.parameters.T_robot_world
    targets = points @ transform[:2, :2].T + transform[:3, 3][None, :2]
    heights = np.full(len(points), transform[2, 3]) + points @ transform[2, :2]
    heat = np.full((len(points), 5), np.nan)
    back = np.full((len(points), 5), np.nan)
    reasons = []
    for index in range(len(points)):
        target = np.array([targets[index, 0], targets[index, 1], heights[index]])
        near = rig.lens_pose_for_target(target, sun_ray_robot, d_lp)
        if near.x is None:
            reasons.append(f'unreachable at d_lp {d_lp * 100:.1f} cm: {near.reason}')
            continue
        far = rig.lens_pose_for_target(target, sun_ray_robot, d_lp + retreat,
                                       preferred_yaw=near.yaw)
        if far.x is None:
            reasons.append(f'unreachable at the retreat d_lp {(d_lp + retreat) * 100:.1f} cm: '
                           f'{far.reason}')
            continue
        heat[index], back[index] = near.x, far.x
        reasons.append('')
    return ReachResult(heat, back, reasons)
