"""
Move the lens so that its focus never sweeps across the panel at heating distance.

A lens held at the heating distance d_lp concentrates the sun enough to char the wood in a
few seconds; moving it sideways there would draw a burnt trail between two dots. So a move
to a new point goes in up to three legs (each a joint-space move of the arm and the wrist):

1. **retreat**: if the lens is near the heating distance, move it along the sun ray over the
   point its focus is on now, to a travel distance (the focus spreads out: a retreat of
   3 cm is the paper's delta d_lp, Sec. IV-B; where that is out of reach, the first
   reachable of the other travel distances, each at least a safe margin from the heating
   distance, e.g. 1.5 cm beyond or short of it);
2. **travel**: at that distance, to the pose over the new point;
3. **approach**: along the sun ray to the goal's distance, if that is near the heating
   distance.

A move that stays on the same point (the focus moves less than ``same_point`` on the panel,
e.g. the retreat of Algorithm 1 line 10) is one leg along the ray. The goal's pose comes
from ``FocusTargeting`` (Eqs 14-15 with the spot-model correction); the retreat and travel
poses, where the focus is spread out anyway, from Eqs 14-15 alone. No rclpy.

API: ``focus_point(rig, x, sun_robot, T_robot_world)`` (where the ray through the lens
centre meets the panel, world frame, and the distance to it along the ray);
``plan_focus_moves(...) -> [Leg]``.
"""

from dataclasses import dataclass

from helio_optics.geometry import invert_transform, transform_points, unit
import numpy as np

# The paper's distances along the sun ray (Sec. IV-B): a dot is heated at d_lp = 8.2 cm (the
# smallest spot of its focal calibration, Sec. V-A), and the lens retreats by delta d_lp =
# 3 cm after it. The lens planner owns both (``lens_planner_parameters``: these are its
# defaults; a focal calibration moves the first, issue 32); the offline plans take them too.
HEATING_DISTANCE = 0.082
RETREAT_OFFSET = 0.03


class MovePlanningError(ValueError):
    """No safe sequence of moves reaches the goal; the message says why."""


@dataclass
class Leg:
    """One joint-space move of the sequence."""

    name: str            # 'retreat', 'travel', 'approach' or 'direct'
    x: np.ndarray        # the five joints to reach [rad]
    d_lp: float          # lens-to-focus distance along the sun ray at the end [m]
    point: np.ndarray    # world point (3,) the lens is aimed at at the end [m]


def focus_point(rig, x, sun_robot, T_robot_world):
    """
    Return (world point (3,), distance [m]) of the ray through the lens centre on the panel.

    The ray is the sun's through the lens centre O_l; the distance is from O_l along it.
    Return (None, inf) when the ray does not reach the panel.
    """
    T_robot_world = np.asarray(T_robot_world, dtype=float)
    sun = unit(np.asarray(sun_robot, dtype=float).reshape(3))
    centre = rig.forward(x).T_robot_lens[:3, 3]
    normal, origin = T_robot_world[:3, 2], T_robot_world[:3, 3]
    along = float(sun @ normal)
    if along >= -1e-9:
        return None, float('inf')
    distance = float((origin - centre) @ normal) / along
    if distance <= 0.0:
        return None, float('inf')
    hit = centre + distance * sun
    return transform_points(invert_transform(T_robot_world), hit), distance


def safe_to_travel_at(distance, heating_distance, safe_margin):
    """Return whether the focus may move sideways at `distance` (>= `safe_margin` from heating)."""
    return abs(distance - heating_distance) >= safe_margin - 1e-9


def plan_focus_moves(targeting, x_now, target_world, d_lp, sun_robot, T_robot_world,
                     heating_distance, travel_distances, safe_margin=0.015, same_point=1e-3):
    """
    Return the legs that bring the focus from joints `x_now` to `target_world` at `d_lp`.

    `targeting` is a ``helio_optics.focus_targeting.FocusTargeting``. A distance is safe to
    move the focus sideways at when it lies at least `safe_margin` from `heating_distance`;
    the retreat and travel legs take the first reachable of `travel_distances` (the paper's
    retreat first). The last leg's pose is the corrected focus pose of the goal. Raise
    MovePlanningError naming the leg and the reason (an unreachable pose) when no safe
    sequence exists.
    """
    rig = targeting.rig
    target = np.zeros(3)
    given = np.asarray(target_world, dtype=float).ravel()
    target[:min(3, given.size)] = given[:3]
    goal = _solve(targeting, target, d_lp, sun_robot, T_robot_world, 'the goal')
    here, distance_now = focus_point(rig, x_now, sun_robot, T_robot_world)
    if here is not None and float(np.hypot(*(here[:2] - target[:2]))) <= same_point:
        return [Leg('direct', goal.lens.x, d_lp, target)]

    def safe(distance):
        return safe_to_travel_at(distance, heating_distance, safe_margin)
    travel = [d for d in travel_distances if safe(d)]
    if not travel:
        raise MovePlanningError(f'no travel distance in {list(travel_distances)} lies '
                                f'{safe_margin * 100:.1f} cm from the heating distance')
    legs = []
    if here is not None and not safe(distance_now):
        distance, x = _first_reachable(rig, here, travel, sun_robot, T_robot_world,
                                       'the retreat over the present point')
        legs.append(Leg('retreat', x, distance, here))
    if safe(d_lp):
        legs.append(Leg('travel', goal.lens.x, d_lp, target))
        return legs
    distance, x = _first_reachable(rig, target, travel, sun_robot, T_robot_world,
                                   'the travel pose over the goal')
    legs.append(Leg('travel', x, distance, target))
    legs.append(Leg('approach', goal.lens.x, d_lp, target))
    return legs


def _first_reachable(rig, point, distances, sun_robot, T_robot_world, what):
    """Return (distance, joints) of the first reachable pose over `point`, or raise."""
    reasons = []
    for distance in distances:
        try:
            return distance, _axis_pose(rig, point, distance, sun_robot, T_robot_world, what)
        except MovePlanningError as error:
            reasons.append(str(error))
    raise MovePlanningError('; '.join(reasons))


def _axis_pose(rig, point, d_lp, sun_robot, T_robot_world, what):
    """Return the joints of Eqs 14-15 (lens axis on `point`) or raise MovePlanningError."""
    lens = rig.lens_pose_for_target(transform_points(np.asarray(T_robot_world, dtype=float),
                                                     point), sun_robot, d_lp)
    if lens.x is None:
        raise MovePlanningError(f'{what} at d_lp {d_lp * 100:.1f} cm is unreachable: '
                                f'{lens.reason}')
    return lens.x


def _solve(targeting, point, d_lp, sun_robot, T_robot_world, what):
    solution = targeting.aim(point, sun_robot, d_lp, T_robot_world)
    if solution.lens.x is None:
        raise MovePlanningError(f'{what} at d_lp {d_lp * 100:.1f} cm is unreachable: '
                                f'{solution.lens.reason}')
    return solution
