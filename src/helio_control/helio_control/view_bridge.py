"""
Node view_bridge: the graph live in the Foxglove app, over Foxglove's WebSocket protocol.

A Foxglove WebSocket server (``foxglove-sdk``) on ``host``:``port`` (localhost by default)
offers these channels (names under the graph's namespace):

- ``/rgb/image_raw`` and ``/thermal/image_raw``: the camera images as the graph sends them
  (``cdr`` with their ``ros2msg`` schema, as in the recording), at most one every
  ``rgb_period`` / ``thermal_period`` seconds of wall time;
- ``/thermal/stats`` (cdr): every message, for the plots of T_max and N_p;
- ``/view/rgb/annotations``, ``/view/thermal/annotations`` (``foxglove.ImageAnnotations``),
  ``/view/scene``, ``/view/sun_truth`` (``foxglove.SceneUpdate``) and ``/view/metrics``
  (``helio.ViewMetrics``), JSON with a JSON schema, drawn by ``view_model.ViewModel``
  at each image forwarded and stamped with that image's stamp (``plan_file``: the run's
  plan.json, for the next targets).

It never slows the graph: it is its own process; every subscription keeps the newest
message only (depth 1, best effort, latched topics transient local); images are decimated
by wall time before anything is converted, and nothing is drawn while no client subscribes;
the server keeps at most ``message_backlog_size`` messages per client and drops the oldest
for a slow client.
"""

import os
import sys
import threading
import time

import foxglove
from helio_control.bag_files import full_type_name, message_class, message_definition
from helio_control.view_model import cdr_stamp_ns, INPUTS, output_schema_bytes, OUTPUTS
from helio_control.view_model import PlanFile, RGB_IMAGE, THERMAL_IMAGE, ViewModel
from helio_optics.node_kit import topics
from helio_optics.node_kit.deployment import declare_rig
from helio_optics.node_kit.parameters import declare
from helio_optics.node_kit.runner import run_node
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message

# Longest wait for the server to stop [s]: a client that stopped reading holds its close
# handshake for tens of seconds (50 s measured with a client whose socket was full).
STOP_TIMEOUT = 2.0
LATCHED_INPUTS = (topics.SUN_ESTIMATE, topics.THERMAL_WINDOW, 'sim/truth/sun_direction')
FORWARDED = {RGB_IMAGE: 'sensor_msgs/msg/Image', THERMAL_IMAGE: 'sensor_msgs/msg/Image',
             topics.THERMAL_STATS: 'helio_msgs/msg/ThermalStats'}
NEWEST_ONLY = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.BEST_EFFORT)
NEWEST_LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                            reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.TRANSIENT_LOCAL)


def declare_view_model(node):
    """Declare the view's parameters on `node`; return (ViewModel, PlanFile)."""
    marker_side = declare(node, 'marker_side', 0.04, 'ArUco marker black square, as the '
                          "spot detector's [m].", 0.001, 1.0)
    panel_extent = declare(node, 'panel_extent', [-0.04, 0.16, -0.04, 0.16], 'The wood '
                           'around the marker: x0, x1, y0, y1 in the world frame [m].')
    rig, _ = declare_rig(node)
    plan_file = declare(node, 'plan_file', '', "The painting's plan.json, read when it "
                        'appears or changes: the next targets (empty: none).')
    return ViewModel(rig, marker_side, panel_extent), PlanFile(plan_file)


def ros_channel(topic, type_name, context=None):
    """Return a foxglove Channel carrying a ROS 2 type as CDR (schema: its ros2msg text)."""
    type_name = full_type_name(type_name)
    schema = foxglove.Schema(name=type_name, encoding='ros2msg',
                             data=message_definition(type_name).encode())
    return foxglove.Channel(topic, schema=schema, message_encoding='cdr', context=context)


def json_channel(topic, schema_name, context=None):
    """Return a foxglove Channel of JSON messages with their JSON schema."""
    schema = foxglove.Schema(name=schema_name, encoding='jsonschema',
                             data=output_schema_bytes(schema_name))
    return foxglove.Channel(topic, schema=schema, message_encoding='json', context=context)


class ViewBridgeNode(Node):
    """Subscribe, decimate, draw and log to the Foxglove server (module docstring)."""

    stuck = False                        # the server's stop outlived STOP_TIMEOUT

    def __init__(self, **kwargs):
        """Declare the parameters, start the server, create the channels and subscriptions."""
        super().__init__('view_bridge', **kwargs)
        host = declare(self, 'host', '127.0.0.1', 'Address the WebSocket server binds to '
                       '(127.0.0.1: this machine only).')
        port = declare(self, 'port', 8765, 'WebSocket port (0: any free port, logged).', 0,
                       65535)
        self.periods = {
            RGB_IMAGE: declare(self, 'rgb_period', 0.5, 'Shortest wall time between two RGB '
                               'images forwarded (with their annotations and the scene) [s].',
                               0.0, 60.0),
            THERMAL_IMAGE: declare(self, 'thermal_period', 0.25, 'Shortest wall time between '
                                   'two thermal images forwarded [s].', 0.0, 60.0)}
        backlog = declare(self, 'message_backlog_size', 16, 'Messages queued per client; a '
                          'slow client loses the oldest [-].', 1, 1024)
        self.model, self.plan = declare_view_model(self)
        self.server = foxglove.start_server(name='helio', host=host, port=port,
                                            message_backlog_size=backlog)
        self.port = self.server.port
        self.channels = {}
        for topic, type_name in FORWARDED.items():
            self.channels[topic] = ros_channel(self.resolve_topic_name(topic), type_name)
        prefix = self.get_namespace().rstrip('/')
        for topic, schema_name in OUTPUTS.items():
            self.channels[topic] = json_channel(prefix + topic, schema_name)
        self._last_forward = dict.fromkeys(FORWARDED, -float('inf'))
        self.counts = dict.fromkeys(self.channels, 0)
        for topic, (type_name, _) in INPUTS.items():
            self.create_subscription(message_class(type_name), topic, self._input(topic),
                                     NEWEST_LATCHED if topic in LATCHED_INPUTS
                                     else NEWEST_ONLY, raw=True)
        for topic in (RGB_IMAGE, THERMAL_IMAGE):
            self.create_subscription(message_class(FORWARDED[topic]), topic,
                                     self._image(topic), NEWEST_ONLY, raw=True)
        self.get_logger().info(f'Foxglove WebSocket server on ws://{host}:{self.port} '
                               f'(open it in the Foxglove app: Open connection, Foxglove '
                               'WebSocket)')

    def _input(self, topic):
        cls = message_class(INPUTS[topic][0])
        forwarded = self.channels.get(topic)

        def take(data):
            self.model.feed(topic, deserialize_message(data, cls))
            if forwarded is not None and forwarded.has_sinks():
                self._log(topic, bytes(data), cdr_stamp_ns(data))
        return take

    def _image(self, topic):
        def take(data):
            now = time.monotonic()
            if now - self._last_forward[topic] < self.periods[topic]:
                return                   # dropped: the bridge forwards the newest only
            self._last_forward[topic] = now
            stamp_ns = cdr_stamp_ns(data)
            if self.channels[topic].has_sinks():
                self._log(topic, bytes(data), stamp_ns)
            if not any(self.channels[output].has_sinks() for output in OUTPUTS):
                return                   # nobody looks: nothing drawn
            if topic == RGB_IMAGE:
                problem = self.plan.refresh(self.model)
                if problem:
                    self.get_logger().warning(problem, once=True)
            for output, message in self.model.outputs_for_image(topic, stamp_ns):
                if self.channels[output].has_sinks():
                    self._log(output, message, stamp_ns)
        return take

    def _log(self, topic, message, stamp_ns):
        self.channels[topic].log(message, log_time=stamp_ns)
        self.counts[topic] += 1

    def destroy_node(self):
        """Log what was sent, stop the server (at most `STOP_TIMEOUT`), then destroy."""
        self.get_logger().info('messages sent: ' + ', '.join(
            f'{topic} {count}' for topic, count in sorted(self.counts.items())))
        stopping = threading.Thread(target=self.server.stop, daemon=True)
        stopping.start()
        stopping.join(STOP_TIMEOUT)
        if stopping.is_alive():
            self.get_logger().warning(f'the server did not stop within {STOP_TIMEOUT:g} s (a '
                                      'client that does not read): leaving without it')
            ViewBridgeNode.stuck = True
        return super().destroy_node()


def main(args=None):
    """Run the view bridge until Ctrl-C."""
    run_node(ViewBridgeNode, args)
    if ViewBridgeNode.stuck:
        # the server's shutdown at exit would wait on that client's close handshake (tens
        # of seconds, measured): the node is destroyed and rclpy shut down, nothing is left
        # to save
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)


if __name__ == '__main__':
    main()
