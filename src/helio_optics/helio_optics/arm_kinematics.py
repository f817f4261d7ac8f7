"""
Kinematics of the Dobot Magician's 3-DOF arm (the first three joints of x in R^5, Sec. II-B).

The Magician keeps its end-effector flange level through a parallelogram linkage. Its
firmware reports the rear-arm angle j2 from the vertical and the forearm angle j3 from the
horizontal (both absolute), so with rear arm L1 and forearm L2 (robot frame, origin on the
base axis at the shoulder height, z up, x forward at j1 = 0):

    reach  = L1 sin(j2) + L2 cos(j3) + tool_x
    height = L1 cos(j2) - L2 sin(j3) + tool_z
    x, y   = reach cos(j1), reach sin(j1)

The wrist that carries the lens (two servos) and the lens pose of Eqs 14-15 build on this.
``DobotArm.inverse_many`` solves N flange positions at once (numpy), returning per position
the first check it fails (``REACHABLE``, ``BEYOND_REACH``, ``INSIDE_REACH`` or a joint's
index in ``limits()``); ``DobotArm.inverse`` is it for one position, raising UnreachableError.
Units: metres and radians (the serial protocol's millimetres and degrees are converted by
the driver). Defaults are the manufacturer's specification; every value is a parameter.
"""

from dataclasses import dataclass
import math

import numpy as np


# failure codes of the inverse kinematics of many poses; a joint limit is its index (>= 0)
REACHABLE = -1          # every check passed
BEYOND_REACH = -2       # the flange farther from the shoulder than both links reach
INSIDE_REACH = -3       # the flange nearer the shoulder than the links can fold


class UnreachableError(ValueError):
    """A target the arm cannot reach; says which joint and by how much."""

    def __init__(self, message, joint=None, excess=0.0):
        """Keep the joint name and the excess (rad or m) beside the message."""
        super().__init__(message)
        self.joint = joint
        self.excess = excess


@dataclass(frozen=True)
class JointLimit:
    """Closed interval of a joint [rad]."""

    name: str
    lower: float
    upper: float

    def excess(self, value):
        """How far `value` lies outside the interval (0 inside) [rad]."""
        return max(self.lower - value, value - self.upper, 0.0)


@dataclass(frozen=True)
class DobotArmParameters:
    """Link lengths [m] and joint limits [rad] of the Dobot Magician (specification values)."""

    rear_arm: float = 0.135
    forearm: float = 0.147
    tool_x: float = 0.0597      # flange offset beyond the forearm tip, horizontal [m]
    tool_z: float = 0.0         # flange offset below (-) or above (+) the forearm tip [m]
    base_height: float = 0.0    # height of the shoulder above the robot frame origin [m]
    j1_limits: tuple = (math.radians(-90.0), math.radians(90.0))
    j2_limits: tuple = (math.radians(0.0), math.radians(85.0))
    j3_limits: tuple = (math.radians(-10.0), math.radians(95.0))
    j4_limits: tuple = (math.radians(-150.0), math.radians(150.0))   # end servo (unused by
    #                                                                  the lens rig)

    def limits(self):
        """Return the three joint limits in order."""
        return (JointLimit('j1 (base)', *self.j1_limits),
                JointLimit('j2 (rear arm)', *self.j2_limits),
                JointLimit('j3 (forearm)', *self.j3_limits))

    def end_servo_limit(self):
        """Return the JointLimit of the end servo j4."""
        return JointLimit('j4 (end servo)', *self.j4_limits)


class DobotArm:
    """Forward and inverse kinematics of the Magician's flange position."""

    def __init__(self, parameters=None):
        """Use the given DobotArmParameters, or the specification defaults."""
        self.parameters = parameters or DobotArmParameters()

    @property
    def _limit_bounds(self):
        """Return the (lower, upper) arrays of the three joint limits [rad] (kept)."""
        if getattr(self, '_bounds_of', None) is not self.parameters:
            self._bounds = limit_bounds(self.parameters.limits())
            self._bounds_of = self.parameters
        return self._bounds

    def forward(self, joints):
        """Flange position (x, y, z) [m] in the robot frame for joints (j1, j2, j3) [rad]."""
        j1, j2, j3 = (float(v) for v in joints[:3])
        p = self.parameters
        reach = p.rear_arm * math.sin(j2) + p.forearm * math.cos(j3) + p.tool_x
        height = p.base_height + p.rear_arm * math.cos(j2) - p.forearm * math.sin(j3) + p.tool_z
        return np.array([reach * math.cos(j1), reach * math.sin(j1), height])

    def inverse(self, position, check_limits=True):
        """
        Joints (j1, j2, j3) [rad] that put the flange at `position` [m], elbow up.

        ``inverse_many`` for one position. Raises UnreachableError naming the joint (or the
        reach) and by how much.
        """
        x, y, z = (float(v) for v in position)
        if not all(math.isfinite(v) for v in (x, y, z)):
            raise ValueError(f'target {[x, y, z]} is not a finite position')
        joints, failure, excess = self.inverse_many(np.array([[x, y, z]]), check_limits)
        if failure[0] in (BEYOND_REACH, INSIDE_REACH):
            side = 'beyond' if failure[0] == BEYOND_REACH else 'inside'
            raise UnreachableError(
                f"target {position} is {side} the arm's reach by {excess[0] * 1000:.1f} mm",
                joint='reach', excess=float(excess[0]))
        if failure[0] != REACHABLE:
            self.check_limits(joints[0])        # raises, naming the joint
        return joints[0]

    def inverse_many(self, positions, check_limits=True):
        """
        Joints (N, 3) [rad] putting the flange at each of `positions` (N, 3) [m], elbow up.

        Returns (joints, failure, excess): per position the first check it fails
        (``REACHABLE``, ``BEYOND_REACH``, ``INSIDE_REACH``, or the index of the first joint
        outside its limit in ``limits()``, checked with `check_limits` only) and by how much
        [m or rad]. Rows out of the links' reach hold NaN joints.
        """
        p = self.parameters
        positions = np.asarray(positions, dtype=float).reshape(-1, 3)
        x, y = positions[:, 0], positions[:, 1]
        reach = np.hypot(x, y) - p.tool_x
        height = positions[:, 2] - (p.tool_z + p.base_height)
        distance = np.hypot(reach, height)
        longest, shortest = p.rear_arm + p.forearm, abs(p.rear_arm - p.forearm)
        failure, excess = np.full(len(positions), REACHABLE), np.zeros(len(positions))
        beyond, inside = distance > longest, distance < shortest
        if (beyond | inside).any():
            failure[beyond], excess[beyond] = BEYOND_REACH, distance[beyond] - longest
            failure[inside], excess[inside] = INSIDE_REACH, shortest - distance[inside]
        # Absolute link angles from the horizontal: rear arm a1 = pi/2 - j2, forearm a2 = -j3.
        cos_spread = (p.rear_arm ** 2 - p.forearm ** 2 + distance ** 2) / (
            2.0 * p.rear_arm * np.maximum(distance, 1e-300))
        a1 = np.arctan2(height, reach) + np.arccos(np.minimum(np.maximum(cos_spread, -1.0),
                                                              1.0))
        a2 = np.arctan2(height - p.rear_arm * np.sin(a1), reach - p.rear_arm * np.cos(a1))
        joints = np.empty((len(positions), 3))
        joints[:, 0] = np.arctan2(y, x)
        joints[:, 1] = 0.5 * math.pi - a1
        joints[:, 2] = -a2
        joints[beyond | inside] = np.nan
        if check_limits:
            first_limit_failure(self._limit_bounds, joints, failure, excess)
        return joints, failure, excess

    def check_limits(self, joints):
        """Raise UnreachableError for the first joint outside its limits."""
        check_joint_limits(self.parameters.limits(), joints)


def limit_error(limit, value):
    """Return the UnreachableError of `value` outside its JointLimit, naming it and by how much."""
    excess = limit.excess(value)
    return UnreachableError(
        f'{limit.name} would be {math.degrees(value):.2f} deg, '
        f'{math.degrees(excess):.2f} deg outside '
        f'[{math.degrees(limit.lower):.1f}, {math.degrees(limit.upper):.1f}] deg',
        joint=limit.name, excess=excess)


def check_joint_limits(limits, joints):
    """Raise UnreachableError naming the first joint outside its JointLimit, and by how much."""
    for limit, value in zip(limits, joints):
        if not math.isfinite(value):     # NaN compares false with both limits
            raise ValueError(f'{limit.name} would be {value}: not a finite angle')
        if limit.excess(value) > 0.0:
            raise limit_error(limit, value)


def limit_bounds(limits):
    """Return the lower and upper bounds (k,) [rad] of a sequence of k JointLimits."""
    return (np.array([limit.lower for limit in limits]),
            np.array([limit.upper for limit in limits]))


def first_limit_failure(bounds, joints, failure, excess):
    """
    Mark in `failure` and `excess` (N,) the first joint of each row of `joints` out of limits.

    `bounds` are ``limit_bounds`` of the joints' limits. Rows whose `failure` is already set
    (not ``REACHABLE``) keep it; otherwise the index of the first limit its joint violates
    (a NaN violates every limit) and by how much [rad], as ``check_joint_limits`` would
    raise it.
    """
    lower, upper = bounds
    values = joints[:, :len(lower)]
    outside = ~((values >= lower) & (values <= upper))
    if not outside.any():
        return
    first = np.argmax(outside, axis=1)
    rows = np.flatnonzero(outside.any(axis=1) & (failure == REACHABLE))
    value = values[rows, first[rows]]
    failure[rows] = first[rows]
    excess[rows] = np.maximum(np.maximum(lower[first[rows]] - value,
                                         value - upper[first[rows]]), 0.0)
