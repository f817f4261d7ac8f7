"""
Node replayer: play a bag back into the graph with ``/clock``.

What ``ros2 bag play --clock`` does.

Every recorded topic is published again with its recorded type and the first offered QoS
profile of its recording (reliability, durability, depth), as raw CDR, in log-time order,
paced so that ``rate`` bag seconds pass per wall second. ``/clock`` is published from the
bag's time line (the recorded log times: simulated time for a recording of the simulated
world) every ``clock_period`` wall seconds and with every message, so nodes with
``use_sim_time`` live on the recording's clock; the recording's own ``/clock`` messages are
not replayed. Recorded absolute names are published as relative names (``/spot`` ->
``spot``) so a replay runs under a namespace; ``/clock``, ``/diagnostics`` and ``/rosout``
stay global. ``exclude`` leaves topics out (by default ``/rosout`` and
``/parameter_events``), e.g. a node's recorded outputs when the node itself runs on the
replay. The node shuts down when the bag has been played.

A bag a crash left without its footer is recovered first (``bag_files.recover_bag``).
"""

import threading
import time

from helio_control.bag_files import changed_types, describe_changed_types, message_class
from helio_control.bag_files import read_messages, read_topics, recover_bag
from helio_optics.node_kit.parameters import declare, parameter_descriptor
from helio_optics.node_kit.runner import run_node
import rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock

GLOBAL_TOPICS = ('/clock', '/diagnostics', '/rosout', '/parameter_events')


def replay_name(topic):
    """Return the name a recorded topic is published under (relative unless global)."""
    return topic if topic in GLOBAL_TOPICS else topic.lstrip('/')


def replay_qos(profiles, default_depth=10):
    """Return the QoS of a replay publisher from the recorded offered profiles."""
    profile = profiles[0] if profiles else {}
    return QoSProfile(
        depth=max(1, int(profile.get('depth', default_depth) or default_depth)),
        reliability=ReliabilityPolicy.BEST_EFFORT
        if profile.get('reliability') == 'best_effort' else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL
        if profile.get('durability') == 'transient_local' else DurabilityPolicy.VOLATILE)


class ReplayerNode(Node):
    """Publish a bag's messages paced on the wall clock, with /clock from the bag."""

    def __init__(self, **kwargs):
        """Read the bag's topics, create the publishers, start the playing thread."""
        super().__init__('replayer', **kwargs)
        self.bag = declare(self, 'bag', '', 'Bag directory to play [path].')
        if not self.bag:
            raise ValueError('parameter bag is required: the bag directory to play')
        self.rate = declare(self, 'rate', 1.0, 'Bag seconds played per wall second [-].',
                            0.01, 1000.0)
        self.clock_period = declare(self, 'clock_period', 0.025, 'Wall period of /clock '
                                    'between messages [s].', 0.001, 1.0)
        self.start_delay = declare(self, 'start_delay', 0.5, 'Wall time to let subscribers '
                                   'discover the publishers before playing [s].', 0.0, 60.0)
        self.end_delay = declare(self, 'end_delay', 0.5, 'Wall time to keep the publishers '
                                 'after the last message, so it is delivered [s].', 0.0, 60.0)
        descriptor = parameter_descriptor('exclude', '', 'Recorded topics not played.',
                                          read_only=True)
        self.exclude = set(self.declare_parameter(
            'exclude', ['/rosout', '/parameter_events'], descriptor).value)
        descriptor = parameter_descriptor('topics', '', 'Topics to play (empty: all).',
                                          read_only=True)
        only = self.declare_parameter('topics', Parameter.Type.STRING_ARRAY, descriptor).value
        only = {('/' + t.lstrip('/')) for t in (only or [])}
        repaired = recover_bag(self.bag)
        if repaired is not None:
            self.get_logger().warn(f'{self.bag} was not closed (crash?): recovered '
                                   f'{repaired} messages')
        self.topics = {}
        self.publishers_by_topic = {}
        recorded = read_topics(self.bag)
        changed = changed_types(recorded.values())
        if changed:
            raise ValueError(f'{self.bag}: {describe_changed_types(changed)}')
        for name, info in recorded.items():
            absolute = '/' + name.lstrip('/')
            if name == '/clock' or absolute in self.exclude or name in self.exclude or \
                    (only and absolute not in only):
                continue
            self.topics[name] = info
            self.publishers_by_topic[name] = self.create_publisher(
                message_class(info.type_name), replay_name(absolute),
                replay_qos(info.offered_qos_profiles))
        self.clock = self.create_publisher(Clock, '/clock', 10)
        self.published = 0
        self.done = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._play, name='replay', daemon=True)
        self._thread.start()
        self.get_logger().info(f'playing {self.bag} at rate {self.rate}: '
                               f'{len(self.topics)} topics')

    def _publish_clock(self, nanoseconds):
        message = Clock()
        message.clock.sec, message.clock.nanosec = divmod(int(nanoseconds), 10**9)
        self.clock.publish(message)

    def _play(self):
        try:
            self._stop.wait(self.start_delay)
            wall_start, bag_start = None, None
            for topic, _, log_time, data in read_messages(self.bag, list(self.topics)):
                if self._stop.is_set():
                    return
                if wall_start is None:
                    wall_start, bag_start = time.monotonic(), log_time
                    self._publish_clock(log_time)
                due = wall_start + (log_time - bag_start) * 1e-9 / self.rate
                while not self._stop.is_set():
                    remaining = due - time.monotonic()
                    if remaining <= 0.0:
                        break
                    self._stop.wait(min(remaining, self.clock_period))
                    elapsed = (time.monotonic() - wall_start) * self.rate
                    self._publish_clock(min(log_time, bag_start + int(elapsed * 1e9)))
                self._publish_clock(log_time)
                self.publishers_by_topic[topic].publish(bytes(data))
                self.published += 1
            self.get_logger().info(f'played {self.published} messages')
            self._stop.wait(self.end_delay)
        finally:
            self.done.set()
            if not self._stop.is_set():
                rclpy.try_shutdown(context=self.context)

    def destroy_node(self):
        """Stop playing, then destroy."""
        self._stop.set()
        self._thread.join(timeout=5.0)
        return super().destroy_node()


def main(args=None):
    """Play a bag (parameters ``bag``, ``rate``, ...) until it ends or Ctrl-C."""
    run_node(ReplayerNode, args)


if __name__ == '__main__':
    main()
