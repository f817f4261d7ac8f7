"""run_node: every node's main() spins until shutdown and always cleans up."""

from helio_optics.node_runner import run_node
import pytest
import rclpy
from rclpy.node import Node


class ShutsDownItself(Node):
    """A node that asks for an external shutdown from its first timer tick."""

    destroyed = 0

    def __init__(self):
        super().__init__('helio_test_shuts_down_itself')
        self.create_timer(0.01, lambda: rclpy.try_shutdown())

    def destroy_node(self):
        type(self).destroyed += 1
        return super().destroy_node()


class FailsToStart(Node):
    """A node whose constructor refuses a bad parameter."""

    def __init__(self):
        super().__init__('helio_test_fails_to_start')
        raise ValueError('port must not be empty')


def test_external_shutdown_ends_the_spin_and_destroys_the_node():
    run_node(ShutsDownItself, args=[])
    assert ShutsDownItself.destroyed == 1
    assert not rclpy.ok()


def test_a_constructor_error_reaches_the_caller_after_rclpy_shut_down():
    with pytest.raises(ValueError, match='port must not be empty'):
        run_node(FailsToStart, args=[])
    assert not rclpy.ok()
