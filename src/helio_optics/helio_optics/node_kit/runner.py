"""The main() of every helio node: spin one node until shutdown, then clean up."""

from helio_optics.node_kit.process_tuning import single_threaded_numerics
import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.executors import ExternalShutdownException


def run_node(node_class, args=None):
    """
    Run `node_class()` in rclpy.spin until Ctrl-C or an external shutdown, then destroy it.

    The pattern of the ros2/examples nodes, written once: a node that fails in its constructor
    (a bad parameter) raises after rclpy is shut down again, so the process exits non-zero
    with the node's message. A Ctrl-C or SIGTERM that arrives while the node is still being
    constructed shuts the context down under it (its next create_* call fails): that is a
    normal stop, not an error. rclpy is shut down even when destroy_node() raises.

    Numeric libraries run on one thread (`single_threaded_numerics`), set before the node is
    built and again after (a library its constructor loaded); the node logs the pools.
    """
    single_threaded_numerics()
    rclpy.init(args=args)
    node = None
    try:
        node = node_class()
        pools = single_threaded_numerics()
        node.get_logger().info('numeric thread pools: ' + ', '.join(
            f'{name} {count}' for name, count in sorted(pools.items())))
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if rclpy.ok():
            raise           # a real error (the context is still up)
    finally:
        try:
            if node is not None:
                node.destroy_node()
        finally:
            _shut_down()


def _shut_down():
    """
    Shut rclpy down unless it is already.

    try_shutdown checks and shuts down in two steps: a SIGINT's handler shutting the context
    down between them makes it raise "rcl_shutdown already called"; that is a clean stop.
    """
    try:
        rclpy.try_shutdown()
    except RCLError:
        if rclpy.ok():
            raise
