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
Units: metres and radians (the serial protocol's millimetres and degrees are converted by
the driver). Defaults are the manufacturer's specification; every value is a parameter.
"""

from dataclasses import dataclass
import math

import numpy as np


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

        Raises UnreachableError naming the joint (or the reach) and by how much.
        """
        p = self.parameters
        x, y, z = (float(v) for v in position)
        if not all(math.isfinite(v) for v in (x, y, z)):
            raise ValueError(f'target {[x, y, z]} is not a finite position')
        j1 = math.atan2(y, x)
        reach = math.hypot(x, y) - p.tool_x
        height = z - p.tool_z - p.base_height
        distance = math.hypot(reach, height)
        longest, shortest = p.rear_arm + p.forearm, abs(p.rear_arm - p.forearm)
        if distance > longest or distance < shortest:
            excess = distance - longest if distance > longest else shortest - distance
            side = 'beyond' if distance > longest else 'inside'
            raise UnreachableError(
                f"target {position} is {side} the arm's reach by {excess * 1000:.1f} mm",
                joint='reach', excess=excess)
        # Absolute link angles from the horizontal: rear arm a1 = pi/2 - j2, forearm a2 = -j3.
        cos_spread = (p.rear_arm ** 2 + distance ** 2 - p.forearm ** 2) / (
            2.0 * p.rear_arm * distance)
        a1 = math.atan2(height, reach) + math.acos(max(-1.0, min(1.0, cos_spread)))
        a2 = math.atan2(height - p.rear_arm * math.sin(a1), reach - p.rear_arm * math.cos(a1))
        joints = np.array([j1, math.pi / 2.0 - a1, -a2])
        if check_limits:
            self.check_limits(joints)
        return joints

    def check_limits(self, joints):
        """Raise UnreachableError for the first joint outside its limits."""
        check_joint_limits(self.parameters.limits(), joints)


def check_joint_limits(limits, joints):
    """Raise UnreachableError naming the first joint outside its JointLimit, and by how much."""
    for limit, value in zip(limits, joints):
        if not math.isfinite(value):     # NaN compares false with both limits
            raise ValueError(f'{limit.name} would be {value}: not a finite angle')
        excess = limit.excess(value)
        if excess > 0.0:
            raise UnreachableError(
                f'{limit.name} would be {math.degrees(value):.2f} deg, '
                f'{math.degrees(excess):.2f} deg outside '
                f'[{math.degrees(limit.lower):.1f}, {math.degrees(limit.upper):.1f}] deg',
                joint=limit.name, excess=excess)
