"""helio_optics.bench_report: the printed table and the flat JSON every benchmark writes."""

import argparse
import json
import math
import os
import time

from helio_optics.bench_report import add_json_option, call_durations, median_call_ms
from helio_optics.bench_report import machine_description, machine_figures, report
from helio_optics.bench_report import write_figures
import numpy as np
import pytest

FIGURES = {
    'trace_rays_per_s': 1.4321e7,
    'estimate_levenberg_marquardt_1_spot_ms_median': 3.5,
    'rig_forward_us_per_call': np.float64(19.25),
    'e2e_640x480_30hz_frames_sent': 300,
    'e2e_640x480_30hz_frames_dropped': np.int64(2),
    'ephemeris_sun_position_ms_per_call': 0.000381,
}


def printed_table(capsys):
    """Return {name: text of the value} from what report printed."""
    lines = capsys.readouterr().out.splitlines()
    return dict(line.split() for line in lines)


def test_json_holds_every_figure_as_a_flat_number(tmp_path, capsys):
    path = tmp_path / 'figures.json'
    assert report(FIGURES, str(path)) == 0
    text = path.read_text()
    written = json.loads(text)
    assert set(written) == set(FIGURES)
    for name, value in FIGURES.items():
        assert written[name] == value, name
        assert isinstance(written[name], int) == isinstance(value, (int, np.integer)), name
    assert list(written) == sorted(FIGURES)  # sorted keys: diffable between runs
    assert text.endswith('}\n')


def test_every_key_is_printed_once_with_its_value(capsys):
    assert report(FIGURES) == 0
    table = printed_table(capsys)
    assert set(table) == set(FIGURES)
    for name, value in FIGURES.items():
        assert float(table[name]) == pytest.approx(float(value), rel=1e-5), name
    assert table['e2e_640x480_30hz_frames_sent'] == '300'


def test_missing_parent_directories_are_created(tmp_path, capsys):
    path = tmp_path / 'bench' / 'today' / 'optics.json'
    assert report({'a_ms': 1.0}, path) == 0
    assert json.loads(path.read_text()) == {'a_ms': 1.0}


def test_an_unwritable_path_is_a_clear_error_after_the_figures_are_printed(tmp_path, capsys):
    blocker = tmp_path / 'not_a_directory'
    blocker.write_text('')
    path = blocker / 'figures.json'
    assert report(FIGURES, str(path)) == 1
    captured = capsys.readouterr()
    assert all(name in captured.out for name in FIGURES)  # nothing measured is lost
    assert f'cannot write the benchmark figures to {path}' in captured.err
    with pytest.raises(OSError, match='cannot write the benchmark figures to'):
        write_figures(FIGURES, path)


def test_a_figure_not_measured_is_written_as_null(tmp_path, capsys):
    path = tmp_path / 'figures.json'
    assert report({'latency_ms_median': math.nan, 'frames': 0}, path) == 0
    assert json.loads(path.read_text()) == {'latency_ms_median': None, 'frames': 0}
    assert printed_table(capsys)['latency_ms_median'] == 'nan'


@pytest.mark.parametrize('value', ['fast', [1.0, 2.0], {'ms': 1.0}, True, None])
def test_a_figure_that_is_not_a_number_is_refused_before_anything_is_written(
        tmp_path, capsys, value):
    path = tmp_path / 'figures.json'
    with pytest.raises(TypeError, match='figure bad_figure'):
        report({'good_ms': 1.0, 'bad_figure': value}, path)
    assert not path.exists()
    assert capsys.readouterr().out == ''


def test_json_option_takes_a_path_and_defaults_to_none():
    parser = argparse.ArgumentParser()
    add_json_option(parser)
    assert parser.parse_args([]).json is None
    assert parser.parse_args(['--json', '/tmp/b.json']).json == '/tmp/b.json'


def busy_for(seconds):
    """Return a call that spins on the clock for at least `seconds`, counting its calls."""
    calls = []

    def call():
        calls.append(None)
        end = time.perf_counter() + seconds
        while time.perf_counter() < end:
            pass
    return call, calls


def test_call_durations_times_each_call_once():
    call, calls = busy_for(0.002)
    durations = call_durations(call, 5)
    assert len(calls) == 5 and len(durations) == 5
    assert all(d >= 0.002 for d in durations)   # each call spins at least 2 ms


def test_median_call_ms_is_in_milliseconds():
    call, calls = busy_for(0.003)
    assert median_call_ms(call, 3) >= 3.0 and len(calls) == 3


def test_the_machine_yardsticks_are_in_their_units():
    figures = machine_figures(repeats=2)
    assert set(figures) == {'machine_python_loop_ns', 'machine_memory_copy_gb_s'}
    # a loop turn of CPython takes tens of nanoseconds, not seconds or picoseconds
    assert 1.0 < figures['machine_python_loop_ns'] < 2000.0
    # a memory copy runs at 0.1-1000 GB/s on any machine that runs this project
    assert 0.1 < figures['machine_memory_copy_gb_s'] < 1000.0


def test_a_report_with_the_machine_names_it_and_adds_its_yardsticks(tmp_path, capsys):
    path = tmp_path / 'figures.json'
    assert report(FIGURES, str(path), machine=True) == 0
    first, *rest = capsys.readouterr().out.splitlines()
    assert first == f'machine: {machine_description()}'
    assert first.endswith(f', {len(os.sched_getaffinity(0))} cores')
    written = json.loads(path.read_text())
    assert set(written) == set(FIGURES) | {'machine_python_loop_ns',
                                           'machine_memory_copy_gb_s'}
    assert len(rest) == len(written)
    assert 'machine_python_loop_ns' not in FIGURES     # the caller's figures left as they were
