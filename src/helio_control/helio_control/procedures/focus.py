"""
The focus procedure (paper Eqs 14-15): the lens placed so the sun's focus lands on a point.

The lens pose comes from the sun estimate, corrected so the spot's power centre (not only
the lens axis) lands on the target (``FocusTargeting``); the five joints by the rig's inverse
kinematics; the moves in legs that keep the focus off the wood while it travels
(``lens_moves``: retreat, travel at the retreat distance, approach). Also the retreat of a
lens left at the heating distance (the lens planner's lease and its interrupt).

The distances along the sun ray have one owner, the lens planner (issue 32): the heating
distance is its focal calibration's (``port.heating_distance``: calibration/focus, else its
``heating_distance`` parameter, the paper's 8.2 cm), the retreat distance that plus
``retreat_offset`` (the paper's delta d_lp, 3 cm, Sec. IV-B), so both follow a calibration.
A goal asks for either by name (``FocusLens.Goal.distance``: ``HEATING``, ``RETREAT``);
``d_lp`` gives one explicitly.
"""

import math

from helio_control import lens_moves
from helio_control.procedures.lens_rig_port import GoalFailed
from helio_msgs.action import FocusLens
from helio_msgs.msg import LensPose
from helio_optics.node_kit.conversions import array_to_point, point_to_array
from helio_optics.node_kit.conversions import stamp_from_seconds
import numpy as np


def distances(port):
    """Return (heating, retreat distance) [m] of a port (or any holder of both inputs)."""
    return port.heating_distance, port.heating_distance + port.settings.retreat_offset


def check_goal(port, goal):
    """Return (world target (3,), d_lp, travel d_lp) of a FocusLens goal; GoalFailed if bad."""
    settings = port.settings
    frame = goal.target.header.frame_id or 'world'
    if frame != 'world':
        raise GoalFailed(f"target frame '{frame}': give the target in 'world' (the "
                         'marker frame, z = 0 on the panel)')
    target = point_to_array(goal.target.point)
    if not np.all(np.isfinite(target)):
        raise GoalFailed(f'the target {target.tolist()} is not finite')
    if abs(target[2]) > 1e-6:
        raise GoalFailed(f'the target lies {target[2] * 1000:.1f} mm off the panel (z must '
                         'be 0 in the world frame)')
    heating, retreat = distances(port)
    if goal.distance == FocusLens.Goal.HEATING:
        d_lp = heating
    elif goal.distance == FocusLens.Goal.RETREAT:
        d_lp = retreat
    elif goal.distance == FocusLens.Goal.AT_D_LP:
        d_lp = goal.d_lp if goal.d_lp != 0.0 else heating
    else:
        raise GoalFailed(f'distance {goal.distance}: give AT_D_LP (0, the d_lp field), HEATING '
                         '(1) or RETREAT (2)')
    if not (math.isfinite(d_lp) and d_lp > 0.0):
        raise GoalFailed(f'd_lp must be a finite distance > 0 m, got {goal.d_lp}')
    if goal.travel_d_lp != 0.0:
        travel, asked = goal.travel_d_lp, f'travel_d_lp {goal.travel_d_lp} m'
    elif goal.travel_offset != 0.0:
        travel = heating + goal.travel_offset
        asked = f'travel_offset {goal.travel_offset} m'
    else:
        travel, asked = retreat, 'the retreat distance'
    if not (math.isfinite(travel) and lens_moves.safe_to_travel_at(
            travel, heating, settings.safe_margin)):
        raise GoalFailed(f'{asked}: the focus may move sideways only '
                         f'{settings.safe_margin * 100:.1f} cm or more from the heating '
                         f'distance {heating * 100:.1f} cm (safe_margin)')
    return target, d_lp, travel


def plan_focus(port, target, d_lp, travel=None):
    """
    Return (legs, present joints) that bring the focus to `target` at `d_lp`.

    The focus moves sideways at `travel` (default the retreat distance), else at the first
    reachable distance a safe margin from the heating distance.
    """
    settings = port.settings
    heating, retreat = distances(port)
    sun = port.sun_ray()
    x_now = port.present_joints()
    try:
        legs = lens_moves.plan_focus_moves(
            port.targeting, x_now, target, d_lp, sun, port.rig.parameters.T_robot_world,
            heating, (travel or retreat, heating + settings.safe_margin,
                      heating - settings.safe_margin),
            settings.safe_margin, settings.same_point)
    except (lens_moves.MovePlanningError, ValueError) as error:
        raise GoalFailed(str(error)) from None
    return legs, x_now


def lens_position(port, x):
    """Return the lens centre (robot frame, (3,)) of joints `x` by the believed rig."""
    return port.rig.forward(x).T_robot_lens[:3, 3]


def lens_pose(port, x, d_lp):
    """Return the LensPose message of joints `x` at `d_lp`, stamped now (node clock)."""
    pose = port.rig.forward(x)
    message = LensPose()
    message.header.stamp = stamp_from_seconds(port.now())
    message.header.frame_id = 'robot'
    message.position = array_to_point(pose.T_robot_lens[:3, 3])
    message.yaw, message.pitch, message.d_lp = pose.yaw, pose.pitch, float(d_lp)
    message.joints = [float(v) for v in x]
    return message


async def focus(port, goal, result):
    """
    Run a FocusLens goal: fill `result` (achieved, position_error, message).

    `result.achieved` is the lens pose of the joints the drivers reached (forward
    kinematics), `position_error` its distance from the commanded one [m].
    """
    target, d_lp, travel = check_goal(port, goal)
    await port.wait_for_inputs()
    alive = port.client_alive()                 # a client to outlive?
    legs, x_now = plan_focus(port, target, d_lp, travel)
    solution = port.targeting.aim(target, port.sun_ray(), d_lp,
                                  port.rig.parameters.T_robot_world)
    feedback = FocusLens.Feedback()
    feedback.commanded = lens_pose(port, legs[-1].x, d_lp)
    commanded = lens_position(port, legs[-1].x)
    reached = x_now
    for leg in legs:
        feedback.joints = [float(v) for v in reached]
        feedback.distance_remaining = float(np.linalg.norm(
            commanded - lens_position(port, reached)))
        port.feedback(feedback)
        reached = await port.move(leg.x)
    at_heating = not lens_moves.safe_to_travel_at(d_lp, port.heating_distance,
                                                  port.settings.safe_margin)
    port.placed(at_heating, alive)
    result.achieved = lens_pose(port, reached, d_lp)
    result.position_error = float(np.linalg.norm(lens_position(port, reached) - commanded))
    correction = np.hypot(*solution.correction[:2])
    result.message = (f'focused on ({target[0] * 100:.2f}, {target[1] * 100:.2f}) cm at '
                      f'd_lp {d_lp * 100:.2f} cm in {len(legs)} leg(s) '
                      f'({", ".join(leg.name for leg in legs)}); aim corrected by '
                      f'{correction * 1e3:.3f} mm; lens within '
                      f'{result.position_error * 1e3:.3f} mm of the command')


async def retreat(port):
    """Move the lens along the sun ray to the retreat distance over where it focuses now."""
    x_now = port.present_joints()
    here, _ = lens_moves.focus_point(port.rig, x_now, port.sun_ray(),
                                     port.rig.parameters.T_robot_world)
    if here is None:
        raise GoalFailed('the lens does not face the panel: nothing to retreat')
    legs, _ = plan_focus(port, here, distances(port)[1])
    for leg in legs:
        await port.move(leg.x)
