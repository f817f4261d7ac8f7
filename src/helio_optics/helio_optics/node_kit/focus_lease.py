"""
The focus lease: a lens left at the heating distance by a client that died is taken away.

The painter's fire-safety watchdog (paper Algorithm 1 plus issue 13's rule: the lens never
rests at the heating distance without fresh thermal data) lives in the painter; a painter
killed outright (SIGKILL, a crash, the power of its computer) cannot retreat, and the lens
would stay focused on one spot. So the painter publishes a heartbeat while it lives, and the
lens planner, which placed the lens, holds a lease on that heartbeat:

- a ``focus`` goal that ends at the heating distance while the heartbeat was alive when the
  goal began arms the lease (a goal from a client without heartbeat, e.g. an operator's
  ``ros2 action send_goal``, never does);
- a move off the heating distance disarms it;
- an armed lease whose heartbeat has been silent for ``timeout`` on the node clock *and*
  ``wall_timeout`` of wall time has expired: the lens planner retreats the lens. Both
  clocks, so that neither a simulated world running 10x faster than the painter's process
  (a heartbeat 0.1 s of simulated time late is 10 ms of wall time) nor a paused one makes
  the lease expire while the painter is alive.

One step down, the servo driver holds the same lease on the lens planner (issue 30): the
lens planner beats on ``lens/heating`` while a lens it placed is at the heating distance and
says ``clear`` when it leaves; a lens planner that dies there (or whose retreat fails)
falls silent, and the servo driver turns the lens off the sun by itself
(``LensHeatingBeat``, ``servo_driver``'s ``heating_guard``).

``FocusLease`` is pure Python (no rclpy); ``declare_lease`` wires one on a node (its
parameters, its beats, its check) and imports rclpy when called. Times in seconds.
"""

import math


class FocusLease:
    """Whether the lens at the heating distance is still held for a live client."""

    def __init__(self, timeout=0.15, wall_timeout=0.3):
        """Expire after `timeout` [s node clock] and `wall_timeout` [s wall] of silence."""
        if not (timeout > 0.0 and wall_timeout > 0.0):
            raise ValueError(f'lease timeouts must be > 0 s, got {timeout} and {wall_timeout}')
        self.timeout, self.wall_timeout = float(timeout), float(wall_timeout)
        self._heard = (-math.inf, -math.inf)       # (node clock, wall) of the last heartbeat
        self.armed = False

    def heard(self, now, wall_now):
        """Note a heartbeat at `now` (node clock) and `wall_now` (wall) [s]."""
        self._heard = (float(now), float(wall_now))

    def alive(self, now, wall_now):
        """Return whether the heartbeat has been heard within either timeout."""
        return not self._silent(now, wall_now)

    def placed(self, at_heating, alive_when_asked):
        """
        Note where a ``focus`` goal left the lens.

        `at_heating`: at the heating distance (within the safe margin); `alive_when_asked`:
        the heartbeat was alive when the goal began (``alive`` then).
        """
        self.armed = bool(at_heating and alive_when_asked)

    def disarm(self):
        """Note that the lens left the heating distance (a retreat, another procedure)."""
        self.armed = False

    def expired(self, now, wall_now):
        """Return whether the lens must be taken away now (armed, heartbeat silent)."""
        return self.armed and self._silent(now, wall_now)

    def silence(self, now, wall_now):
        """Return (node clock, wall) seconds since the last heartbeat."""
        return now - self._heard[0], wall_now - self._heard[1]

    def _silent(self, now, wall_now):
        node_silence, wall_silence = self.silence(now, wall_now)
        return node_silence > self.timeout and wall_silence > self.wall_timeout


# lens/heating (std_msgs/Header): frame_id says whether a lens is at the heating distance
HEATING_TOPIC = 'lens/heating'
HEATING, CLEAR = 'heating', 'clear'


def declare_lease(node, prefix, topic, holder, action, on_beat, check):
    """
    Declare a lease's parameters on `node`, subscribe to its beats, check it; return it.

    Parameters ``<prefix>_topic`` (default `topic`; '' turns the lease off),
    ``<prefix>_timeout`` (0.15 s, node clock) and ``<prefix>_timeout_wall`` (0.3 s), with
    descriptors saying whose beats they are (`holder`) and what is done when they stop
    (`action`). `on_beat(message)` gets each std_msgs/Header beat; `check()` runs every
    0.05 s of wall time (steady clock), so a paused ``/clock`` cannot hold it.
    """
    from helio_optics.node_kit.parameters import declare
    from rclpy.clock import Clock, ClockType
    from std_msgs.msg import Header
    beats = declare(node, f'{prefix}_topic', topic,
                    f'std_msgs/Header beats of {holder}: silent past both timeouts, {action} '
                    "('': off).")
    lease = FocusLease(
        declare(node, f'{prefix}_timeout', 0.15,
                f'Silence of the beats (node clock) after which {action}, with '
                f'{prefix}_timeout_wall [s].', 0.05, 60.0),
        declare(node, f'{prefix}_timeout_wall', 0.3,
                'The same silence in wall time (both must pass) [s].', 0.05, 60.0))
    if beats:
        node.create_subscription(Header, beats, on_beat, 10)
        node.create_timer(0.05, check, clock=Clock(clock_type=ClockType.STEADY_TIME))
    return lease
