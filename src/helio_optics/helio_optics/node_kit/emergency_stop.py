"""
The graph's emergency stop (issue 30, item 2): one latched topic that every actor hears.

``emergency_stop`` (std_msgs/msg/Bool; reliable, transient local, so that a node started
later still hears it) says whether the emergency stop is engaged. The servo driver owns it
and serves ``emergency_stop`` and ``emergency_stop_reset`` (std_srvs/srv/Trigger): the wrist
is what takes the focus off the wood fastest and with nothing else running, so the stop
works with the painter, the lens planner or the arm's driver dead. ``helio stop`` and
``helio reset`` call those services (``ros2 service call /emergency_stop
std_srvs/srv/Trigger`` does the same).

Engaged, every node that moves or heats acts on its own, from this topic alone: the drivers
abort the job they run, stop their device (the servo driver turns the lens off the sun) and
refuse goals; the painter ends its painting without asking for a retreat (the drivers made
it) and refuses goals; until the reset. Relative names: the stop belongs to the graph's
namespace.
"""

from helio_optics.node_kit.qos import LATCHED
from std_msgs.msg import Bool

TOPIC = 'emergency_stop'
SERVICE = 'emergency_stop'
RESET_SERVICE = 'emergency_stop_reset'
QOS = LATCHED
HOW_TO_RESET = ('reset it with `helio reset` (or ros2 service call /emergency_stop_reset '
                'std_srvs/srv/Trigger) once the rig is safe')


def refusal(what):
    """Return the text refusing `what` (a goal, a service) while the stop is engaged."""
    return f'{what} refused: the EMERGENCY STOP is engaged; {HOW_TO_RESET}'


class EmergencyStopListener:
    """
    Follow ``emergency_stop`` for a node: ``engaged``, and a callback on every change.

    `on_change(engaged)` runs on the node's executor when the state changes (not for a
    repeated message).
    """

    def __init__(self, node, on_change=None):
        """Subscribe `node` to the emergency stop topic."""
        self.engaged = False
        self._on_change = on_change
        self.subscription = node.create_subscription(Bool, TOPIC, self._on_message, QOS)

    def _on_message(self, message):
        engaged = bool(message.data)
        if engaged == self.engaged:
            return
        self.engaged = engaged
        if self._on_change is not None:
            self._on_change(engaged)
