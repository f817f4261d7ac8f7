"""
The dot-size calibration burn before a painting (issue 29, item 3; beyond the paper).

The paper burns every dot to N_p = 30 and calls it "a charred dot ~0.2 cm wide". How wide a
dot of a given N_p target chars, and how long it takes, depend on the wood, the sun, the
lens and the thermal camera, so a painting that asks for a dot width (``dot_radius`` with a
calibration) or estimates its time needs the rig's own law. Before a painting, with
``calibrate_dots`` ``missing`` (no ``dots.yaml`` in the calibration directory for this rig
description) or ``always``, the painter burns a short row of test dots on a margin of the
panel (``dot_calibration.*``: ``dot_size_calibration.calibration_row``), each one as a dot of
the painting is burnt (``DotProcedure.paint``: Algorithm 1 lines 6-14 with the paper's
cooling rule, so each dot starts on cold wood), measures each with the RGB camera
(``helio_perception.char_dots``, the dot's verification), fits d^2 = a + b N_p and the dwell
per target (``fit_dot_size``) and saves ``dots.yaml``, which the plan then reads.

The row is left out, with the reason in the log and the result, when it would burn into
the goal's canvas or points, on a dry run, or when the fit is refused (too few dots
measured): the painting goes on as without a calibration. Pure Python: no rclpy.
"""

from dataclasses import dataclass
import math

from helio_control.calibration_store import rig_description
from helio_control.dot_check import guessed_diameter
from helio_control.dot_size_calibration import (calibration_row, DotCalibrationError, DotSample,
                                                fit_dot_size, HOLDS, N_P_TARGETS,
                                                save_dot_calibration)
import numpy as np

CALIBRATE_DOTS = ('missing', 'always', 'never')


@dataclass
class DotRowSettings:
    """Where and how the test row is burnt (the painter's ``dot_calibration.*``)."""

    n_p_targets: tuple = N_P_TARGETS          # [-] one goal's worth of dots per target
    per_target: int = 2
    start: tuple = (0.06, 0.14)               # the first dot, world x, y [m]
    pitch: float = 0.005                      # along +x [m]
    holds: tuple = HOLDS                      # [s] at the largest target (<= 0: none)

    def row(self):
        """Return the row's RowGoals (``calibration_row``)."""
        return calibration_row(tuple(self.n_p_targets), self.per_target, tuple(self.start),
                               self.pitch, tuple(self.holds))


def row_conflict(row, canvas, points, clearance):
    """
    Return why the test row cannot be burnt beside a goal, or ''.

    `canvas` is (x_min, y_min, side) [m] of the goal's canvas (None for a goal of points);
    `points` (K, 2) [m] the goal's own dots; no test dot may lie within `clearance` [m] of
    either.
    """
    tests = np.array([point for goal in row for point in goal.points], dtype=float)
    if canvas is not None:
        x_min, y_min, side = canvas
        inside = ((tests[:, 0] > x_min - clearance) & (tests[:, 0] < x_min + side + clearance)
                  & (tests[:, 1] > y_min - clearance) & (tests[:, 1] < y_min + side + clearance))
        if np.any(inside):
            return (f'the test row (from ({tests[0, 0]:.3f}, {tests[0, 1]:.3f}) m) lies on the '
                    f'canvas ({x_min:.3f}, {y_min:.3f}) m, side {side:.3f} m: move '
                    'dot_calibration.start')
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(points):
        nearest = np.min(np.hypot(*(tests[:, None, :] - points[None, :, :]).transpose(2, 0, 1)))
        if nearest < clearance:
            return (f"a test dot lies {nearest * 1e3:.1f} mm from one of the goal's points: "
                    'move dot_calibration.start')
    return ''


async def burn_test_row(dot, feedback, settings, row, say):
    """
    Burn, measure and fit the test `row` (RowGoals); save dots.yaml; return (fit, note).

    `dot` is the painting's DotProcedure (its checks, retreats and camera look), `say(text)`
    logs a line. An N_p target that a test dot cannot reach within ``max_heating`` (a camera
    whose pixels see less of the hot spot: a Lepton in low gain stops near N_p 25) ends the
    unheld part of the row there, and the held dots are held at the largest target a test
    dot burnt to. The fit is None, and the note says why, when there is no calibration.
    """
    samples = []
    reached = None            # the largest N_p target a test dot burnt to
    out_of_reach = None       # the first N_p target a test dot could not reach
    index = 0
    for goal in row:
        n_p, hold = goal.n_p_target, goal.hold
        if hold > 0.0:
            n_p = reached
        skip = ('no N_p target was reached' if n_p is None else
                f'N_p {out_of_reach} was not reached' if not hold and out_of_reach is not None
                and n_p >= out_of_reach else '')
        if skip:
            say(f'test dots {index + 1}-{index + len(goal.points)} left out: {skip}')
            index += len(goal.points)
            continue
        any_burnt = False
        for k, point in enumerate(goal.points):
            index += 1
            dot.check()
            feedback.phase = 'calibrating_dots'
            record = await dot.paint(feedback, index - 1, np.array(point, dtype=float), n_p,
                                     'paper', False, False, guessed_diameter(n_p), (),
                                     hold=hold)
            measured = float(record.get('measured_diameter', 0.0))
            held = f', held {hold:g} s' if hold else ''
            say(f"test dot {index} (N_p {n_p}{held}): {record['outcome']}, "
                f"{measured * 1e3:.2f} mm in {record['dwell']:.1f} s")
            if record['outcome'] == 'burnt' and measured > 0.0:
                samples.append(DotSample(n_p, measured, float(record['dwell']), hold,
                                         float(record.get('cooling', 0.0))))
                any_burnt = True
            elif not hold and record['outcome'] == 'failed' and record['peak_n_p'] < n_p:
                out_of_reach, left = n_p, len(goal.points) - k - 1
                if left:
                    say(f'test dots {index + 1}-{index + left} left out: N_p {n_p} was not '
                        'reached')
                index += left
                break
        if any_burnt and not hold:
            reached = n_p if reached is None else max(reached, n_p)
    try:
        calibration = fit_dot_size(samples)
    except DotCalibrationError as error:
        return None, f'dot-size calibration not made: {error}'
    path = save_dot_calibration(settings.calibration_dir, calibration,
                                rig_description(settings.rig_file) if settings.rig_file
                                else '', made_by='painter (the test row before a painting)')
    say(f'dot-size calibration saved as {path}: ' + '; '.join(calibration.summary()))
    return calibration, (f'dot-size calibration from {len(samples)} test dots: '
                         f'{calibration.summary()[0]}')


def needs_test_row(rule, calibration_present, dry_run):
    """Return whether a painting burns the test row first (`rule`: CALIBRATE_DOTS)."""
    if rule not in CALIBRATE_DOTS:
        raise ValueError(f'calibrate_dots must be one of {CALIBRATE_DOTS}, got {rule!r}')
    return not dry_run and (rule == 'always' or (rule == 'missing' and not calibration_present))


def canvas_of(options):
    """Return (x_min, y_min, side) [m] of a plan's canvas (PlanOptions)."""
    return (float(options.offset_x), float(options.offset_y), float(options.canvas_size))


def clearance_of(calibration_pitch, dot_pitch):
    """Return the clearance [m] between the test row and a goal: the larger pitch, twice."""
    return 2.0 * max(float(calibration_pitch), float(dot_pitch), math.ulp(1.0))
