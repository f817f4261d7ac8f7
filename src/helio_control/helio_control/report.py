"""
The run report: ``helio report RUN_DIR`` / ``make_report(run_dir)``.

Reads a run directory (``runs/<UTC time>/``):

- ``journal.jsonl`` (``helio_control.run_journal``: the goal, one line per dot, the result),
- ``plan.json`` (``helio_control.plan.Plan``: the planned dots and the time estimate),
- ``canvas.png`` and ``dots.csv`` (the simulated world's burnt panel and each charred dot's
  centroid and diameter: ground truth; on real hardware a photograph may stand in for the
  canvas, and without ``dots.csv`` the placement figures are left out),
- ``recording/`` (the rosbag2/MCAP bag: ``thermal/stats`` for T_max and N_p over time,
  ``sun/estimate`` and, in the simulated world, ``sim/truth/sun_direction``),

and writes beside them ``summary.json``, the plots (``thermal.png``, ``dwell.png``,
``placement.png``, ``sun.png``), ``overlay.png`` (targets versus burnt dots, world frame)
and ``report.html``, self-contained (images inlined as data URIs). Without ``canvas.png``
the last ``sim/canvas`` frame of the recording is written as ``canvas.png``.

Per target (``measured_per`` ``target``), when the run directory holds the world's char map
(``canvas_mask.png``, its extent from ``dots.csv``'s header) and ``plan.json``: each burnt
dot is measured at its target in the char map as the painter's camera verdict measures it
(``helio_perception.char_dots``: the char nearest the target, not the connected region, so
dots 2 mm apart that touch are counted and sized one by one), against its expected diameter
(``helio_control.dot_check``); a target without char of at least half of it counts as
without char, the placement error is the char's centroid to the target, the diameters
those of the targets with char. Otherwise (``measured_per`` ``connected region``): each
burnt dot's target is paired with one charred dot of ``dots.csv`` by a minimum-cost
one-to-one assignment (scipy's ``linear_sum_assignment``) within ``match_radius`` (2 dot
pitches by default); a target with no charred dot inside it counts as missing. Diameter
coefficient of variation: standard deviation / mean of those diameters. The painter's own
evidence, the RGB camera's verdict per dot (the journal's ``verdict``), is counted beside
it (``dots_verified_by_camera``, ``camera_diameter_*``). Painting time: the result's
duration (the graph's clock: simulated seconds in simulation) less the dot-size test row's
(the journal's ``dot_calibration_s``, ``dot_calibration_time_s``: it is burnt before the plan
is made, so the plan cannot estimate it); the plan's estimate is compared with it as
(estimate - actual) / actual.

Pure Python (numpy, OpenCV, matplotlib with the Agg backend, the bag reader): no rclpy
graph is needed, the bag's messages are decoded with the installed message classes.
"""

import base64
from dataclasses import dataclass
import html
import json
import math
import os

import re

import cv2
from helio_control.bag_files import BagError, decode_messages, read_topics, recover_bag
from helio_control.dot_check import expected_dot
from helio_control.run_journal import read_journal
from helio_optics.node_kit import topics
from helio_perception.char_dots import measure_in_mask
import numpy as np

PLOTS = ('overlay.png', 'thermal.png', 'dwell.png', 'placement.png', 'sun.png')


class ReportError(ValueError):
    """A run directory the report cannot read."""


@dataclass
class Report:
    """What make_report wrote."""

    run_dir: str
    summary: dict
    html_path: str
    images: dict          # name -> path


def read_dots_csv(path):
    """Return the charred dots of a dots.csv as an N x 4 array (x, y, diameter, area) [m]."""
    rows = []
    with open(path, encoding='utf-8') as stream:
        for line in stream:
            line = line.strip()
            if not line or line.startswith('#') or line.startswith('x_m'):
                continue
            try:
                rows.append([float(v) for v in line.split(',')[:4]])
            except ValueError:
                raise ReportError(f'{path}: not a dots.csv row: {line!r}') from None
    return np.asarray(rows, float).reshape(-1, 4)


# dots.csv's header: the extent and pixel of canvas.png and canvas_mask.png
EXTENT = re.compile(r'span x (-?[0-9.]+)\.\.(-?[0-9.]+) m, y (-?[0-9.]+)\.\.(-?[0-9.]+) m, '
                    r'([0-9.]+) m/px')


def read_char_map(run_dir):
    """
    Return (charred mask, rows from y_min; origin (x, y) [m]; cell [m]) of a run, or None.

    From the world's ``canvas_mask.png`` (255 bare, 0 charred, row 0 at y_max) and the
    extent in ``dots.csv``'s header; None when either is missing.
    """
    mask_path, csv_path = (os.path.join(run_dir, name) for name in ('canvas_mask.png',
                                                                    'dots.csv'))
    if not (os.path.isfile(mask_path) and os.path.isfile(csv_path)):
        return None
    with open(csv_path, encoding='utf-8') as stream:
        found = EXTENT.search(stream.readline())
    mask = cv2.imread(mask_path, cv2.IMREAD_GRAYSCALE)
    if found is None or mask is None:
        return None
    x_min, _, y_min, _, cell = (float(v) for v in found.groups())
    return np.flipud(mask) <= 127, (x_min, y_min), cell


def measure_targets(char_map, plan, dots):
    """Return per journal dot its ``char_dots.DotMeasure`` in the char map (see the module)."""
    charred, origin, cell = char_map
    measures = []
    for dot in dots:
        expected, neighbours = expected_dot(plan, dot.index)
        measures.append(measure_in_mask(charred, origin, cell, dot.target, expected,
                                        neighbours))
    return measures


def match_targets(targets, dots, match_radius):
    """
    Pair targets with charred dots one to one (minimum total distance); return pairs.

    Returns a list, per target, of (index into `dots` or None, distance [m] or nan).
    """
    from scipy.optimize import linear_sum_assignment
    targets = np.asarray(targets, float).reshape(-1, 2)
    dots = np.asarray(dots, float).reshape(-1, 2)
    pairs = [(None, math.nan)] * len(targets)
    if len(targets) == 0 or len(dots) == 0:
        return pairs
    distance = np.linalg.norm(targets[:, None, :] - dots[None, :, :], axis=2)
    cost = np.where(distance <= match_radius, distance, 1e3 + distance)
    rows, columns = linear_sum_assignment(cost)
    for row, column in zip(rows, columns):
        if distance[row, column] <= match_radius:
            pairs[row] = (int(column), float(distance[row, column]))
    return pairs


def recording_series(bag):
    """Return the time series the report plots from a bag: thermal, sun estimates, truth."""
    series = {'thermal': [], 'sun': [], 'truth': [], 'canvas': None}
    try:
        recover_bag(bag)
        recorded = read_topics(bag)
    except (BagError, OSError) as error:
        raise ReportError(f'recording {bag}: {error}') from None

    def find(suffix):
        return [name for name in recorded if name.rstrip('/').endswith(suffix)]
    wanted = (find(topics.THERMAL_STATS) + find(topics.SUN_ESTIMATE)
              + find('sim/truth/sun_direction') + find(topics.SIM_CANVAS))
    for topic, log_time, message in decode_messages(bag, wanted):
        t = log_time * 1e-9
        if topic.endswith(topics.THERMAL_STATS):
            series['thermal'].append((t, message.t_max, message.n_p))
        elif topic.endswith(topics.SUN_ESTIMATE):
            d = message.direction
            series['sun'].append((t, d.x, d.y, d.z, message.elevation, message.azimuth))
        elif topic.endswith('sim/truth/sun_direction'):
            v = message.vector
            series['truth'].append((t, v.x, v.y, v.z))
        elif topic.endswith(topics.SIM_CANVAS):
            series['canvas'] = message
    return series


def _figure():
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    return plt


def _save(plt, figure, path):
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)
    return path


def _angle_deg(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    cosine = np.sum(a * b, axis=-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def plot_thermal(series, dots, path):
    """Plot T_max and N_p over time (recording; else the journal's per-dot peaks)."""
    plt = _figure()
    figure, left = plt.subplots(figsize=(8, 3.5))
    if series['thermal']:
        data = np.asarray(series['thermal'], float)
        t = data[:, 0] - data[0, 0]
        left.plot(t, data[:, 1], color='tab:red', lw=0.8, label='T_max')
        right = left.twinx()
        right.plot(t, data[:, 2], color='tab:blue', lw=0.8, label='N_p')
        right.set_ylabel('N_p [pixels]', color='tab:blue')
        left.set_xlabel('time since the recording began [s]')
    elif dots:
        left.plot([d.index for d in dots], [d.t_max for d in dots], 'o', color='tab:red')
        right = left.twinx()
        right.plot([d.index for d in dots], [d.peak_n_p for d in dots], 's', color='tab:blue')
        right.set_ylabel('peak N_p [pixels]', color='tab:blue')
        left.set_xlabel('dot (no recording: per-dot peaks from the journal)')
    left.set_ylabel('T_max [degC]', color='tab:red')
    left.set_title('Thermal camera: T_max and N_p')
    return _save(plt, figure, path)


def plot_dwell(dots, path):
    """Plot the heating time per dot."""
    plt = _figure()
    figure, axes = plt.subplots(figsize=(8, 3))
    colours = {'burnt': 'tab:orange', 'skipped': 'tab:gray', 'failed': 'tab:red'}
    axes.bar([d.index for d in dots], [d.dwell for d in dots],
             color=[colours[d.outcome] for d in dots])
    axes.set_xlabel('dot')
    axes.set_ylabel('dwell (heating) [s]')
    axes.set_title('Dwell per dot (orange burnt, grey skipped, red failed)')
    return _save(plt, figure, path)


def plot_placement(indices, errors, path):
    """Plot the placement error per dot [mm]."""
    plt = _figure()
    figure, axes = plt.subplots(figsize=(8, 3))
    errors = np.asarray(errors, float) * 1e3
    axes.bar(indices, np.nan_to_num(errors, nan=0.0), color='tab:green')
    missing = [i for i, e in zip(indices, errors) if not math.isfinite(e)]
    if missing:
        axes.plot(missing, [0.0] * len(missing), 'rx', label='no charred dot')
        axes.legend()
    axes.set_xlabel('dot')
    axes.set_ylabel('placement error [mm]')
    finite = errors[np.isfinite(errors)]
    mean = f'{np.mean(finite):.2f} mm' if len(finite) else 'n/a'
    axes.set_title(f'Placement error per dot (mean {mean})')
    return _save(plt, figure, path)


def plot_sun(series, path):
    """Plot the sun estimate over time and its error against the truth."""
    plt = _figure()
    figure, (top, bottom) = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    start = min([s[0] for s in series['sun'][:1] + series['truth'][:1]], default=0.0)
    if series['sun']:
        data = np.asarray(series['sun'], float)
        top.plot(data[:, 0] - start, np.degrees(data[:, 4]), '.-', label='elevation (pysolar '
                 'at the estimate)')
        top.plot(data[:, 0] - start, np.degrees(data[:, 5]) - 180.0, '.-',
                 label='azimuth - 180')
        top.legend(fontsize=8)
        if series['truth']:
            truth = np.asarray(series['truth'], float)
            nearest = np.abs(truth[:, 0][None, :] - data[:, 0][:, None]).argmin(axis=1)
            error = _angle_deg(data[:, 1:4], truth[nearest, 1:4])
            bottom.plot(data[:, 0] - start, error, '.-', color='tab:purple')
            bottom.set_ylabel('error vs true sun [deg]')
    else:
        top.text(0.5, 0.5, 'no sun estimate in the recording', ha='center',
                 transform=top.transAxes)
    top.set_ylabel('[deg]')
    top.set_title('Sun estimate over time')
    bottom.set_xlabel('time since the recording began [s]')
    return _save(plt, figure, path)


def plot_overlay(targets, outcomes, charred, pairs, path, canvas_extent=None, pitch=0.002):
    """Plot targets (circles) versus charred dots (filled, true size), world frame."""
    plt = _figure()
    figure, axes = plt.subplots(figsize=(6, 6))
    for x, y, diameter, _ in charred:
        axes.add_patch(plt.Circle((x * 1e3, y * 1e3), diameter * 1e3 / 2, color='0.15'))
    targets = np.asarray(targets, float).reshape(-1, 2)
    colours = {'burnt': 'tab:orange', 'skipped': 'tab:gray', 'failed': 'tab:red'}
    for (x, y), outcome in zip(targets, outcomes):     # a target: a circle one pitch wide
        axes.add_patch(plt.Circle((x * 1e3, y * 1e3), pitch * 1e3 / 2, fill=False,
                                  edgecolor=colours.get(outcome, 'tab:blue'), linewidth=1.2))
    for (x, y), (match, _) in zip(targets, pairs):
        if match is not None:
            axes.plot([x * 1e3, charred[match][0] * 1e3], [y * 1e3, charred[match][1] * 1e3],
                      color='tab:green', lw=0.8)
    if canvas_extent is not None:      # (x0, y0, side) [m]: the canvas the plan used
        x0, y0, side = canvas_extent
        axes.add_patch(plt.Rectangle((x0 * 1e3, y0 * 1e3), side * 1e3, side * 1e3, fill=False,
                                     edgecolor='0.6', linestyle='--'))
    points = np.vstack([targets, charred[:, :2]]) if len(charred) else targets
    if canvas_extent is not None:
        corner = np.asarray(canvas_extent[:2], float)
        points = np.vstack([points, corner, corner + canvas_extent[2]])
    if len(points):
        low, high = points.min(axis=0) * 1e3 - 3.0, points.max(axis=0) * 1e3 + 3.0
        half = 0.5 * max(high - low)
        centre = 0.5 * (low + high)
        axes.set_xlim(centre[0] - half, centre[0] + half)
        axes.set_ylim(centre[1] - half, centre[1] + half)
    axes.set_aspect('equal')
    axes.set_xlabel('world x [mm]')
    axes.set_ylabel('world y [mm]')
    axes.set_title('Targets (circles) vs burnt dots (black, true size)')
    return _save(plt, figure, path)


def _image_tag(path, title):
    with open(path, 'rb') as stream:
        data = base64.b64encode(stream.read()).decode('ascii')
    return (f'<figure><img alt="{html.escape(title)}" src="data:image/png;base64,{data}">'
            f'<figcaption>{html.escape(title)}</figcaption></figure>')


def write_html(path, summary, images):
    """Write the self-contained report.html."""
    rows = ''.join(f'<tr><th>{html.escape(str(k))}</th><td>{html.escape(_format(v))}</td></tr>'
                   for k, v in summary.items() if not isinstance(v, (dict, list)))
    figures = ''.join(_image_tag(p, title) for title, p in images.items())
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>helio run {html.escape(
        summary.get('run', ''))}</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:70em}}
table{{border-collapse:collapse}}th,td{{border:1px solid #ccc;padding:2px 8px;text-align:left}}
figure{{display:inline-block;margin:1em}}img{{max-width:100%;border:1px solid #ddd}}</style>
</head><body><h1>helio run {html.escape(summary.get('run', ''))}</h1>
<p>{html.escape(summary.get('message', ''))}</p>
<table>{rows}</table>{figures}</body></html>
"""
    with open(path, 'w', encoding='utf-8') as stream:
        stream.write(page)
    return path


def _format(value):
    if isinstance(value, float):
        return f'{value:.6g}'
    return str(value)


def _finite_or_none(value):
    return float(value) if value is not None and math.isfinite(value) else None


def camera_figures(dots):
    """Return the summary's figures of the painter's own RGB verdicts (journal ``verdict``)."""
    seen = [d.measured_diameter for d in dots if d.verdict == 'charred']
    return {
        'dots_verified_by_camera': len(seen),
        'dots_camera_not_charred': sum(d.verdict == 'not charred' for d in dots),
        'dots_not_verified': sum(d.outcome != 'skipped' and not d.verdict for d in dots),
        'camera_diameter_mean_m': float(np.mean(seen)) if seen else None,
        'camera_diameter_cv': float(np.std(seen) / np.mean(seen)) if len(seen) > 1 else None,
    }


def make_report(run_dir, match_radius=None):
    """Write the report of `run_dir` (see the module docstring); return a Report."""
    if not os.path.isdir(run_dir):
        raise ReportError(f'no run directory {run_dir}')
    journal_path = os.path.join(run_dir, 'journal.jsonl')
    if not os.path.isfile(journal_path):
        raise ReportError(f'{run_dir} has no journal.jsonl: not a run directory')
    journal = read_journal(journal_path)
    plan = None
    plan_path = os.path.join(run_dir, 'plan.json')
    if os.path.isfile(plan_path):
        from helio_control.plan import Plan
        with open(plan_path, encoding='utf-8') as stream:
            plan = Plan.from_json(stream.read())
    series = {'thermal': [], 'sun': [], 'truth': [], 'canvas': None}
    bag = os.path.join(run_dir, 'recording')
    if os.path.isdir(bag):
        series = recording_series(bag)
    canvas_path = os.path.join(run_dir, 'canvas.png')
    if not os.path.isfile(canvas_path) and series['canvas'] is not None:
        from helio_optics.node_kit.conversions import image_to_numpy
        cv2.imwrite(canvas_path, image_to_numpy(series['canvas']))
    dots = journal.dots
    targets = [d.target for d in dots]
    pitch = float((plan.parameters.get('dot_radius') if plan else None) or 0.002)
    match_radius = match_radius or 2.0 * pitch
    dots_csv = os.path.join(run_dir, 'dots.csv')
    charred = read_dots_csv(dots_csv) if os.path.isfile(dots_csv) else np.zeros((0, 4))
    burnt = [i for i, d in enumerate(dots) if d.outcome == 'burnt']
    pairs = [(None, math.nan)] * len(dots)
    char_map = read_char_map(run_dir) if plan is not None else None
    components = len(charred)
    if char_map is not None:        # per target: each its char, centroid and diameter
        measures = measure_targets(char_map, plan, [dots[i] for i in burnt])
        rows = []
        for i, measure in zip(burnt, measures):
            if measure.diameter > 0.0:
                pairs[i] = (len(rows), measure.offset) if measure.charred else (None, math.nan)
                rows.append([*measure.centre, measure.diameter,
                             math.pi * measure.diameter ** 2 / 4.0])
        charred = np.asarray(rows, float).reshape(-1, 4)
    elif len(charred):
        matched = match_targets([targets[i] for i in burnt], charred[:, :2], match_radius)
        for i, pair in zip(burnt, matched):
            pairs[i] = pair
    errors = [pairs[i][1] for i in burnt]
    finite_errors = [e for e in errors if math.isfinite(e)]
    diameters = [charred[pairs[i][0], 2] for i in burnt if pairs[i][0] is not None]
    result = journal.result
    actual = result.duration if result else (
        (dots[-1].end - journal.run.started) if dots and journal.run else None)
    row_time = journal.run.dot_calibration_s if journal.run else 0.0
    if actual is not None:
        actual -= row_time            # the test row is burnt before the plan: not estimated
    estimate = float(plan.time_estimate.get('total_s')) if plan else None
    summary = {
        'run': os.path.basename(os.path.normpath(run_dir)),
        'message': result.message if result else 'no result line: the run did not finish',
        'success': bool(result.success) if result else False,
        'dots_planned': len(plan) if plan is not None else len(dots),
        'dots_burnt': sum(d.outcome == 'burnt' for d in dots),
        'dots_skipped': sum(d.outcome == 'skipped' for d in dots),
        'dots_failed': sum(d.outcome == 'failed' for d in dots),
        'measured_per': 'target' if char_map is not None else 'connected region',
        'charred_dots_seen': int(components) if os.path.isfile(dots_csv) else None,
        'dots_without_char': sum(pairs[i][0] is None for i in burnt)
        if len(charred) or char_map is not None else None,
        'mean_placement_error_m': _finite_or_none(np.mean(finite_errors))
        if finite_errors else None,
        'max_placement_error_m': _finite_or_none(max(finite_errors)) if finite_errors else None,
        'diameter_mean_m': _finite_or_none(np.mean(diameters)) if diameters else None,
        'diameter_cv': _finite_or_none(np.std(diameters) / np.mean(diameters))
        if len(diameters) > 1 else None,
        'painting_time_s': _finite_or_none(actual) if actual is not None else None,
        'dot_calibration_time_s': _finite_or_none(row_time),
        'wall_time_s': _finite_or_none(result.wall_duration) if result else None,
        'plan_estimate_s': estimate,
        'estimate_error_ratio': _finite_or_none((estimate - actual) / actual)
        if estimate is not None and actual else None,
        'mean_dwell_s': _finite_or_none(np.mean([d.dwell for d in dots if d.outcome ==
                                                 'burnt'])) if burnt else None,
        'journal_truncated': journal.truncated,
    }
    summary.update(camera_figures(dots))
    if series['sun'] and series['truth']:
        data = np.asarray(series['sun'], float)
        truth = np.asarray(series['truth'], float)
        nearest = np.abs(truth[:, 0][None, :] - data[:, 0][:, None]).argmin(axis=1)
        summary['final_sun_error_deg'] = float(_angle_deg(data[-1, 1:4],
                                                          truth[nearest[-1], 1:4]))
    with open(os.path.join(run_dir, 'summary.json'), 'w', encoding='utf-8') as stream:
        json.dump(summary, stream, indent=2)
        stream.write('\n')
    images = {}
    if os.path.isfile(canvas_path):
        images['The burnt panel (canvas.png)'] = canvas_path
    extent = None
    if plan is not None and plan.parameters.get('canvas_size'):
        p = plan.parameters
        extent = (p['offset_x'] - pitch / 2, p['offset_y'] - pitch / 2, p['canvas_size'])
    images['Targets versus burnt dots'] = plot_overlay(
        targets, [d.outcome for d in dots], charred, pairs,
        os.path.join(run_dir, 'overlay.png'), extent, pitch)
    images['T_max and N_p over time'] = plot_thermal(series, dots,
                                                     os.path.join(run_dir, 'thermal.png'))
    images['Dwell per dot'] = plot_dwell(dots, os.path.join(run_dir, 'dwell.png'))
    if len(charred):
        images['Placement error per dot'] = plot_placement(
            [dots[i].index for i in burnt], errors, os.path.join(run_dir, 'placement.png'))
    images['Sun estimate over time'] = plot_sun(series, os.path.join(run_dir, 'sun.png'))
    html_path = write_html(os.path.join(run_dir, 'report.html'), summary, images)
    return Report(run_dir, summary, html_path, images)
