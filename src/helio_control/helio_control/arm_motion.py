"""
How long the rig takes to move between two joint vectors x in R^5 (the metric the arm pays).

The Dobot moves its three joints on one synchronised trapezoidal profile (PTP joint mode,
``helio_drivers.motion_profile.synchronised_profile``): with joint distances d_k and limits
v_k, a_k the normalised limits are V = min v_k / d_k and A = min a_k / d_k, so with
m_v = max d_k / v_k and m_a = max d_k / a_k the duration is

    2 sqrt(m_a)            when m_a >= m_v^2 (triangular: the speed limit is never reached)
    m_v + m_a / m_v        otherwise (accelerate, cruise, decelerate).

The two wrist servos (Pololu Maestro) move at the same time, each on its own trapezoid;
both channels share one speed and acceleration limit (``servo_driver.yaml``), so their
slower channel takes the same formula with the larger of the two distances. A move takes
the longer of the arm and the wrist. Both maxima are Chebyshev distances of scaled joint
vectors, so a whole time matrix is a few vectorised passes (``move_time_matrix``).

Not modelled here: command latency and settling (the cycle model's per-move overhead).
"""

from dataclasses import dataclass
import math

import numpy as np


@dataclass(frozen=True)
class MotionLimits:
    """Joint speed and acceleration limits of the rig [rad/s, rad/s^2]."""

    arm_velocity: tuple = (math.radians(100.0),) * 3        # Dobot j1..j3 PTP joint speed
    arm_acceleration: tuple = (math.radians(100.0),) * 3    # Dobot j1..j3 PTP acceleration
    wrist_velocity: float = 1000.0 / 636.6197723675814      # 1000 us/s at 636.6 us/rad
    wrist_acceleration: float = 5000.0 / 636.6197723675814  # 5000 us/s^2

    def __post_init__(self):
        """Reject limits that are not positive and finite."""
        values = list(self.arm_velocity) + list(self.arm_acceleration) + [
            self.wrist_velocity, self.wrist_acceleration]
        if len(self.arm_velocity) != 3 or len(self.arm_acceleration) != 3:
            raise ValueError('arm limits need three values (j1, j2, j3)')
        if not all(math.isfinite(v) and v > 0.0 for v in values):
            raise ValueError(f'motion limits must be positive and finite, got {values}')


def trapezoid_time(m_v, m_a):
    """Duration of a normalised trapezoidal move from m_v = d/v and m_a = d/a (arrays) [s]."""
    m_v = np.asarray(m_v, dtype=float)
    m_a = np.asarray(m_a, dtype=float)
    with np.errstate(divide='ignore', invalid='ignore'):
        cruise = m_v + np.where(m_v > 0.0, m_a / np.where(m_v > 0.0, m_v, 1.0), 0.0)
    return np.where(m_a >= m_v * m_v, 2.0 * np.sqrt(m_a), cruise)


def move_time(x_from, x_to, limits):
    """Time of the move between joint vectors (..., 5) [rad] -> (...) [s] (broadcasting)."""
    delta = np.abs(np.asarray(x_to, dtype=float) - np.asarray(x_from, dtype=float))
    arm = delta[..., :3]
    arm_time = trapezoid_time(np.max(arm / np.asarray(limits.arm_velocity), axis=-1),
                              np.max(arm / np.asarray(limits.arm_acceleration), axis=-1))
    wrist = np.max(delta[..., 3:5], axis=-1)
    wrist_time = trapezoid_time(wrist / limits.wrist_velocity,
                                wrist / limits.wrist_acceleration)
    return np.maximum(arm_time, wrist_time)


def _chebyshev(a, b, out, scratch):
    """out[i, j] = max_k |a[i, k] - b[j, k]| (float32, in place)."""
    np.subtract(a[:, None, 0], b[None, :, 0], out=out)
    np.abs(out, out=out)
    for k in range(1, a.shape[1]):
        np.subtract(a[:, None, k], b[None, :, k], out=scratch)
        np.abs(scratch, out=scratch)
        np.maximum(out, scratch, out=out)


def _trapezoid_of_scaled(m_v, ratio, out):
    """In place: m_v = d / v -> trapezoid time when m_a = ratio * m_v (ratio = v / a) [s]."""
    cruise = m_v > ratio
    cruise_values = m_v[cruise] + ratio
    np.multiply(m_v, 4.0 * ratio, out=out)
    np.sqrt(out, out=out)
    out[cruise] = cruise_values


def move_time_matrix(x_from, x_to, limits, chunk=128):
    """
    Matrix of move times [s] between every row of x_from (N x 5) and of x_to (M x 5).

    float32, computed in blocks of `chunk` rows (5000 x 5000 in 0.3-0.5 s here). The
    arm's joints must share one ratio v_k / a_k (true of the Dobot's PTP settings) for the
    fast path; otherwise the exact per-joint maxima are taken row block by row block.
    """
    x_from = np.asarray(x_from, dtype=float)
    x_to = np.asarray(x_to, dtype=float)
    velocity = np.asarray(limits.arm_velocity, dtype=float)
    acceleration = np.asarray(limits.arm_acceleration, dtype=float)
    ratios = velocity / acceleration
    uniform = np.allclose(ratios, ratios[0], rtol=1e-12)
    arm_from = (x_from[:, :3] / velocity).astype(np.float32)
    arm_to = (x_to[:, :3] / velocity).astype(np.float32)
    wrist_from = (x_from[:, 3:5] / limits.wrist_velocity).astype(np.float32)
    wrist_to = (x_to[:, 3:5] / limits.wrist_velocity).astype(np.float32)
    wrist_ratio = limits.wrist_velocity / limits.wrist_acceleration
    result = np.empty((len(x_from), len(x_to)), np.float32)
    for start in range(0, len(x_from), chunk):
        stop = min(len(x_from), start + chunk)
        block = result[start:stop]
        scaled = np.empty_like(block)
        scratch = np.empty_like(block)
        if uniform:
            _chebyshev(arm_from[start:stop], arm_to, scaled, scratch)
            _trapezoid_of_scaled(scaled, ratios[0], block)
        else:
            block[:] = move_time(x_from[start:stop, None, :], x_to[None, :, :], limits)
        _chebyshev(wrist_from[start:stop], wrist_to, scaled, scratch)
        _trapezoid_of_scaled(scaled, wrist_ratio, scratch)
        np.maximum(block, scratch, out=block)
    return result
