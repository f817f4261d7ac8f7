"""
The robot-world calibration procedure (paper Sec. II-B) and the marker views it takes.

Poses from which the RGB camera sees the whole marker (by the believed rig and the camera
model); each frame's marker pose (the spot detector's ``camera_pose``, Eqs 7-9) with the
kinematic camera pose of the joints when its image was taken gives T_robot_world
(``world_calibration.estimate_world_in_robot``).
"""

import math

from helio_control.procedures.lens_rig_port import GoalFailed
from helio_control.world_calibration import estimate_world_in_robot, marker_poses
from helio_msgs.action import CalibrateWorld
from helio_optics.node_kit.conversions import matrix_to_pose, pose_to_matrix
from helio_optics.node_kit.conversions import stamp_to_seconds
import numpy as np

# fewer poses than this showing the marker leave the calibration to the rig file's guess
MIN_POSES = 3


def has_marker_pose(message):
    """
    Return whether a spot observation carries a camera pose from the marker (Eqs 7-9).

    Observed after the arm stopped, it was detected after the move: the spot detector
    detects the marker again whenever the joints change, and reuses it while they are still.
    A pose from the kinematics (no marker in view) would calibrate the rig with itself.
    """
    return message.camera_pose_source == 'marker'


async def marker_views(port, poses, feedback):
    """
    Visit `poses`; return (reported joints, T_world_rgb, pose index) of each marker pose.

    Each frame's marker pose is paired with the joints when its image was taken (the
    detector reuses a pose while the joints stay within its tolerance), not those the
    move reported on arrival: a servo arrives within 1 us (about 0.1 deg, i.e. 0.25 mm
    on a marker 15 cm away) and settles after. `feedback` (with index, phase and,
    where it has it, poses_used) is published as it goes.
    """
    joints, world_rgb, indices = [], [], []
    for index, x in enumerate(poses):
        feedback.index, feedback.phase = index, 'moving'
        port.feedback(feedback)
        await port.move(x)
        feedback.phase = 'observing'
        port.feedback(feedback)
        seen = await port.observe(port.settings.observe_frames, has_marker_pose)
        if not seen:
            port.log(f'pose {index}: no marker pose seen', warning=True)
            continue
        for message in seen:     # every frame's marker pose: their noise averages out
            taken = stamp_to_seconds(message.header.stamp) - message.marker_pose_age
            lookup = port.joints_at(taken)
            if not lookup:
                port.log(f'pose {index}: a marker pose skipped: {lookup.reason}', warning=True)
                continue
            joints.append(np.asarray(lookup.positions, dtype=float))
            world_rgb.append(pose_to_matrix(message.camera_pose))
            indices.append(index)
        if hasattr(feedback, 'poses_used'):
            feedback.poses_used = len(joints)
        port.feedback(feedback)
    return joints, world_rgb, indices


async def calibrate_world(port, request, result):
    """Run a CalibrateWorld goal: measure T_robot_world; use and save it if `apply`."""
    settings = port.settings
    camera = await port.camera()
    total = request.poses or settings.world_poses
    poses = marker_poses(port.rig, camera, settings.marker_side, settings.view_points,
                         settings.world_distance, total, settings.view_margin)
    if len(poses) < MIN_POSES:
        raise GoalFailed(f'only {len(poses)} poses show the whole marker to the camera '
                         'according to the rig file: check world_in_robot in the rig file '
                         'and the panel_extent parameter')
    feedback = CalibrateWorld.Feedback(total=len(poses))
    joints, world_rgb, _ = await marker_views(port, poses, feedback)
    robot_rgb = [port.rig.forward(x).T_robot_rgb for x in joints]
    try:
        estimate = estimate_world_in_robot(robot_rgb, world_rgb)
    except ValueError as error:
        raise GoalFailed(f'robot-world calibration failed: {error}') from None
    before = port.rig.parameters
    result.world_in_robot = matrix_to_pose(estimate.T_robot_world)
    result.world_yaw = estimate.world_yaw
    result.residual_position = estimate.residual_position
    result.residual_angle = estimate.residual_angle
    result.tilt = estimate.tilt
    result.poses_used = estimate.used
    result.shift_from_rig_file = float(np.linalg.norm(
        estimate.world_in_robot - np.asarray(before.world_in_robot)))
    result.turn_from_rig_file = float(math.remainder(estimate.world_yaw - before.world_yaw,
                                                     2.0 * math.pi))
    if request.apply:
        port.use_world(estimate.world_in_robot, estimate.world_yaw)
        result.saved_to = port.save('robot_world.yaml', {'rig': {
            'world_in_robot': [float(v) for v in estimate.world_in_robot],
            'world_yaw': float(estimate.world_yaw)}}, {
            'residual_position_m': float(estimate.residual_position),
            'residual_angle_rad': float(estimate.residual_angle),
            'poses_used': int(estimate.used)})
    result.message = (
        f'T_robot_world from {estimate.used} poses ({len(estimate.rejected)} left out): '
        f'marker at {np.round(estimate.world_in_robot * 1000, 2).tolist()} mm, yaw '
        f'{math.degrees(estimate.world_yaw):.3f} deg; spread '
        f'{estimate.residual_position * 1000:.2f} mm, '
        f'{math.degrees(estimate.residual_angle):.3f} deg; tilt '
        f'{math.degrees(estimate.tilt):.2f} deg; moved '
        f'{result.shift_from_rig_file * 1000:.2f} mm and '
        f'{math.degrees(result.turn_from_rig_file):.3f} deg from the rig file'
        + ('' if request.apply else ' (not applied)'))
