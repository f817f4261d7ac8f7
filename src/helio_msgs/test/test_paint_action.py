"""An action server and client exchange a PaintPattern goal, feedback and result."""

import threading

from conftest import load_interface
import rclpy
from rclpy.action import ActionClient, ActionServer, GoalResponse
from rclpy.executors import MultiThreadedExecutor
from rclpy.task import Future


def test_paint_pattern_goal_feedback_result(private_context):
    paint_pattern = load_interface('action', 'PaintPattern')
    server_node = rclpy.create_node('helio_test_paint_server', context=private_context)
    client_node = rclpy.create_node('helio_test_paint_client', context=private_context)
    seen_goals = []

    def decide(goal):
        # Accept only goals that name exactly one source of dots.
        sources = [bool(goal.image_path), goal.image.width > 0, len(goal.points) > 0]
        return GoalResponse.ACCEPT if sum(sources) == 1 else GoalResponse.REJECT

    def execute(goal_handle):
        goal = goal_handle.request
        seen_goals.append(goal)
        total = len(goal.points)
        for index in range(goal.start_index, total):
            goal_handle.publish_feedback(paint_pattern.Feedback(
                index=index, total=total, phase='heating', t_max=180.9, n_p=index * 10,
                elapsed=float(index), eta=float(total - index)))
        goal_handle.succeed()
        return paint_pattern.Result(success=True, dots_burnt=total - goal.start_index,
                                    dots_skipped=goal.start_index, duration=1.5,
                                    message='done')

    server = ActionServer(server_node, paint_pattern, 'paint', execute,
                          goal_callback=decide)
    client = ActionClient(client_node, paint_pattern, 'paint')
    executor = MultiThreadedExecutor(num_threads=2, context=private_context)
    executor.add_node(server_node)
    executor.add_node(client_node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    feedback = []
    try:
        assert client.wait_for_server(timeout_sec=10.0)

        from geometry_msgs.msg import Point
        goal = paint_pattern.Goal(points=[Point(x=0.05 + 0.005 * i, y=0.05) for i in range(4)],
                                  canvas_size=0.08, dot_radius=0.002, n_p_target=30,
                                  ordering='nearest_2opt', start_index=1)
        goal_handle = on_executor(executor, lambda: client.send_goal_async(
            goal, feedback_callback=lambda m: feedback.append(m)))
        assert goal_handle.accepted
        result = on_executor(executor, goal_handle.get_result_async).result
        assert (result.success, result.dots_burnt, result.dots_skipped) == (True, 3, 1)
        assert result.message == 'done'
        assert seen_goals[0].points[3].x == goal.points[3].x
        assert seen_goals[0].ordering == 'nearest_2opt'
        # Feedback for dots 1..3 arrived before the result, in order.
        assert [f.feedback.index for f in feedback] == [1, 2, 3]
        assert feedback[-1].feedback.n_p == 30

        # A goal naming two sources of dots is rejected by the server.
        bad = paint_pattern.Goal(image_path='/tmp/x.png', points=[Point()])
        assert not on_executor(executor, lambda: client.send_goal_async(bad)).accepted
    finally:
        executor.shutdown()
        spinner.join(timeout=10.0)
        server.destroy()
        client.destroy()
        server_node.destroy_node()
        client_node.destroy_node()


def on_executor(executor, request, timeout_sec=10.0):
    """
    Call `request()` on the executor's thread and wait for the future it returns.

    rclpy 7.1.6's ActionClient registers a request's future after sending it, without a
    lock: from another thread, a response taken in between by the executor is dropped.
    """
    return wait(wait(executor.create_task(request), timeout_sec), timeout_sec)


def wait(future: Future, timeout_sec=10.0):
    """Wait for a future completed by the background executor; fail after timeout_sec."""
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    assert done.wait(timeout_sec), f'future not done within {timeout_sec} s'
    return future.result()
