"""Coroutine waits of the kit on a real node: sleeps, bounded waits, discovery, threads."""

import threading

from helio_optics.node_kit.awaitables import discovered, FirstOf, in_thread, sleep, within
from helio_optics.node_kit.in_process_graph import InProcessGraph
from rclpy.parameter import Parameter
from rclpy.time import Time
from rosgraph_msgs.msg import Clock


def run(graph, coroutine, timeout=10.0):
    """Run `coroutine` as a task of the graph's executor; return its result."""
    task = graph.executor.create_task(coroutine)
    graph.wait_until(task.done, timeout, 'the task')
    return task.result()


def test_sleep_and_within_count_simulated_time_and_wait_for_the_clock_to_start():
    with InProcessGraph() as graph:
        node = graph.add(graph.helper.__class__('sim_timed', context=graph.context,
                                                parameter_overrides=[
                                                    Parameter('use_sim_time', value=True)]))
        clock = graph.helper.create_publisher(Clock, '/clock', 10)
        never = FirstOf()

        async def procedure():
            before = node.get_clock().now().nanoseconds
            done = await within(node, never, 2.0)    # waits for /clock, then 2 s of it
            return before, done, node.get_clock().now().nanoseconds
        task = graph.executor.create_task(procedure())
        graph.wait_until(lambda: node.get_clock().now().nanoseconds == 0 or task.done(), 5.0)
        assert not task.done()                       # no /clock yet: nothing fired
        second = 1000.0                              # a jump of 1000 s, then 0.5 s steps
        while not task.done() and second < 1010.0:
            clock.publish(Clock(clock=Time(seconds=second).to_msg()))
            graph.wait_until(lambda s=second: node.get_clock().now().nanoseconds
                             >= s * 1e9 or task.done(), 5.0)
            second += 0.5
        graph.wait_until(task.done, 10.0, 'the task')
        before, done, after = task.result()
        assert before == 0 and done is False
        assert after >= 1002 * 10 ** 9               # 2 s of simulated time, not the jump


def test_within_is_true_when_the_future_completes_first():
    with InProcessGraph() as graph:
        future = FirstOf()
        graph.helper.create_timer(0.1, lambda: future.offer('done'))
        assert run(graph, within(graph.helper, future, 5.0)) is True
        assert future.result() == 'done' and not future.offer('again')
        assert run(graph, sleep(graph.helper, 0.05)) is None


def test_discovery_that_never_happens_is_a_timeout_naming_it():
    async def look():
        try:
            await discovered(graph.helper, lambda: False, 0.3, 'the phantom server')
        except TimeoutError as error:     # an exception would stop the executor's spin
            return str(error)
    with InProcessGraph() as graph:
        assert run(graph, look()) == 'the phantom server is not available after 0.3 s'
        servers = iter([False, False, True])
        assert run(graph, discovered(graph.helper, lambda: next(servers), 5.0, 'x')) is None


def test_a_computation_on_a_thread_leaves_the_executor_serving_callbacks():
    """While in_thread's function blocks, a timer keeps firing; its result or error comes."""
    release, ticks = threading.Event(), []

    def blocked(value):
        assert release.wait(10.0)
        return value * 2

    def failing():
        raise ValueError('no fit')

    async def procedure():
        doubled = await in_thread(graph.helper, blocked, 21)
        try:
            await in_thread(graph.helper, failing)
        except ValueError as error:
            return doubled, str(error)
        return doubled, None

    with InProcessGraph() as graph:
        graph.helper.create_timer(0.01, lambda: ticks.append(1))
        task = graph.executor.create_task(procedure())
        graph.wait_until(lambda: len(ticks) >= 5, 5.0, 'timer ticks while the thread blocks')
        assert not task.done()
        release.set()
        graph.wait_until(task.done, 10.0, 'the task')
        assert task.result() == (42, 'no fit')
