"""
Bags written by bag_files, checked by readers that share no code with it.

``rosbags`` parses the written ``ros2msg`` schemas, recomputes each type's RIHS01 hash from
them (it must equal the installed interface's hash) and decodes the messages; ``mcap``'s
reader checks the summary, indexes and chunk CRCs; ``mcap_ros2`` (Foxglove's parser)
decodes the message types it accepts.
"""

import os
from pathlib import Path

from geometry_msgs.msg import Point
from helio_control.bag_files import _field_type_to_msg, type_hash
from helio_control.bag_files import bag_file, BagError, BagWriter, changed_types, decode_messages
from helio_control.bag_files import is_complete, message_definition, qos_profile_dict
from helio_control.bag_files import read_topics, recover_bag, salvage_records, TopicInfo
from helio_msgs.action import PaintPattern
from helio_msgs.msg import SpotObservation, ThermalStats
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import pytest
from rclpy.serialization import serialize_message
from rosbags.highlevel import AnyReader
from sensor_msgs.msg import CameraInfo

SECOND = 10**9


class FakeClock:
    """A clock the test advances: when chunks close by time is the test's choice."""

    def __init__(self):
        """Start at 0 s."""
        self.now = 0.0

    def __call__(self):
        """Return the time [s]."""
        return self.now


def messages(count):
    """Return `count` (topic, message) pairs of three types."""
    result = []
    for i in range(count):
        result.append(('/thermal/stats', ThermalStats(t_max=20.0 + i, n_p=i)))
        spot = SpotObservation(valid=i % 2 == 0, area=1e-6 * i,
                               contour=[Point(x=0.01 * i, y=0.02, z=0.0)])
        result.append(('/spot', spot))
        feedback = PaintPattern.Impl.FeedbackMessage()
        feedback.feedback.index, feedback.feedback.phase = i, 'heating'
        result.append(('/paint/_action/feedback', feedback))
    return result


TYPES = {'/thermal/stats': 'helio_msgs/msg/ThermalStats',
         '/spot': 'helio_msgs/msg/SpotObservation',
         '/paint/_action/feedback': 'helio_msgs/action/PaintPattern_FeedbackMessage'}


def write_bag(directory, items, chunk_size=2000, clock=None):
    """Write `items` one per 0.1 s of log time; return the writer (closed)."""
    writer = BagWriter(str(directory), chunk_size=chunk_size, chunk_period=1e9,
                       clock=clock or FakeClock())
    for name, type_name in TYPES.items():
        writer.add_topic(TopicInfo(name, type_name, [qos_profile_dict()]))
    for i, (topic, message) in enumerate(items):
        writer.write(topic, SECOND + i * SECOND // 10, serialize_message(message))
    writer.close()
    return writer


def test_a_bag_reads_back_equal_with_rosbags_mcap_and_rclpy(tmp_path):
    items = messages(40)
    write_bag(tmp_path / 'bag', items)
    # rclpy decoding through our reader: equal messages in order
    decoded = [(topic, message) for topic, _, message in decode_messages(str(tmp_path / 'bag'))]
    assert decoded == items
    # rosbags: hashes recomputed from our schema text, every message decoded
    with AnyReader([Path(tmp_path / 'bag')]) as reader:
        seen = [(c.topic, reader.deserialize(raw, c.msgtype)) for c, _, raw in reader.messages()]
        types = {c.topic: c.msgtype for c in reader.connections}
    assert types == TYPES
    assert [t for t, _ in seen] == [t for t, _ in items]
    assert [m.t_max for t, m in seen if t == '/thermal/stats'] == \
        [m.t_max for t, m in items if t == '/thermal/stats']
    assert [m.feedback.index for t, m in seen if t.endswith('feedback')] == list(range(40))
    # mcap's reader with Foxglove's ros2msg parser (it refuses action-part type names)
    with open(bag_file(str(tmp_path / 'bag')), 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        spots = [m for _, _, _, m in reader.iter_decoded_messages(topics=['/spot'])]
        summary = reader.get_summary()
    assert [s.area for s in spots] == [m.area for t, m in items if t == '/spot']
    assert summary.statistics.message_count == 120 and summary.statistics.chunk_count > 3
    assert {c.topic: read_topics(str(tmp_path / 'bag'))[c.topic].message_count
            for c in summary.channels.values()} == dict.fromkeys(TYPES, 40)


def test_a_bag_of_an_older_message_definition_is_named_not_misread(tmp_path):
    # a recording made before ThermalStats gained fields: its hash is not the installed one
    older = 'RIHS01_' + '0' * 64
    writer = BagWriter(str(tmp_path / 'bag'), clock=FakeClock())
    writer.add_topic(TopicInfo('/thermal/stats', 'helio_msgs/msg/ThermalStats',
                               [qos_profile_dict()], type_hash=older))
    writer.add_topic(TopicInfo('/spot', 'helio_msgs/msg/SpotObservation', [qos_profile_dict()]))
    writer.write('/thermal/stats', SECOND, serialize_message(ThermalStats(n_p=3)))
    writer.write('/spot', SECOND, serialize_message(SpotObservation(area=1e-6)))
    writer.close()
    topics = read_topics(str(tmp_path / 'bag'))
    assert changed_types(topics.values()) == {
        'helio_msgs/msg/ThermalStats': (older, type_hash('helio_msgs/msg/ThermalStats'))}
    with pytest.raises(BagError, match='older definition of helio_msgs/msg/ThermalStats.*'
                                       're-record'):
        list(decode_messages(str(tmp_path / 'bag')))
    # the topics of unchanged types still read
    assert [m.area for _, _, m in decode_messages(str(tmp_path / 'bag'), ['/spot'])] == [1e-6]


def test_schemas_are_the_installed_definitions_with_their_nested_types():
    text = message_definition('sensor_msgs/msg/CameraInfo')
    from ament_index_python.packages import get_package_share_directory
    with open(os.path.join(get_package_share_directory('sensor_msgs'), 'msg',
                           'CameraInfo.msg')) as stream:
        assert text.startswith(stream.read())
    for nested in ('std_msgs/Header', 'builtin_interfaces/Time', 'sensor_msgs/RegionOfInterest'):
        assert text.count(f'\n{"=" * 80}\nMSG: {nested}\n') == 1
    assert type_hash('sensor_msgs/msg/CameraInfo').startswith('RIHS01_')
    assert CameraInfo       # the type the text describes is installed


def test_chunks_close_by_time_so_a_crash_loses_at_most_the_open_one(tmp_path):
    clock = FakeClock()
    writer = BagWriter(str(tmp_path / 'bag'), chunk_size=1 << 30, chunk_period=1.0,
                       clock=clock)
    writer.add_topic(TopicInfo('/thermal/stats', TYPES['/thermal/stats']))
    for i in range(30):                      # 3 s of messages, 10 per second
        clock.now = 0.1 * i
        writer.write('/thermal/stats', SECOND + i * SECOND // 10,
                     serialize_message(ThermalStats(n_p=i)))
    # the writer is "killed" here: not closed; what reached the file:
    path = bag_file(str(tmp_path / 'bag'))
    assert not is_complete(path)
    _, _, salvaged, complete = salvage_records(path)
    assert not complete
    # a chunk closes with the message that finds it open >= 1 s: the first holds the
    # messages at 0.0..1.0 s (11), the second 1.1..2.1 s (11); 2.2..2.9 s (8) were open
    assert [m.sequence for m in salvaged] == list(range(1, 23))
    assert recover_bag(str(tmp_path / 'bag')) == 22
    assert is_complete(path) and recover_bag(str(tmp_path / 'bag')) is None
    with AnyReader([Path(tmp_path / 'bag')]) as reader:
        assert reader.message_count == 22


def test_a_bag_is_not_written_over_and_bad_settings_are_named(tmp_path):
    write_bag(tmp_path / 'bag', messages(1))
    with pytest.raises(BagError, match='already holds a bag'):
        BagWriter(str(tmp_path / 'bag'))
    with pytest.raises(BagError, match='compression must be one of'):
        BagWriter(str(tmp_path / 'other'), compression='gzip')
    writer = BagWriter(str(tmp_path / 'third'))
    with pytest.raises(BagError, match='was not added'):
        writer.write('/nothing', 0, b'')
    writer.close()
    with pytest.raises(BagError, match='not installed'):
        message_definition('no_such_msgs/msg/Thing')
    with pytest.raises(BagError, match='is not a bag'):
        read_topics(str(tmp_path))


@pytest.mark.parametrize('idl, msg', [
    ('double', 'float64'), ('boolean', 'bool'), ('octet', 'byte'), ('float', 'float32'),
    ('sequence<double>', 'float64[]'), ('sequence<int32, 5>', 'int32[<=5]'),
    ('double[9]', 'float64[9]'), ('string<8>', 'string<=8'),
    ('sequence<geometry_msgs/Point>', 'geometry_msgs/Point[]'), ('uint8[16]', 'uint8[16]'),
])
def test_generated_definitions_spell_field_types_as_msg_files_do(idl, msg):
    assert _field_type_to_msg(idl) == msg


def test_the_recording_benchmark_writes_flat_json(tmp_path):
    from helio_control import bench_recording
    import json
    status = bench_recording.main(['--frames', '2', '--json', str(tmp_path / 'b.json')])
    assert status in (0, None)
    figures = json.loads((tmp_path / 'b.json').read_text())
    assert figures['write_rgb_640x480_zstd_frames_per_s'] > 0
    assert 0 < figures['write_thermal_160x120_zstd_size_ratio'] < 1.0    # zstd compresses
