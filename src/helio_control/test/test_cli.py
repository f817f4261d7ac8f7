"""The helio command's pure parts: goal options, the progress line, the Dobot's port, sky."""

import json

from helio_control.cli import build_goal, build_parser, CommandError, find_dobot_port
from helio_control.cli import goal_options, ProgressBar
from helio_msgs.action import PaintPattern
import pytest
from serial.tools.list_ports_common import ListPortInfo


def usb_port(device, vid=None, pid=None):
    """Return a pyserial port description (what list_ports.comports() yields)."""
    port = ListPortInfo(device, skip_link_detection=True)
    port.vid, port.pid = vid, pid
    return port


def test_the_dobot_is_found_by_its_adapters_usb_ids():
    ports = [usb_port('/dev/ttyS0'), usb_port('/dev/ttyACM0', 0x1FFB, 0x0089),   # Maestro
             usb_port('/dev/ttyUSB0', 0x10C4, 0xEA60)]
    assert find_dobot_port(ports) == '/dev/ttyUSB0'
    assert find_dobot_port([usb_port('/dev/ttyUSB3', 0x1A86, 0x7523)]) == '/dev/ttyUSB3'


def test_no_dobot_or_two_candidates_are_refused_with_the_ports_named():
    with pytest.raises(CommandError, match=r'no Dobot found.*/dev/ttyACM0 \(1ffb:0089\)'):
        find_dobot_port([usb_port('/dev/ttyACM0', 0x1FFB, 0x0089)])
    with pytest.raises(CommandError, match='several serial ports.*ttyUSB0, /dev/ttyUSB1'):
        find_dobot_port([usb_port('/dev/ttyUSB0', 0x10C4, 0xEA60),
                         usb_port('/dev/ttyUSB1', 0x1A86, 0x7523)])


def test_every_option_sets_its_goal_field():
    parser = build_parser(PaintPattern)
    arguments = parser.parse_args(
        ['paint', 'x.png', '--canvas-size', '0.07', '--dot-radius', '0.0025',
         '--offset-x', '0.04', '--offset-y', '0.06', '--n-p-target', '25',
         '--feature-mode', 'edges', '--ordering', 'nearest', '--start-index', '3', '--dry-run',
         '--points', '0.05,0.06', '0.07,0.08'])
    goal = build_goal(PaintPattern.Goal, arguments, '/abs/x.png')
    assert goal.image_path == '/abs/x.png'
    assert (goal.canvas_size, goal.dot_radius, goal.offset_x, goal.offset_y) == \
        (0.07, 0.0025, 0.04, 0.06)
    assert (goal.n_p_target, goal.start_index, goal.dry_run) == (25, 3, True)
    assert (goal.feature_mode, goal.ordering) == ('edges', 'nearest')
    assert [(p.x, p.y, p.z) for p in goal.points] == [(0.05, 0.06, 0.0), (0.07, 0.08, 0.0)]
    # options not given keep the goal's defaults (the painter's defaults then apply)
    default = build_goal(PaintPattern.Goal, parser.parse_args(['paint', 'x.png']), 'x.png')
    assert default.canvas_size == 0.0 and default.dry_run is False and not default.points


def test_a_field_added_to_the_goal_becomes_an_option():
    class Goal:
        """A goal with one more field than PaintPattern's, as the lead will add."""

        @staticmethod
        def get_fields_and_field_types():
            return {**PaintPattern.Goal.get_fields_and_field_types(),
                    'tone_dot_size': 'boolean', 'tone_gamma': 'double'}

    names = {option for _, _, option in goal_options(Goal)}
    assert {'--tone-dot-size', '--tone-gamma', '--n-p-target'} <= names
    assert '--image-path' not in names and '--image' not in names


def test_the_progress_line_shows_dots_phase_temperature_n_p_and_eta():
    feedback = PaintPattern.Feedback(index=15, total=60, phase='heating', t_max=180.9, n_p=24,
                                     elapsed=600.0, eta=1800.0)
    line = ProgressBar(width=20).line(feedback)
    assert line.startswith('[#####...............] 15/60 dots')
    assert 'heating' in line and 'T_max  180.9 degC' in line and 'N_p  24' in line
    assert 'ETA 30.0 min' in line
    assert 'ETA ?' in ProgressBar().line(PaintPattern.Feedback(total=0, eta=0.0))


def test_into_a_file_the_progress_is_written_once_per_dot_and_phase():
    import io
    stream = io.StringIO()
    bar = ProgressBar(stream)
    for index, phase in ((0, 'moving'), (0, 'heating'), (0, 'heating'), (0, 'heating'),
                         (1, 'moving')):
        bar(PaintPattern.Impl.FeedbackMessage(
            feedback=PaintPattern.Feedback(index=index, total=2, phase=phase)))
    lines = stream.getvalue().splitlines()
    assert len(lines) == 3 and 'heating' in lines[1] and lines[2].startswith('[' + '#' * 15)


def test_sky_takes_its_options():
    arguments = build_parser(PaintPattern).parse_args(
        ['sky', '--date', '2026-06-21', '--heading', '200', '--canvas-size', '0.06',
         '--utc-offset', '2', '--camera-size', '1280x720', '--marker-in-view', '--step', '5'])
    assert arguments.date.isoformat() == '2026-06-21' and arguments.heading == 200.0
    assert arguments.canvas_size == 0.06 and arguments.utc_offset == 2.0
    assert arguments.camera_size == (1280, 720) and arguments.marker_in_view
    assert arguments.step == 5.0 and arguments.heading_step == 15.0
    for bad in (['--date', '21.6.2026'], ['--step', '0'], ['--camera-size', '640'],
                ['--timezone', 'Europe/Berlin', '--utc-offset', '2']):
        with pytest.raises(SystemExit):
            build_parser(PaintPattern).parse_args(['sky'] + bad)


def test_sky_prints_the_hours_and_fails_in_one_line_when_the_sun_never_serves(capsys, tmp_path):
    # the default site (the simulated world's, Munich) at the simulated world's heading
    common = ['sky', '--date', '2026-06-21', '--heading', '200', '--timezone', 'Europe/Berlin',
              '--step', '30', '--heading-step', '90']
    arguments = build_parser(PaintPattern).parse_args(common + ['--json',
                                                                str(tmp_path / 'sky.json')])
    assert arguments.handler(arguments) == 0
    out = capsys.readouterr().out
    assert 'times CEST (Europe/Berlin)' in out
    assert 'served at heading 200 deg: ' in out and 'best heading ' in out
    with open(tmp_path / 'sky.json') as stream:
        written = json.load(stream)
    assert written['hours'] > 0 and written['heading_deg'] == 200.0
    assert [entry['heading_deg'] for entry in written['scan']] == [0.0, 90.0, 180.0, 270.0]
    # Munich's sun never stands 70 deg up: no sweep, the canvas is never served
    arguments = build_parser(PaintPattern).parse_args(common + ['--min-elevation', '70'])
    with pytest.raises(CommandError, match='does not serve this canvas on 2026-06-21 at '
                       r'heading 200 deg \(mostly: the sun stands .* below the lowest the '
                       'sweep estimates'):
        arguments.handler(arguments)
