"""A helio_msgs message crosses from one process to another through Fast DDS."""

import subprocess
import sys
import textwrap

from conftest import load_interface
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.task import Future

PUBLISHER = textwrap.dedent('''
    import sys
    import rclpy
    from helio_msgs.msg import ThermalStats

    rclpy.init()
    node = rclpy.create_node('helio_test_publisher')
    publisher = node.create_publisher(ThermalStats, sys.argv[1], 10)
    count = [0]

    def publish():
        count[0] += 1
        publisher.publish(ThermalStats(t_max=180.9, threshold=180.9, n_p=30, hottest_u=80,
                                       hottest_v=count[0], saturated=True, camera_cap=180.9))

    node.create_timer(0.05, publish)
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
''')


def test_message_crosses_processes(private_context, tmp_path):
    thermal_stats = load_interface('msg', 'ThermalStats')
    topic = f'/helio_test/thermal_stats_{tmp_path.name[-8:].replace("-", "_")}'
    node = rclpy.create_node('helio_test_subscriber', context=private_context)
    received = Future()
    node.create_subscription(
        thermal_stats, topic,
        lambda message: received.done() or received.set_result(message), 10)
    executor = SingleThreadedExecutor(context=private_context)
    executor.add_node(node)
    child = subprocess.Popen([sys.executable, '-c', PUBLISHER, topic],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        executor.spin_until_future_complete(received, timeout_sec=30.0)
        assert received.done(), 'no message from the publisher process within 30 s'
        message = received.result()
        assert (message.t_max, message.n_p, message.saturated) == (180.9, 30, True)
        assert message.hottest_v >= 1
        assert child.poll() is None, 'the publisher process died: ' + child.stdout.read()
    finally:
        child.terminate()
        child.wait(timeout=10)
        executor.shutdown()
        node.destroy_node()
