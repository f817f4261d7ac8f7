"""
What the driver nodes share that needs no rclpy: the DeviceStatus message and move deadlines.

`MoveDeadline` decides when a move has run too long. The limit counts on the node's clock
(simulated seconds under ``use_sim_time``), so a simulation slower than real time does not
abort a move early and one faster than real time does not let it run long; a second limit
counts on the monotonic wall clock, so a /clock that stops cannot hold a goal forever.
"""

from builtin_interfaces.msg import Time
from helio_msgs.msg import DeviceStatus


def device_status(stamp, device, port, connected, reconnect_attempts, alarms, message):
    """Build a DeviceStatus message."""
    status = DeviceStatus()
    status.header.stamp = stamp if isinstance(stamp, Time) else stamp.to_msg()
    status.device = device
    status.port = port
    status.connected = bool(connected)
    status.reconnect_attempts = int(reconnect_attempts)
    status.alarms = list(alarms)
    status.message = message
    return status


class MoveDeadline:
    """
    A move's time limits: `limit_s` on the node clock, `wall_limit_s` on the wall clock [s].

    Node-clock readings of 0 (a simulated clock before its first /clock message) and readings
    that go backwards (a simulation restarted) re-anchor the start instead of counting as
    elapsed time, so neither aborts a move nor stretches it.
    """

    def __init__(self, limit_s, wall_limit_s, node_now_s, wall_now_s):
        """Start both clocks at `node_now_s` (node clock) and `wall_now_s` (monotonic) [s]."""
        if not limit_s > 0.0 or not wall_limit_s > 0.0:
            raise ValueError(f'move time limits must be positive, got {limit_s} s (node clock) '
                             f'and {wall_limit_s} s (wall clock)')
        self.limit_s = float(limit_s)
        self.wall_limit_s = float(wall_limit_s)
        self.node_start_s = float(node_now_s)
        self.wall_start_s = float(wall_now_s)

    def node_elapsed(self, node_now_s):
        """Return the node-clock time since the start [s] (re-anchoring, see the class)."""
        if self.node_start_s <= 0.0 or node_now_s < self.node_start_s:
            self.node_start_s = float(node_now_s)
        return node_now_s - self.node_start_s

    def exceeded(self, node_now_s, wall_now_s):
        """Return why the move has run too long, or None while it may go on."""
        node_elapsed = self.node_elapsed(node_now_s)
        if node_elapsed > self.limit_s:
            return f'move not finished within {self.limit_s:.2f} s on the node clock'
        wall_elapsed = wall_now_s - self.wall_start_s
        if wall_elapsed > self.wall_limit_s:
            return (f'move not finished within {self.wall_limit_s:.2f} s of wall time while '
                    f'the node clock advanced only {node_elapsed:.2f} s of its '
                    f'{self.limit_s:.2f} s (is /clock running?)')
        return None


class TwoClockSchedule:
    """
    A period due on whichever of two clocks reaches it first: the node clock or the wall clock.

    Beside a simulated world (``use_sim_time``) a driver's periodic work (its joint states)
    must follow simulated time, whatever the machine's load makes of the ratio between the
    clocks: the world steps its devices on simulated time and a node matches an image to the
    joints within tolerances of simulated time. The node clock therefore decides. The wall
    clock decides too, so that a paused /clock (a world holding for a slow consumer, or one
    stopped) still gets the output every `period` of wall time, stamped with the same
    simulated instant. On a real rig both clocks run together and this is a plain period.

    Node-clock readings of 0 (no /clock yet) and readings that go backwards (a simulation
    restarted) re-anchor the node clock's side instead of waiting for the old time to return.

    A reading counts as a period on when it is within a thousandth of the period of it: epoch
    seconds as floats are only good to about 0.2 us, so ticks exactly one period apart (a
    rate of one per world step) differ by a little less than the period every other time.
    """

    def __init__(self, period):
        """Be due every `period` [s] of either clock, and at once the first time."""
        if not period > 0.0:
            raise ValueError(f'period must be > 0 s, got {period}')
        self.period = float(period)
        self._at_least = self.period * (1.0 - 1e-3)
        self._node_last = None
        self._wall_last = None

    def due(self, node_now_s, wall_now_s):
        """Return whether the work is due at these readings; if so, count it as done."""
        node_ok = node_now_s > 0.0
        if self._node_last is not None and node_ok and node_now_s < self._node_last:
            self._node_last = None                    # the node clock went back: restarted
        due = (self._wall_last is None
               or wall_now_s - self._wall_last >= self._at_least
               or (node_ok and (self._node_last is None
                                or node_now_s - self._node_last >= self._at_least)))
        if due:
            self._wall_last = wall_now_s
            self._node_last = node_now_s if node_ok else None
        return due

    def wall_due_at(self):
        """Return the wall time [s] at which the wall clock's side is next due."""
        return -float('inf') if self._wall_last is None else self._wall_last + self.period
