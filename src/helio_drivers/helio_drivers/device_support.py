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
