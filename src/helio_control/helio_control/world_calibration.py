"""
Robot-world calibration from the ArUco marker (paper Sec. II-B).

"At the beginning of each solar painting task, the world-robot transformation matrix is
obtained by observing the ArUco marker."

Each arm pose i gives two views of the RGB camera: T_robot_rgb_i from the forward
kinematics of the joints (the rig model), and T_world_rgb_i from the marker (Eqs 7-9, the
spot detector's camera pose). Their product T_robot_world_i = T_robot_rgb_i T_world_rgb_i^-1
is one measurement of where the marker lies in the robot frame. The panel and the robot
stand on the same level ground (the paper's setting), so the estimate is the 4-DOF transform
that ``RigParameters`` holds (position and yaw about the vertical); the tilt of the measured
marker z axes is reported as a check of that assumption, not applied.

The estimate is robust: the position is the component-wise median refined by the mean of
the measurements within ``outlier_distance`` of it, the yaw likewise on the circle; poses
beyond are left out and counted. The residuals are the rms spread of the measurements used.

API: ``estimate_world_in_robot(T_robot_rgb, T_world_rgb, ...) -> WorldCalibration``;
``marker_poses(rig, camera, marker_side, points, distance, count, margin)``: the arm poses
from which the camera should see the whole marker (by the rig file), squarest views first.
"""

from dataclasses import dataclass, field
import math

from helio_control import sun_sweep
from helio_optics.geometry import invert_transform, transform_points
from helio_perception.ground_plane import marker_view_angle
import numpy as np


@dataclass
class WorldCalibration:
    """The estimate of T_robot_world and how well the poses agreed."""

    world_in_robot: np.ndarray        # marker centre in the robot frame (3,) [m]
    world_yaw: float                  # marker x from robot x about the vertical [rad]
    residual_position: float          # rms distance of the used measurements [m]
    residual_angle: float             # rms yaw difference of the used measurements [rad]
    tilt: float                       # mean angle of the measured marker z from vertical [rad]
    used: int                         # measurements used
    rejected: list = field(default_factory=list)   # indices left out

    @property
    def T_robot_world(self):  # noqa: N802 (the project's transform naming)
        """Return the 4x4 transform of the estimate."""
        c, s = math.cos(self.world_yaw), math.sin(self.world_yaw)
        transform = np.eye(4)
        transform[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
        transform[:3, 3] = self.world_in_robot
        return transform


def _check_transforms(name, transforms):
    transforms = np.asarray(transforms, dtype=float)
    if transforms.ndim != 3 or transforms.shape[1:] != (4, 4):
        raise ValueError(f'{name} must be a list of 4x4 transforms, got shape '
                         f'{transforms.shape}')
    if not np.all(np.isfinite(transforms)):
        raise ValueError(f'{name} holds NaN or infinite values')
    rotations = transforms[:, :3, :3]
    error = np.abs(np.einsum('kij,kil->kjl', rotations, rotations) - np.eye(3)).max()
    if error > 1e-6:
        raise ValueError(f'{name} holds a matrix that is not a rotation (|R^T R - I| = '
                         f'{error:.2e})')
    return transforms


def estimate_world_in_robot(T_robot_rgb, T_world_rgb, min_poses=3, outlier_distance=3e-3,
                            outlier_angle=math.radians(1.5)):
    """
    Estimate T_robot_world from paired camera poses (see the module docstring).

    `T_robot_rgb` and `T_world_rgb` are K 4x4 transforms each (K >= `min_poses`). Raise
    ValueError naming the problem (too few poses, non-finite or non-rotation input, fewer
    than `min_poses` measurements agreeing within the outlier bounds).
    """
    robot = _check_transforms('T_robot_rgb', T_robot_rgb)
    world = _check_transforms('T_world_rgb', T_world_rgb)
    if robot.shape[0] != world.shape[0]:
        raise ValueError(f'{robot.shape[0]} kinematic poses but {world.shape[0]} marker poses')
    if robot.shape[0] < min_poses:
        raise ValueError(f'robot-world calibration needs at least {min_poses} poses, got '
                         f'{robot.shape[0]}')
    measured = np.array([r @ invert_transform(w) for r, w in zip(robot, world)])
    positions = measured[:, :3, 3]
    yaws = np.arctan2(measured[:, 1, 0], measured[:, 0, 0])
    tilts = np.arccos(np.clip(measured[:, 2, 2], -1.0, 1.0))
    centre = np.median(positions, axis=0)
    yaw_centre = _circular_median(yaws)
    distance = np.linalg.norm(positions - centre, axis=1)
    turn = np.abs(_wrap(yaws - yaw_centre))
    keep = (distance <= outlier_distance) & (turn <= outlier_angle)
    if np.count_nonzero(keep) < min_poses:
        raise ValueError(
            f'only {np.count_nonzero(keep)} of {len(keep)} marker measurements agree within '
            f'{outlier_distance * 1e3:.1f} mm and {math.degrees(outlier_angle):.1f} deg '
            f'(spread {np.median(distance) * 1e3:.2f} mm, {math.degrees(np.median(turn)):.2f} '
            'deg): is the rig file far off, or the marker pose unreliable?')
    position = positions[keep].mean(axis=0)
    yaw = yaw_centre + float(np.mean(_wrap(yaws[keep] - yaw_centre)))
    yaw = math.atan2(math.sin(yaw), math.cos(yaw))
    residual_position = float(np.sqrt(np.mean(np.sum((positions[keep] - position) ** 2,
                                                     axis=1))))
    residual_angle = float(np.sqrt(np.mean(_wrap(yaws[keep] - yaw) ** 2)))
    return WorldCalibration(world_in_robot=position, world_yaw=yaw,
                            residual_position=residual_position,
                            residual_angle=residual_angle,
                            tilt=float(np.mean(tilts[keep])), used=int(np.count_nonzero(keep)),
                            rejected=[int(i) for i in np.flatnonzero(~keep)])


def marker_view_candidates(rig, camera, marker_side, points, distances, tilts, azimuths,
                           wrist_turns=(0.0,), margin=30.0):
    """
    Yield (marker view angle [rad], joints) of each pose from which the camera sees the marker.

    The lens stands each of `distances` [m] over each panel point of `points` (world x, y),
    its axis tilted each of `tilts` [deg] off the vertical towards each of `azimuths` [rad],
    the wrist turned by each of `wrist_turns` [rad] (the same axis reached with another
    yaw); a pose counts when the rig model's kinematics put the marker's corners `margin`
    [px] inside the image. The one candidate search of ``marker_poses`` (robot-world
    calibration) and ``rig_calibration.marker_view_poses``.
    """
    T_robot_world = rig.parameters.T_robot_world
    T_world_robot = invert_transform(T_robot_world)
    corners = sun_sweep.marker_corners(marker_side)
    for px, py in points:
        for tilt in tilts:
            for azimuth in azimuths:
                axis = sun_sweep.tilted_axis(np.array([0.0, 0.0, -1.0]), math.radians(tilt),
                                             azimuth)
                for distance in distances:
                    centre = transform_points(T_robot_world, [px, py, 0.0]) + distance * axis
                    for turn in wrist_turns:
                        yaw, pitch = rig.yaw_pitch_for_axis(
                            axis, math.atan2(centre[1], centre[0]) + turn)
                        try:
                            x = rig.inverse(centre, yaw, pitch)
                        except ValueError:
                            continue
                        T_world_rgb = T_world_robot @ rig.forward(x).T_robot_rgb
                        if sun_sweep.in_view(camera, T_world_rgb, corners, margin):
                            yield marker_view_angle(T_world_rgb), x


def marker_poses(rig, camera, marker_side, points, distance=0.11, count=8, margin=30.0):
    """
    Return up to `count` joint vectors from which the RGB camera sees the whole marker.

    The lens stands `distance` [m] over panel `points` (world (x, y)), its axis tilted 0, 15
    or 30 deg off the vertical towards 8 azimuths (``marker_view_candidates``). The marker's
    depth is measured worst at a slant (up to 1.5 mm at 15 cm seen 40 deg off its normal,
    against 0.05 mm square on): the squarest views are kept, spread over the candidates.
    """
    candidates = list(marker_view_candidates(
        rig, camera, marker_side, points, (distance,), (0.0, 15.0, 30.0),
        [math.radians(azimuth) for azimuth in range(0, 360, 45)], margin=margin))
    candidates.sort(key=lambda candidate: candidate[0])
    squarest = [x for _, x in candidates[:3 * count]]
    return sun_sweep.spread(squarest)[:count]


def _wrap(angles):
    return (np.asarray(angles) + math.pi) % (2.0 * math.pi) - math.pi


def _circular_median(angles):
    """Return the angle minimising the summed absolute wrapped differences (of the samples)."""
    angles = np.asarray(angles, dtype=float)
    costs = [np.abs(_wrap(angles - a)).sum() for a in angles]
    return float(angles[int(np.argmin(costs))])
