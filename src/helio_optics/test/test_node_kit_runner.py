"""run_node: every node's main() spins until shutdown and always cleans up."""

import os
import signal
import time

from helio_optics.node_kit.runner import run_node
import pytest
import rclpy
from rclpy.node import Node
from sensor_msgs.msg import JointState


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


class InterruptedWhileStarting(Node):
    """A node whose start is cut short by a shutdown (Ctrl-C during its constructor)."""

    def __init__(self):
        super().__init__('helio_test_interrupted_while_starting')
        rclpy.try_shutdown()                          # what the signal handler does
        self.create_publisher(JointState, 'never', 1)  # the context is gone: RCLError


class FailsToStop(Node):
    """A node stopped by Ctrl-C (no signal handler here) whose destroy_node raises."""

    def __init__(self):
        super().__init__('helio_test_fails_to_stop')
        self.create_timer(0.01, self._interrupt)

    def _interrupt(self):
        raise KeyboardInterrupt

    def destroy_node(self):
        super().destroy_node()
        raise RuntimeError('could not stop the device')


def test_a_stop_while_the_node_starts_is_a_normal_exit():
    run_node(InterruptedWhileStarting, args=[])
    assert not rclpy.ok()


def test_rclpy_is_shut_down_even_when_destroy_node_raises():
    with pytest.raises(RuntimeError, match='could not stop the device'):
        run_node(FailsToStop, args=[])
    assert not rclpy.ok()
    rclpy.init(args=[])          # a later init works: nothing was left behind
    rclpy.shutdown()


class StopsSafely(Node):
    """A node with an on_interrupt coroutine: it publishes on the way out (still up)."""

    interrupt_timeout = 2.0
    log = []

    def __init__(self):
        super().__init__('helio_test_stops_safely')
        self.publisher = self.create_publisher(JointState, 'stopping', 1)
        self.create_timer(0.05, self._signal_once)
        self._sent = 0

    def _signal_once(self):
        if not self._sent:       # what Ctrl-C does, from inside the process
            self._sent = 1
            os.kill(os.getpid(), signal.SIGINT)

    async def on_interrupt(self):
        from helio_optics.node_kit.awaitables import sleep
        type(self).log.append('interrupted')
        await sleep(self, 0.2, wall=True)         # the node still spins: timers run
        self.publisher.publish(JointState(name=['still up']))
        type(self).log.append(f'published, context ok: {rclpy.ok()}')

    def destroy_node(self):
        type(self).log.append('destroyed')
        return super().destroy_node()


class HangsOnTheWayOut(StopsSafely):
    """An on_interrupt that never ends: the second signal (SIGTERM) stops the node."""

    log = []

    async def on_interrupt(self):
        from helio_optics.node_kit.awaitables import sleep
        type(self).log.append('interrupted')
        os.kill(os.getpid(), signal.SIGTERM)
        await sleep(self, 60.0, wall=True)


def test_a_node_with_on_interrupt_acts_on_the_first_signal_before_it_goes():
    before = signal.getsignal(signal.SIGINT)
    run_node(StopsSafely, args=[])
    # on_interrupt ran to its end (not cut at interrupt_timeout), the node still up
    assert StopsSafely.log == ['interrupted', 'published, context ok: True', 'destroyed']
    assert not rclpy.ok() and signal.getsignal(signal.SIGINT) is before


def test_a_second_signal_stops_a_node_whose_on_interrupt_hangs():
    started = time.monotonic()
    run_node(HangsOnTheWayOut, args=[])
    assert HangsOnTheWayOut.log == ['interrupted', 'destroyed']
    assert time.monotonic() - started < 30.0 and not rclpy.ok()    # not the 60 s hang


class CtrlCInsideAConversion(Node):
    """
    A Ctrl-C whose KeyboardInterrupt rclpy's message conversion turned into a RuntimeError.

    The timer calls the process's SIGINT handler itself, as Python does for the signal, and
    masks its KeyboardInterrupt as pybind11 does; rclpy's own shutdown of the context (a
    thread of its own, a moment later) has not happened: the context is still up.
    """

    def __init__(self):
        super().__init__('helio_test_ctrl_c_inside_a_conversion')
        self.create_timer(0.01, self._take)

    def _take(self):
        try:
            signal.getsignal(signal.SIGINT)(signal.SIGINT, None)
        except KeyboardInterrupt:
            raise RuntimeError("Unable to convert call argument '0' to Python object") from None


class FailsWhileSpinning(Node):
    """A node with a real error in a callback, no signal anywhere."""

    def __init__(self):
        super().__init__('helio_test_fails_while_spinning')
        self.create_timer(0.01, self._fail)

    def _fail(self):
        raise RuntimeError('a real error in a callback')


def test_a_ctrl_c_masked_as_another_exception_is_a_normal_stop():
    before = signal.getsignal(signal.SIGINT)
    run_node(CtrlCInsideAConversion, args=[])          # no exception: a normal stop
    assert not rclpy.ok() and signal.getsignal(signal.SIGINT) is before


def test_a_callback_error_without_a_signal_reaches_the_caller():
    with pytest.raises(RuntimeError, match='a real error in a callback'):
        run_node(FailsWhileSpinning, args=[])
    assert not rclpy.ok()
