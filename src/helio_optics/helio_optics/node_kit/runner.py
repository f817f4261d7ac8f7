"""The main() of every helio node: spin one node until shutdown, then clean up."""

import signal
import threading
import time

from helio_optics.node_kit.process_tuning import single_threaded_numerics
import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions


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

    A node class with an ``on_interrupt`` coroutine method (the painter, the lens planner:
    the nodes that can leave the focus on the wood) is stopped safely: the first Ctrl-C or
    SIGTERM runs ``on_interrupt`` on the node's executor, the node still up, for at most its
    ``interrupt_timeout`` seconds (default 5) of wall time, and only then the node is
    destroyed; a second signal stops it at once (`spin_until_interrupt_done`).

    A Ctrl-C can also surface as another exception. rclpy's handler shuts the context down on
    a thread of its own, a moment after Python raised KeyboardInterrupt in whatever Python
    code ran; inside rclpy's conversion of a taken message (a message class's constructor)
    pybind11 turns that into "Unable to convert call argument" RuntimeError while the
    context is still up. So the process notes each SIGINT (`_SignalNote`, installed before
    rclpy's handler, which calls it), and an exception after one is a normal stop.
    """
    single_threaded_numerics()
    safe_stop = hasattr(node_class, 'on_interrupt')
    # rclpy's own handler shuts the context down at the first signal: nothing could be
    # published after it, so a node that must act on the way out takes the signals itself
    interrupted = _SignalNote(signal.SIGINT)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO if safe_stop
               else None)
    node = None
    try:
        node = node_class()
        pools = single_threaded_numerics()
        node.get_logger().info('numeric thread pools: ' + ', '.join(
            f'{name} {count}' for name, count in sorted(pools.items())))
        if safe_stop:
            spin_until_interrupt_done(node)
        else:
            rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if rclpy.ok() and not interrupted.seen:
            raise           # a real error (the context is still up, no Ctrl-C)
    finally:
        try:
            if node is not None:
                node.destroy_node()
        finally:
            _shut_down()
            interrupted.restore()


class _SignalNote:
    """
    A Python handler for `signum` that notes the signal, then raises KeyboardInterrupt.

    Installed before rclpy.init, it is the handler rclpy's own one chains to; ``restore``
    puts the previous handler back. Off the main thread (where Python takes no handler) it
    notes nothing.
    """

    def __init__(self, signum):
        self.signum, self.seen, self.previous = signum, False, None
        if threading.current_thread() is threading.main_thread():
            self.previous = signal.signal(signum, self._note)

    def _note(self, _signum, _frame):
        self.seen = True
        raise KeyboardInterrupt

    def restore(self):
        if self.previous is not None:
            signal.signal(self.signum, self.previous)
            self.previous = None


def spin_until_interrupt_done(node, poll_period=0.05):
    """
    Spin `node` until a Ctrl-C or SIGTERM and its ``on_interrupt`` coroutine have ended.

    The signal's handler only schedules ``on_interrupt`` on the executor (a Python handler
    runs between the executor's waits, which a steady timer ends at least every
    `poll_period`: a wait with a timeout would build a timer at every wait). The spin goes on
    until the coroutine is done or ``interrupt_timeout`` [s wall] has passed since the
    signal; a second signal raises KeyboardInterrupt.
    """
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    state = {}
    waker = node.create_timer(poll_period, lambda: None,
                              clock=Clock(clock_type=ClockType.STEADY_TIME))

    def on_signal(signum, _frame):
        if state:
            raise KeyboardInterrupt     # the second signal: stop now
        name = signal.Signals(signum).name
        node.get_logger().warning(f'{name}: stopping safely first ({node.get_name()})')
        state['deadline'] = time.monotonic() + getattr(node, 'interrupt_timeout', 5.0)
        state['task'] = executor.create_task(node.on_interrupt)

    previous = {signum: signal.signal(signum, on_signal)
                for signum in (signal.SIGINT, signal.SIGTERM)}
    try:
        while rclpy.ok():
            executor.spin_once()
            task = state.get('task')
            if task is None:
                continue
            if task.done():
                if task.exception() is not None:
                    node.get_logger().error(f'stopping safely failed: {task.exception()!r}')
                return
            if time.monotonic() > state['deadline']:
                node.get_logger().error('stopping safely did not end within interrupt_timeout')
                return
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        node.destroy_timer(waker)
        executor.remove_node(node)


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
