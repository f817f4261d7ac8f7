"""
Benchmark: paint the sample word on drawn builds, with and without the rig calibration.

``python -m helio_control.bench_build --seeds N [--scale S] [--out DIR] [--json PATH]``

For each seed the simulated world is built as a real rig is (``sim_world`` ``build:=drawn``,
``build_seed``, ``build_scale``: sim/build.py), and ``helio paint sample:text`` paints the
word through the whole graph twice: once with the painter's rig calibration
(``calibrate_rig: missing``: the graph starts with none, so it calibrates) and once without
(``never``: the rig file and the robot-world calibration only, as before issue 28). Each run
has its own calibration directory, so nothing saved leaks from one build to the next.

Per run it prints whether the word was painted (or why not), the placement of the burnt dots
against the plan (the world's ``dots.csv`` against ``plan.json``: mean and 95th percentile,
paired one to one as the run report pairs them), the sun error (the report's
``final_sun_error_deg``), the rig calibration's residuals and the rig time it took (the lens
planner's log). The machine has 2 shared cores: run nothing else heavy beside it. A run
takes 4-10 minutes of wall time.
"""

import argparse
import json
import math
import os
import re
import subprocess
import sys
import time

from helio_control.report import match_targets, read_dots_csv
import numpy as np

CALIBRATED = re.compile(r'rig calibrated from (\d+) marker views and (\d+) spots in ([\d.]+) s: '
                        r'camera chain rms ([\d.]+) mm, ([\d.]+) deg; spots rms ([\d.]+) mm')


def placement(run_dir, match_radius=0.01):
    """
    Return each planned dot's distance [m] to its charred dot (NaN: none within the radius).

    Planned dots (``plan.json``) and the world's charred dots (``dots.csv``) are paired one
    to one at the least total distance (``report.match_targets``, as the run report does,
    within `match_radius`: a word shifted by more than half the pitch pairs dots with their
    neighbours, so a large error reads smaller than it is).
    """
    with open(os.path.join(run_dir, 'plan.json')) as stream:
        targets = np.asarray(json.load(stream)['dots_m'], dtype=float).reshape(-1, 2)
    charred = read_dots_csv(os.path.join(run_dir, 'dots.csv'))
    return np.array([distance for _, distance in
                     match_targets(targets, charred[:, :2], match_radius)])


def calibration_of(run_dir):
    """Return the rig calibration's figures from the lens planner's log (None: none ran)."""
    try:
        with open(os.path.join(run_dir, 'logs', 'lens_planner.log')) as stream:
            text = stream.read()
    except OSError:
        return None
    found = CALIBRATED.findall(text)
    if not found:
        return None
    views, spots, seconds, position, angle, spot = found[-1]
    return {'views': int(views), 'spots': int(spots), 'rig_time_s': float(seconds),
            'residual_position_mm': float(position), 'residual_angle_deg': float(angle),
            'spot_residual_mm': float(spot)}


def paint(run_dir, seed, scale, calibrate, real_time_factor, timeout):
    """Paint the sample word in the drawn world of `seed`; return the run's figures."""
    started = time.monotonic()
    command = [sys.executable, '-m', 'helio_control', 'paint', 'sample:text', '--dot-radius',
               '0.003', '--sim', '--out', run_dir, '--real-time-factor',
               str(real_time_factor),
               '--set', 'sim_world.build=drawn', '--set', f'sim_world.build_seed={seed}',
               '--set', f'sim_world.build_scale={scale}',
               '--set', f'painter.calibrate_rig={"missing" if calibrate else "never"}']
    done = subprocess.run(command, capture_output=True, text=True, timeout=timeout)
    figures = {'seed': seed, 'calibrated': calibrate, 'wall_s': time.monotonic() - started,
               'exit': done.returncode}
    summary_path = os.path.join(run_dir, 'summary.json')
    if os.path.exists(summary_path):
        with open(summary_path) as stream:
            summary = json.load(stream)
        figures.update(painted=bool(summary.get('success')), message=summary.get('message'),
                       dots_burnt=summary.get('dots_burnt'),
                       dots_planned=summary.get('dots_planned'),
                       sun_error_deg=summary.get('final_sun_error_deg'))
    else:
        lines = [line for line in done.stderr.splitlines() if line.startswith('[helio]')]
        figures.update(painted=False, message=lines[-1] if lines else done.stderr[-300:])
    if os.path.exists(os.path.join(run_dir, 'dots.csv')) and \
            os.path.exists(os.path.join(run_dir, 'plan.json')):
        errors = placement(run_dir)
        finite = errors[np.isfinite(errors)]
        figures.update(placement_mean_mm=float(np.mean(finite) * 1e3) if finite.size else None,
                       placement_p95_mm=float(np.percentile(finite, 95) * 1e3)
                       if finite.size else None)
    figures['calibration'] = calibration_of(run_dir)
    return figures


def row(figures):
    """Return one printed line of a run."""
    def number(name, digits=2):
        value = figures.get(name)
        return '-' if value is None or not math.isfinite(value) else f'{value:.{digits}f}'

    calibration = figures.get('calibration') or {}
    what = 'painted' if figures.get('painted') else 'NOT painted'
    return (f"seed {figures['seed']:3d}  {'with' if figures['calibrated'] else 'without':7s} "
            f"{what:11s} placement mean {number('placement_mean_mm')} mm, "
            f"p95 {number('placement_p95_mm')} mm; sun {number('sun_error_deg', 3)} deg; "
            f"calibration {calibration.get('residual_position_mm', '-')} mm / "
            f"{calibration.get('residual_angle_deg', '-')} deg / spots "
            f"{calibration.get('spot_residual_mm', '-')} mm in "
            f"{calibration.get('rig_time_s', '-')} s rig time"
            + ('' if figures.get('painted') else f"  ({figures.get('message')})"))


def main(args=None):
    """Run the benchmark (see the module docstring)."""
    parser = argparse.ArgumentParser(prog='python -m helio_control.bench_build',
                                     description=__doc__.strip().splitlines()[0])
    parser.add_argument('--seeds', type=int, default=10, help='drawn builds to paint on')
    parser.add_argument('--first-seed', type=int, default=0)
    parser.add_argument('--scale', type=float, default=1.0,
                        help="the builds' tolerances over a 3D-printed rig's (1/3: careful)")
    parser.add_argument('--only', choices=('with', 'without'),
                        help='paint only with or only without the rig calibration')
    parser.add_argument('--real-time-factor', type=float, default=6.0)
    parser.add_argument('--timeout', type=float, default=1800.0, help='per painting [s]')
    parser.add_argument('--out', default='runs/bench_build', help='run directories')
    parser.add_argument('--json', help="write every run's figures here")
    arguments = parser.parse_args(args)
    modes = [True, False] if arguments.only is None else [arguments.only == 'with']
    results = []
    for seed in range(arguments.first_seed, arguments.first_seed + arguments.seeds):
        for calibrate in modes:
            run_dir = os.path.abspath(os.path.join(
                arguments.out, f'seed{seed}_{"with" if calibrate else "without"}'))
            figures = paint(run_dir, seed, arguments.scale, calibrate,
                            arguments.real_time_factor, arguments.timeout)
            results.append(figures)
            print(row(figures), flush=True)
            if arguments.json:
                with open(arguments.json, 'w') as stream:
                    json.dump({'scale': arguments.scale, 'runs': results}, stream, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
