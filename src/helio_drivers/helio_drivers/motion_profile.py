"""
Time-optimal trapezoidal velocity profile, the motion law of both emulated devices.

A move of length 1 in a normalised coordinate s in [0, 1] under a velocity limit V [1/s] and
an acceleration limit A [1/s^2]: accelerate at A, cruise at V (if it is reached), decelerate
at A. For a move of distance d under limits v, a the normalised limits are V = v/d,
A = a/d; several joints moving together use the smallest of their normalised limits so that
they arrive at the same time and none exceeds its own limits (the Dobot's joint-interpolated
PTP moves behave this way). Infinite limits give an instant move.
"""

import math


class TrapezoidProfile:
    """s(t) from 0 to 1 with |s'| <= velocity_limit and |s''| <= acceleration_limit."""

    def __init__(self, velocity_limit, acceleration_limit):
        """Plan the normalised move; limits in 1/s and 1/s^2 (math.inf allowed)."""
        if not velocity_limit > 0.0 or not acceleration_limit > 0.0:
            raise ValueError(f'profile limits must be positive, got velocity {velocity_limit}, '
                             f'acceleration {acceleration_limit}')
        self.velocity_limit = velocity = float(velocity_limit)
        self.acceleration_limit = acceleration = float(acceleration_limit)
        if math.isinf(velocity) and math.isinf(acceleration):
            self.ramp_time, self.peak_velocity, self.duration = 0.0, math.inf, 0.0
        elif math.isinf(acceleration):
            self.ramp_time, self.peak_velocity, self.duration = 0.0, velocity, 1.0 / velocity
        elif velocity * velocity / acceleration >= 1.0:   # triangular: V is never reached
            self.ramp_time = math.sqrt(1.0 / acceleration)
            self.peak_velocity = acceleration * self.ramp_time
            self.duration = 2.0 * self.ramp_time
        else:
            self.ramp_time = velocity / acceleration
            self.peak_velocity = velocity
            self.duration = velocity / acceleration + 1.0 / velocity

    def position(self, t):
        """Normalised position s in [0, 1] at time t [s] after the start."""
        if t >= self.duration:
            return 1.0
        if t <= 0.0:
            return 0.0
        ramp, peak, acceleration = self.ramp_time, self.peak_velocity, self.acceleration_limit
        if ramp == 0.0:
            return t * peak
        ramp_distance = 0.5 * acceleration * ramp * ramp
        if t < ramp:
            return 0.5 * acceleration * t * t
        if t <= self.duration - ramp:
            return ramp_distance + peak * (t - ramp)
        remaining = self.duration - t
        return 1.0 - 0.5 * acceleration * remaining * remaining

    def velocity(self, t):
        """Normalised velocity s'(t) [1/s]."""
        if t <= 0.0 or t >= self.duration:
            return 0.0
        if self.ramp_time == 0.0:
            return self.peak_velocity
        if t < self.ramp_time:
            return self.acceleration_limit * t
        if t <= self.duration - self.ramp_time:
            return self.peak_velocity
        return self.acceleration_limit * (self.duration - t)


def synchronised_profile(distances, velocity_limits, acceleration_limits):
    """
    One profile that moves every axis its distance and respects every axis's own limits.

    Returns a TrapezoidProfile for s in [0, 1] (axis i is at start + distance_i * s), or None
    when every distance is zero.
    """
    velocity, acceleration = math.inf, math.inf
    moving = False
    for distance, v_max, a_max in zip(distances, velocity_limits, acceleration_limits):
        distance = abs(float(distance))
        if distance == 0.0:
            continue
        moving = True
        velocity = min(velocity, v_max / distance)
        acceleration = min(acceleration, a_max / distance)
    if not moving:
        return None
    return TrapezoidProfile(velocity, acceleration)
