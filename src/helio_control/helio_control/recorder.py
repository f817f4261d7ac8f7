"""
Node recorder: record the graph's topics into a rosbag2/MCAP bag (``helio_control.bag_files``).

What ``ros2 bag record -a --include-hidden-topics -s mcap`` does, in a node: every topic of
the graph as it appears (discovered every ``discovery_period``), including the actions'
hidden ``_action/feedback`` and ``_action/status`` topics, ``/clock``, ``/diagnostics`` and
``/rosout``; ``exclude`` names topics to leave out (default ``/parameter_events``) and
``topics`` restricts the recording to a list. Messages are taken as raw CDR (no
deserialisation) and written by one writer thread. Camera topics (types in
``camera_types``: images, compressed images, camera infos) keep every
``camera_decimation``-th message per topic so a recording stays small; ``topic_decimation``
(``TOPIC=N``) sets it per topic.

The subscription QoS follows the publishers' offered profiles as rosbag2 adapts them:
reliable only when every publisher is reliable, transient-local only when every publisher
is. Each message is logged at the recorder's clock: ROS time, so with ``use_sim_time`` the
bag's time line is the simulated one (messages that arrive before the first ``/clock`` get
its first value).

``Recorder`` runs this node as its own process (the painter's runs and ``helio record``
use it); ``python -m helio_control.recorder`` / the ``recorder`` executable is the node.
Stopping it (SIGINT) closes the bag; a SIGKILL loses at most the last chunk
(``bag_files``).
"""

import atexit
import json
import os
import queue
import threading
import time

from helio_control.bag_files import BagError, BagWriter, COMPRESSIONS, message_class
from helio_control.bag_files import JsonMcapWriter, qos_profile_dict, TopicInfo, VIEW_FILE
from helio_control.view_model import cdr_stamp_ns, INPUTS, output_schema_bytes, OUTPUTS
from helio_control.view_model import RGB_IMAGE, THERMAL_IMAGE
from helio_optics.node_kit.parameters import declare, parameter_descriptor
from helio_optics.node_kit.processes import NodeProcess
from helio_optics.node_kit.runner import run_node
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message

CAMERA_TYPES = ('sensor_msgs/msg/Image', 'sensor_msgs/msg/CompressedImage',
                'sensor_msgs/msg/CameraInfo')


def offered_qos(info):
    """Return a publisher's offered QoS (TopicEndpointInfo) as a rosbag2 v9 dict."""
    qos = info.qos_profile

    def name(policy):
        return policy.name.lower() if hasattr(policy, 'name') else str(policy).lower()

    def duration(value):
        nanoseconds = value.nanoseconds
        return {'sec': nanoseconds // 10**9, 'nsec': nanoseconds % 10**9}
    profile = qos_profile_dict(name(qos.history), qos.depth, name(qos.reliability),
                               name(qos.durability), name(qos.liveliness))
    for key, value in (('deadline', qos.deadline), ('lifespan', qos.lifespan),
                       ('liveliness_lease_duration', qos.liveliness_lease_duration)):
        if value.nanoseconds > 0:
            profile[key] = duration(value)
    return profile


def subscription_qos(profiles, depth=100):
    """Return the QoS to subscribe with, adapted to the publishers' offered `profiles`."""
    reliable = bool(profiles) and all(p['reliability'] == 'reliable' for p in profiles)
    latched = bool(profiles) and all(p['durability'] == 'transient_local' for p in profiles)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE if reliable
                      else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                      else DurabilityPolicy.VOLATILE)


NODE_NAME = 'recorder'


def recorder_subscribed(node, topics):
    """
    Tell whether `node` sees the recorder subscribed to every topic of `topics`.

    The recorder subscribes to topics as it discovers them (``discovery_period``): what a
    recording must hold from its first message is recorded only once this holds.
    """
    return all(any(info.node_name == NODE_NAME
                   for info in node.get_subscriptions_info_by_topic(topic))
               for topic in topics)


class RecorderNode(Node):
    """Subscribe to the graph's topics and hand their raw messages to the bag writer."""

    def __init__(self, **kwargs):
        """Declare the parameters, open the bag, start discovery and the writer thread."""
        super().__init__(NODE_NAME, **kwargs)
        output_dir = declare(self, 'output_dir', '', 'Bag directory to create (must not hold '
                             'a bag) [path].')
        if not output_dir:
            raise ValueError('parameter output_dir is required: the bag directory to create')
        self.topics = self._string_list('topics', 'Topics to record (empty: every topic).')
        self.exclude = set(self._string_list('exclude', 'Topics never recorded.',
                                             ['/parameter_events']))
        self.camera_types = set(self._string_list(
            'camera_types', 'Message types decimated by camera_decimation.',
            list(CAMERA_TYPES)))
        self.decimation = declare(self, 'camera_decimation', 5, 'Keep every N-th message of '
                                  'a camera topic [-].', 1, 10000)
        self.topic_decimation = {}
        for item in self._string_list('topic_decimation', 'Per-topic decimation overriding '
                                      'camera_decimation, as TOPIC=N (any topic).'):
            topic, equals, count = item.rpartition('=')
            if not equals or not count.isdigit() or int(count) < 1:
                raise ValueError(f'parameter topic_decimation: {item!r} is not TOPIC=N (N >= 1)')
            self.topic_decimation[self.resolve_topic_name(topic)] = int(count)
        period = declare(self, 'discovery_period', 0.5, 'Period of looking for new topics '
                         '[s].', 0.05, 60.0)
        chunk_size = declare(self, 'chunk_size_bytes', 4 << 20, 'Uncompressed size at which '
                             'a chunk is closed and written [bytes].', 1024, 1 << 30)
        chunk_period = declare(self, 'chunk_period', 2.0, 'Longest time a chunk stays open: '
                               'what a crash can lose at most [s].', 0.05, 600.0)
        compression = declare(self, 'compression', 'zstd', 'Chunk compression.',
                              choices=sorted(COMPRESSIONS))
        self.topics = {self.resolve_topic_name(t) for t in self.topics}
        self.exclude = {self.resolve_topic_name(t) for t in self.exclude}
        self.bag = BagWriter(output_dir, chunk_size, chunk_period, compression,
                             clock=time.monotonic)
        atexit.register(self.bag.close)   # an interrupt before spin still closes the bag
        view_file = declare(self, 'view_file', VIEW_FILE, 'File of the bag directory the '
                            'drawings of the Foxglove view go to, beside the bag (empty: '
                            'none).')
        self.view = None
        if view_file:
            from helio_control.view_bridge import declare_view_model
            model, plan = declare_view_model(self)
            self.view = ViewRecording(self, model, JsonMcapWriter(
                os.path.join(output_dir, view_file), chunk_size, chunk_period, compression),
                plan)
            atexit.register(self.view.writer.close)
        self.failure = ''
        self._queue = queue.Queue()
        self._recorded = {}
        self._counts = {}
        self._early = []                 # messages received before the clock started
        self._lock = threading.Lock()
        self._writer = threading.Thread(target=self._write_loop, name='bag-writer',
                                        daemon=True)
        self._writer.start()
        self.create_timer(period, self._discover)
        self.get_logger().info(f'recording to {self.bag.path} (camera topics: every '
                               f'{self.decimation}. message; {compression} chunks)')
        self._discover()

    def _string_list(self, name, description, default=None):
        descriptor = parameter_descriptor(name, '', description, read_only=True)
        if default:
            return list(self.declare_parameter(name, default, descriptor).value)
        value = self.declare_parameter(name, Parameter.Type.STRING_ARRAY, descriptor).value
        return list(value or [])

    # ------------------------------------------------------------------ discovery
    def _discover(self):
        for topic, types in self.get_topic_names_and_types():
            if topic in self._recorded or topic in self.exclude:
                continue
            if self.topics and topic not in self.topics:
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            if not publishers:
                continue                 # only subscribers so far: its QoS is not known
            type_name = types[0]
            try:
                cls = message_class(type_name)
            except BagError as error:
                self.get_logger().warn(f'not recording {topic}: {error}')
                self._recorded[topic] = None
                continue
            profiles = [offered_qos(p) for p in publishers]
            type_hash = str(publishers[0].topic_type_hash or '')
            info = TopicInfo(topic, type_name, profiles,
                             type_hash if type_hash.startswith('RIHS') else '')
            self._queue.put(('topic', info))
            self._counts[topic] = 0
            every = self.topic_decimation.get(
                topic, self.decimation if type_name in self.camera_types else 1)
            self._recorded[topic] = self.create_subscription(
                cls, topic, self._callback(topic, every), subscription_qos(profiles),
                raw=True)
            self.get_logger().info(f'recording {topic} [{type_name}]'
                                   + (f' every {every}. message' if every > 1 else ''))

    def _callback(self, topic, every):
        def take(data):
            count = self._counts[topic]
            self._counts[topic] = count + 1
            if count % every:
                return
            now = self.get_clock().now().nanoseconds
            with self._lock:
                if now == 0:             # simulated time not started yet
                    self._early.append((topic, data))
                    return
                for early_topic, early_data in self._early:
                    self._queue.put(('message', early_topic, now, early_data))
                self._early.clear()
            self._queue.put(('message', topic, now, data))
        return take

    # ------------------------------------------------------------------ writing
    def _write_loop(self):
        while True:
            try:
                item = self._queue.get(timeout=0.1)
            except queue.Empty:
                item = None
            try:
                if item is None:
                    self.bag.flush_if_due()
                elif item[0] == 'stop':
                    return
                elif item[0] == 'topic':
                    self.bag.add_topic(item[1])
                else:
                    self.bag.write(item[1], item[2], item[3])
                    if self.view is not None:
                        self._draw(item[1], item[2], item[3])
            except (OSError, BagError, ValueError) as error:
                if not self.failure:
                    self.failure = f'writing {self.bag.path} failed: {error}'
                    self.get_logger().fatal(self.failure)

    def _draw(self, topic, log_time_ns, data):
        try:
            self.view.take(topic, log_time_ns, data)
        except Exception as error:   # noqa: B902 - the drawings must never end the recording
            self.get_logger().error(f'the view drawings stop ({type(error).__name__}: '
                                    f'{error}); the bag goes on')
            self.view.writer.close()
            self.view = None

    def destroy_node(self):
        """Write what is queued, close the bag (summary and footer), then destroy."""
        self._queue.put(('stop',))
        self._writer.join(timeout=30.0)
        try:
            self.bag.close()
        except (OSError, ValueError) as error:
            self.failure = self.failure or f'closing {self.bag.path} failed: {error}'
        if self.view is not None:
            self.view.writer.close()
        counts = {t.name: t.message_count for t in self.bag.topics.values()}
        self.get_logger().info(f'bag closed: {sum(counts.values())} messages on '
                               f'{len(counts)} topics in {self.bag.directory}')
        return super().destroy_node()


class ViewRecording:
    """
    The Foxglove view's drawings of the recorded messages (``view_model``), into a JSON MCAP.

    Fed by the writer thread with what is recorded (camera topics decimated as in the bag):
    inputs update the model; each recorded RGB or thermal image writes the drawings the live
    bridge would send with it, logged at the image's time and stamped with its stamp.
    """

    def __init__(self, node, model, writer, plan):
        """Resolve the model's topics in `node`'s namespace; register the outputs."""
        self.model, self.writer, self.plan = model, writer, plan
        self.inputs = {node.resolve_topic_name(topic): (topic, message_class(type_name))
                       for topic, (type_name, _) in INPUTS.items()}
        self.images = {node.resolve_topic_name(t): t for t in (RGB_IMAGE, THERMAL_IMAGE)}
        prefix = node.get_namespace().rstrip('/')
        self.outputs = {topic: prefix + topic for topic in OUTPUTS}
        for topic, schema_name in OUTPUTS.items():
            writer.add_topic(self.outputs[topic], schema_name, output_schema_bytes(schema_name))

    def take(self, topic, log_time_ns, data):
        """Take one recorded message (raw CDR) of `topic` (absolute name)."""
        if topic in self.inputs:
            name, cls = self.inputs[topic]
            self.model.feed(name, deserialize_message(data, cls))
        elif topic in self.images:
            self.plan.refresh(self.model)        # a plan not read is drawn without
            for output, message in self.model.outputs_for_image(self.images[topic],
                                                                cdr_stamp_ns(data)):
                self.writer.write(self.outputs[output], log_time_ns,
                                  json.dumps(message).encode())


class Recorder:
    """
    The recorder node in its own process: ``Recorder(out_dir).start()`` ... ``.stop()``.

    `topics` (None: all), `camera_decimation`, `namespace`, `use_sim_time` and further node
    parameters (``chunk_period``, ``compression``, ...) as keyword arguments.
    """

    def __init__(self, out_dir, topics=None, camera_decimation=5, namespace='',
                 use_sim_time=False, log_dir=None, env=None, **parameters):
        """Describe the recorder process (nothing runs before `start`)."""
        self.out_dir = os.path.abspath(out_dir)
        node_parameters = {'output_dir': self.out_dir, 'camera_decimation': camera_decimation,
                           'use_sim_time': bool(use_sim_time), **parameters}
        if topics:
            node_parameters['topics'] = list(topics)
        self.process = NodeProcess('helio_control', 'recorder', node_parameters,
                                   namespace=namespace, log_dir=log_dir, env=env)

    def start(self, timeout=30.0):
        """Start the process and wait until the bag exists; return self."""
        self.process.start()
        return self.start_wait(timeout)

    def start_wait(self, timeout=30.0):
        """Wait until the started recorder opened its bag; return self."""
        deadline = time.monotonic() + timeout
        ready = threading.Event()
        while not os.path.exists(os.path.join(self.out_dir, 'metadata.yaml')):
            if not self.process.alive():
                raise BagError(f'recorder exited with status {self.process.returncode()}: '
                               f'{self.process.tail(5).strip()}')
            if time.monotonic() > deadline:
                self.process.stop()
                raise BagError(f'recorder did not open {self.out_dir} within {timeout} s')
            ready.wait(0.05)
        return self

    def stop(self):
        """Stop the recorder (SIGINT: it closes the bag); return the bag directory."""
        self.process.stop()
        if self.process.returncode() not in (0, None, -2):
            raise BagError(f'recorder failed (status {self.process.returncode()}): '
                           f'{self.process.tail(5).strip()}')
        return self.out_dir

    def kill(self):
        """SIGKILL the recorder (tests of crash safety)."""
        import signal
        self.process.signal(signal.SIGKILL)
        self.process.process.wait(10.0)

    def __enter__(self):
        """Start recording."""
        return self.start()

    def __exit__(self, *exc):
        """Stop recording."""
        self.stop()


def main(args=None):
    """Run the recorder node until Ctrl-C."""
    run_node(RecorderNode, args)


if __name__ == '__main__':
    main()
