"""The run journal: written line by line, read back equal, crashes and bad lines named."""

import json

from geometry_msgs.msg import Point
from helio_control.run_journal import goal_to_dict, JournalError, JournalWriter, read_journal
from helio_msgs.action import PaintPattern
import numpy as np
import pytest
from sensor_msgs.msg import Image

DOT = {'index': 0, 'target': [0.06, 0.062], 'n_p_target': 30, 'start': 10.0, 'end': 35.5,
       'dwell': 18.2, 'peak_n_p': 31, 't_max': 180.9, 'outcome': 'burnt'}


def test_a_journal_reads_back_what_was_written_and_each_line_is_on_disk_at_once(tmp_path):
    path = tmp_path / 'run' / 'journal.jsonl'
    goal = PaintPattern.Goal(image_path='sample:logo', n_p_target=30, canvas_size=0.08)
    with JournalWriter(str(path)) as writer:
        writer.run(goal, started=100.0, wall_started=1.7e9)
        writer.dot(**DOT)
        # flushed per line: another reader sees both lines while the writer is open
        assert len(path.read_text().splitlines()) == 2
        writer.dot(**{**DOT, 'index': 1, 'outcome': 'skipped', 'reason': 'unreachable',
                      'restarts': 2})
        writer.result(success=False, dots_burnt=1, dots_skipped=1, duration=40.0,
                      wall_duration=12.5, message='1 dot unreachable')
    journal = read_journal(str(path))
    assert journal.run.goal['image_path'] == 'sample:logo'
    assert journal.run.goal['n_p_target'] == 30
    assert journal.run.started == 100.0
    assert [d.index for d in journal.dots] == [0, 1]
    assert journal.dots[0].target == [0.06, 0.062] and journal.dots[0].dwell == 18.2
    assert journal.dots[1].reason == 'unreachable' and journal.dots[1].restarts == 2
    assert journal.dots[0].restarts == 0
    assert journal.result.dots_burnt == 1 and journal.result.success is False
    assert not journal.truncated
    # every line is one JSON object with the documented keys
    first, *_ = [json.loads(line) for line in path.read_text().splitlines()]
    assert set(first) == {'kind', 'goal', 'started', 'wall_started', 'dot_calibration_s'}


def test_a_dot_line_from_before_restarts_were_counted_reads_as_none(tmp_path):
    path = tmp_path / 'journal.jsonl'
    path.write_text(json.dumps({'kind': 'run', 'goal': {}, 'started': 0.0,
                                'wall_started': 0.0}) + '\n'
                    + json.dumps({**DOT, 'kind': 'dot'}) + '\n')
    assert read_journal(str(path)).dots[0].restarts == 0


def test_a_line_cut_off_by_a_crash_is_flagged_and_the_finished_dots_kept(tmp_path):
    path = tmp_path / 'journal.jsonl'
    with JournalWriter(str(path)) as writer:
        writer.run({'image_path': 'x.png'}, 0.0, 0.0)
        writer.dot(**DOT)
    with open(path, 'a') as stream:
        stream.write('{"kind": "dot", "index": 1, "tar')
    journal = read_journal(str(path))
    assert journal.truncated and len(journal.dots) == 1 and journal.result is None


@pytest.mark.parametrize('line, message', [
    ('not json', 'not JSON'),
    ('{"kind": "dot"}', 'misses'),
    ('{"kind": "paint"}', 'unknown kind'),
    (json.dumps({**DOT, 'kind': 'dot', 'outcome': 'charred'}), 'outcome must be one of'),
    (json.dumps({**DOT, 'kind': 'dot', 'target': [1.0]}), 'target must be'),
    (json.dumps({**DOT, 'kind': 'dot', 'peak_n_p': -3}), 'peak_n_p must be a count'),
])
def test_a_malformed_line_is_refused_with_its_line_number(tmp_path, line, message):
    path = tmp_path / 'journal.jsonl'
    path.write_text(json.dumps({'kind': 'run', 'goal': {}, 'started': 0, 'wall_started': 0})
                    + '\n' + line + '\n')
    with pytest.raises(JournalError, match=message) as raised:
        read_journal(str(path))
    assert ':2:' in str(raised.value)


def test_records_out_of_order_are_refused(tmp_path):
    path = tmp_path / 'journal.jsonl'
    path.write_text(json.dumps({**DOT, 'kind': 'dot'}) + '\n')
    with pytest.raises(JournalError, match='before the run line'):
        read_journal(str(path))


def test_the_writer_refuses_a_bad_record_and_writes_nothing(tmp_path):
    path = tmp_path / 'journal.jsonl'
    with JournalWriter(str(path)) as writer:
        with pytest.raises(JournalError, match='dwell must be finite'):
            writer.dot(**{**DOT, 'dwell': float('nan')})
    assert path.read_text() == ''


def test_a_goal_becomes_plain_json_without_the_image_bytes():
    image = Image(width=4, height=2, encoding='mono8', step=4, data=bytes(8))
    goal = PaintPattern.Goal(image=image, points=[Point(x=0.05, y=0.06, z=0.0)],
                             dry_run=True)
    data = goal_to_dict(goal)
    json.dumps(data)                                   # plain JSON values only
    assert data['image']['width'] == 4 and data['image']['data_bytes'] == 8
    assert 'data' not in data['image']
    assert data['points'] == [{'x': 0.05, 'y': 0.06, 'z': 0.0}]
    assert data['dry_run'] is True
    assert set(data) == set(PaintPattern.Goal.get_fields_and_field_types())
    assert goal_to_dict(np.array([1.0, 2.0])) == [1.0, 2.0]
