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


def test_results_unless_returns_the_results_or_gives_up_on_trouble_and_cancels():
    """A server that accepts and never answers (a killed driver) is given up on, canceled."""
    from helio_msgs.action import MoveWrist
    from helio_optics.node_kit.awaitables import GoalTrouble, results_unless
    from rclpy.action import ActionClient, ActionServer, CancelResponse

    canceled = []

    async def execute(goal_handle):
        if goal_handle.request.yaw > 0.0:          # the hung server: answers only a cancel
            while not goal_handle.is_cancel_requested:
                await sleep(graph.helper, 0.02, wall=True)
            canceled.append(goal_handle.request.pitch)
            goal_handle.canceled()
            return MoveWrist.Result(message='canceled')
        goal_handle.succeed()
        return MoveWrist.Result(success=True, achieved_pitch=goal_handle.request.pitch)

    trouble = []

    async def procedure(yaw):
        client = ActionClient(graph.helper, MoveWrist, 'wrist')
        await discovered(graph.helper, client.server_is_ready, 10.0, 'wrist')
        handles = [await client.send_goal_async(MoveWrist.Goal(yaw=yaw, pitch=pitch))
                   for pitch in (0.25, 0.5)]
        try:
            replies = await results_unless(graph.helper, handles, lambda: ''.join(trouble),
                                           poll=0.05)
        except GoalTrouble as error:
            return str(error)
        return [reply.result.achieved_pitch for reply in replies]

    with InProcessGraph() as graph:
        ActionServer(graph.helper, MoveWrist, 'wrist', execute,
                     cancel_callback=lambda _request: CancelResponse.ACCEPT)
        assert run(graph, procedure(0.0)) == [0.25, 0.5]       # both results, in order
        graph.helper.create_timer(0.3, lambda: trouble.append('servo silent for 1.0 s'))
        assert run(graph, procedure(1.0)) == 'servo silent for 1.0 s'
        graph.wait_until(lambda: len(canceled) == 2, 10.0, 'the cancels at the server')
        assert sorted(canceled) == [0.25, 0.5]                  # both goals canceled
