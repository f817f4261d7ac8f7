"""
What the RGB camera checks a planned dot against (issue 29, item 4).

Its expected diameter, and the targets around it whose char is theirs. Pure Python: no rclpy.

The expected burnt diameter is the plan's dot pitch (``dot_radius``, paper r_p: "a charred
dot ~0.2 cm wide" at N_p 30), scaled by the square root of the dot's N_p target over the
paper's 30 (a dot's area grows with N_p, paper Fig. 8d). The simulated world burns 1.40 mm
at N_p 15 and 1.61 mm at N_p 20 (``test/test_painter.py``): 1.41 and 1.63 mm by this rule.
With a dot-size calibration (item 3: the plan's ``parameters['dot_size']``), the expected
diameter is the calibration's for the dot's N_p target instead: what the camera measured.
"""

import math

from helio_control.dot_size_calibration import DotSizeCalibration, held_dots
import numpy as np

# targets within this many expected diameters of a dot are its neighbours
NEIGHBOUR_REACH = 2.5
PAPER_N_P = 30.0     # the paper's N_p target of a dot r_p wide
PAPER_PITCH = 0.002  # [m] the paper's r_p: "a charred dot ~0.2 cm wide" at N_p 30


def guessed_diameter(n_p, pitch=PAPER_PITCH):
    """
    Return the expected burnt diameter [m] of a dot of N_p target `n_p`, uncalibrated.

    The plan's dot pitch `pitch` [m] scaled by the square root of n_p over the paper's 30.
    """
    return float(pitch) * math.sqrt(max(float(n_p), 1.0) / PAPER_N_P)


def dot_hold(plan, index):
    """
    Return how long [s] the plan's dot is held at its N_p target once reached (0: not).

    The plan's ``hold_s`` (a dot-size calibration's, for dots wider than N_p can ask for)
    holds the dots at the plan's full ``n_p_target``; lighter tones are not held.
    """
    parameters = plan.parameters
    return float(held_dots(plan.n_p_targets[index], parameters.get('n_p_target', -1),
                           parameters.get('hold_s') or 0.0))


def expected_dot(plan, index):
    """Return (expected diameter [m], neighbouring targets (K, 2) [m]) of the plan's dot."""
    parameters = plan.parameters
    n_p = max(float(plan.n_p_targets[index]), 1.0)
    if parameters.get('dot_size'):
        expected = DotSizeCalibration.from_parameters(parameters['dot_size']).diameter_of(
            n_p, dot_hold(plan, index))
    else:
        expected = guessed_diameter(n_p, float(parameters.get('dot_radius') or PAPER_PITCH))
    dots = np.asarray(plan.dots, dtype=float).reshape(-1, 2)
    distance = np.hypot(*(dots - dots[index]).T)
    near = (distance <= NEIGHBOUR_REACH * expected) & (np.arange(len(dots)) != index)
    return expected, dots[near]
