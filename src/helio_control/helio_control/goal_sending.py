"""
Goals sent to another node's action server, as the controller nodes send them (issue 32).

A killed server stays discovered for seconds and never answers: every goal must be accepted
within a limit of wall time (``accepted``), and one accepted after that is canceled when it
must not move after all (a retreat whose next way is taken, a move given up). A driver
killed mid-move never sends its result: the wait for a result ends when a device the goal
moves faults (``result_unless``), and the goal is canceled. ``run_goal`` does it all for one
goal, its server first discovered (or, for an urgent goal, there now). Each raises
``GoalNotRun`` with a sentence for the goal's own failure; the lens planner
(``node_lens_rig``) and the painter (``painter_node``) turn it into theirs.

No rclpy import: it takes the node and an ``rclpy.action.ActionClient``.
"""

from helio_optics.node_kit.awaitables import cancel_if_accepted, discovered, GoalTrouble
from helio_optics.node_kit.awaitables import results_unless, within


class GoalNotRun(Exception):
    """A goal was refused, not accepted in time, or given up; the message says which."""


async def accepted(node, client, goal, name, limit, cancel_late=True,
                   hint='is its node running?', refused=''):
    """
    Send `goal` to `client`'s server `name`; return its handle once accepted.

    GoalNotRun when it is not accepted within `limit` [s wall] (`hint` says what to check; a
    late acceptance is then canceled when `cancel_late`) or refused (`refused`: why it may
    have been).
    """
    sent = client.send_goal_async(goal)
    if not await within(node, sent, limit, wall=True):
        if cancel_late:
            sent.add_done_callback(cancel_if_accepted)
        raise GoalNotRun(f'{name} did not accept the goal within {limit:g} s ({hint})')
    handle = sent.result()
    if not handle.accepted:
        raise GoalNotRun(f'{name} refused the goal' + (f' ({refused})' if refused else ''))
    return handle


async def result_unless(node, handles, fault, name):
    """
    Return the replies (GetResult responses) of the goals `handles`, in order.

    `fault()` says why the wait must end ('' while it need not: a device the goals move
    faults); the goals are then canceled and GoalNotRun names `name` and the reason.
    """
    try:
        return await results_unless(node, handles, fault)
    except GoalTrouble as trouble:
        raise GoalNotRun(f'{name} given up: {trouble}') from None


async def run_goal(node, client, name, goal, limit, fault, server_timeout=None,
                   cancel_late=True, server_hint='is its node running?'):
    """
    Send `goal` to `client`'s server `name` and return its result (GoalNotRun if not run).

    The server is waited for at most `server_timeout` [s wall] (`server_hint` says what to
    check); with None it must be there now (an urgent goal has no time to wait). Then
    ``accepted`` within `limit` [s wall] (`cancel_late`) and ``result_unless`` `fault()`.
    """
    if server_timeout is None:
        if not client.server_is_ready():
            raise GoalNotRun(f'no {name} server (its node is gone)')
    else:
        try:
            await discovered(node, client.server_is_ready, server_timeout,
                             f'{name} ({server_hint})')
        except TimeoutError as error:
            raise GoalNotRun(str(error)) from None
    handle = await accepted(node, client, goal, name, limit, cancel_late)
    reply, = await result_unless(node, [handle], fault, name)
    return reply.result
