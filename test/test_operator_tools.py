"""
The operator's tools with real processes.

``helio`` sub-commands, graph supervision, the run report of a real simulated painting, and
the launch entries.
"""

import json
import os
import signal
import socket
import subprocess
import sys

from foxglove_ws import FoxgloveClient
from helio_control.bringup import hardware_graph, node_entries, node_processes
from helio_control.bringup import SIMULATED_DEVICE_REPLY_TIMEOUT, SIMULATED_RECONNECT_MAX
from helio_control.bringup import simulated_graph
from helio_control.cli import build_parser, goal_options
from helio_control.report import make_report, read_dots_csv
from helio_control.run_journal import JournalWriter
from helio_msgs.action import PaintPattern
import numpy as np
import pytest
from test_view_bridge import CHECKED, well_formed

HELIO = [sys.executable, '-m', 'helio_control.cli']


def helio(*arguments, timeout=120, **kwargs):
    """Run ``helio`` as a process; return the CompletedProcess."""
    return subprocess.run(HELIO + list(arguments), capture_output=True, text=True,
                          timeout=timeout, **kwargs)


def wait_for(condition, timeout, what):
    """
    Poll `condition()` until it holds; fail naming `what` after `timeout` s.

    For states of other processes, which give no event to wait on (/proc, the process
    table): polled every 20 ms.
    """
    import threading
    import time
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return
        threading.Event().wait(0.02)
    raise AssertionError(f'{what} did not happen within {timeout} s')


def alive(pid):
    """Return whether a process id is still running (not a zombie)."""
    try:
        with open(f'/proc/{pid}/stat') as stream:
            return stream.read().split()[2] != 'Z'
    except OSError:
        return False


# ---------------------------------------------------------------------------- the command
def sub_commands():
    """Return the names of the helio command's sub-commands, as its parser has them."""
    parser = build_parser(PaintPattern)
    commands = next(action for action in parser._actions if action.dest == 'command')
    return sorted(commands.choices)


def test_every_sub_command_has_help():
    names = sub_commands()
    assert {'sim', 'rig', 'paint', 'stop', 'reset', 'doctor', 'calibrations'} <= set(names)
    for command in names:
        done = helio(command, '--help')
        assert done.returncode == 0 and 'usage: helio' in done.stdout, command
    # and the list of the command's own help names each one
    listed = helio('--help').stdout
    assert all(name in listed for name in names)


def test_preview_is_the_preview_command(tmp_path):
    done = helio('preview', 'sample:logo', '--out', str(tmp_path))
    assert done.returncode == 0, done.stderr
    assert (tmp_path / 'preview.png').is_file() and (tmp_path / 'plan.json').is_file()


def test_paint_options_are_the_goal_fields_one_to_one():
    fields = PaintPattern.Goal.get_fields_and_field_types()
    options = {name for name, _, _ in goal_options(PaintPattern.Goal)}
    # every field but the picture's own (image_path from PICTURE, image not on a command line)
    assert options == set(fields) - {'image_path', 'image'}
    text = build_parser(PaintPattern).format_help()
    paint = subprocess.run(HELIO + ['paint', '--help'], capture_output=True, text=True,
                           timeout=60).stdout
    assert text and all(f'--{name.replace("_", "-")}' in paint for name in options)
    # each with its meaning and unit from the action's own comments, not "goal field NAME"
    flat = ' '.join(paint.split())
    assert not any(f'goal field {name}' in flat for name in options)
    assert 'dot_radius: dot pitch r_p [m]' in flat and 'dot-size calibration' in flat


@pytest.mark.parametrize('arguments, status, message', [
    (['paint', '/nonexistent/picture.png'], 1, 'picture not found'),
    (['paint', 'sample:nothing'], 1, 'no sample picture'),
    (['paint', 'sample:logo', '--n-p-target', '-3'], 2, 'must be >= 0'),
    (['paint', 'sample:logo', '--canvas-size', 'wide'], 2, 'invalid _finite_float value'),
    (['paint', 'sample:logo', '--no-such-option', '1'], 2, 'unrecognized arguments'),
    (['paint'], 2, 'needs a PICTURE or --points'),
    (['sim', '--nodes', 'painter_of_dreams'], 1, 'not in the simulated graph'),
    (['rig', '--dobot-port', '/dev/nonexistent0', '--servo-port', '/dev/nonexistent1'], 1,
     'does not exist'),
    (['report', '/nonexistent/run'], 1, 'no run directory'),
    (['print', 'marker', '--out', '/tmp/marker.jpg'], 1, 'write a .png or a .pdf'),
    (['print', 'board', '--squares', 'seven', '--out', '/tmp/board.png'], 1,
     '--squares is COLUMNSxROWS'),
    (['sky', '--date', '2026-06-21', '--min-elevation', '70', '--step', '60',
      '--heading-step', '120'], 1, 'does not serve this canvas on 2026-06-21'),
    (['sky', '--site', '/nonexistent/site.yaml'], 1, '/nonexistent/site.yaml'),
    (['sky', '--date', '2026-13-01'], 2, 'a date is YYYY-MM-DD'),
    (['calibrate', 'focus'], 2, "invalid choice: 'focus'"),
    (['calibrate', 'rig', '--namespace', '/nobody_here', '--connect-timeout', '1'], 1,
     'no lens planner answers on /nobody_here/calibrate_rig in ROS_DOMAIN_ID'),
])
def test_bad_input_exits_non_zero_with_one_line(tmp_path, arguments, status, message):
    done = helio(*arguments, cwd=str(tmp_path))
    assert done.returncode == status, done.stderr
    assert message in done.stderr
    assert 'Traceback' not in done.stderr
    assert len([line for line in done.stderr.splitlines() if 'error' in line]) == 1


def test_sky_prints_the_hours_of_the_day_and_writes_them_as_json(tmp_path):
    # issue 30: the default site (the simulated world's) at the simulated world's heading
    done = helio('sky', '--date', '2026-06-21', '--heading', '200', '--timezone',
                 'Europe/Berlin', '--heading-step', '45', '--json', str(tmp_path / 'sky.json'))
    assert done.returncode == 0, done.stderr
    assert 'served at heading 200 deg: ' in done.stdout and 'best heading' in done.stdout
    with open(tmp_path / 'sky.json') as stream:
        day = json.load(stream)
    served = [sample for sample in day['samples'] if sample['served']]
    assert served and all(sample['reach_share'] == 1.0 and sample['sweep'] == 'yes'
                          and sample['elevation_deg'] >= 30.0 for sample in served)
    assert day['hours'] == pytest.approx(len(served) * day['step_s'] / 3600.0)


def test_paint_with_no_graph_reachable_says_so_in_one_line_and_starts_no_simulation(tmp_path):
    # issue 30: without --sim, helio paint never falls back to the simulated graph (a rig's
    # graph in another domain or namespace was painted in a simulation instead)
    done = helio('paint', 'sample:logo', '--connect-timeout', '1', '--out',
                 str(tmp_path / 'run'), '--namespace', '/nobody_here',
                 env={**os.environ, 'ROS_DOMAIN_ID': '117'})
    assert done.returncode == 1
    assert ('no painter answers on /nobody_here/paint in ROS_DOMAIN_ID 117 within 1 s'
            in done.stderr)
    assert '--sim' in done.stderr and 'Traceback' not in done.stderr
    assert 'starting the simulated graph' not in done.stderr
    assert not (tmp_path / 'run' / 'logs').exists()          # no node process was started


# the bridge's annotated channels, under the namespace of the graph helio paint starts
VIEWED = ('/paint_test/view/scene', '/paint_test/view/rgb/annotations',
          '/paint_test/view/thermal/annotations')


def free_port():
    """Return a TCP port free on localhost now (the kernel's pick)."""
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return probe.getsockname()[1]


def test_paint_starts_the_simulated_graph_paints_reports_and_stops_all_of_it(tmp_path):
    """No graph running: helio paint --sim --view starts the simulated one, paints two dots."""
    targets = [(0.06, 0.06), (0.09, 0.07)]
    port = free_port()
    out, err = tmp_path / 'stdout.txt', tmp_path / 'stderr.txt'     # files: never blocks
    with open(out, 'w') as stdout, open(err, 'w') as stderr:
        process = subprocess.Popen(
            HELIO + ['paint', '--sim', '--points', *[f'{x},{y}' for x, y in targets],
                     '--start-timeout', '120', '--out', str(tmp_path / 'run'), '--namespace',
                     '/paint_test', '--view', '--view-port', str(port)],
            stdout=stdout, stderr=stderr, text=True)
    viewer = None
    try:
        # --view (issue 33): the live bridge serves the painting while it runs
        def connected():
            nonlocal viewer
            assert process.poll() is None, err.read_text()[-3000:]
            try:
                viewer = FoxgloveClient(port, [f'/paint_test{topic}' for topic in CHECKED],
                                        timeout=2.0)
            except OSError:
                return False          # not listening yet
            return True
        wait_for(connected, 180.0, 'the view bridge of helio paint --view')
        assert viewer.subscribed.wait(120.0), f'advertised: {sorted(viewer.channels)}'
        viewer.wait_until(lambda: all(viewer.messages[topic] for topic in VIEWED), 300.0,
                          lambda: {topic: len(found) for topic, found in
                                   viewer.messages.items()})
        process.wait(timeout=600)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        if viewer is not None:
            viewer.close()
    stdout, stderr = out.read_text(), err.read_text()
    assert process.returncode == 0, stderr[-3000:]
    assert 'Traceback' not in stderr
    assert f'Foxglove view: ws://127.0.0.1:{port}' in stderr
    for topic in VIEWED:
        assert well_formed(viewer, topic), topic
    assert str(tmp_path / 'run' / 'report.html') in stdout + stderr
    with open(tmp_path / 'run' / 'summary.json') as stream:
        summary = json.load(stream)
    assert (summary['dots_burnt'], summary['dots_skipped'], summary['dots_failed']) == (2, 0, 0)
    # the world's char map (not the painter's word): two dots, each on its target
    charred = read_dots_csv(tmp_path / 'run' / 'dots.csv')
    assert len(charred) == 2
    for x, y in targets:
        assert np.min(np.hypot(charred[:, 0] - x, charred[:, 1] - y)) < 0.3e-3
    logs = tmp_path / 'run' / 'logs'
    started = sorted(p.stem for p in logs.glob('*.log'))
    assert {'sim_world', 'dobot_driver', 'lens_planner', 'painter', 'view_bridge'} <= set(
        started)
    # no node process is left: every started executable's pid is gone
    leftovers = subprocess.run(['pgrep', '-f', str(logs)], capture_output=True, text=True)
    assert leftovers.stdout.strip() == ''


@pytest.mark.parametrize('stop', [signal.SIGINT, signal.SIGTERM], ids=['ctrl_c', 'sigterm'])
def test_ctrl_c_during_paint_stops_the_graph_it_started_and_exits_130(tmp_path, stop):
    run = tmp_path / 'run'
    process = subprocess.Popen(
        HELIO + ['paint', 'sample:logo', '--sim', '--connect-timeout', '1', '--start-timeout',
                 '120', '--out', str(run), '--namespace', '/paint_interrupt'],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    for line in process.stderr:
        if 'starting the simulated graph' in line:
            break
    logs = run / 'logs'
    # the graph's node processes start (their parameter files name the log folder)
    wait_for(lambda: subprocess.run(['pgrep', '-f', str(logs)], capture_output=True,
                                    text=True).stdout.split(), 120.0, 'a node process')
    process.send_signal(stop)      # a terminal's Ctrl-C, or a supervisor's SIGTERM
    rest = process.stderr.read()
    assert process.wait(120) == 130, rest
    assert 'Traceback' not in rest
    leftovers = subprocess.run(['pgrep', '-f', str(logs)], capture_output=True, text=True)
    assert leftovers.stdout.strip() == ''


# ---------------------------------------------------------------------------- supervision
def start_sim(tmp_path, *nodes):
    """Start ``helio sim`` with `nodes`; return (process, {node: pid}) once all are up."""
    process = subprocess.Popen(
        HELIO + ['sim', '--nodes', *nodes, '--log-dir', str(tmp_path / 'logs'),
                 '--stop-timeout', '3', '--port-dir', str(tmp_path / 'ports')],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    pids = {}
    for line in process.stderr:
        if ' pid ' in line:
            name, pid = line.split()[1], int(line.split()[-1])
            pids[name] = pid
        if len(pids) == len(nodes):
            break
    assert len(pids) == len(nodes), process.stderr.read()
    # a pid is printed at the spawn; a signal sent before the node's rclpy took over its
    # handlers was swallowed by the interpreter's start-up (seen for sim_world: its SIGINT
    # lost in importlib, so it ended by SIGTERM). Each node logs its thread pools once up.

    def up(node):
        path = tmp_path / 'logs' / f'{node}.log'
        return path.exists() and 'numeric thread pools' in path.read_text(errors='replace')
    wait_for(lambda: all(up(node) for node in nodes), 120.0, f'{", ".join(nodes)} up')
    return process, pids


def test_a_node_that_dies_is_reported_at_once_with_its_log_and_the_graph_stops(tmp_path):
    process, pids = start_sim(tmp_path, 'sim_world', 'thermal_monitor')
    os.kill(pids['thermal_monitor'], signal.SIGKILL)
    rest = process.stderr.read()
    assert process.wait(60) == 1
    assert 'node thermal_monitor died (exit status -9)' in rest
    assert 'its last log lines' in rest
    assert not any(alive(pid) for pid in pids.values())


def test_ctrl_c_stops_every_node_and_exits_130(tmp_path):
    process, pids = start_sim(tmp_path, 'sim_world', 'thermal_monitor', 'spot_detector')
    process.send_signal(signal.SIGINT)
    rest = process.stderr.read()
    assert process.wait(60) == 130
    assert 'sim_world (SIGINT)' in rest
    assert not any(alive(pid) for pid in pids.values())


def wait_stopped(pid, timeout=10.0):
    """Wait until process `pid` is in the stopped state (T) or fail after `timeout` s."""
    def stopped():
        with open(f'/proc/{pid}/stat') as stream:
            return stream.read().rsplit(')', 1)[1].split()[0] == 'T'
    wait_for(stopped, timeout, f'process {pid} to stop')


def test_a_hung_node_is_escalated_to_sigkill(tmp_path):
    """A node that reacts neither to SIGINT nor to SIGTERM (stopped) ends by SIGKILL."""
    process, pids = start_sim(tmp_path, 'sim_world', 'thermal_monitor')
    os.kill(pids['thermal_monitor'], signal.SIGSTOP)
    wait_stopped(pids['thermal_monitor'])   # SIGINT sent before the stop would be taken first
    process.send_signal(signal.SIGINT)
    rest = process.stderr.read()
    assert process.wait(60) == 130
    assert 'thermal_monitor (SIGKILL)' in rest and 'sim_world (SIGINT)' in rest
    assert not any(alive(pid) for pid in pids.values())


def test_the_nodes_of_a_killed_supervisor_stop_with_it(tmp_path):
    """A helio sim killed outright (SIGKILL: it cannot stop them) takes its nodes along."""
    # they used to run on, orphaned: a test's timed-out `helio paint` left a whole simulated
    # graph running for 40 minutes beside the next test runs (2026-11-27)
    process, pids = start_sim(tmp_path, 'sim_world', 'thermal_monitor')
    process.kill()
    process.wait(30)
    wait_for(lambda: not any(alive(pid) for pid in pids.values()), 60.0,
             'the nodes of the killed helio sim to stop')


# ---------------------------------------------------------------------------- bringup/launch
def test_the_launch_entries_are_what_the_runner_starts(tmp_path):
    specs = simulated_graph(str(tmp_path))
    for entry, process in zip(node_entries(specs, '/rig1'), node_processes(specs, '/rig1')):
        command = process.command()
        assert command[0].endswith(f'/lib/{entry["package"]}/{entry["executable"]}')
        for path in entry['parameter_files']:
            assert path in command and os.path.isfile(path)
        assert '__ns:=/rig1' in command and f'__node:={entry["name"]}' in command
    hardware = node_entries(hardware_graph('/dev/ttyUSB7', '/dev/ttyACM3'))
    assert {e['name'] for e in hardware} >= {'dobot_driver', 'servo_driver', 'spot_detector'}
    assert 'sim_world' not in {e['name'] for e in hardware}
    assert all('use_sim_time' not in e['parameters'] for e in hardware)
    assert next(e for e in hardware if e['name'] == 'dobot_driver')['parameters']['port'] == \
        '/dev/ttyUSB7'
    # the emulated devices answer from a loaded process: their drivers wait longer per reply,
    # and retry the world's ptys, which open late, without a real device's long backoff; the
    # real devices' drivers keep their configured timeouts and backoff
    simulated = node_entries(specs)
    for name in ('dobot_driver', 'servo_driver'):
        parameters = next(e for e in simulated if e['name'] == name)['parameters']
        assert parameters['timeout'] == SIMULATED_DEVICE_REPLY_TIMEOUT
        assert parameters['reconnect_max'] == SIMULATED_RECONNECT_MAX
        real = next(e for e in hardware if e['name'] == name)['parameters']
        assert 'timeout' not in real and 'reconnect_max' not in real


def test_the_launch_files_are_installed_and_name_launch_when_it_is_missing():
    """``launch`` is not installable here: the files are checked to build from bringup."""
    from ament_index_python.packages import get_package_share_directory
    import importlib.util
    share = get_package_share_directory('helio_control')
    for graph in ('sim', 'rig'):
        path = os.path.join(share, 'launch', f'{graph}.launch.py')
        spec = importlib.util.spec_from_file_location(f'{graph}_launch', path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        try:
            import launch  # noqa: F401
        except ImportError:
            with pytest.raises(ImportError, match='launch_ros'):
                module.generate_launch_description()
        else:       # a ROS 2 installation: the description builds
            assert module.generate_launch_description().entities


# ---------------------------------------------------------------------------- run report
@pytest.fixture(scope='module')
def painted_run(tmp_path_factory):
    """Paint three dots in the simulated world (the TRUE sun); journal them with the writer."""
    from helio_control.plan import load_plan_options, plan_dots
    from true_sun_painting import DEFAULT_DOTS, TrueSunPainting
    import time
    run_dir = tmp_path_factory.mktemp('run')
    targets = DEFAULT_DOTS[:3]
    plan = plan_dots(np.asarray(targets), load_plan_options(), None, None)
    (run_dir / 'plan.json').write_text(plan.to_json())
    demo = TrueSunPainting(str(run_dir / 'ports'), log=lambda message: None)
    peaks = {}
    read = demo.next_thermal_np

    def observed():            # keep each frame's N_p and T_max for the journal
        n_p, t_max = read()
        peaks['n_p'] = max(peaks.get('n_p', 0), n_p)
        peaks['t_max'] = max(peaks.get('t_max', -1e9), t_max)
        return n_p, t_max
    demo.next_thermal_np = observed
    wall = time.time()
    try:
        with JournalWriter(str(run_dir / 'journal.jsonl')) as journal:
            journal.run({'image_path': '', 'points': [list(t) for t in targets]},
                        demo.world.time, wall)
            start_all = demo.world.time
            for index, target in enumerate(plan.dots.tolist()):
                peaks.clear()
                start = demo.world.time
                record, = demo.paint([tuple(target)])
                journal.dot(index=index, target=target, n_p_target=30, start=start,
                            end=demo.world.time, dwell=record['heated_s'],
                            peak_n_p=peaks['n_p'], t_max=peaks['t_max'], outcome='burnt')
            journal.result(success=True, dots_burnt=3, dots_skipped=0,
                           duration=demo.world.time - start_all,
                           wall_duration=time.time() - wall, message='3 dots burnt')
        demo.world.write_outputs(str(run_dir))
    finally:
        demo.close()
    return run_dir, plan


def test_the_report_of_a_simulated_painting_matches_the_worlds_truth(painted_run):
    run_dir, plan = painted_run
    done = helio('report', str(run_dir))
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == str(run_dir / 'report.html')
    summary = json.loads((run_dir / 'summary.json').read_text())
    assert summary['dots_planned'] == 3 and summary['dots_burnt'] == 3
    assert summary['dots_skipped'] == 0 and summary['dots_without_char'] == 0
    # second method: each target's nearest charred dot in the world's dots.csv (the report
    # measures the char map per target: the same pixels, but dots.csv rounds to 1 um)
    assert summary['measured_per'] == 'target'
    charred = read_dots_csv(str(run_dir / 'dots.csv'))
    nearest = [np.min(np.linalg.norm(charred[:, :2] - target, axis=1)) for target in plan.dots]
    assert summary['mean_placement_error_m'] == pytest.approx(np.mean(nearest), abs=1.5e-6)
    assert summary['mean_placement_error_m'] < 1e-3        # aimed with the true sun
    diameters = charred[:, 2]
    assert summary['diameter_cv'] == pytest.approx(np.std(diameters) / np.mean(diameters),
                                                   abs=1e-3)
    estimate = plan.time_estimate['total_s']
    actual = summary['painting_time_s']
    assert summary['plan_estimate_s'] == pytest.approx(estimate)
    assert summary['estimate_error_ratio'] == pytest.approx((estimate - actual) / actual)
    html = (run_dir / 'report.html').read_text()
    assert html.count('<img') >= 5 and 'src="http' not in html and 'src="data:image/png' in html
    for name in ('canvas.png', 'overlay.png', 'thermal.png', 'dwell.png', 'placement.png',
                 'sun.png'):
        assert (run_dir / name).stat().st_size > 1000, name


def test_the_report_refuses_a_directory_without_a_journal(tmp_path):
    with pytest.raises(ValueError, match='no journal.jsonl'):
        make_report(str(tmp_path))


def test_the_report_reads_the_recording_of_a_run(tmp_path):
    """A run directory with a recording (the fixture bag) and a journal, no dots.csv."""
    import shutil
    from conftest import REPO
    from pathlib import Path
    from rosbags.highlevel import AnyReader
    import yaml
    bag = os.path.join(REPO, 'bags', 'sim_one_dot')
    shutil.copytree(bag, tmp_path / 'recording')
    fixture = yaml.safe_load((tmp_path / 'recording' / 'fixture.yaml').read_text())
    dot = fixture['dots'][0]
    with JournalWriter(str(tmp_path / 'journal.jsonl')) as journal:
        journal.run({'points': [dot['target']]}, dot['focus_start'] - 5.0, 0.0)
        journal.dot(index=0, target=dot['target'], n_p_target=30, start=dot['focus_start'],
                    end=dot['focus_end'] + 3.0, dwell=dot['focus_end'] - dot['focus_start'],
                    peak_n_p=dot['peak_n_p'], t_max=180.9, outcome='burnt')
    report = make_report(str(tmp_path))
    # second reader: the recorded thermal statistics through rosbags
    with AnyReader([Path(tmp_path / 'recording')]) as reader:
        connections = [c for c in reader.connections if c.topic == '/thermal/stats']
        t_max = [reader.deserialize(raw, c.msgtype).t_max
                 for c, _, raw in reader.messages(connections=connections)]
    from helio_control.report import recording_series
    series = recording_series(str(tmp_path / 'recording'))
    assert [value for _, value, _ in series['thermal']] == t_max
    assert len(series['truth']) > 0 and series['sun'] == []
    summary = report.summary
    assert summary['dots_burnt'] == 1 and summary['success'] is False   # no result line
    assert summary['mean_placement_error_m'] is None                    # no dots.csv
    assert summary['painting_time_s'] == pytest.approx(dot['focus_end'] + 3.0 -
                                                       dot['focus_start'] + 5.0)
    assert (tmp_path / 'thermal.png').stat().st_size > 1000
    assert 'placement.png' not in report.html_path and not (tmp_path / 'placement.png').exists()
