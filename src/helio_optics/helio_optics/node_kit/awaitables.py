"""
Waiting inside a coroutine callback (an async action execute callback) without blocking.

A node whose actions wait on other actions, services, topics or time writes its procedures
as coroutines awaiting rclpy Futures; the executor runs other callbacks meanwhile, so the
node works in a plain ``rclpy.spin`` (one thread; helio_drivers' DeviceActionNode explains
why the MultiThreadedExecutor of rclpy 7.1.6 is avoided). These helpers make the waits:

- ``await sleep(node, seconds, wall=False)``: node-clock time (simulated under
  ``use_sim_time``), or steady wall time;
- ``await within(node, future, seconds)``: True when `future` is done in time;
- ``await discovered(node, ready, timeout, what)``: a server found by discovery, which has
  no event to wait on (looked at every 50 ms), bounded by wall time so a stopped /clock
  cannot hold it; raises TimeoutError naming `what`.
- ``await clock_running(node)``: the node's clock has started (the node-clock waits above
  wait for it first);
- ``FirstOf``: one Future that any callback may complete (the first result wins);
- ``NextTurn``: run a callable at the executor's next turn, after the messages that are
  already waiting (a node-clock timeout that must not beat data queued behind a /clock);
- ``await results_unless(node, handles, trouble, poll)``: accepted action goals' results,
  unless `trouble()` names a reason first (a driver fallen silent: a killed action server
  never answers), then the goals are canceled and GoalTrouble raised;
- ``cancel_if_accepted``: a done-callback for a goal request given up on (it may still be
  accepted, late);
- ``await in_thread(node, function, *args)``: a long computation (a calibration's fit) on a
  thread of its own, its result (or exception) handed back by a guard condition, so the
  executor serves heartbeats, leases and topics meanwhile.
"""

import threading
import time

from rclpy.clock import Clock, ClockType
from rclpy.task import Future


class FirstOf(Future):
    """A Future that ignores every result but the first."""

    def offer(self, result):
        """Complete with `result` unless already done; return whether this one counted."""
        if self.done():
            return False
        self.set_result(result)
        return True


class NextTurn:
    """
    Run callables at the executor's next turn, after the messages already waiting.

    A node-clock timer that fires because a /clock message was taken may be ahead of data
    sent before that /clock but not yet taken (another writer, another DDS queue): a busy
    machine delays one more than the other. rclpy's executor takes every ready subscription
    of a turn before its guard conditions, so a timeout deferred through a guard condition
    first lets the data that arrived meanwhile through; a FirstOf it completes then counts
    only if that data did not.
    """

    def __init__(self, node):
        """Create the guard condition on `node` (call from the node's thread)."""
        self._calls = []
        self._guard = node.create_guard_condition(self._run)

    def call(self, function):
        """Run `function()` at the executor's next turn."""
        self._calls.append(function)
        self._guard.trigger()

    def _run(self):
        calls, self._calls = self._calls, []
        for function in calls:
            function()


async def clock_running(node, timeout=60.0):
    """
    Wait until the node's clock runs (under ``use_sim_time``: the first /clock arrived).

    Before that the clock reads 0, and the first /clock is a jump of years that fires every
    timer at once: a wait timed before it would end at once.
    """
    deadline = time.monotonic() + timeout
    while node.get_clock().now().nanoseconds == 0:
        if time.monotonic() > deadline:
            raise TimeoutError(f'the node clock did not start within {timeout:g} s (is /clock '
                               'published?)')
        await sleep(node, 0.05, wall=True)


async def sleep(node, seconds, wall=False):
    """Wait `seconds` of the node's clock (of the steady wall clock with `wall`)."""
    if seconds <= 0.0:
        return
    if not wall:
        await clock_running(node)
    done = FirstOf()
    clock = Clock(clock_type=ClockType.STEADY_TIME) if wall else None
    timer = node.create_timer(seconds, lambda: done.offer(True), clock=clock)
    try:
        await done
    finally:
        node.destroy_timer(timer)


async def within(node, future, seconds, wall=False):
    """Return whether `future` is done within `seconds` of the node's clock (or `wall`)."""
    if future.done():
        return True
    if not wall:
        await clock_running(node)
    waker = FirstOf()
    future.add_done_callback(lambda _: waker.offer(True))
    clock = Clock(clock_type=ClockType.STEADY_TIME) if wall else None
    timer = node.create_timer(seconds, lambda: waker.offer(False), clock=clock)
    try:
        await waker
    finally:
        node.destroy_timer(timer)
    return future.done()


class GoalTrouble(Exception):
    """An action goal's result given up on: what `result_unless`'s `trouble()` said."""


def cancel_if_accepted(sent):
    """Cancel the goal of a send_goal_async future that completed after it was given up on."""
    handle = sent.result() if sent.done() and sent.exception() is None else None
    if handle is not None and handle.accepted:
        handle.cancel_goal_async()


async def results_unless(node, handles, trouble, poll=0.1):
    """
    Return the result responses of the accepted goals `handles`, unless trouble comes first.

    Every result is asked for at once (a result asked for only after another goal ended can
    find its goal expired on the server). `trouble()` is asked every `poll` seconds of wall
    time while a result is awaited; a non-empty answer (why a result will not come: its
    server's driver fell silent, a device fault) cancels the goals not done and raises
    GoalTrouble with it. A killed action server stays discovered for seconds and answers
    nothing, so a bare await would wait forever.
    """
    results = [handle.get_result_async() for handle in handles]
    for result in results:
        while not await within(node, result, poll, wall=True):
            why = trouble()
            if why:
                for handle, other in zip(handles, results):
                    if not other.done():
                        handle.cancel_goal_async()
                raise GoalTrouble(why)
    return [result.result() for result in results]


async def discovered(node, ready, timeout, what):
    """Wait until `ready()` holds, at most `timeout` wall seconds; TimeoutError naming it."""
    deadline = time.monotonic() + timeout
    while not ready():
        if time.monotonic() > deadline:
            raise TimeoutError(f'{what} is not available after {timeout:g} s')
        await sleep(node, 0.05, wall=True)


async def in_thread(node, function, *args):
    """
    Return `function(*args)` computed on a thread of its own; raise what it raised.

    The executor goes on meanwhile (one thread, ``rclpy.spin``): the thread triggers a guard
    condition when it is done, whose callback completes the awaited future (as the drivers'
    device threads wake their action callbacks).
    """
    future = Future()
    outcome = {}

    def finished():
        if future.done():
            return
        if 'error' in outcome:
            future.set_exception(outcome['error'])
        else:
            future.set_result(outcome.get('value'))

    guard = node.create_guard_condition(finished)

    def run():
        try:
            outcome['value'] = function(*args)
        except BaseException as error:      # handed to the awaiting coroutine
            outcome['error'] = error
        guard.trigger()

    threading.Thread(target=run, name=f'in_thread:{getattr(function, "__name__", "")}',
                     daemon=True).start()
    try:
        return await future
    finally:
        node.destroy_guard_condition(guard)
