"""
What every helio benchmark shares: timing calls, ``--json PATH``, a printed table, flat JSON.

    parser = argparse.ArgumentParser(...)
    add_json_option(parser)
    ...
    return report(figures, args.json)

Figures are a flat dict ``{name_with_unit: number}``, e.g. ``spot_detect_1280x720_ms_median``.
``machine_figures()`` adds two yardsticks of the machine a run was made on (this project's
machines have differed 2-3x in speed from one session to the next, so figures of two runs
compare only through them) and ``machine_description()`` names its processor.
Ints stay ints, numpy scalars become Python numbers, and a non-finite figure (nothing
measured) is printed as ``nan``/``inf`` and written as JSON ``null``, so the file is always
valid JSON. No rclpy import.
"""

import json
import math
import numbers
import os
import platform
import statistics
import sys
import time


def call_durations(call, count, clock=time.perf_counter):
    """
    Return the durations [s] of `count` successive calls of `call()`.

    `clock` is wall time by default; ``time.process_time`` measures this process's CPU time.
    """
    durations = []
    for _ in range(count):
        started = clock()
        call()
        durations.append(clock() - started)
    return durations


def median_call_ms(call, count, clock=time.perf_counter):
    """Return the median duration of `count` calls of `call()` [ms] (`clock`: see above)."""
    return 1e3 * statistics.median(call_durations(call, count, clock))


def machine_description():
    """Return the processor's model name and the cores this process may use, for a report."""
    model = platform.processor() or platform.machine()
    try:
        with open('/proc/cpuinfo') as stream:
            for line in stream:
                if line.startswith('model name'):
                    model = line.split(':', 1)[1].strip()
                    break
    except OSError:
        pass
    return f'{model}, {len(os.sched_getaffinity(0))} cores'


def machine_figures(repeats=5):
    """
    Return yardsticks of this machine's speed, the best of `repeats` runs each.

    ``machine_python_loop_ns``: one turn of a plain Python loop (the interpreter's speed:
    the nodes' glue, rclpy); ``machine_memory_copy_gb_s``: a 64 MiB numpy copy, bytes
    copied per second (the memory's: the simulated world's frames and fields stream
    through it). A figure of another run scales by their ratio only roughly: a benchmark
    mixes both, and the caches.
    """
    import numpy as np

    def loop():
        total = 0
        for k in range(200_000):
            total += k & 7
        return total
    loop_s = min(call_durations(loop, repeats))
    source = np.ones(64 << 20, np.uint8)
    target = np.empty_like(source)
    np.copyto(target, source)        # the pages faulted in before the timing
    copy_s = min(call_durations(lambda: np.copyto(target, source), repeats))
    return {'machine_python_loop_ns': 1e9 * loop_s / 200_000,
            'machine_memory_copy_gb_s': source.nbytes / copy_s / 1e9}


def add_json_option(parser):
    """Add the benchmarks' ``--json PATH`` option to an argparse parser."""
    parser.add_argument('--json', metavar='PATH',
                        help='also write the figures to PATH as flat JSON (units in the keys; '
                             'missing parent directories are created)')


def flat_figures(figures):
    """
    Return the figures as a JSON-ready dict: str keys, int or float values, None for nan/inf.

    Raise TypeError naming the key on a value that is not a real number (a string, a list, a
    nested dict: the JSON must stay flat) and on a key that is not a string.
    """
    flat = {}
    for name, value in figures.items():
        if not isinstance(name, str):
            raise TypeError(f'figure name {name!r} is not a string')
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise TypeError(f'figure {name} is {type(value).__name__} {value!r}, '
                            'not a number')
        if isinstance(value, numbers.Integral):
            flat[name] = int(value)
        else:
            value = float(value)
            flat[name] = value if math.isfinite(value) else None
    return flat


def format_figures(figures):
    """Return the table of figures, one line a figure: name padded, value right-aligned."""
    width = max((len(name) for name in figures), default=0)
    lines = []
    for name, value in figures.items():
        if isinstance(value, numbers.Integral) and not isinstance(value, bool):
            text = f'{int(value):d}'
        else:
            text = f'{float(value):.6g}'
        lines.append(f'{name:<{width}}  {text:>12}')
    return '\n'.join(lines)


def write_figures(figures, path):
    """
    Write the figures to `path` as flat, sorted, indented JSON; create missing directories.

    The figures are checked (`flat_figures`) before the file is touched. Raise OSError (its
    errno kept, so e.g. PermissionError) naming the path and the reason when the directory
    cannot be made or the file written.
    """
    text = json.dumps(flat_figures(figures), indent=2, sort_keys=True, allow_nan=False) + '\n'
    path = os.path.abspath(os.fspath(path))
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        with open(path, 'w') as stream:
            stream.write(text)
    except OSError as error:
        raise OSError(error.errno, f'cannot write the benchmark figures to {path}: '
                                   f'{error.strerror or error}') from error


def report(figures, json_path=None, stream=None, machine=False):
    """
    Print every figure, then write them to `json_path` when given; return the exit status.

    The table is printed first, so a failed write loses no figure: the reason goes to stderr
    and the status is 1. A figure that is not a number is a programming error (TypeError).
    With `machine` the machine's description is printed first and its yardsticks
    (``machine_figures``) join the figures.
    """
    flat_figures(figures)  # refuse a bad figure before printing anything
    stream = stream or sys.stdout
    if machine:
        print(f'machine: {machine_description()}', file=stream)
        figures = {**figures, **machine_figures()}
    print(format_figures(figures), file=stream, flush=True)
    if json_path:
        try:
            write_figures(figures, json_path)
        except OSError as error:
            print(f'error: {error.strerror}', file=sys.stderr)
            return 1
    return 0
