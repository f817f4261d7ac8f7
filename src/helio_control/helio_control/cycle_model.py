"""
How long a painting takes: a per-dot cycle model of Algorithm 1 (paper Sec. IV-B, V-C).

One dot, as the painter runs it (Algorithm 1, lines 6-14):

1. approach: move from the retreat pose (lens d_lp + delta d_lp from the dot) to the heating
   pose (d_lp), one commanded move;
2. heat until N_p >= N_p target: ``heating_onset_s`` until the first thermal pixel reaches
   the camera cap (T_p taken as 180.9 degC), then ``heating_per_pixel_s`` per pixel of N_p
   (paper Fig. 8 a/c: about 20 s to N_p = 30 at d_lp 8.2 cm; the defaults, 16.3 s, are a
   dot burnt alone in the simulated world, timed from the focus reached: the approach has
   warmed the wood by then), shortened by the heat the dot burnt just before left in the
   wood: past its first ``preheat_onset_s`` (the hot spot forming at the focus, which the
   neighbour's heat barely speeds: a 1.5 mm dot of 4.7 s alone took 3.8 s 1.5 mm after
   another), times 1 - ``preheat_share`` exp(-(r / ``preheat_reach``)^2) for a previous dot r
   away (the world's N_p 30-33 dots: 0.62, 0.72, 0.76, 0.85 and 0.94 of a dot burnt alone
   after one 2.0, 2.8, 3.0, 4.2 and 6.0 mm away; the words at 1.5, 2 and 3 mm pitch within
   +4, +9 and +1 % of the heating measured);
3. retreat by delta d_lp (one move) and wait until N_p has dropped to 0 (Sec. IV-B3: T_max
   stays at the cap about 3 s): the wait ``cooling_s`` starts when the retreat starts, so
   the retreat move is hidden in it when shorter;
4. each N_p decision waits for a thermal frame: ``thermal_frame_s`` on average for each of
   the two decisions (the frame in progress is half a period, the detection another half);
5. travel to the next dot's retreat pose: the joint-space move time (``arm_motion``), plus
   ``move_overhead_s`` per commanded move (serial command, queue start, executed-index
   polling at 20 ms, settling).

Plus ``start_s`` once (sun estimation sweep and the first move). Every parameter lives in
``config/cycle_model.yaml``; ``fit_cycle_model`` refits them from per-dot logs of real or
simulated runs.

Assumed and not modelled: a clear sky at the irradiance of the calibration (heating time
scales roughly with 1 / irradiance; a cloud stops the charring, paper Fig. 15 d); the sun
estimate is updated by Eq 18 without new sweeps; no failed or repeated dots; the same wood.
The estimate gives a low..high range from ``heating_spread`` (the relative spread of the
heating time between dots: simulated 14.6-17.2 s, +-8 %; set 15 % by default).
"""

from dataclasses import asdict, dataclass, fields, replace
import math

from helio_control.arm_motion import MotionLimits
from helio_optics.config_files import read_parameter_section
import numpy as np


@dataclass(frozen=True)
class CycleModel:
    """Parameters of the per-dot cycle [s]; see the module docstring."""

    heating_onset_s: float = 11.0
    heating_per_pixel_s: float = 0.176
    cooling_s: float = 3.1
    thermal_frame_s: float = 0.115
    move_overhead_s: float = 0.1
    start_s: float = 60.0
    heating_spread: float = 0.15
    preheat_onset_s: float = 3.0
    preheat_share: float = 0.5
    preheat_reach: float = 0.004

    def __post_init__(self):
        """Reject negative or non-finite parameters."""
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
                raise ValueError(f'cycle model {f.name} must be a finite number >= 0, '
                                 f'got {value!r}')

    def heating_time(self, n_p_target):
        """Heating time to reach N_p >= n_p_target (array or scalar) [s], a dot alone."""
        return self.heating_onset_s + self.heating_per_pixel_s * np.asarray(n_p_target,
                                                                            dtype=float)

    def preheat_factor(self, distance):
        """
        Return the heating time's share left after a dot burnt `distance` [m] away before.

        1 - preheat_share exp(-(distance / preheat_reach)^2) (array or scalar; an infinite
        or NaN distance, no dot before: 1).
        """
        distance = np.asarray(distance, dtype=float)
        if self.preheat_reach <= 0.0:
            return np.ones_like(distance)
        near = np.where(np.isfinite(distance), distance, np.inf) / self.preheat_reach
        return 1.0 - min(self.preheat_share, 1.0) * np.exp(-near * near)

    @classmethod
    def from_parameters(cls, values):
        """Build from a dict of the field names (unknown names raise ValueError)."""
        names = {f.name for f in fields(cls)}
        unknown = set(values) - names
        if unknown:
            raise ValueError(f'unknown cycle model parameter(s): {", ".join(sorted(unknown))}')
        return cls(**{name: float(value) for name, value in values.items()})

    def to_parameters(self):
        """Return the parameters as a dict (the names of config/cycle_model.yaml)."""
        return asdict(self)


def motion_limits_from_parameters(values):
    """Return the MotionLimits of the ``motion`` section of config/cycle_model.yaml."""
    known = {'arm_velocity_deg_s', 'arm_acceleration_deg_s2', 'wrist_velocity_deg_s',
             'wrist_acceleration_deg_s2'}
    unknown = set(values) - known
    if unknown:
        raise ValueError(f'unknown motion parameter(s): {", ".join(sorted(unknown))}')
    defaults = MotionLimits()
    return MotionLimits(
        arm_velocity=tuple(math.radians(float(v)) for v in values['arm_velocity_deg_s'])
        if 'arm_velocity_deg_s' in values else defaults.arm_velocity,
        arm_acceleration=tuple(math.radians(float(v))
                               for v in values['arm_acceleration_deg_s2'])
        if 'arm_acceleration_deg_s2' in values else defaults.arm_acceleration,
        wrist_velocity=math.radians(float(values['wrist_velocity_deg_s']))
        if 'wrist_velocity_deg_s' in values else defaults.wrist_velocity,
        wrist_acceleration=math.radians(float(values['wrist_acceleration_deg_s2']))
        if 'wrist_acceleration_deg_s2' in values else defaults.wrist_acceleration)


def load_cycle_config(path=None):
    """
    Read config/cycle_model.yaml: return (CycleModel, MotionLimits).

    Without `path` the deployment file is looked up (``helio_optics.config_files``); when
    there is none the built-in defaults (the same values) are returned.
    """
    if path is None:
        from helio_optics.config_files import config_path

        path = config_path('cycle_model.yaml', required=False)
        if path is None:
            return CycleModel(), MotionLimits()
    model = CycleModel.from_parameters(read_parameter_section(path, 'cycle_model'))
    try:
        limits = motion_limits_from_parameters(read_parameter_section(path, 'motion'))
    except ValueError as error:
        if 'no ros__parameters.motion' not in str(error):
            raise
        limits = MotionLimits()
    return model, limits


def estimate_time(model, n_p_targets, approach_s, retreat_s, travel_s, heating_time=None,
                  previous_distance=None, held_s=None):
    """
    Time estimate of a painting [s] as a dict of parts that add up to ``total_s``.

    `n_p_targets`, `approach_s` and `retreat_s` have one value per dot (the last two: the
    joint-space move times between each dot's retreat and heating poses); `travel_s` has one
    value per move between successive dots (N - 1 values). Parts: ``start_s``,
    ``heating_s``, ``retreat_cooling_s`` (per dot the longer of the cooling wait and the
    retreat move with its overhead), ``approach_s``, ``travel_s``, ``overhead_s`` (command
    overheads of the approach and travel moves, thermal frame waits). `heating_time`
    (N_p targets -> seconds) replaces the model's heating time (a dot-size calibration's
    measured dwells, of dots burnt alone). `previous_distance` [m], one per dot: how far
    the dot burnt before it lies (NaN or inf for the first): its heating past
    ``preheat_onset_s`` is shortened by ``preheat_factor``. `held_s` [s], one per dot: its
    hold at the target once reached (``dot_cycle``), added as it is.
    """
    n_p_targets = np.asarray(n_p_targets, dtype=float)
    approach_s = np.asarray(approach_s, dtype=float)
    retreat_s = np.asarray(retreat_s, dtype=float)
    travel_s = np.asarray(travel_s, dtype=float)
    count = len(n_p_targets)
    heating = np.asarray((heating_time or model.heating_time)(n_p_targets), dtype=float)
    if previous_distance is not None:
        preheat = model.preheat_factor(np.asarray(previous_distance, dtype=float).reshape(count))
        onset = np.minimum(heating, model.preheat_onset_s)
        heating = onset + (heating - onset) * preheat
    parts = {'start_s': model.start_s if count else 0.0,
             'heating_s': float(np.sum(heating) + (0.0 if held_s is None else
                                                   np.sum(held_s))),
             'retreat_cooling_s': float(np.sum(np.maximum(
                 model.cooling_s, retreat_s + model.move_overhead_s))),
             'approach_s': float(np.sum(approach_s)),
             'travel_s': float(np.sum(travel_s)),
             'overhead_s': (count + len(travel_s)) * model.move_overhead_s
             + 2 * count * model.thermal_frame_s}
    total = sum(parts.values())
    spread = model.heating_spread * parts['heating_s']
    return dict(parts, dots=int(count), total_s=total, total_low_s=total - spread,
                total_high_s=total + spread,
                per_dot_s=(total - parts['start_s']) / count if count else 0.0)


def fit_cycle_model(records, model=None):
    """
    Refit the cycle model from per-dot logs; return (model, report).

    Each record is a dict with ``heating_s`` (focus to N_p >= target), ``cooling_s``
    (retreat start to N_p = 0) and ``move_s`` (travel to the next dot, commanded to
    reached); optional ``n_p_target`` and ``predicted_move_s`` (the joint-space time of that
    move). With two or more distinct N_p targets, heating = onset + per_pixel * N_p is
    fitted by least squares; otherwise both heating terms are scaled to the mean.
    ``move_overhead_s`` becomes the mean of move_s - predicted_move_s when predictions are
    given; ``heating_spread`` the relative standard deviation of the heating residuals.
    """
    model = model or CycleModel()
    if not records:
        raise ValueError('no records to fit the cycle model to')
    heating = np.array([float(r['heating_s']) for r in records])
    cooling = np.array([float(r['cooling_s']) for r in records])
    if not (np.all(np.isfinite(heating)) and np.all(np.isfinite(cooling))):
        raise ValueError('records hold non-finite heating_s or cooling_s')
    targets = np.array([float(r.get('n_p_target', 30.0)) for r in records])
    changes = {}
    if len(np.unique(targets)) >= 2:
        design = np.column_stack([np.ones_like(targets), targets])
        (onset, per_pixel), *_ = np.linalg.lstsq(design, heating, rcond=None)
        changes.update(heating_onset_s=max(0.0, float(onset)),
                       heating_per_pixel_s=max(0.0, float(per_pixel)))
    else:
        scale = float(np.mean(heating) / np.mean(model.heating_time(targets)))
        changes.update(heating_onset_s=model.heating_onset_s * scale,
                       heating_per_pixel_s=model.heating_per_pixel_s * scale)
    changes['cooling_s'] = float(np.mean(cooling))
    predicted = [(float(r['move_s']), float(r['predicted_move_s'])) for r in records
                 if 'move_s' in r and 'predicted_move_s' in r]
    if predicted:
        measured, expected = np.array(predicted).T
        changes['move_overhead_s'] = max(0.0, float(np.mean(measured - expected)))
    fitted = replace(model, **changes)
    residual = heating - fitted.heating_time(targets)
    spread = float(np.std(residual) / np.mean(heating)) if len(records) > 1 else \
        model.heating_spread
    fitted = replace(fitted, heating_spread=spread)
    report = {'records': len(records),
              'heating_rms_residual_s': float(np.sqrt(np.mean(residual ** 2))),
              'cooling_std_s': float(np.std(cooling))}
    return fitted, report
