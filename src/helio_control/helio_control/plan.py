"""
A picture becomes a painting plan: ordered world dots P_w (paper Sec. IV-C, Eq 17, Fig. 9).

Entry points (no rclpy):

- ``plan_picture(picture, options=None, rig=None, sun_ray_robot=None) -> Plan``: picture
  (path, ``sample:NAME``, array, sensor_msgs/Image or ``Picture``) -> features -> Eq 17 grid
  -> world dots -> canvas, spacing and reach checks -> ordering -> time estimate -> quality.
- ``plan_dots(points, options, ...) -> Plan``: the same from explicit world points (the
  PaintPattern goal's ``points``), without features or quality.
- ``load_plan_options(path=None, **overrides) -> PlanOptions``: config/picture.yaml plus
  overrides; ``options_from_goal(goal, defaults)`` maps PaintPattern fields (0 / '' mean
  the default).

``Plan`` holds the ordered dots (N x 2, world metres), per-dot N_p targets, the grid cells,
the rejected dots with their reasons, travel (m and s), the time estimate with its parts,
quality figures, mode, ordering and every parameter used; ``to_json`` / ``from_json``.

Without ``rig`` the deployment rig (config/rig.yaml) is used; without ``sun_ray_robot`` a
nominal sun (``sun_elevation_deg``, ``sun_azimuth_deg``) stands in and the plan says so:
the painter re-checks reach with its own sun estimate.
"""

from dataclasses import asdict, dataclass, field, fields, replace
import json
import math

from helio_control.arm_motion import move_time
from helio_control.cycle_model import estimate_time, load_cycle_config
from helio_control.dot_layout import check_reach, grid_for_picture, outside_canvas, too_close
from helio_control.dot_size_calibration import held_dots
from helio_control.features import cell_means, extract_features, FEATURE_MODES, LINE_MODES
from helio_control.features import working_image
from helio_control.halftone import KERNELS
from helio_control.lens_moves import HEATING_DISTANCE, RETREAT_OFFSET
from helio_control.path_ordering import order_dots, ORDERINGS, TravelMetric
from helio_control.picture_input import load_picture
from helio_control.quality import chamfer_mm, ssim_of_dots
from helio_optics.config_files import read_parameter_section
import numpy as np

PLAN_FORMAT = 'helio_plan/1'


class PlanError(ValueError):
    """A plan that cannot be made (no dots, nothing reachable); the message says why."""


class PlanOptionsError(ValueError):
    """Nonsense options (sizes, modes); the message names the option."""


# the options that take one of a few words (the codes their modules run)
OPTION_CHOICES = {'feature_mode': FEATURE_MODES + ('auto',), 'ordering': ORDERINGS,
                  'v_axis': ('flip', 'paper'), 'tone_kernel': tuple(KERNELS)}


@dataclass
class PlanOptions:
    """
    Options of a plan; names and defaults of config/picture.yaml (SI units).

    What each one means, and its unit: ``picture_options.OPTIONS``.
    """

    canvas_size: float = 0.08
    dot_radius: float = 0.002
    offset_x: float = 0.05
    offset_y: float = 0.05
    n_p_target: int = 30
    feature_mode: str = 'auto'
    ordering: str = 'fast_tsp'
    v_axis: str = 'flip'
    max_canvas_size: float = 0.10
    oversample: int = 8
    canny_low: float = 50.0
    canny_high: float = 150.0
    threshold_block_nodes: float = 3.0
    threshold_offset: float = 0.04
    tone_kernel: str = 'floyd_steinberg'
    tone_gamma: float = 1.0
    tone_dot_size: bool = False
    n_p_min: int = 15
    d_lp: float = HEATING_DISTANCE      # the lens planner's defaults (it owns both)
    retreat: float = RETREAT_OFFSET
    solver_budget_s: float = 0.0
    min_separation: float = 0.0
    cooling_wait: bool = True
    sun_elevation_deg: float = 60.0
    sun_azimuth_deg: float = 0.0

    def validate(self):
        """Raise PlanOptionsError naming the first nonsense option; return self."""
        def number(name, positive=True, allow_zero=False):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise PlanOptionsError(f'{name} must be a number, got {value!r}')
            if not math.isfinite(value):
                raise PlanOptionsError(f'{name} must be finite, got {value}')
            if positive and (value < 0.0 or (value == 0.0 and not allow_zero)):
                raise PlanOptionsError(f'{name} must be > 0, got {value}')
            return value

        for name in ('max_canvas_size', 'canvas_size', 'dot_radius', 'd_lp', 'retreat',
                     'canny_low', 'canny_high', 'threshold_block_nodes', 'tone_gamma'):
            number(name)
        for name in ('offset_x', 'offset_y', 'sun_elevation_deg', 'sun_azimuth_deg',
                     'threshold_offset'):
            number(name, positive=False)
        number('solver_budget_s', allow_zero=True)
        number('min_separation', allow_zero=True)
        if not isinstance(self.cooling_wait, (bool, np.bool_)):
            raise PlanOptionsError(f'cooling_wait must be true or false, got '
                                   f'{self.cooling_wait!r}')
        if self.canvas_size > self.max_canvas_size:
            raise PlanOptionsError(
                f'canvas_size {self.canvas_size} m is larger than the rig can reach: at most '
                f'{self.max_canvas_size} m (max_canvas_size, config/picture.yaml)')
        if self.dot_radius > self.canvas_size:
            raise PlanOptionsError(f'dot_radius {self.dot_radius} m is larger than the canvas '
                                   f'({self.canvas_size} m)')
        for name in ('n_p_target', 'n_p_min', 'oversample'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise PlanOptionsError(f'{name} must be a whole number >= 1, got {value!r}')
        if self.oversample > 32:
            raise PlanOptionsError(f'oversample must be <= 32, got {self.oversample}')
        if self.n_p_min > self.n_p_target:
            raise PlanOptionsError(f'n_p_min {self.n_p_min} exceeds n_p_target '
                                   f'{self.n_p_target}')
        for name, allowed in OPTION_CHOICES.items():
            if getattr(self, name) not in allowed:
                raise PlanOptionsError(f'{name} must be one of {", ".join(allowed)}, got '
                                       f'{getattr(self, name)!r}')
        if not 0.0 < self.sun_elevation_deg <= 90.0:
            raise PlanOptionsError(f'sun_elevation_deg must be in (0, 90], got '
                                   f'{self.sun_elevation_deg}')
        return self

    def nominal_sun_ray(self):
        """Robot-frame unit sun ray s0 (pointing down) of the nominal sun."""
        elevation = math.radians(self.sun_elevation_deg)
        azimuth = math.radians(self.sun_azimuth_deg)
        return -np.array([math.cos(elevation) * math.cos(azimuth),
                          math.cos(elevation) * math.sin(azimuth), math.sin(elevation)])


def load_plan_options(path=None, **overrides):
    """Return the options of config/picture.yaml (``picture``) with `overrides` applied."""
    values = {}
    if path is None:
        from helio_optics.config_files import config_path

        path = config_path('picture.yaml', required=False)
    if path is not None:
        values = read_parameter_section(path, 'picture')
    names = {f.name for f in fields(PlanOptions)}
    unknown = (set(values) | set(overrides)) - names
    if unknown:
        raise PlanOptionsError(f'unknown picture option(s): {", ".join(sorted(unknown))}')
    values.update({k: v for k, v in overrides.items() if v is not None})
    return PlanOptions(**values)


# the options a PaintPattern goal carries (a test holds them to the action's fields)
GOAL_FIELDS = ('canvas_size', 'dot_radius', 'offset_x', 'offset_y', 'n_p_target',
               'feature_mode', 'ordering')


def options_from_goal(goal, defaults=None):
    """
    Return PlanOptions from a PaintPattern goal (fields 0 or '' keep the default).

    `goal` is anything with the attributes of ``helio_msgs/action/PaintPattern`` goals;
    no message import here.
    """
    options = replace(defaults or load_plan_options())
    for name in GOAL_FIELDS:
        value = getattr(goal, name, None)
        if value in (None, '', 0, 0.0):
            continue
        setattr(options, name, value)
    return options


@dataclass
class Plan:
    """An ordered painting plan in the world frame (the painter's input)."""

    dots: np.ndarray                                    # N x 2 world x, y [m], burn order
    n_p_targets: np.ndarray                             # N, per-dot N_p target [pixels]
    grid_uv: np.ndarray                                 # N x 2 feature-grid cell (-1: given)
    rejected: list = field(default_factory=list)        # dicts x_m, y_m, reason
    travel_m: float = 0.0                               # path length dot to dot [m]
    travel_s: float = 0.0                               # joint-space move time [s]
    time_estimate: dict = field(default_factory=dict)   # parts and total [s]
    quality: dict = field(default_factory=dict)         # see helio_control.quality
    mode: str = ''
    ordering: str = ''
    parameters: dict = field(default_factory=dict)      # options and derived figures
    warnings: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    def __len__(self):
        """Return the number of dots to burn."""
        return len(self.dots)

    def to_dict(self):
        """JSON-ready dict (lists and numbers)."""
        return {'format': PLAN_FORMAT, 'mode': self.mode, 'ordering': self.ordering,
                'dot_count': len(self.dots),
                'dots_m': [[float(x), float(y)] for x, y in self.dots],
                'n_p_targets': [int(n) for n in self.n_p_targets],
                'grid_uv': [[int(u), int(v)] for u, v in self.grid_uv],
                'rejected': list(self.rejected), 'travel_m': float(self.travel_m),
                'travel_s': float(self.travel_s), 'time_estimate': dict(self.time_estimate),
                'quality': dict(self.quality), 'parameters': dict(self.parameters),
                'warnings': list(self.warnings), 'notes': list(self.notes)}

    def to_json(self, indent=1):
        """Return the plan as JSON text (plan.json)."""
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False, default=_jsonable)

    @classmethod
    def from_json(cls, text):
        """Read a plan written by ``to_json``; raise ValueError on another format."""
        data = json.loads(text)
        if data.get('format') != PLAN_FORMAT:
            raise ValueError(f'not a helio plan (format {data.get("format")!r}, expected '
                             f'{PLAN_FORMAT!r})')
        return cls(dots=np.array(data['dots_m'], dtype=float).reshape(-1, 2),
                   n_p_targets=np.array(data['n_p_targets'], dtype=int),
                   grid_uv=np.array(data['grid_uv'], dtype=int).reshape(-1, 2),
                   rejected=data['rejected'], travel_m=data['travel_m'],
                   travel_s=data['travel_s'], time_estimate=data['time_estimate'],
                   quality=data['quality'], mode=data['mode'], ordering=data['ordering'],
                   parameters=data['parameters'], warnings=data['warnings'],
                   notes=data['notes'])


def _jsonable(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f'{type(value).__name__} is not JSON serialisable')


def _finite_or_none(figures):
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in figures.items()}


def default_rig():
    """Return the deployment rig (config/rig.yaml, else built-in defaults) and its file."""
    from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters, Rig

    path = default_rig_file()
    return Rig(load_rig_parameters(path)) if path else Rig(), path


def plan_picture(picture, options=None, rig=None, sun_ray_robot=None, cycle=None,
                 dot_size=None, hold=0.0):
    """
    Plan the painting of a picture (paper Sec. IV-C, Eq 17; Fig. 9); return a Plan.

    `options` default to config/picture.yaml; `rig` to the deployment rig; `sun_ray_robot`
    (robot-frame unit ray s0, pointing down) to the nominal sun of the options; `cycle`
    ((CycleModel, MotionLimits)) to config/cycle_model.yaml; `dot_size` (a
    ``dot_size_calibration.DotSizeCalibration``, or None) to the heating time of the cycle
    model and `hold` [s] to the full-target dots' hold (see ``plan_dots``). Raises
    PictureError, PlanOptionsError or PlanError with a message naming the problem.
    """
    options = (options or load_plan_options()).validate()
    source = load_picture(picture)
    grid = grid_for_picture(source.width, source.height, options)
    rows, columns = grid.shape
    if rows < 1 or columns < 1:
        raise PlanError(f'{source.name}: {source.width}x{source.height} px is too narrow: its '
                        f'short side maps to less than one dot on a {options.canvas_size} m '
                        f'canvas of {options.dot_radius} m dots')
    image = working_image(source.grey, grid.shape, grid.pixels_per_node, options.oversample)
    features = extract_features(image, grid.shape, options.oversample, options)
    v, u = np.nonzero(features.dots)
    if len(u) == 0:
        raise PlanError(f'{source.name}: mode {features.mode} found nothing to paint '
                        f'on a {columns}x{rows} dot grid')
    grid_uv = np.column_stack([u, v])
    n_p = np.full(len(u), options.n_p_target, dtype=int)
    if features.mode == 'tones' and options.tone_dot_size:
        darkness = np.clip(features.darkness[v, u], 0.0, 1.0)
        n_p = np.rint(options.n_p_min + (options.n_p_target - options.n_p_min)
                      * darkness).astype(int)
    plan = plan_dots(grid.world(grid_uv), options, rig, sun_ray_robot, grid_uv=grid_uv,
                     n_p_targets=n_p, cycle=cycle, dot_size=dot_size, hold=hold)
    plan.mode = features.mode
    plan.warnings[:0] = list(source.warnings)
    plan.notes[:0] = list(features.notes)
    plan.parameters.update(picture=source.name, picture_size_px=[source.width, source.height],
                           omega_s=grid.omega_s, grid_columns=columns, grid_rows=rows)
    plan.quality = _finite_or_none(plan_quality(plan, features, options))
    return plan


def plan_quality(plan, features, options):
    """Quality figures of the kept dots against the features (``helio_control.quality``)."""
    uv = plan.grid_uv.astype(float)
    if features.mode in LINE_MODES:
        figures = chamfer_mm(uv, features.strokes, options.dot_radius)
        return dict(figures, kind='chamfer_mm', value=figures['chamfer_mm'])
    sizes = np.sqrt(plan.n_p_targets / float(options.n_p_target))
    value = ssim_of_dots(uv, features.reference, options.oversample, sizes)
    coverage = float(np.mean(features.dots))
    darkness = float(np.mean(cell_means(1.0 - features.reference, options.oversample)))
    return {'kind': 'ssim', 'value': value, 'ssim': value, 'dot_fraction': coverage,
            'reference_darkness': darkness}


def plan_dots(points, options=None, rig=None, sun_ray_robot=None, grid_uv=None,
              n_p_targets=None, cycle=None, dot_size=None, hold=0.0):
    """
    Plan explicit world points (N x 2 [m]): canvas, spacing and reach checks, order, time.

    Dots outside the canvas, closer than the pitch r_p to an earlier dot, or unreachable
    for the sun are rejected with a reason (``Plan.rejected``), never dropped silently. With
    `dot_size` (a ``DotSizeCalibration``; the N_p targets already its, see
    ``dot_size_calibration.sized_options``) the time estimate heats each dot for the
    calibration's measured dwell, and the plan's ``parameters['dot_size']`` keeps the law
    (the camera then expects each dot at the law's diameter, ``dot_check``). `hold` [s]:
    the dots at the full N_p target are held there that long (``dot_check.dot_hold``, a
    dot wider than N_p can ask for: ``DotSizeCalibration.dot_for``).
    """
    options = (options or load_plan_options()).validate()
    if not (math.isfinite(hold) and hold >= 0.0):
        raise PlanError(f'a hold must be a finite time >= 0 s, got {hold}')
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if not np.all(np.isfinite(points)):
        raise PlanError('dot coordinates must be finite')
    grid_uv = np.full((len(points), 2), -1, dtype=int) if grid_uv is None else \
        np.asarray(grid_uv, dtype=int)
    n_p = np.full(len(points), options.n_p_target, dtype=int) if n_p_targets is None else \
        np.asarray(n_p_targets, dtype=int)
    model, limits = cycle or load_cycle_config()
    measured_cooling = None if dot_size is None else dot_size.cooling(options.n_p_target, hold)
    if measured_cooling is not None:                  # the rig's own, from the test row
        model = replace(model, cooling_s=measured_cooling)
    parameters = asdict(options)
    if dot_size is not None:
        parameters['dot_size'] = dot_size.to_parameters()
    parameters['hold_s'] = float(hold)
    if rig is None:
        rig, rig_file = default_rig()
        parameters['rig_file'] = rig_file or 'built-in defaults'
    else:
        parameters['rig_file'] = 'given'
    if sun_ray_robot is None:
        sun = options.nominal_sun_ray()
        parameters['sun_source'] = ('nominal (sun_elevation_deg, sun_azimuth_deg): the '
                                    'painter re-checks reach with its estimate')
    else:
        sun = np.asarray(sun_ray_robot, dtype=float).reshape(3)
        norm = float(np.linalg.norm(sun))
        if not math.isfinite(norm) or norm == 0.0:
            raise PlanError(f'sun ray {sun} is not a direction')
        sun = sun / norm
        if sun[2] >= 0.0:
            raise PlanError(f'sun ray {sun} does not point down: the sun is not up')
        parameters['sun_source'] = 'given'
    parameters['sun_ray_robot'] = [float(c) for c in sun]
    parameters.update(cycle_model=model.to_parameters(), motion_limits={
        name: list(value) if isinstance(value, tuple) else value
        for name, value in asdict(limits).items()})

    rejected = []
    keep = np.ones(len(points), dtype=bool)
    outside = outside_canvas(points, options)
    x0, y0 = options.offset_x, options.offset_y
    for index in np.nonzero(outside)[0]:
        keep[index] = False
        rejected.append(_rejection(points[index], grid_uv[index], (
            f'outside the canvas x {x0:.4f}..{x0 + options.canvas_size:.4f} m, '
            f'y {y0:.4f}..{y0 + options.canvas_size:.4f} m')))
    inside = np.nonzero(keep)[0]
    for later, earlier in too_close(points[inside], options.dot_radius).items():
        index, other = inside[later], inside[earlier]
        keep[index] = False
        rejected.append(_rejection(points[index], grid_uv[index], (
            f'closer than the dot pitch {options.dot_radius * 1e3:.2f} mm to the dot at '
            f'({points[other][0]:.4f}, {points[other][1]:.4f}) m')))
    candidates = np.nonzero(keep)[0]
    reach = check_reach(points[candidates], rig, sun, options.d_lp, options.retreat)
    for position, reason in enumerate(reach.reasons):
        if reason:
            keep[candidates[position]] = False
            rejected.append(_rejection(points[candidates[position]],
                                       grid_uv[candidates[position]], reason))
    reachable = reach.reachable
    kept = candidates[reachable]
    if len(kept) == 0:
        detail = f' (first reason: {rejected[0]["reason"]})' if rejected else ''
        raise PlanError(f'no dot can be painted: all {len(points)} rejected{detail}')
    joints_heat = reach.joints_heat[reachable]
    joints_retreat = reach.joints_retreat[reachable]
    # successive dots closer than min_separation cost the hot neighbour's cooling wait
    metric = TravelMetric(joints_retreat, limits, points[kept], options.min_separation,
                          model.cooling_s)
    uv = grid_uv[kept] if np.all(grid_uv[kept] >= 0) else None
    budget = options.solver_budget_s or None
    order = order_dots(metric, options.ordering, uv, budget)
    parameters['close_steps'] = metric.close_steps(order)
    travel = move_time(joints_retreat[order[:-1]], joints_retreat[order[1:]], limits)
    approach = move_time(joints_retreat[order], joints_heat[order], limits)
    # the window rule goes on without the cooling wait (a hot neighbour still costs it above)
    estimate = estimate_time(model if options.cooling_wait else replace(model, cooling_s=0.0),
                             n_p[kept][order], approach, approach, travel,
                             None if dot_size is None else dot_size.dwell,
                             previous_distances(points[kept][order]),
                             _held_seconds(dot_size, n_p[kept][order], options.n_p_target,
                                           hold))
    return Plan(dots=points[kept][order], n_p_targets=n_p[kept][order],
                grid_uv=grid_uv[kept][order], rejected=rejected,
                travel_m=metric.path_length(order), travel_s=float(np.sum(travel)),
                time_estimate=estimate, mode='points', ordering=options.ordering,
                parameters=parameters)


def previous_distances(dots):
    """Return each dot's distance [m] to the dot before it in burn order (inf for the first)."""
    dots = np.asarray(dots, dtype=float).reshape(-1, 2)
    return np.concatenate([[np.inf], np.hypot(*np.diff(dots, axis=0).T)])


def _held_seconds(dot_size, n_p_targets, full_target, hold):
    """Return each dot's time held at its target (the calibration's, measured), or None."""
    if dot_size is None or not hold > 0.0:
        return None
    held = dot_size.heating_time(full_target, hold) - float(dot_size.dwell(full_target))
    return held_dots(n_p_targets, full_target, max(held, 0.0))


def _rejection(point, uv, reason):
    return {'x_m': float(point[0]), 'y_m': float(point[1]), 'u': int(uv[0]), 'v': int(uv[1]),
            'reason': reason}
