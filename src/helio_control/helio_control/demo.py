"""
The main job of `./helio.sh demo`.

Until the simulated painting exists, this runs the most complete thing the workspace has:
a PaintPattern action server and client over real rclpy and Fast DDS, each on its own node,
exchanging a goal of explicit dots, feedback per dot and a result.
"""

import argparse
import sys
import threading

from geometry_msgs.msg import Point
from helio_msgs.action import PaintPattern
import rclpy
from rclpy.action import ActionClient, ActionServer
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor


def run_demo(dots):
    """Send a goal of `dots` points to an in-process server; return the result."""
    server_node = rclpy.create_node('helio_demo_painter')
    client_node = rclpy.create_node('helio_demo_operator')

    def execute(goal_handle):
        total = len(goal_handle.request.points)
        for index, point in enumerate(goal_handle.request.points):
            goal_handle.publish_feedback(PaintPattern.Feedback(
                index=index, total=total, phase='planned', elapsed=0.0, eta=0.0))
        goal_handle.succeed()
        return PaintPattern.Result(success=True, dots_burnt=0, dots_skipped=total,
                                   message='foundation demo: no world to burn yet')

    server = ActionServer(server_node, PaintPattern, 'paint', execute)
    client = ActionClient(client_node, PaintPattern, 'paint')
    executor = MultiThreadedExecutor(num_threads=2)
    executor.add_node(server_node)
    executor.add_node(client_node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        if not client.wait_for_server(timeout_sec=10.0):
            raise RuntimeError('the /paint action server did not appear within 10 s')
        goal = PaintPattern.Goal(points=[Point(x=0.05 + 0.004 * i, y=0.05) for i in range(dots)])
        done = threading.Event()
        sent = client.send_goal_async(goal, feedback_callback=lambda f: print(
            f'feedback: dot {f.feedback.index + 1}/{f.feedback.total} {f.feedback.phase}'))
        sent.add_done_callback(lambda _: done.set())
        if not done.wait(10.0) or not sent.result().accepted:
            raise RuntimeError('the goal was not accepted within 10 s')
        done.clear()
        result_future = sent.result().get_result_async()
        result_future.add_done_callback(lambda _: done.set())
        if not done.wait(30.0):
            raise RuntimeError('no result within 30 s')
        return result_future.result().result
    finally:
        executor.shutdown()
        spinner.join(timeout=10.0)
        server.destroy()
        client.destroy()


def main(args=None):
    """Run the demo; print the result."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--dots', type=int, default=5, help='number of dots in the goal')
    options = parser.parse_args(args)
    rclpy.init()
    try:
        result = run_demo(options.dots)
        print(f'result: success={result.success} burnt={result.dots_burnt} '
              f'skipped={result.dots_skipped}: {result.message}')
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
