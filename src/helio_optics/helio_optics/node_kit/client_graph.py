"""
A client's view of a helio graph: the graph the ``helio`` command and the tests talk through.

A private rclpy Context, a helper node (its clients, subscriptions and publishers) and one
executor spinning on its own thread (as ``rclpy.spin`` runs a node), with waits that end on
an event and never on a sleep. ``helio paint``, ``calibrate``, ``doctor``, ``stop`` and the
fixture recorder reach a running graph through it; the node tests' ``InProcessGraph``
(``in_process_graph``) is this graph with the nodes under test spun beside the helper.

Usage::

    with ClientGraph('helio_paint', namespace='rig1') as graph:
        client = graph.action_client(PaintPattern, 'paint', timeout=5.0)
        handle = graph.send_goal(client, goal, feedback)
        stats = graph.collect(ThermalStats, 'thermal/stats')
        stats.wait_for_count(1)

Every wait has a timeout (``GraphTimeout``) and ends at once when the graph is said to have
broken (``fail(reason)``: ``GraphFailure``). A private Context keeps the graph's nodes apart
from any other graph in the same process; DDS still connects it to every process in the
same ``ROS_DOMAIN_ID``, so a test run picks a private domain.
"""

import threading
import time

from helio_optics.node_kit.qos import latched
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor

DEFAULT_TIMEOUT = 15.0
TRANSIENT_LOCAL_QOS = latched(10)


# a goal request unanswered this long is sent again (``send_goal``) [s]
GOAL_RESEND_AFTER = 10.0
# a node's parameter read unanswered this long is sent again (``wait_for_nodes``) [s]
NODE_ASK_AGAIN = 2.0


class GraphTimeout(AssertionError):
    """Something waited for did not happen in time (in a test: fails the test)."""


class GraphFailure(AssertionError):
    """The graph broke during a wait (a node process died, ...)."""


class Collector:
    """Messages of one subscription, with waits that wake on each arrival."""

    def __init__(self, failure=lambda: ''):
        """Start empty; `failure()` says why waiting is pointless ('' while all is well)."""
        self.messages = []
        self._arrived = threading.Condition()
        self._failure = failure

    def wake(self):
        """Wake the waiters so that they look at `failure()` again."""
        with self._arrived:
            self._arrived.notify_all()

    def __call__(self, message):
        """Take one message (the subscription callback)."""
        with self._arrived:
            self.messages.append(message)
            self._arrived.notify_all()

    def wait_until(self, predicate, timeout=DEFAULT_TIMEOUT, what='a matching message'):
        """Wait until `predicate(messages)` holds; return the messages or raise GraphTimeout."""
        with self._arrived:
            if not self._arrived.wait_for(
                    lambda: self._failure() or predicate(self.messages), timeout):
                raise GraphTimeout(f'{what} did not arrive within {timeout} s '
                                   f'({len(self.messages)} message(s) so far)')
            if self._failure():
                raise GraphFailure(f'while waiting for {what}: {self._failure()}')
            return list(self.messages)

    def wait_for_count(self, count, timeout=DEFAULT_TIMEOUT):
        """Wait until `count` messages arrived; return them."""
        return self.wait_until(lambda messages: len(messages) >= count, timeout,
                               f'{count} message(s)')

    def wait_for_message(self, predicate=lambda message: True, timeout=DEFAULT_TIMEOUT):
        """Wait for a message satisfying `predicate`; return the first such message."""
        messages = self.wait_until(lambda found: any(predicate(m) for m in found), timeout)
        return next(m for m in messages if predicate(m))

    def clear(self):
        """Forget the messages received so far."""
        with self._arrived:
            self.messages.clear()


def wait_for_future(future, timeout=DEFAULT_TIMEOUT, what='the future'):
    """Wait until an rclpy future spun by another thread is done; return its result."""
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    if not done.wait(timeout):
        raise GraphTimeout(f'{what} was not done within {timeout} s')
    return future.result()


class ClientGraph:
    """See the module docstring."""

    def __init__(self, helper_name='helio_client', namespace=''):
        """Create the Context, the executor and the helper node, and start spinning."""
        self.context = Context()
        rclpy.init(context=self.context)
        self.namespace = namespace
        self.nodes = []          # nodes spun beside the helper (InProcessGraph.add)
        self.failure = ''
        self._collectors = []
        self._waiters = set()
        try:
            self.executor = SingleThreadedExecutor(context=self.context)
            self.helper = rclpy.create_node(helper_name, namespace=namespace,
                                            context=self.context)
            self.executor.add_node(self.helper)
            self._thread = threading.Thread(target=self._spin, daemon=True,
                                            name='client-graph')
            self._thread.start()
        except BaseException:
            rclpy.try_shutdown(context=self.context)
            raise

    def _spin(self):
        try:
            self.executor.spin()
        except Exception:        # a shut-down context ends the spin; nothing to report
            if self.context.ok():
                raise

    def collect(self, message_type, topic, qos=10):
        """Subscribe the helper node to `topic`; return the Collector of its messages."""
        collector = Collector(lambda: self.failure)
        self._collectors.append(collector)
        self.helper.create_subscription(message_type, topic, collector, qos)
        return collector

    def fail(self, reason):
        """
        Say the graph broke (e.g. a node process died): every wait raises GraphFailure.

        Thread-safe; ``ProcessGroup(on_death=...)`` calls it from its watcher thread.
        """
        self.failure = self.failure or reason
        for collector in self._collectors:
            collector.wake()
        for waiter in list(self._waiters):
            waiter.set()

    def _check_failure(self, what):
        if self.failure:
            raise GraphFailure(f'while waiting for {what}: {self.failure}')

    def result_of(self, future, timeout=DEFAULT_TIMEOUT, what='the future'):
        """Wait until `future` is done (or the graph fails); return its result."""
        done = threading.Event()
        self._waiters.add(done)
        future.add_done_callback(lambda _: done.set())
        try:
            if not done.wait(timeout):
                raise GraphTimeout(f'{what} was not done within {timeout} s')
        finally:
            self._waiters.discard(done)
        if not future.done():
            self._check_failure(what)
        return future.result()

    def call(self, client, request, timeout=DEFAULT_TIMEOUT):
        """Call a service through `client` once it is available; return the response."""
        self.wait_until(client.service_is_ready, timeout,
                        f'service {client.srv_name} available')
        return self.result_of(client.call_async(request), timeout,
                              f'the response of {client.srv_name}')

    def action_client(self, action_type, name, timeout=DEFAULT_TIMEOUT):
        """Return an ActionClient of the helper node once its server is available."""
        from rclpy.action import ActionClient
        client = ActionClient(self.helper, action_type, name)
        self.wait_until(client.server_is_ready, timeout, f'action server {name} available')
        return client

    def on_executor(self, request, timeout=DEFAULT_TIMEOUT, what='the request'):
        """
        Call `request()` on the executor's thread; return the result of the future it returns.

        rclpy's ActionClient (7.1.6) registers a request's future only after sending it,
        without a lock: a response the executor thread takes in between is dropped ("the
        goal response was not done"). Sending from the executor's own thread closes that gap.
        """
        task = self.executor.create_task(request)
        future = self.result_of(task, timeout, f'{what} to be sent')
        return self.result_of(future, timeout, what)

    def send_goal(self, client, goal, feedback=None, timeout=DEFAULT_TIMEOUT,
                  resend_after=GOAL_RESEND_AFTER):
        """
        Send `goal`; return its ClientGoalHandle (accepted or not: check ``accepted``).

        A goal request written before the server's request reader has matched this client's
        writer is lost: DDS hands a volatile sample only to the readers matched when it is
        written, and ``server_is_ready`` sees the server in the graph before that. Seen as a
        goal response that never came (the word test waited 15 minutes, twice, 2026-11-27).
        Unanswered, the goal is sent again, with a new goal id, every `resend_after` s
        until `timeout`.
        """
        return self._asked_again(
            lambda wait: self.on_executor(
                lambda: client.send_goal_async(goal, feedback_callback=feedback), wait,
                'the goal response'), timeout, resend_after)

    @staticmethod
    def _asked_again(ask, timeout, every):
        """
        Return ``ask(wait)``, asked again every `every` s until one answers within `timeout`.

        `ask(wait)` sends its request and waits `wait` s for the answer (GraphTimeout when
        none): for a request whose answer DDS may drop while the two sides are still matching.
        """
        deadline = time.monotonic() + timeout
        while True:
            wait = max(min(every, deadline - time.monotonic()), 0.0)
            try:
                return ask(wait)
            except GraphTimeout:
                if time.monotonic() >= deadline:
                    raise

    def goal_result(self, handle, timeout=DEFAULT_TIMEOUT):
        """Wait for an accepted goal's GetResult response (``.status``, ``.result``)."""
        return self.on_executor(handle.get_result_async, timeout, 'the goal result')

    def cancel_goal(self, handle, timeout=DEFAULT_TIMEOUT):
        """Ask to cancel an accepted goal; return the CancelGoal response."""
        return self.on_executor(handle.cancel_goal_async, timeout, 'the cancel response')

    def run_goal(self, client, goal, feedback=None, timeout=DEFAULT_TIMEOUT):
        """Send `goal`, require it accepted, and return its GetResult response."""
        handle = self.send_goal(client, goal, feedback, timeout)
        if not handle.accepted:
            raise AssertionError(f'goal {goal} was rejected')
        return self.goal_result(handle, timeout)

    def wait_for_nodes(self, names, timeout=DEFAULT_TIMEOUT):
        """
        Wait until every node of `names` (relative to the namespace) answers a parameter read.

        A node answers its ``get_parameters`` service only once its constructor is done and
        its executor spins, so this waits out each node's start-up (imports, warm-up, opened
        ports), not merely its appearance in the graph. One deadline for all; GraphTimeout
        names the nodes that did not answer.
        """
        from rcl_interfaces.srv import GetParameters
        deadline = time.monotonic() + timeout
        request = GetParameters.Request(names=['use_sim_time'])
        for index, name in enumerate(names):
            client = self.helper.create_client(GetParameters, f'{name}/get_parameters')
            try:
                # asked again every NODE_ASK_AGAIN s: a response written before the server
                # matched this client's reader is lost ("failed to send response (timeout)",
                # seen in a fresh run), and the request is not sent again
                self._asked_again(lambda wait: self.call(client, request, wait),
                                  max(deadline - time.monotonic(), 0.0), NODE_ASK_AGAIN)
            except GraphTimeout:
                raise GraphTimeout(f'node(s) {", ".join(names[index:])} did not answer within '
                                   f'{timeout:g} s (not started, or still starting)') from None
            finally:
                self.helper.destroy_client(client)

    def wait_until(self, condition, timeout=DEFAULT_TIMEOUT, what='the condition'):
        """
        Wait until `condition()` holds; raise GraphTimeout naming `what` on timeout.

        The condition is re-checked whenever the helper node's timer fires (every 20 ms of
        executor time) and at once when the graph fails (GraphFailure).
        """
        event = threading.Event()
        self._waiters.add(event)
        timer = self.helper.create_timer(0.02, event.set)
        try:
            deadline = time.monotonic() + timeout
            while not condition():
                self._check_failure(what)
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    raise GraphTimeout(f'{what} did not hold within {timeout} s')
                event.wait(remaining)
                event.clear()
        finally:
            self._waiters.discard(event)
            self.helper.destroy_timer(timer)

    def close(self):
        """Stop spinning, destroy the helper (and any node spun beside it), end the Context."""
        self.executor.shutdown(timeout_sec=5.0)
        for node in reversed(self.nodes):
            node.destroy_node()
        self.helper.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self._thread.join(timeout=5.0)

    def __enter__(self):
        """Return the graph."""
        return self

    def __exit__(self, *exc):
        """Close the graph."""
        self.close()
