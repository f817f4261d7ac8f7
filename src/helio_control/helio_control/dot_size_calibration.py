"""
The dot-size calibration: from an N_p target to the burnt dot's diameter (issue 29, item 3).

Beyond the paper, which burns every dot to N_p = 30 and calls it "a charred dot ~0.2 cm
wide": a short row of test dots at several N_p targets, each dot's diameter measured by the
RGB camera (``helio_perception.char_dots``) and its heating time (``dwell``) taken from the
painter's journal, gives the law the planner inverts: the N_p target of a requested diameter,
and the dwell the time estimate counts for it.

The law: the charred **area** grows linearly with N_p, d^2 = a + b N_p (b > 0). N_p counts
the thermal camera's pixels above the pyrolysis temperature: an area of the wood's surface,
and the paper's Fig. 8d shows the charred area growing with it. The simulated world agrees:
its dots burnt to N_p 15, 20 and 30 are 1.40-1.43, 1.61-1.63 and 1.96-1.99 mm wide
(``test/test_painter.py``), d^2 = 2.0, 2.6 and 3.9 mm^2: on one line within 1 %. The dwell
is not linear in N_p (the world's test dots: 3, 9 and 55 s to N_p 15, 25 and 40: past 30 the
hot spot grows slowly), so it is the mean dwell of each target, its logarithm interpolated
linearly between targets (and along the end segments beyond them).

Wider than N_p can ask for: the thermal image's hot area levels off long before the char
stops spreading (the world's N_p stops near 45, its char still grows: 2.0 mm at N_p 30
after 18 s, 2.45 mm after 60 s more), so the row also burns dots at its largest N_p target
*held* there for ``holds`` seconds (``dot_cycle``'s ``hold``). Their mean charred area at
each hold, and the N_p law's area at the target for no hold, are interpolated linearly in
the hold (and along the last segment beyond it), the dwells likewise: ``dot_for`` gives the
N_p target, and for a dot wider than the largest target's, that target and a hold.

A fit needs ``MIN_SAMPLES`` dots at ``MIN_TARGETS`` distinct N_p targets, and the mean
diameter must grow with the N_p target: anything else is refused with the reason, never
saved. Saved as ``dots.yaml`` in the calibration directory (``calibration_store``: refused on
load for another rig description). Pure Python: no rclpy.
"""

from dataclasses import asdict, dataclass
import math
import os

from helio_control.calibration_store import load_calibration, save_calibration
import numpy as np

DOTS_FILE = 'dots.yaml'
MIN_SAMPLES = 3
MIN_TARGETS = 2


class DotCalibrationError(ValueError):
    """Samples a dot-size law cannot be fitted to; the message says why."""


@dataclass(frozen=True)
class DotSample:
    """One test dot: N_p target, diameter the camera measured [m], dwell [s], hold [s]."""

    n_p_target: int
    diameter: float
    dwell: float
    hold: float = 0.0
    cooling: float = 0.0         # the retreat's wait for N_p = 0 [s] (0: not measured)


@dataclass(frozen=True)
class DotSizeCalibration:
    """The fitted law d^2 = a + b N_p and dwell = c + e N_p, with its residuals."""

    area_intercept: float        # a [m^2]
    area_per_n_p: float          # b [m^2 per pixel]
    dwell_n_p: tuple             # the N_p targets measured, ascending
    dwell_s: tuple               # the mean dwell of each [s]
    n_p_min: int                 # the N_p targets it was fitted over
    n_p_max: int
    residual_rms: float          # of the diameters about the law [m]
    residual_max: float          # the largest [m]
    dwell_residual_rms: float    # of the dwells [s]
    samples: int
    hold_n_p: int = 0            # the N_p target the held dots were burnt to (0: none)
    hold_s: tuple = ()           # the holds measured, ascending [s]
    hold_area: tuple = ()        # the mean charred area of each [m^2]
    hold_dwell_s: tuple = ()     # the mean dwell of each (reaching the target + hold) [s]
    cooling_s: tuple = ()        # the mean wait for N_p = 0 after the retreat, per N_p target
    hold_cooling_s: tuple = ()   # ... and per hold [s] (empty: not measured)

    def diameter(self, n_p):
        """Return the burnt diameter [m] of N_p target `n_p` (array or scalar)."""
        area = self.area_intercept + self.area_per_n_p * np.asarray(n_p, dtype=float)
        return np.sqrt(np.maximum(area, 0.0))

    def n_p_target(self, diameter):
        """Return the N_p target (a whole number >= 1) that burns a dot `diameter` [m] wide."""
        if not (math.isfinite(diameter) and diameter > 0.0):
            raise ValueError(f'a dot diameter must be > 0 m, got {diameter}')
        n_p = (diameter * diameter - self.area_intercept) / self.area_per_n_p
        return max(1, int(round(n_p)))

    def dwell(self, n_p):
        """
        Return the heating time [s] to N_p target `n_p` (array or scalar).

        The logarithm of the dwell is interpolated linearly in N_p (and along the end
        segments beyond the targets): the dwell grows about exponentially with N_p (the
        world's 15.3 and 48.5 s at N_p 30 and 40; its dots burnt alone at N_p 33 took 19-21 s,
        a linear interpolation says 25 s, this 21.6 s).
        """
        log_dwell = np.log(np.asarray(self.dwell_s, dtype=float))
        return np.exp(_along(n_p, self.dwell_n_p, log_dwell))

    def _holds(self):
        """Return the holds measured with no hold first [s] (held dots only)."""
        return (0.0,) + tuple(self.hold_s)

    def _held_areas(self):
        """Return the charred area [m^2] at each of ``_holds``: the N_p law's, then measured."""
        return (float(self.diameter(self.hold_n_p)) ** 2,) + tuple(self.hold_area)

    def dot_for(self, diameter):
        """
        Return (N_p target, hold [s]) that burn a dot `diameter` [m] wide.

        Within the N_p law's measured range or without held dots: ``n_p_target`` and no
        hold; wider: the held dots' target and the hold interpolated in the charred area.
        """
        n_p = self.n_p_target(diameter)
        if not self.hold_s or diameter <= float(self.diameter(self.n_p_max)):
            return n_p, 0.0
        return self.hold_n_p, max(0.0, float(_along(diameter * diameter, self._held_areas(),
                                                    self._holds())))

    def diameter_of(self, n_p, hold=0.0):
        """Return the burnt diameter [m] of N_p target `n_p` held `hold` [s] at it."""
        if hold > 0.0 and self.hold_s:
            return math.sqrt(max(float(_along(hold, self._holds(), self._held_areas())), 0.0))
        return float(self.diameter(n_p))

    def heating_time(self, n_p, hold=0.0):
        """Return the heating time [s] of N_p target `n_p` held `hold` [s] (at least 0)."""
        if hold > 0.0 and self.hold_s:
            dwells = (float(self.dwell(self.hold_n_p)),) + tuple(self.hold_dwell_s)
            return max(0.0, float(_along(hold, self._holds(), dwells)))
        return float(self.dwell(n_p))

    def cooling(self, n_p, hold=0.0):
        """
        Return the retreat's wait for N_p = 0 [s] after a dot of N_p `n_p` held `hold` [s].

        Interpolated between the test dots' means (held: between the holds'), the nearest
        end's beyond them; None when the row did not measure it.
        """
        if hold > 0.0 and self.hold_s and len(self.hold_cooling_s) == len(self.hold_s):
            return float(np.interp(hold, self.hold_s, self.hold_cooling_s))
        if len(self.cooling_s) != len(self.dwell_n_p):
            return None
        return float(np.interp(n_p, self.dwell_n_p, self.cooling_s))

    def within(self, diameter):
        """Return whether `diameter` [m] lies within the diameters the fit measured."""
        low, high = self.diameter([self.n_p_min, self.n_p_max])
        if self.hold_s:
            high = max(high, math.sqrt(max(self.hold_area[-1], 0.0)))
        return bool(low <= diameter <= high)

    def to_parameters(self):
        """Return the law as plain values (the ``dot_size`` section of dots.yaml)."""
        return {name: ([float(v) for v in value] if isinstance(value, (tuple, list)) else
                       int(value) if isinstance(value, (int, np.integer)) else float(value))
                for name, value in asdict(self).items()}

    @classmethod
    def from_parameters(cls, values):
        """Build from ``to_parameters`` values; ValueError naming a missing or bad one."""
        optional = ('hold_n_p', 'hold_s', 'hold_area', 'hold_dwell_s', 'cooling_s',
                    'hold_cooling_s')                           # since held dots
        try:
            fields = {name: values[name] for name in cls.__dataclass_fields__
                      if name not in optional or name in values}
            for name in ('dwell_n_p', 'dwell_s', 'hold_s', 'hold_area', 'hold_dwell_s',
                         'cooling_s', 'hold_cooling_s'):
                if name in fields:
                    fields[name] = tuple(float(v) for v in fields[name])
            calibration = cls(**fields)
        except (KeyError, TypeError) as error:
            raise ValueError(f'not a dot-size calibration: {error!r}') from None
        holds = calibration.hold_s
        if len(calibration.hold_area) != len(holds) or \
                len(calibration.hold_dwell_s) != len(holds) or \
                (holds and (calibration.hold_n_p < 1 or min(holds) <= 0.0)):
            raise ValueError('hold_s, hold_area and hold_dwell_s must hold one value per hold '
                             '(each > 0 s) and hold_n_p must be >= 1')
        if not calibration.area_per_n_p > 0.0:
            raise ValueError(f'area_per_n_p must be > 0, got {calibration.area_per_n_p}')
        if len(calibration.dwell_n_p) < 2 or len(calibration.dwell_n_p) != len(
                calibration.dwell_s) or not min(calibration.dwell_s) > 0.0:
            raise ValueError('dwell_n_p and dwell_s must hold two or more values each, the '
                             'dwells > 0 s')
        return calibration

    def summary(self):
        """Return the law and its residuals for a person (one line each)."""
        return [f'd^2 = {self.area_intercept * 1e6:.3f} mm^2 + {self.area_per_n_p * 1e6:.4f} '
                f'mm^2 x N_p (N_p {self.n_p_min}-{self.n_p_max}: '
                f'{self.diameter(self.n_p_min) * 1e3:.2f}-'
                f'{self.diameter(self.n_p_max) * 1e3:.2f} mm; {self.samples} dots)',
                f'diameter residual RMS {self.residual_rms * 1e3:.3f} mm, largest '
                f'{self.residual_max * 1e3:.3f} mm',
                'dwell: ' + ', '.join(f'{s:.1f} s at N_p {n:g}' for n, s in
                                      zip(self.dwell_n_p, self.dwell_s))
                + f' (RMS {self.dwell_residual_rms:.2f} s about the means)'] + (
                    [f'held at N_p {self.hold_n_p}: ' + ', '.join(
                        f'{math.sqrt(max(a, 0.0)) * 1e3:.2f} mm after {h:g} s ({d:.1f} s in '
                        'all)' for h, a, d in zip(self.hold_s, self.hold_area,
                                                  self.hold_dwell_s))]
                    if self.hold_s else [])


def _along(x, xs, ys):
    """Interpolate ys(xs) at x (array or scalar) linearly; beyond an end along its segment."""
    x = np.asarray(x, dtype=float)
    xs, ys = np.asarray(xs, dtype=float), np.asarray(ys, dtype=float)
    low = ys[0] + (x - xs[0]) * (ys[1] - ys[0]) / (xs[1] - xs[0])
    high = ys[-1] + (x - xs[-1]) * (ys[-1] - ys[-2]) / (xs[-1] - xs[-2])
    return np.where(x < xs[0], low, np.where(x > xs[-1], high, np.interp(x, xs, ys)))


def held_dots(n_p_targets, full_target, hold):
    """
    Return each dot's hold [s] at its N_p target (an array).

    `hold` for the dots at the plan's full `full_target` (a dot wider than N_p can ask
    for), none for lighter tones.
    """
    return np.where(np.asarray(n_p_targets) == int(full_target), float(hold), 0.0)


def fit_dot_size(samples):
    """
    Fit d^2 = a + b N_p and each target's mean dwell to DotSamples; a DotSizeCalibration.

    Raises DotCalibrationError for fewer than ``MIN_SAMPLES`` usable samples (a diameter and
    a dwell > 0) or ``MIN_TARGETS`` N_p targets, and for dots that do not grow with N_p, or
    that take less time to a higher N_p target.
    """
    usable = [s for s in samples if s.diameter > 0.0 and s.dwell > 0.0
              and math.isfinite(s.diameter) and math.isfinite(s.dwell)]
    held = [s for s in usable if s.hold > 0.0]
    usable = [s for s in usable if not s.hold > 0.0]
    targets = sorted({int(s.n_p_target) for s in usable})
    if len(usable) < MIN_SAMPLES or len(targets) < MIN_TARGETS:
        raise DotCalibrationError(
            f'too few test dots: {len(usable)} measured at {len(targets)} N_p target(s) '
            f'({len(samples) - len(usable)} without a diameter or a dwell); at least '
            f'{MIN_SAMPLES} dots at {MIN_TARGETS} targets are needed')
    n_p = np.array([s.n_p_target for s in usable], dtype=float)
    diameter = np.array([s.diameter for s in usable])
    dwell = np.array([s.dwell for s in usable])
    means = [float(np.mean(diameter[n_p == target])) for target in targets]
    for (low, small), (high, large) in zip(zip(targets, means), zip(targets[1:], means[1:])):
        if not large > small:
            raise DotCalibrationError(
                f'the dots do not grow with N_p: N_p {low} burnt {small * 1e3:.2f} mm, N_p '
                f'{high} {large * 1e3:.2f} mm (a cloud, a missed focus, or a camera that '
                'cannot see them?)')
    dwells = [float(np.mean(dwell[n_p == target])) for target in targets]
    for (low, short), (high, long) in zip(zip(targets, dwells), zip(targets[1:], dwells[1:])):
        if long < short:
            raise DotCalibrationError(
                f'a higher N_p target took less time: N_p {low} in {short:.1f} s, N_p {high} in '
                f'{long:.1f} s (a cloud or a stale thermal stream during a test dot?)')
    design = np.column_stack([np.ones_like(n_p), n_p])
    (a, b), *_ = np.linalg.lstsq(design, diameter ** 2, rcond=None)
    if not b > 0.0:
        raise DotCalibrationError(f'the charred area does not grow with N_p (slope '
                                  f'{b * 1e6:.4f} mm^2 per pixel)')
    fitted = np.sqrt(np.maximum(a + b * n_p, 0.0))
    residual = diameter - fitted
    mean_dwell = np.interp(n_p, targets, dwells)
    holds = _fit_holds(held, targets[-1], float(a + b * targets[-1]), dwells[-1])
    coolings = _mean_coolings(usable, targets, lambda s: s.n_p_target)
    if coolings:
        holds['cooling_s'] = coolings
        if held:
            holds['hold_cooling_s'] = _mean_coolings(held, holds['hold_s'], lambda s: s.hold)
    return DotSizeCalibration(
        area_intercept=float(a), area_per_n_p=float(b),
        dwell_n_p=tuple(float(t) for t in targets), dwell_s=tuple(dwells),
        n_p_min=targets[0], n_p_max=targets[-1],
        residual_rms=float(np.sqrt(np.mean(residual ** 2))),
        residual_max=float(np.max(np.abs(residual))),
        dwell_residual_rms=float(np.sqrt(np.mean((dwell - mean_dwell) ** 2))),
        samples=len(usable) + len(held), **holds)


def _mean_coolings(samples, groups, group_of):
    """Return the mean measured cooling of each group, () when a group has none."""
    means = []
    for group in groups:
        waited = [s.cooling for s in samples if group_of(s) == group and s.cooling > 0.0]
        if not waited:
            return ()
        means.append(float(np.mean(waited)))
    return tuple(means)


def _fit_holds(held, n_p_max, area_at_max, dwell_at_max):
    """
    Return the hold fields of a calibration from the held DotSamples (empty: none).

    Held dots must have been burnt to the largest N_p target, and their mean area and dwell
    must grow with the hold from the N_p law's area and dwell at that target (no hold).
    """
    if not held:
        return {}
    others = sorted({int(s.n_p_target) for s in held} - {int(n_p_max)})
    if others:
        raise DotCalibrationError(f'held test dots must be burnt to the largest N_p target '
                                  f'{n_p_max}, not {others}')
    hold = np.array([s.hold for s in held])
    values = sorted(set(hold.tolist()))
    area = [float(np.mean([s.diameter ** 2 for s in held if s.hold == h])) for h in values]
    dwell = [float(np.mean([s.dwell for s in held if s.hold == h])) for h in values]
    for (low, small), (high, large) in zip(zip([0.0] + values, [area_at_max] + area),
                                           zip(values, area)):
        if not large > small:
            raise DotCalibrationError(
                f'the held dots do not grow with the hold: {math.sqrt(max(small, 0.0)) * 1e3:.2f}'
                f' mm after {low:g} s, {math.sqrt(large) * 1e3:.2f} mm after {high:g} s at '
                f'N_p {n_p_max}')
    for (low, short), (high, long) in zip(zip([0.0] + values, [dwell_at_max] + dwell),
                                          zip(values, dwell)):
        if long < short:
            raise DotCalibrationError(f'a longer hold took less time: {short:.1f} s with '
                                      f'{low:g} s held, {long:.1f} s with {high:g} s')
    return {'hold_n_p': int(n_p_max), 'hold_s': tuple(values), 'hold_area': tuple(area),
            'hold_dwell_s': tuple(dwell)}


def samples_from_journal(journal):
    """
    Return the DotSamples of a run's journal (``run_journal.read_journal``).

    A sample per dot burnt that the camera measured (``measured_diameter`` > 0), whatever its
    verdict: a test dot is judged against a guess of its size, its diameter is what counts.
    """
    return [DotSample(int(dot.n_p_target), float(dot.measured_diameter), float(dot.dwell),
                      float(dot.hold), float(dot.cooling))
            for dot in journal.dots
            if dot.outcome == 'burnt' and dot.measured_diameter > 0.0]


def save_dot_calibration(directory, calibration, description, made_by='helio calibrate dots'):
    """Write `calibration` as `directory`/dots.yaml for a rig description; return the path."""
    return save_calibration(directory, DOTS_FILE, {'dot_size': calibration.to_parameters()},
                            description, made_by, notes={
                                'residual_rms_mm': round(calibration.residual_rms * 1e3, 4),
                                'n_p_range': f'{calibration.n_p_min}-{calibration.n_p_max}'})


def load_dot_calibration(directory, description):
    """
    Return the DotSizeCalibration saved in `directory` for a rig description, or None.

    Raises ``calibration_store.CalibrationRefused`` for a file made for another rig
    description or not a dot-size calibration.
    """
    from helio_control.calibration_store import CalibrationRefused
    loaded = load_calibration(directory, DOTS_FILE, description)
    if loaded is None:
        return None
    try:
        return DotSizeCalibration.from_parameters(loaded[0].get('dot_size') or {})
    except ValueError as error:
        raise CalibrationRefused(f'{directory}/{DOTS_FILE}: {error}') from None


def sized_options(options, calibration, n_p_given=False):
    """
    Return (options burning dots ``dot_radius`` wide, the hold [s] at their N_p target).

    The options are a copy. With a calibration, the goal's ``dot_radius`` (the paper's r_p,
    which the plan uses as the pitch and the width of a dot) is the burnt dot's diameter:
    the N_p target is the calibration's for it, unless the goal gave one (`n_p_given`: a
    test dot's, or a user who asks for N_p). ``n_p_min`` (the lightest tone's N_p) is kept
    at most that target. A dot wider than the calibration's largest N_p target burns is
    held at that target (``DotSizeCalibration.dot_for``); a goal that gave its N_p target
    is not held (hold 0). Without a calibration, the options as they are and no hold.
    """
    from dataclasses import replace
    if calibration is None or n_p_given:
        return replace(options), 0.0
    n_p, hold = calibration.dot_for(float(options.dot_radius))
    return replace(options, n_p_target=n_p, n_p_min=min(int(options.n_p_min), n_p)), hold


def dot_size_for_painting(directory, rig_file):
    """
    Return (DotSizeCalibration or None, note) for a painting: dots.yaml of `directory`.

    None without a file (note ''), or with a file refused (made for another rig description,
    not a dot-size calibration: the note says why, and the painting goes on as without one).
    """
    from helio_control.calibration_store import CalibrationRefused, rig_description
    try:
        description = rig_description(rig_file) if rig_file else ''
        return load_dot_calibration(os.path.expanduser(directory), description), ''
    except (CalibrationRefused, OSError) as error:
        return None, f'dot-size calibration not used: {error}'


def painting_note(directory, rig_file):
    """Return (what a painting will size its dots by, whether that is a warning)."""
    calibration, note = dot_size_for_painting(directory, rig_file)
    if note:
        return note, True
    if calibration is None:
        return (f"no dot-size calibration in {directory}: dots are sized by the goal's N_p "
                'target'), False
    return f'dot-size calibration read back from {directory}: {calibration.summary()[0]}', False


# the test row's defaults: on the margin 1 cm above the default canvas (0.05-0.13 m), dots
# 5 mm apart so that the widest (~2.7 mm) stay apart. Not between the marker and the canvas:
# at y 0.04 the simulated world's N_p stops at 13 (measured with its true focus)
ROW_START = (0.06, 0.14)
ROW_PITCH = 0.005
# up to 30: the world's N_p grows slowly past it (40 after 55 s, 45 after 90 s, the painter's
# max_heating), while its char goes on spreading: wider dots are held at 30 (HOLDS)
N_P_TARGETS = (12, 18, 24, 30)
# [s] at N_p 30 in the world: 2.0 mm after 18 s, 2.2 mm held 20 s more, 2.35 mm 45 s more;
# 2.5 mm is reached about 70 s on (the law's last segment)
HOLDS = (20.0, 45.0)


@dataclass(frozen=True)
class RowGoal:
    """One PaintPattern goal of the test row: its dots at one N_p target, its small canvas."""

    n_p_target: int
    points: tuple            # ((x, y), ...) world [m]
    offset_x: float          # the canvas that holds them (the painter refuses dots outside)
    offset_y: float
    canvas_size: float
    hold: float = 0.0        # [s] held at the target once reached (dot_cycle)


def calibration_row(n_p_targets=N_P_TARGETS, per_target=2, start=ROW_START, pitch=ROW_PITCH,
                    holds=()):
    """
    Return the RowGoals of a row of test dots: `per_target` dots for each N_p target.

    The row runs along +x from `start` (world x, y [m]) by `pitch` [m]; one goal per
    target, as a PaintPattern goal holds one N_p target, then one per hold in `holds` [s]
    (held at the largest target; holds <= 0 are left out). Each goal's canvas is the square
    just around its own dots (its side at least the row's pitch and at most 0.1 m).
    """
    if per_target < 1 or not n_p_targets:
        raise ValueError('a test row needs at least one N_p target and one dot per target')
    if len(set(n_p_targets)) < MIN_TARGETS or len(n_p_targets) * per_target < MIN_SAMPLES:
        raise ValueError(f'a fit needs {MIN_SAMPLES} dots at {MIN_TARGETS} N_p targets at '
                         f'least, not {per_target} at {sorted(set(n_p_targets))}')
    for hold in holds:
        if not math.isfinite(hold):
            raise ValueError(f'a hold must be a finite time [s], got {hold}')
    groups = [(int(n_p), 0.0) for n_p in n_p_targets] + \
        [(int(max(n_p_targets)), float(hold)) for hold in sorted(set(holds)) if hold > 0.0]
    goals, k = [], 0
    for n_p, hold in groups:
        if n_p < 1:
            raise ValueError(f'an N_p target must be >= 1, got {n_p}')
        points = tuple((start[0] + pitch * (k + i), start[1]) for i in range(per_target))
        k += per_target
        margin = 0.5 * pitch
        side = min(max(points[-1][0] - points[0][0] + 2.0 * margin, 2.0 * pitch), 0.1)
        goals.append(RowGoal(n_p, points, points[0][0] - margin, start[1] - 0.5 * side, side,
                             hold))
    return goals
