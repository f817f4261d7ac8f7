"""
The live Foxglove view (issue 33): the view bridge beside the simulated graph painting.

One graph (the painter's nodes, the world at 6x). A first goal paints one dot with no bridge
running (it also calibrates robot-world and sweeps for the sun, as a painting's start does).
Then the bridge starts (port 0: the OS picks one) and three clients connect over the
Foxglove WebSocket protocol (``foxglove_ws``, written from the protocol's text): one reads
everything, one subscribes and never reads again (a slow client), one subscribes and
vanishes. A second goal paints one dot, a third another. The reading client must receive
well-formed messages of the advertised schemas on the annotated RGB, thermal and scene
channels while those dots are painted, and the painter's per-dot figures (dwell and the time
from the move to the cool-down, simulated seconds, from its journal) must stay within noise
of the dot without the bridge. The figures are printed.

The recorder records the whole run, as ``helio paint`` does: the bag opens with ``rosbags``
and ``mcap``'s reader, and the view's drawings (``view.mcap`` in the bag directory) hold
the annotation and scene topics. The shipped layout (config/foxglove/helio.json) names only
topics that both the live bridge and the recording carry.
"""

import glob
import json
import os
from pathlib import Path
import re
import time

from conftest import graph_of_processes, REPO
from foxglove_ws import FoxgloveClient
from geometry_msgs.msg import Point
from helio_control.bag_files import bag_file, VIEW_FILE
from helio_control.bringup import node_environment
from helio_control.recorder import Recorder
from helio_control.run_journal import read_journal
from helio_control.view_scene import schema_errors
from helio_msgs.action import PaintPattern
from helio_optics.node_kit.processes import NodeProcess
from mcap.reader import make_reader
import pytest
from rclpy.serialization import deserialize_message
from rosbags.highlevel import AnyReader
from sensor_msgs.msg import Image

NODES = ('sim_world', 'dobot_driver', 'servo_driver', 'spot_detector', 'thermal_monitor',
         'sun_estimator', 'lens_planner', 'painter')
WORLD = {'sim_world': {'real_time_factor': 6.0, 'flux_rays': 20000}}
CHECKED = ('/view/rgb/annotations', '/view/thermal/annotations', '/view/scene',
           '/rgb/image_raw', '/thermal/image_raw')
TIMEOUT = 600.0
LAYOUT = os.path.join(REPO, 'config', 'foxglove', 'helio.json')
# small dots, the window cooling rule: the view is under test, not the charring (the
# painter's own tests burn to the paper's N_p 30)
N_P_TARGET = 15


def start_bridge(tmp_path, timeout=60.0):
    """Start the view bridge process on a free port; return (process, port)."""
    bridge = NodeProcess('helio_control', 'view_bridge', {'port': 0, 'use_sim_time': True},
                         log_dir=str(tmp_path / 'logs'), env=node_environment())
    bridge.start()
    deadline = time.monotonic() + timeout
    while True:
        with open(bridge.log_path) as stream:
            found = re.search(r'ws://127\.0\.0\.1:(\d+)', stream.read())
        if found:
            return bridge, int(found.group(1))
        assert bridge.alive(), f'view_bridge exited: {bridge.tail()}'
        assert time.monotonic() < deadline, 'view_bridge did not start its server'
        time.sleep(0.05)       # polling the log file for the port (no event to wait on)


def cpu_seconds(pid):
    """Return the CPU time (user + system) a process used so far [s] (/proc)."""
    with open(f'/proc/{pid}/stat') as stream:
        fields = stream.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def paint_dot(graph, client, run_dir, x, y):
    """Paint one dot; return (its journal record, the goal's wall time [s])."""
    goal = PaintPattern.Goal(run_dir=str(run_dir), fresh=True, n_p_target=N_P_TARGET,
                             cooling='window', points=[Point(x=x, y=y, z=0.0)])
    started = time.monotonic()
    result = graph.run_goal(client, goal, timeout=TIMEOUT).result
    wall = time.monotonic() - started
    assert result.success, result.message
    (dot,) = read_journal(str(run_dir / 'journal.jsonl')).dots
    return dot, wall


def well_formed(client, topic):
    """Check every message of `topic` against its advertised schema; return them."""
    channel = client.channels[topic]
    messages = client.decoded(topic)
    if channel['encoding'] == 'json':
        assert channel['schemaEncoding'] == 'jsonschema'
        schema = json.loads(channel['schema'])
        for message in messages:
            assert schema_errors(message, schema) == []
    else:
        assert (channel['encoding'], channel['schemaEncoding']) == ('cdr', 'ros2msg')
        for message in messages:
            image = deserialize_message(message, Image)
            assert image.width > 0 and len(image.data) == image.step * image.height
    return messages


def test_the_bridge_streams_the_painting_and_leaves_its_timing_alone(tmp_path):
    bag = str(tmp_path / 'recording')
    with graph_of_processes(tmp_path, NODES, WORLD) as (_, graph):
        painter = graph.action_client(PaintPattern, 'paint', 120.0)
        recorder = Recorder(bag, use_sim_time=True, log_dir=str(tmp_path / 'logs'),
                            chunk_period=0.5, env=node_environment()).start(60.0)
        alone, alone_wall = paint_dot(graph, painter, tmp_path / 'alone', 0.05, 0.05)
        bridge, port = start_bridge(tmp_path)
        reader = FoxgloveClient(port, CHECKED)
        slow = FoxgloveClient(port, CHECKED, read=False)
        vanished = FoxgloveClient(port, CHECKED)
        try:
            assert all(c.subscribed.wait(30.0) for c in (reader, slow, vanished))
            vanished.close()
            cpu_before = cpu_seconds(bridge.pid)
            watched, watched_wall = paint_dot(graph, painter, tmp_path / 'watched', 0.06, 0.05)
            bridge_cpu = cpu_seconds(bridge.pid) - cpu_before
            reader.wait_for({'/view/rgb/annotations': 1, '/view/thermal/annotations': 1,
                             '/view/scene': 1}, 60.0)
            counts = {topic: len(reader.messages[topic]) for topic in CHECKED}
        finally:
            for client in (reader, slow):
                client.close()
            bridge.stop()
            recorder.stop()
        assert bridge.returncode() in (0, -2), bridge.tail()

    rgb = well_formed(reader, '/view/rgb/annotations')
    thermal = well_formed(reader, '/view/thermal/annotations')
    scenes = well_formed(reader, '/view/scene')
    well_formed(reader, '/rgb/image_raw')
    well_formed(reader, '/thermal/image_raw')
    # what was drawn: the marker outline on the RGB image, the hottest point on the thermal,
    # the panel, marker and the lens and camera frames in the scene
    assert any(message['points'] for message in rgb)
    assert all(message['circles'] for message in thermal)
    ids = {entity['id'] for scene in scenes for entity in scene['entities']}
    assert {'panel', 'marker', 'targets', 'lens', 'rgb_camera', 'thermal_camera',
            'sun_estimate'} <= ids
    # annotations are stamped as the image they belong to
    image_stamps = {stamp for stamp, _ in reader.messages['/rgb/image_raw']}
    assert {stamp for stamp, _ in reader.messages['/view/rgb/annotations']} <= image_stamps

    print(f'\nmessages received per channel while a dot was painted: {counts}')
    print(f'the bridge used {bridge_cpu:.1f} s of CPU in {watched_wall:.1f} s '
          f'({100 * bridge_cpu / watched_wall:.0f} % of one core)')
    for name, dot, wall in (('no bridge', alone, alone_wall),
                            ('bridge, 3 clients (1 slow, 1 gone)', watched, watched_wall)):
        print(f'{name}: dwell {dot.dwell:.2f} s, move to cool-down {dot.end - dot.start:.2f} s '
              f'(simulated), goal {wall:.1f} s wall')
    assert watched.dwell == pytest.approx(alone.dwell, rel=0.5)
    assert watched.end - watched.start == pytest.approx(alone.end - alone.start, rel=0.5)

    recorded = check_recording(bag)
    assert layout_topics() <= recorded
    assert layout_topics() <= set(reader.channels)


def test_the_parameter_file_holds_the_code_defaults():
    """config/view_bridge.yaml says what the node declares (as test_parameter_defaults)."""
    import rclpy
    from rclpy.parameter import Parameter
    from helio_control.view_bridge import ViewBridgeNode
    from ament_index_python.packages import get_package_share_directory
    import yaml
    from test_parameter_defaults import flattened, same
    path = os.path.join(get_package_share_directory('helio_control'), 'config',
                        'view_bridge.yaml')
    with open(path) as stream:
        (section,) = yaml.safe_load(stream).values()
    written = dict(flattened(section['ros__parameters']))
    rclpy.init()
    try:
        # port 0 here: the test must not take the default port another run may hold
        node = ViewBridgeNode(parameter_overrides=[Parameter('port', value=0)])
        declared = {key: p.value for key, p in node._parameters.items()}
        node.destroy_node()
    finally:
        rclpy.shutdown()
    assert written['port'] == 8765 and declared['port'] == 0
    differ = {key: (declared.get(key), value) for key, value in written.items()
              if key != 'port' and not same(declared.get(key), value)}
    assert not differ, f'view_bridge.yaml differs from the code: {differ}'


def layout_topics(path=LAYOUT):
    """Return the topics the Foxglove layout names (keys and values starting with '/')."""
    topics = set()

    def walk(value):
        if isinstance(value, dict):
            for key, item in value.items():
                walk(key)
                walk(item)
        elif isinstance(value, list):
            for item in value:
                walk(item)
        elif isinstance(value, str) and value.startswith('/'):
            topics.add(value.split('.')[0])     # a plot path: /topic.field
    with open(path) as stream:
        walk(json.load(stream))
    return topics


def check_recording(bag):
    """Open the bag with rosbags and mcap, the view file with mcap; return all topics."""
    with AnyReader([Path(bag)]) as reader:
        topics = {connection.topic for connection in reader.connections}
        images = [c for c in reader.connections if c.topic == '/rgb/image_raw']
        for connection, _, raw in reader.messages(connections=images):
            assert reader.deserialize(raw, connection.msgtype).width > 0
    with open(bag_file(bag), 'rb') as stream:
        assert {c.topic for c in make_reader(stream).get_summary().channels.values()} \
            == topics
    (view,) = glob.glob(os.path.join(bag, VIEW_FILE))
    drawn = {}
    with open(view, 'rb') as stream:
        reader = make_reader(stream)
        for schema, channel, message in reader.iter_messages():
            assert (channel.message_encoding, schema.encoding) == ('json', 'jsonschema')
            assert schema_errors(json.loads(message.data), json.loads(schema.data)) == []
            drawn[channel.topic] = drawn.get(channel.topic, 0) + 1
    print(f'recording: {len(topics)} ROS topics; view drawings {drawn}')
    assert {'/view/rgb/annotations', '/view/thermal/annotations', '/view/scene',
            '/view/metrics'} <= set(drawn)
    return topics | set(drawn)
