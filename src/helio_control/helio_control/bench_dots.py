"""
Benchmark: dots burnt as wide as asked under each thermal camera, and the camera's verdicts.

``python -m helio_control.bench_dots [--profiles P,...] [--diameters MM,...] [--failures]
[--out DIR] [--json PATH] [--set NODE.PARAM=VALUE ...]``

What issue 29's "Done when" asks, measured in the simulated world. Per thermal profile
(``helio_optics.thermal_cameras``: ``paper``, ``lepton35_high_gain``, ``lepton35_low_gain``;
the Lepton's flat-field freezes included, every 180 s) and requested diameter (1.5, 2.0 and
2.5 mm by default), ``helio paint sample:text --sim --fresh`` paints the word once with the
world's ``thermal_profile`` and the thermal monitor's ``camera_profile`` set to the profile
and the painter's ``calibrate_dots: always`` (a dot-size calibration row first, so the
goal's ``dot_radius`` is both the pitch and each burnt dot's requested width). The user's
``--set`` go last and win (e.g. ``painter.calibrate_dots=never`` for a quick look).

Per run, from the run directory (the run report's ``summary.json``, ``journal.jsonl``,
``plan.json`` and the world's char map ``canvas_mask.png`` with ``dots.csv``): the dots
charred in the world against the dots planned, the mean burnt diameter (the report's,
measured per target in the char map) and its error against the requested diameter, the
diameter CV, the plan's time estimate against the painting's time, and a judgement against
the issue's bounds (every planned dot charred, |mean error| <= 10 %, CV <= 10 %,
|estimate error| <= 10 %). The issue asks the estimate at 2 and 3 mm pitch: it is judged
where the requested diameter (the pitch) is one of them, and printed "(not judged)" at
others.

**Verdict agreement**: each journal dot's RGB-camera verdict (``verdict``: ``charred`` or
``not charred``) against the world's. The world's truth per target is the run report's
measure (``report.read_char_map`` and ``report.measure_targets``: the char of the char map
nearest the target within its cell, ``helio_perception.char_dots.measure_in_mask``, against
the plan's expected diameter, ``dot_check.expected_dot``), judged by the painter's own rule
(``char_dots._judged``): **charred when the char at the target is at least
``verify.min_diameter_ratio`` (0.5, or the painter's ``--set``) x the expected diameter and
its centroid within ``max_offset_ratio`` (0.5) x the expected diameter of the target**. The
agreement is the share of the dots with a verdict whose verdict equals the world's; dots
without one (not verified, a dry run, nothing heated) are counted apart, never as agreeing.
The issue asks for at least 98 %.

With ``--failures`` (or ``--only-failures``) two more paintings of a few ``--points`` with
the paper profile make dots fail on purpose: a complete cloud (attenuation 0) starting in
the middle of the painting (``sim_world.cloud_schedule``, ``--cloud START,END`` simulated
seconds since the world's start, repeatable; the line says which dot each began in, read
back from the journal), and dots heated too briefly (``painter.max_heating``
``--brief-heating`` s, default 1, the painter's least: given up, then looked at; at 2 s the
paper's camera already charred 1.2 mm dots, at 1 s none). Their agreement is printed, and the
agreement over every dot of every run.

One line per run, a summary at the end; ``--json`` is rewritten after each run, so a crash
keeps what was measured. The machine has 2 shared cores: run nothing heavy beside it. A
word takes several minutes of wall time per run at ``--real-time-factor 0`` (as fast as the
graph keeps up).
"""

import argparse
import datetime
import json
import math
import os
import re
import signal
import subprocess
import sys
import time

from helio_control.painter_parameters import MAX_HEATING_RANGE_S
from helio_control.plan import Plan
from helio_control.report import measure_targets, read_char_map
from helio_control.run_journal import read_journal

PROFILES = ('paper', 'lepton35_high_gain', 'lepton35_low_gain')
DIAMETERS_MM = (1.5, 2.0, 2.5)
BOUNDS = {'diameter_error': 0.10, 'diameter_cv': 0.10, 'estimate_error': 0.10,
          'agreement': 0.98}
# the issue judges the time estimate at these pitches [mm] (dots touching, and the demo's);
# at others it is printed, not judged
ESTIMATE_PITCHES_MM = (2.0, 3.0)
MIN_DIAMETER_RATIO = 0.5     # the painter's verify.min_diameter_ratio (default)
MAX_OFFSET_RATIO = 0.5       # char_dots.CharSettings.max_offset_ratio (the painter's)
# the deliberate failures: a few dots 4 mm apart inside the default canvas (0.05-0.13 m)
FAILURE_POINTS = tuple((0.080 + 0.004 * i, 0.090) for i in range(6))
BRIEF_POINTS = tuple((0.080 + 0.004 * i, 0.100) for i in range(3))
# complete clouds (start_s, end_s) since the world's start. In a run of the sample word
# (2026-11-28) the first dot began 105 s after the world's start (the sun sweep and the world
# calibration before it: a cloud there may stop the painting) and a dot took 16-23 s, 11-17 s
# of it heating; three clouds 35 s apart from 150 s, so that one at least lands in a heating
# (where each began: read back from the journal and printed)
CLOUDS = ((150.0, 160.0), (185.0, 195.0), (220.0, 230.0))
SUMMARY_FIELDS = ('success', 'message', 'dots_planned', 'dots_burnt', 'dots_failed',
                  'measured_per', 'charred_dots_seen', 'dots_without_char', 'diameter_mean_m',
                  'diameter_cv', 'painting_time_s', 'plan_estimate_s', 'estimate_error_ratio',
                  'mean_dwell_s', 'dots_verified_by_camera', 'dots_camera_not_charred',
                  'dot_calibration_time_s', 'wall_time_s')
SLACK = 1e-9                 # a figure at a bound passes


def numbers(text, kind=float):
    """Return the comma list `text` as values of `kind` (argparse type)."""
    try:
        values = [kind(item) for item in text.split(',') if item.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a comma list of numbers: {text!r}') from None
    if not values:
        raise argparse.ArgumentTypeError('an empty list')
    return values


def diameters_m(text):
    """Return the comma list of diameters `text` [mm] in metres (each > 0)."""
    values = numbers(text)
    if not all(value > 0.0 and math.isfinite(value) for value in values):
        raise argparse.ArgumentTypeError(f'diameters must be > 0 mm: {text!r}')
    return [value * 1e-3 for value in values]


def profiles(text):
    """Return the comma list of thermal profiles `text` (each a known one)."""
    names = [name.strip() for name in text.split(',') if name.strip()]
    unknown = [name for name in names if name not in PROFILES]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f'unknown thermal profile(s) {unknown or text!r} '
                                         f'(known: {", ".join(PROFILES)})')
    return names


def brief_heating(text):
    """Return the failures' max_heating `text` [s], within the painter's range."""
    low, high = MAX_HEATING_RANGE_S
    value = numbers(text)
    if len(value) != 1 or not low <= value[0] <= high:
        raise argparse.ArgumentTypeError(f'--brief-heating takes one value of {low:g}-{high:g} '
                                         f"s (the painter's max_heating), not {text!r}")
    return value[0]


def cloud(text):
    """Return the cloud ``START,END`` [s since the world's start] as a (start, end) pair."""
    values = numbers(text)
    if len(values) != 2 or not 0.0 <= values[0] < values[1]:
        raise argparse.ArgumentTypeError(f'--cloud takes START,END with 0 <= START < END, '
                                         f'not {text!r}')
    return tuple(values)


def parse_arguments(args=None):
    """Return the parsed command line (see the module docstring)."""
    parser = argparse.ArgumentParser(prog='python -m helio_control.bench_dots',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--profiles', type=profiles, default=list(PROFILES),
                        help='thermal profiles, comma list (default: all three)')
    parser.add_argument('--diameters', type=diameters_m,
                        default=[d * 1e-3 for d in DIAMETERS_MM],
                        help='requested dot diameters [mm], comma list (default 1.5,2.0,2.5)')
    parser.add_argument('--real-time-factor', type=float, default=0.0,
                        help='of the simulated world (0: as fast as the graph keeps up)')
    parser.add_argument('--timeout', type=float, default=3600.0, help='per painting [s]')
    parser.add_argument('--out', default='runs/bench_dots', help='run directories')
    parser.add_argument('--json', help="write every run's figures here (after each run)")
    parser.add_argument('--set', action='append', default=[], metavar='NODE.PARAM=VALUE',
                        help="passed on to every painting after the benchmark's own "
                        '(so it wins), e.g. painter.max_heating=150; repeatable')
    parser.add_argument('--failures', action='store_true',
                        help='also paint the deliberate failures (a cloud mid-dot, dots '
                        'heated too briefly)')
    parser.add_argument('--only-failures', action='store_true',
                        help='paint only the deliberate failures')
    parser.add_argument('--cloud', type=cloud, action='append', metavar='START,END',
                        help="a complete cloud of the failures [s since the world's start]; "
                        'repeatable (default: '
                        + ' and '.join(f'{a:g},{b:g}' for a, b in CLOUDS) + ')')
    parser.add_argument('--brief-heating', type=brief_heating, default=MAX_HEATING_RANGE_S[0],
                        help="the failures' painter.max_heating for dots heated too briefly "
                        '[s]')
    # testing the pipeline: paint these points instead of the sample word
    parser.add_argument('--points', nargs='+', metavar='X,Y', help=argparse.SUPPRESS)
    arguments = parser.parse_args(args)
    arguments.cloud = arguments.cloud or list(CLOUDS)
    return arguments


def set_value(sets, name, default=None):
    """Return the value of the last ``NAME=VALUE`` of `sets` (a YAML scalar), else default."""
    import yaml
    found = default
    for setting in sets or ():
        key, equals, text = setting.partition('=')
        if equals and key.strip() == name:
            found = yaml.safe_load(text)
    return found


def paint_command(run_dir, picture, points, dot_radius, real_time_factor, sets):
    """Return the ``helio paint`` command line of one painting (`sets`: NODE.PARAM=VALUE)."""
    command = [sys.executable, '-m', 'helio_control', 'paint']
    if picture:
        command.append(picture)
    if points:
        command += ['--points'] + [f'{x:.6f},{y:.6f}' for x, y in points]
    if dot_radius:
        command += ['--dot-radius', f'{dot_radius:.6f}']
    command += ['--sim', '--fresh', '--out', run_dir, '--real-time-factor',
                f'{real_time_factor:g}']
    for setting in sets:
        command += ['--set', setting]
    return command


def profile_sets(profile):
    """Return the ``--set``s that put thermal camera `profile` in the world and the monitor."""
    return [f'sim_world.thermal_profile={profile}', f'thermal_monitor.camera_profile={profile}']


def read_summary(run_dir):
    """Return the run report's ``summary.json`` of `run_dir` (None when there is none)."""
    try:
        with open(os.path.join(run_dir, 'summary.json'), encoding='utf-8') as stream:
            return json.load(stream)
    except (OSError, ValueError):
        return None


def world_truth(run_dir, min_diameter_ratio=MIN_DIAMETER_RATIO,
                max_offset_ratio=MAX_OFFSET_RATIO):
    """
    Return per journal dot its verdict and the world's truth at its target, or None.

    Each a dict: ``index``, ``outcome``, ``verdict`` (the camera's, '' when none),
    ``expected_m`` (the plan's expected diameter), ``world_diameter_m`` (the char measured at
    the target, 0 without), ``world_offset_m`` (its centroid to the target, None without),
    ``world_charred`` (the module's rule). None when the run directory has no journal,
    ``plan.json`` or char map (``canvas_mask.png`` and ``dots.csv``).
    """
    journal_path = os.path.join(run_dir, 'journal.jsonl')
    plan_path = os.path.join(run_dir, 'plan.json')
    if not (os.path.isfile(journal_path) and os.path.isfile(plan_path)):
        return None
    char_map = read_char_map(run_dir)
    if char_map is None:
        return None
    with open(plan_path, encoding='utf-8') as stream:
        plan = Plan.from_json(stream.read())
    dots = read_journal(journal_path).dots
    truths = []
    for dot, measure in zip(dots, measure_targets(char_map, plan, dots)):
        offset = measure.offset if math.isfinite(measure.offset) else None
        charred = (measure.diameter > 0.0 and offset is not None
                   and measure.diameter >= min_diameter_ratio * measure.expected
                   and offset <= max_offset_ratio * measure.expected)
        truths.append({'index': dot.index, 'outcome': dot.outcome, 'verdict': dot.verdict,
                       'verdict_reason': dot.verdict_reason,
                       'camera_diameter_m': dot.measured_diameter,
                       'expected_m': float(measure.expected),
                       'world_diameter_m': float(measure.diameter), 'world_offset_m': offset,
                       'world_charred': bool(charred)})
    return truths


def agreement(truths):
    """
    Return the verdicts' agreement with the world over `truths` (``world_truth``'s dicts).

    ``with_verdict`` dots have the camera's verdict, ``agreeing`` of them the world's,
    ``disagreeing`` lists the others' indices, ``without_verdict`` the dots without one (not
    counted as agreeing); ``agreement`` = agreeing / with_verdict (None without any).
    """
    judged = [t for t in truths if t['verdict'] in ('charred', 'not charred')]
    agreeing = [t for t in judged if (t['verdict'] == 'charred') == t['world_charred']]
    return {'with_verdict': len(judged), 'agreeing': len(agreeing),
            'disagreeing': [t['index'] for t in judged
                            if (t['verdict'] == 'charred') != t['world_charred']],
            'without_verdict': len(truths) - len(judged),
            'agreement': len(agreeing) / len(judged) if judged else None}


def pooled(figures_list):
    """Return the agreement over every dot of the runs' figures (``agreement``'s keys)."""
    with_verdict = sum(f.get('with_verdict') or 0 for f in figures_list)
    agreeing = sum(f.get('agreeing') or 0 for f in figures_list)
    return {'with_verdict': with_verdict, 'agreeing': agreeing,
            'without_verdict': sum(f.get('without_verdict') or 0 for f in figures_list),
            'agreement': agreeing / with_verdict if with_verdict else None}


def judge(figures, requested, bounds=None):
    """
    Return (checks, passed): each of the issue's bounds met (None: not measured).

    `figures` holds ``dots_planned``, ``dots_charred_world``, ``diameter_mean_m``,
    ``diameter_cv`` and ``estimate_error_ratio``; `requested` is the requested diameter
    [m], here also the pitch. Checks: ``all_charred`` (every planned dot charred in the
    world), ``diameter`` (|mean - requested| / requested <= 10 %), ``cv`` (<= 10 %) and, at
    the pitches the issue asks it (``ESTIMATE_PITCHES_MM``), ``estimate`` (|estimate error|
    <= 10 %). Passed only when every check is met; a bound reached exactly is met.
    """
    bounds = {**BOUNDS, **(bounds or {})}

    def within(value, bound):
        return None if value is None or not math.isfinite(value) else \
            abs(value) <= bound + SLACK

    planned, charred = figures.get('dots_planned'), figures.get('dots_charred_world')
    mean = figures.get('diameter_mean_m')
    checks = {
        'all_charred': None if planned is None or charred is None
        else bool(planned > 0 and charred >= planned),
        'diameter': within(None if mean is None else (mean - requested) / requested,
                           bounds['diameter_error']),
        'cv': within(figures.get('diameter_cv'), bounds['diameter_cv']),
    }
    if estimate_judged(requested):
        checks['estimate'] = within(figures.get('estimate_error_ratio'),
                                    bounds['estimate_error'])
    return checks, all(value is True for value in checks.values())


def estimate_judged(pitch):
    """Return whether the issue judges the time estimate at `pitch` [m]."""
    return any(abs(pitch - mm * 1e-3) < 1e-6 for mm in ESTIMATE_PITCHES_MM)


def world_start(sets):
    """Return the simulated world's start as Unix seconds (its ``start_time``)."""
    when = set_value(sets, 'sim_world.start_time')
    if when is None:
        import yaml
        from helio_control.bringup import package_config
        with open(package_config('helio_drivers', 'sim_world.yaml'), encoding='utf-8') as s:
            tree = yaml.safe_load(s)
        when = next(iter(tree.values()))['ros__parameters']['start_time']
    if isinstance(when, datetime.datetime):
        return when.timestamp()
    return datetime.datetime.fromisoformat(str(when)).timestamp()


def cloud_landing(run_dir, start_s, world_start_unix):
    """
    Return where a cloud beginning `start_s` after the world's start fell in the painting.

    A dict: ``dot`` (the journal index of the dot whose cycle, move to end, it began in;
    None when between dots, before the first or after the last), ``into_dot_s`` (seconds
    after that dot's move began), its ``dwell_s``, ``restarts``, ``outcome`` and
    ``verdict``, and ``where`` in words. None without a journal.
    """
    path = os.path.join(run_dir, 'journal.jsonl')
    if not os.path.isfile(path):
        return None
    dots = read_journal(path).dots
    at = world_start_unix + start_s
    for dot in dots:
        if dot.start <= at < dot.end:
            return {'dot': dot.index, 'into_dot_s': at - dot.start, 'dwell_s': dot.dwell,
                    'restarts': dot.restarts, 'outcome': dot.outcome,
                    'verdict': dot.verdict,
                    'where': f'in dot {dot.index}, {at - dot.start:.1f} s after its move '
                    f'began (dwell {dot.dwell:.1f} s, {dot.restarts} restart(s), '
                    f'{dot.outcome}, camera: {dot.verdict or "no verdict"})'}
    if not dots:
        where = 'no dot finished'
    elif at < dots[0].start:
        where = f'{dots[0].start - at:.1f} s before the first dot'
    elif at >= dots[-1].end:
        where = f'{at - dots[-1].end:.1f} s after the last dot'
    else:
        where = 'between dots'
    return {'dot': None, 'where': where}


def measure_run(run_dir, figures, min_diameter_ratio=MIN_DIAMETER_RATIO):
    """Add the run directory's figures to `figures` (a dict; see the module); return it."""
    summary = read_summary(run_dir)
    if summary is not None:
        figures.update({name: summary.get(name) for name in SUMMARY_FIELDS})
        figures['painted'] = bool(summary.get('success'))
    truths = world_truth(run_dir, min_diameter_ratio)
    if truths is not None:
        figures['dots'] = truths
        figures['dots_charred_world'] = sum(t['world_charred'] for t in truths)
        figures.update(agreement(truths))
    requested = figures.get('requested_m')
    mean = figures.get('diameter_mean_m')
    if requested:
        figures['diameter_error_ratio'] = None if mean is None else \
            (mean - requested) / requested
        figures['checks'], figures['passed'] = judge(figures, requested)
    return figures


def set_aside(run_dir):
    """
    Rename an earlier run in `run_dir` to ``<run_dir>.<UTC time>``; return the new name or None.

    A painting that dies before its report would otherwise leave the earlier run's
    ``summary.json`` to be read as its own.
    """
    if not os.path.isdir(run_dir) or not os.listdir(run_dir):
        return None
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime('%Y%m%dT%H%M%SZ')
    aside = f'{run_dir.rstrip(os.sep)}.{stamp}'
    os.rename(run_dir, aside)
    return aside


def paint(run_dir, command, timeout):
    """Run one painting; return its figures (exit, wall time, why not painted)."""
    set_aside(run_dir)
    started = time.monotonic()
    os.makedirs(os.path.dirname(run_dir) or '.', exist_ok=True)
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    try:
        _, stderr = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        # Ctrl-C's path: helio cancels the goal and stops the graph it started (a kill
        # would leave its nodes running)
        process.send_signal(signal.SIGINT)
        try:
            _, stderr = process.communicate(timeout=120.0)
        except subprocess.TimeoutExpired:
            process.kill()
            _, stderr = process.communicate()
        stderr = (stderr or '') + f'\n[helio] timed out after {timeout:g} s'
    exit_code = process.returncode
    figures = {'run_dir': run_dir, 'exit': exit_code, 'wall_s': time.monotonic() - started,
               'painted': False}
    if read_summary(run_dir) is None:
        lines = [line for line in stderr.splitlines() if line.startswith('[helio]')]
        figures['message'] = lines[-1] if lines else stderr[-300:]
        cause = error_in_logs(run_dir)
        if cause:
            figures['message'] += f' ({cause})'
    return figures


def error_in_logs(run_dir):
    """Return the first node log's last exception line ('node: line'), or '' without one."""
    logs = os.path.join(run_dir, 'logs')
    try:
        names = sorted(name for name in os.listdir(logs) if name.endswith('.log'))
    except OSError:
        return ''
    for name in names:
        with open(os.path.join(logs, name), errors='replace') as stream:
            found = [line.strip() for line in stream
                     if re.match(r'^[\w.]+(Error|Exception): ', line.strip())]
        if found:
            return f'{name[:-4]}: {found[-1]}'
    return ''


def _number(value, scale=1.0, digits=2, sign=False):
    if value is None or not math.isfinite(value):
        return '-'
    return f'{value * scale:{"+" if sign else ""}.{digits}f}'


def row(figures):
    """Return one printed line of a run."""
    dots = (f"{figures.get('dots_charred_world', '-')}/{figures.get('dots_planned', '-')} "
            'charred in the world')
    verdicts = (f"verdicts {figures.get('agreeing', '-')}/{figures.get('with_verdict', '-')} "
                f"agree ({figures.get('without_verdict', '-')} without)")
    if figures.get('disagreeing'):
        verdicts += f" disagree at {figures['disagreeing']}"
    what = 'painted' if figures.get('painted') else 'NOT painted'
    head = f"{figures['label']:30s} {what:11s}"
    wall = f"wall {_number(figures.get('wall_s') or figures.get('wall_time_s'), digits=0)} s"
    if figures.get('kind') == 'sized':
        verdict = {True: 'PASS', False: 'FAIL'}[bool(figures.get('passed'))]
        line = (f"{head} {dots}; mean {_number(figures.get('diameter_mean_m'), 1e3)} mm "
                f"({_number(figures.get('diameter_error_ratio'), 100, 1, True)} %), "
                f"CV {_number(figures.get('diameter_cv'), 100, 1)} %, "
                f"estimate {_number(figures.get('estimate_error_ratio'), 100, 1, True)} %"
                + ('' if 'estimate' in (figures.get('checks') or {}) else ' (not judged)')
                + f'; {verdicts}; {wall}  {verdict}')
    else:
        line = f'{head} {dots}; {verdicts}; {wall}'
        for landing in figures.get('clouds') or ():
            line += f"; cloud at {landing['start_s']:g} s: {landing['where']}"
    if not figures.get('painted'):
        line += f"  ({figures.get('message')})"
    return line


def final_summary(results):
    """Return the benchmark's summary: pooled agreements and the runs that passed."""
    sized = [f for f in results if f.get('kind') == 'sized']
    failures = [f for f in results if f.get('kind') != 'sized']
    summary = {'runs_passed': sum(bool(f.get('passed')) for f in sized),
               'runs_sized': len(sized),
               'agreement_sized': pooled(sized)['agreement'],
               'agreement_failures': pooled(failures)['agreement'],
               'agreement_all': pooled(results)['agreement'],
               'dots_with_verdict_all': pooled(results)['with_verdict'],
               'dots_without_verdict_all': pooled(results)['without_verdict']}
    value = summary['agreement_all']
    summary['agreement_passed'] = None if value is None else \
        value >= BOUNDS['agreement'] - SLACK
    return summary


def summary_lines(summary):
    """Return the printed summary."""
    def share(value):
        return '-' if value is None else f'{value * 100:.1f} %'
    return [f"sized runs within the issue's bounds: {summary['runs_passed']} of "
            f"{summary['runs_sized']}",
            f"verdicts agreeing with the world: {share(summary['agreement_all'])} of "
            f"{summary['dots_with_verdict_all']} dots with a verdict (sized runs "
            f"{share(summary['agreement_sized'])}, failures "
            f"{share(summary['agreement_failures'])}; "
            f"{summary['dots_without_verdict_all']} dots without a verdict); at least 98 % "
            f"asked: {'met' if summary['agreement_passed'] else 'NOT met'}"]


def plans(arguments):
    """Return the paintings to run: (label, kind, profile, requested [m], command args)."""
    paintings = []
    if not arguments.only_failures:
        for profile in arguments.profiles:
            for diameter in arguments.diameters:
                sets = (profile_sets(profile) + ['painter.calibrate_dots=always']
                        + list(arguments.set))
                picture = '' if arguments.points else 'sample:text'
                points = [tuple(float(v) for v in point.split(','))
                          for point in arguments.points or ()]
                paintings.append((f'{profile} {diameter * 1e3:.2f} mm', 'sized', profile,
                                  diameter, f'{profile}_{diameter * 1e3:.2f}mm',
                                  (picture, points, diameter, sets)))
    if arguments.failures or arguments.only_failures:
        # floats, each (a ROS double array: YAML reads 140 as an integer)
        schedule = ', '.join(f'{start:.3f}, {end:.3f}, 0.0' for start, end in arguments.cloud)
        sets = profile_sets('paper') + [f'sim_world.cloud_schedule=[{schedule}]']
        paintings.append(('failures: cloud mid-dot', 'cloud', 'paper', None, 'failures_cloud',
                          ('', list(FAILURE_POINTS), 0.0, sets + list(arguments.set))))
        sets = profile_sets('paper') + [f'painter.max_heating={float(arguments.brief_heating)!r}']
        paintings.append(('failures: heated too briefly', 'brief', 'paper', None,
                          'failures_brief',
                          ('', list(BRIEF_POINTS), 0.0, sets + list(arguments.set))))
    return paintings


def main(args=None):
    """Run the benchmark (see the module docstring)."""
    arguments = parse_arguments(args)
    ratio = float(set_value(arguments.set, 'painter.verify.min_diameter_ratio',
                            MIN_DIAMETER_RATIO))
    results = []
    for label, kind, profile, requested, name, (picture, points, radius, sets) in \
            plans(arguments):
        run_dir = os.path.abspath(os.path.join(arguments.out, name))
        command = paint_command(run_dir, picture, points, radius, arguments.real_time_factor,
                                sets)
        figures = {'label': label, 'kind': kind, 'profile': profile, 'requested_m': requested,
                   **paint(run_dir, command, arguments.timeout)}
        measure_run(run_dir, figures, ratio)
        if kind == 'cloud':
            figures['clouds'] = [
                {'start_s': start, 'end_s': end,
                 **(cloud_landing(run_dir, start, world_start(sets))
                    or {'dot': None, 'where': 'no journal'})}
                for start, end in arguments.cloud]
        results.append(figures)
        print(row(figures), flush=True)
        if arguments.json:
            with open(arguments.json, 'w', encoding='utf-8') as stream:
                json.dump({'runs': results, **final_summary(results),
                           'min_diameter_ratio': ratio,
                           'max_offset_ratio': MAX_OFFSET_RATIO}, stream, indent=1)
    for line in summary_lines(final_summary(results)):
        print(line, flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
