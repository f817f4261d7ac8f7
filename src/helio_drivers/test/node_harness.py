"""Driver-node tests on the kit's InProcessGraph: the driver, an action client, its status."""

import contextlib
import threading
import time

from helio_optics.node_kit.in_process_graph import InProcessGraph, TRANSIENT_LOCAL_QOS
from rclpy.time import Time
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState


@contextlib.contextmanager
def driver_on(emulator, make_graph):
    """Yield (emulator, make_graph(emulator)); close the graph, then the emulator."""
    try:
        graph = make_graph(emulator)
        try:
            yield emulator, graph
        finally:
            graph.close()
    finally:
        emulator.close()


class DriverGraph(InProcessGraph):
    """A driver node in an InProcessGraph, its action client and its status messages."""

    def __init__(self, node_class, action_type, action_name, status_topic, parameters):
        from helio_msgs.msg import DeviceStatus
        super().__init__('driver_test_client')
        try:
            self.action_type = action_type
            self.driver = self.add(node_class(**self.node_options(**parameters)))
            self.node = self.helper
            self.joint_states = self.collect(JointState, 'joint_states')
            self.statuses = self.collect(DeviceStatus, status_topic,
                                         TRANSIENT_LOCAL_QOS)
            self.client = self.action_client(action_type, action_name, timeout=10.0)
        except BaseException:
            self.close()
            raise

    def wait_status(self, predicate, timeout=5.0):
        """Wait until a status message satisfies `predicate`; return whether one did."""
        try:
            self.statuses.wait_for_message(predicate, timeout)
        except AssertionError:
            return False
        return True

    def send(self, goal, feedback=None):
        """Send a goal, assert it was accepted and return its handle."""
        handle = super().send_goal(self.client, goal, feedback)
        assert handle.accepted
        return handle

    def run(self, goal, feedback=None):
        """Send a goal and return its GetResult response."""
        return self.goal_result(self.send(goal, feedback), 10.0)

    def timed_run(self, goal):
        """Run a goal; return its GetResult response and the seconds it took."""
        started = time.monotonic()
        response = self.goal_result(DriverGraph.send(self, goal), 10.0)
        return response, time.monotonic() - started

    def unplug_mid_move(self, emulator, goal, moving):
        """
        Send `goal`, unplug `emulator` once a feedback satisfies `moving(feedback)`.

        Return the goal's GetResult response and the seconds from the unplug to the result.
        """
        started = threading.Event()

        def on_feedback(message):
            if moving(message.feedback):
                started.set()
        handle = DriverGraph.send(self, goal, on_feedback)
        assert started.wait(5.0), 'the move did not start'
        unplugged_at = time.monotonic()
        emulator.disconnect()
        response = self.goal_result(handle, 10.0)
        return response, time.monotonic() - unplugged_at

    def replug(self, emulator):
        """Plug the emulator back in; return whether the driver reports the link again."""
        self.statuses.clear()
        emulator.reconnect()
        return self.wait_status(lambda s: s.connected)


class ClockPublisher:
    """Publish /clock from `node` at `rate` times real time (0: a stopped simulation)."""

    def __init__(self, node, rate, start=1000.0, period=0.005):
        self.rate = rate
        self.start = start
        self.period = period
        self.publisher = node.create_publisher(Clock, '/clock', 10)
        self._started = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def now_s(self):
        """Return the simulated time being published [s]."""
        return self.start + self.rate * (time.monotonic() - self._started)

    def _run(self):
        while not self._stop.is_set():
            self.publisher.publish(Clock(clock=Time(seconds=self.now_s()).to_msg()))
            self._stop.wait(self.period)      # pacing the publisher, not synchronising

    def stop(self):
        """Stop publishing."""
        self._stop.set()
        self._thread.join(timeout=5.0)
