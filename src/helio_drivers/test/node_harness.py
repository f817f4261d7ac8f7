"""In-process harness for the driver nodes: private context, client node, executor thread."""

import contextlib
import threading
import time

import rclpy
from rclpy.action import ActionClient
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.time import Time
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState


def wait_for(future, timeout=10.0):
    """Wait on an rclpy future (spun by the executor thread) and return its result."""
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    assert done.wait(timeout), 'future not done in time'
    return future.result()


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


class DriverGraph:
    """A driver node, a client node (action client + subscriptions) and an executor thread."""

    def __init__(self, node_class, action_type, action_name, status_topic, parameters):
        from helio_msgs.msg import DeviceStatus
        self.action_type = action_type
        self.context = rclpy.context.Context()
        rclpy.init(context=self.context)
        try:
            self.driver = node_class(context=self.context, parameter_overrides=[
                Parameter(k, value=v) for k, v in parameters.items()])
            self.node = rclpy.create_node('driver_test_client', context=self.context)
            self.client = ActionClient(self.node, action_type, action_name)
            self.joint_states = []
            self.statuses = []
            self.status_event = threading.Event()
            self.node.create_subscription(JointState, 'joint_states', self.joint_states.append,
                                          10)
            self.node.create_subscription(
                DeviceStatus, status_topic, self._status,
                QoSProfile(depth=20, durability=DurabilityPolicy.TRANSIENT_LOCAL))
            # One thread, as rclpy.spin runs the nodes: no driver callback waits on a device.
            self.executor = SingleThreadedExecutor(context=self.context)
            self.executor.add_node(self.driver)
            self.executor.add_node(self.node)
            self.thread = threading.Thread(target=self.executor.spin, daemon=True)
            self.thread.start()
            assert self.client.wait_for_server(timeout_sec=10.0)
        except BaseException:
            rclpy.try_shutdown(context=self.context)
            raise

    def _status(self, message):
        self.statuses.append(message)
        self.status_event.set()

    def wait_status(self, predicate, timeout=5.0):
        """Wait until a status message satisfies `predicate`; return whether one did."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if any(predicate(s) for s in list(self.statuses)):
                return True
            self.status_event.clear()
            self.status_event.wait(0.1)
        return False

    def send(self, goal, feedback=None):
        """Send a goal, assert it was accepted and return its handle."""
        handle = wait_for(self.client.send_goal_async(goal, feedback_callback=feedback))
        assert handle.accepted
        return handle

    def run(self, goal, feedback=None):
        """Send a goal and return its GetResult response."""
        return wait_for(self.send(goal, feedback).get_result_async())

    def timed_run(self, goal):
        """Run a goal; return its GetResult response and the seconds it took."""
        started = time.monotonic()
        response = wait_for(DriverGraph.send(self, goal).get_result_async())
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
        result = DriverGraph.send(self, goal, on_feedback).get_result_async()
        assert started.wait(5.0), 'the move did not start'
        unplugged_at = time.monotonic()
        emulator.disconnect()
        response = wait_for(result)
        return response, time.monotonic() - unplugged_at

    def replug(self, emulator):
        """Plug the emulator back in; return whether the driver reports the link again."""
        self.statuses.clear()
        emulator.reconnect()
        return self.wait_status(lambda s: s.connected)

    def close(self):
        """Shut everything down (the driver leaves its device stopped)."""
        self.executor.shutdown(timeout_sec=5.0)
        self.driver.destroy_node()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self.thread.join(timeout=5.0)


class SimClock:
    """Publish /clock from `node` at `rate` times real time (0: a stopped simulation)."""

    def __init__(self, node, rate, start_s=1000.0, period_s=0.005):
        self.rate = rate
        self.start_s = start_s
        self.period_s = period_s
        self.publisher = node.create_publisher(Clock, '/clock', 10)
        self._started = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def now_s(self):
        """Return the simulated time being published [s]."""
        return self.start_s + self.rate * (time.monotonic() - self._started)

    def _run(self):
        while not self._stop.is_set():
            self.publisher.publish(Clock(clock=Time(seconds=self.now_s()).to_msg()))
            self._stop.wait(self.period_s)      # pacing the publisher, not synchronising

    def stop(self):
        """Stop publishing."""
        self._stop.set()
        self._thread.join(timeout=5.0)
