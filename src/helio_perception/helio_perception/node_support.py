"""Helpers the perception nodes share: joint states, rig, diagnostics."""

import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from helio_optics.rig_kinematics import default_rig_file, JOINT_NAMES, load_rig_parameters
from helio_optics.rig_kinematics import Rig, RigParameters
import numpy as np


def stamp_seconds(stamp):
    """Return a builtin_interfaces/Time as float seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


class JointCache:
    """The latest position of each joint from /joint_states (the drivers publish parts)."""

    def __init__(self, names=JOINT_NAMES):
        self.names = tuple(names)
        self._positions = {}
        self._received = {}

    def update(self, msg):
        """Take a sensor_msgs/JointState; ignore names without a position."""
        now = time.monotonic()
        for index, name in enumerate(msg.name):
            if index < len(msg.position):
                self._positions[name] = float(msg.position[index])
                self._received[name] = now

    def positions(self, max_age=None):
        """Return x (len(names),) or None when a joint is missing or older than max_age [s]."""
        now = time.monotonic()
        values = []
        for name in self.names:
            if name not in self._positions:
                return None
            if max_age is not None and max_age > 0 and now - self._received[name] > max_age:
                return None
            values.append(self._positions[name])
        return np.array(values)


def load_rig(node, rig_file):
    """Return a Rig from `rig_file` (empty: helio_optics' share/config/rig.yaml)."""
    rig_file = rig_file or default_rig_file()
    if not rig_file:
        node.get_logger().warn('no helio_optics config/rig.yaml found: default rig geometry')
        return Rig(RigParameters())
    return Rig(load_rig_parameters(rig_file))


def diagnostics(node, name, values, stamp, level=DiagnosticStatus.OK, message=''):
    """Build a DiagnosticArray with one status holding `values` (a flat dict)."""
    array = DiagnosticArray()
    array.header.stamp = stamp
    status = DiagnosticStatus(level=level, name=name, message=message,
                              hardware_id=node.get_name())
    status.values = [KeyValue(key=str(k), value=f'{v:.3f}' if isinstance(v, float) else str(v))
                     for k, v in values.items()]
    array.status = [status]
    return array
