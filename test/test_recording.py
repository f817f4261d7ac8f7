"""
The recorder as a process beside the simulated graph.

What it writes, and what a SIGKILL leaves.

The bag is checked with two readers that share no code with the writer: ``rosbags`` (it
parses the ``ros2msg`` schemas, recomputes every type hash and decodes every message) and
``mcap``'s own reader (summary, chunk indexes, statistics). After a SIGKILL the file has no
footer: ``mcap``'s streaming reader still reads every complete chunk, and
``helio record --recover`` makes it a complete bag again that both open.
"""

import os
from pathlib import Path
import signal
import subprocess
import sys

from conftest import graph_of_processes
from helio_control.bag_files import bag_file, is_complete, salvage_records
from helio_control.bringup import node_environment, wait_for_devices
from helio_control.recorder import Recorder, recorder_subscribed
from helio_msgs.msg import ThermalStats
from helio_optics.node_kit.conversions import stamp_to_nanoseconds
from mcap.reader import make_reader
import numpy as np
import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosbags.highlevel import AnyReader
from rosgraph_msgs.msg import Clock
import yaml

THERMAL_RATE = 8.7                      # the world's thermal frames per simulated second
LOSS_BOUND = int(4.0 * (0.5 + 2.0) * 1e9)     # ns of simulated time
NODES = ('sim_world', 'dobot_driver', 'servo_driver', 'thermal_monitor')
# 2x: the recording is under test, not the pace; at 4x the compiled world sends 35 thermal
# frames a second of wall time and the thermal monitor, beside the rest, answered 41 of 140
WORLD = {'sim_world': {'real_time_factor': 2.0, 'flux_rays': 5000,
                       'thermal_rate': THERMAL_RATE}}
EXPECTED = {   # topic: (type, the least count that is plausible for the run)
    '/clock': ('rosgraph_msgs/msg/Clock', 20),
    '/joint_states': ('sensor_msgs/msg/JointState', 20),
    '/rgb/image_raw': ('sensor_msgs/msg/Image', 2),
    '/rgb/camera_info': ('sensor_msgs/msg/CameraInfo', 2),
    '/thermal/image_raw': ('sensor_msgs/msg/Image', 2),
    '/thermal/stats': ('helio_msgs/msg/ThermalStats', 10),
    '/dobot/status': ('helio_msgs/msg/DeviceStatus', 1),
    '/diagnostics': ('diagnostic_msgs/msg/DiagnosticArray', 1),
    '/sim/truth/sun_direction': ('geometry_msgs/msg/Vector3Stamped', 1),
    '/move_arm/_action/status': ('action_msgs/msg/GoalStatusArray', 0),
    '/move_arm/_action/feedback': ('helio_msgs/action/MoveArm_FeedbackMessage', 0),
}


def record_graph(tmp_path, stats_to_wait_for, kill=False):
    """
    Record the graph until `stats_to_wait_for` ThermalStats passed.

    Return the bag directory and the last /clock the test itself received before the
    recorder was stopped or killed [ns].
    """
    bag = str(tmp_path / 'bag')
    counted = {topic for topic, (_, least) in EXPECTED.items() if least > 0}
    with graph_of_processes(tmp_path, NODES, WORLD) as (_, graph):
        # the drivers' joint_states are among what is counted: recorded from when both
        # drivers hold their devices (on a slow machine the world opened its ports 3.9 s
        # after the drivers started, and they connected 2.3 s later, as the recording ended)
        wait_for_devices(graph, 60.0)
        clock = graph.collect(Clock, '/clock', QoSProfile(
            depth=10, reliability=ReliabilityPolicy.BEST_EFFORT))
        stats = graph.collect(ThermalStats, 'thermal/stats',
                              QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        # chunks close at 0.5 s of wall time or 256 KiB (an RGB frame is 900 KiB)
        recorder = Recorder(bag, camera_decimation=4, use_sim_time=True,
                            log_dir=str(tmp_path / 'logs'), chunk_period=0.5,
                            chunk_size_bytes=256 << 10, env=node_environment()).start()
        try:
            recorder.start_wait(60.0)
            # counted from when the recorder subscribed to every topic counted below (the
            # world may run far ahead of its start-up): it finds them by discovery, every
            # 0.5 s, and on a slow machine the drivers' topics showed up there 2 s after the
            # world's, as a short recording ended (3 joint_states)
            graph.wait_until(lambda: recorder_subscribed(graph.helper, counted), 60.0,
                             f'the recorder subscribing to {sorted(counted)}')
            stats.wait_for_count(len(stats.messages) + stats_to_wait_for, 120.0)
            # and until chunks are on disk: the recorder discovers topics and closes chunks on
            # its own wall-clock schedule, which a 4x world can outrun
            graph.wait_until(lambda: len(chunks_on_disk(bag)) >= 3, 120.0,
                             'three chunks of the recording on disk')
        finally:
            last_clock = stamp_to_nanoseconds(clock.messages[-1].clock)
            if kill:
                recorder.kill()
            else:
                recorder.stop()
    return bag, last_clock


def chunks_on_disk(bag):
    """Return the complete Chunk records in the bag's file so far (being written or cut)."""
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader
    chunks = []
    try:
        with open(bag_file(bag), 'rb') as stream:
            for record in StreamReader(stream, emit_chunks=True).records:
                if isinstance(record, Chunk):
                    chunks.append(record)
    except Exception:   # noqa: B902 - no file yet, or the record being written
        pass
    return chunks


def header_stamps(bag, topic):
    """Open with rosbags; return the header stamps of `topic`'s messages in order [ns]."""
    stamps = []
    with AnyReader([Path(bag)]) as reader:
        connections = [c for c in reader.connections if c.topic == topic]
        for connection, _, raw in reader.messages(connections=connections):
            stamps.append(stamp_to_nanoseconds(
                reader.deserialize(raw, connection.msgtype).header.stamp))
    return sorted(stamps)


def rosbags_counts(bag):
    """Open with rosbags, decode every message; return {topic: (type, count)}."""
    counts = {}
    with AnyReader([Path(bag)]) as reader:
        for connection, _, raw in reader.messages():
            reader.deserialize(raw, connection.msgtype)        # every message decodes
            previous = counts.get(connection.topic, (connection.msgtype, 0))
            counts[connection.topic] = (connection.msgtype, previous[1] + 1)
        for connection in reader.connections:
            counts.setdefault(connection.topic, (connection.msgtype, 0))
    return counts


def mcap_counts(bag):
    """Open with mcap's reader; return ({topic: (schema, count)}, summary)."""
    with open(bag_file(bag), 'rb') as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        counts = {}
        for schema, channel, _ in reader.iter_messages():
            previous = counts.get(channel.topic, (schema.name, 0))
            counts[channel.topic] = (schema.name, previous[1] + 1)
        for channel in summary.channels.values():
            counts.setdefault(channel.topic, (summary.schemas[channel.schema_id].name, 0))
    return counts, summary


def test_a_recording_of_the_graph_opens_with_rosbags_and_mcap_with_every_topic(tmp_path):
    bag, _ = record_graph(tmp_path, 40)
    with open(os.path.join(bag, 'metadata.yaml')) as stream:
        metadata = yaml.safe_load(stream)['rosbag2_bagfile_information']
    assert metadata['storage_identifier'] == 'mcap' and metadata['version'] == 9
    from_rosbags = rosbags_counts(bag)
    from_mcap, summary = mcap_counts(bag)
    assert from_rosbags == from_mcap
    for topic, (type_name, least) in EXPECTED.items():
        assert topic in from_mcap, f'{topic} not recorded ({sorted(from_mcap)})'
        assert from_mcap[topic][0] == type_name
        assert from_mcap[topic][1] >= least, (topic, from_mcap[topic])
    # camera topics decimated: every 4th thermal frame recorded, so recorded images lie 4
    # frame periods of the world's 8.7 Hz apart (the median: a frame the recorder missed
    # makes one gap of 5). Counted against thermal/stats instead, the ratio measured how
    # many frames the thermal monitor answered on a loaded machine, not the decimation.
    gaps = np.diff(header_stamps(bag, '/thermal/image_raw')) * 1e-9
    assert np.median(gaps) * THERMAL_RATE == pytest.approx(4.0, abs=0.5), gaps
    # rosbag2_storage_mcap's conventions
    channel = next(c for c in summary.channels.values() if c.topic == '/thermal/stats')
    assert channel.message_encoding == 'cdr'
    assert summary.schemas[channel.schema_id].encoding == 'ros2msg'
    assert channel.metadata['topic_type_hash'].startswith('RIHS01_')
    offered = yaml.safe_load(channel.metadata['offered_qos_profiles'])
    assert offered[0]['reliability'] == 'reliable'
    assert summary.statistics.chunk_count > 1 and summary.chunk_indexes
    assert all(index.compression == 'zstd' for index in summary.chunk_indexes)
    assert sum(t['message_count'] for t in metadata['topics_with_message_count']) == \
        summary.statistics.message_count


def test_after_a_sigkill_the_bag_keeps_all_but_its_last_chunk(tmp_path):
    bag, last_clock = record_graph(tmp_path, 40, kill=True)
    path = bag_file(bag)
    assert not is_complete(path)
    # mcap's streaming reader reads the killed file as it is, up to the cut
    schemas, channels, messages, complete = salvage_records(path)
    assert not complete and messages
    topics = {channels[m.channel_id].topic for m in messages}
    assert {'/clock', '/joint_states', '/thermal/stats'} <= topics
    # the chunks' own message indexes (written after each chunk) bound what was lost: every
    # message of every chunk that reached the file is read back
    in_chunks = sum(len(_chunk_messages(chunk)) for chunk in chunks_on_disk(bag))
    assert len(messages) == in_chunks
    # and what was lost is at most the open chunk: chunk_period (0.5 s wall) plus the
    # writer's queue and the kill's latency (2 s on a loaded machine), at 4 simulated s per s
    last_kept = max(m.log_time for m in messages if channels[m.channel_id].topic == '/clock')
    assert last_clock - last_kept <= LOSS_BOUND, (last_clock - last_kept) * 1e-9
    # the metadata written after every chunk names the file, so rosbag2 tools find it
    with open(os.path.join(bag, 'metadata.yaml')) as stream:
        assert yaml.safe_load(stream)['rosbag2_bagfile_information']['relative_file_paths']
    # helio record --recover: a complete bag again, every salvaged message in it
    done = subprocess.run([sys.executable, '-m', 'helio_control.cli', 'record', '--recover',
                           bag], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert f'{len(messages)} messages kept' in done.stdout
    assert is_complete(path)
    from_rosbags = rosbags_counts(bag)
    from_mcap, _ = mcap_counts(bag)
    assert from_rosbags == from_mcap
    assert sum(count for _, count in from_mcap.values()) == len(messages)


def _chunk_messages(chunk):
    from mcap.records import Message
    from mcap.stream_reader import breakup_chunk
    return [r for r in breakup_chunk(chunk, validate_crc=True) if isinstance(r, Message)]


@pytest.mark.parametrize('arguments, message', [
    (['record'], 'record needs --out'),
    (['record', '--recover', '/nonexistent/bag'], 'is not a bag'),
    (['replay', '/nonexistent/bag'], 'is not a bag'),
])
def test_record_and_replay_refuse_bad_input_in_one_line(arguments, message):
    done = subprocess.run([sys.executable, '-m', 'helio_control.cli', *arguments],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode in (1, 2) and message in done.stderr
    assert 'Traceback' not in done.stderr


def test_sigint_closes_the_bag(tmp_path):
    """The recorder stopped by SIGINT (Ctrl-C) writes summary and footer."""
    bag = str(tmp_path / 'bag')
    recorder = Recorder(bag, log_dir=str(tmp_path / 'logs')).start()
    recorder.process.signal(signal.SIGINT)
    recorder.process.process.wait(30.0)
    assert recorder.process.returncode() == 0, recorder.process.tail()
    assert is_complete(bag_file(bag))
