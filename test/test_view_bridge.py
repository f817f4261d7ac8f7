"""
The live Foxglove view (issue 33): the view bridge's pieces, and its parameter file.

The bridge beside the simulated graph painting is tested in ``test_painter.py``'s graph
(``test_the_view_bridge_streams_the_painting_and_leaves_its_timing_alone``), as the graph
is started, calibrated and its sun estimated there once for every painting test. This module
holds what that test uses: the bridge process on a free port (``start_bridge``), the
painted dot (``paint_dot``), the checks of the streamed channels (``well_formed``), of the
recording (``check_recording``) and of the shipped layout (``layout_topics``).
"""

import glob
import json
import os
from pathlib import Path
import re
import time

from conftest import REPO
from geometry_msgs.msg import Point
from helio_control.bag_files import bag_file, VIEW_FILE
from helio_control.bringup import node_environment
from helio_control.run_journal import read_journal
from helio_control.view_scene import schema_errors
from helio_msgs.action import PaintPattern
from helio_optics.node_kit.processes import NodeProcess
from mcap.reader import make_reader
from rclpy.serialization import deserialize_message
from rosbags.highlevel import AnyReader
from sensor_msgs.msg import Image

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
