"""Helpers the perception nodes share: described parameters, joint states, rig, diagnostics."""

import os
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from helio_optics.rig_kinematics import JOINT_NAMES, load_rig_parameters, Rig, RigParameters
import numpy as np
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor


def declare(node, name, default, description, minimum=None, maximum=None, choices=None):
    """Declare a parameter with a descriptor (and a range for numbers) and return its value."""
    if choices:
        description = f'{description} One of: {", ".join(choices)}.'
    descriptor = ParameterDescriptor(description=description)
    if minimum is not None and isinstance(default, float):
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(minimum), to_value=float(maximum), step=0.0)]
    elif minimum is not None and isinstance(default, int) and not isinstance(default, bool):
        descriptor.integer_range = [IntegerRange(
            from_value=int(minimum), to_value=int(maximum), step=1)]
    value = node.declare_parameter(name, default, descriptor).value
    if choices and value not in choices:
        raise ValueError(f'parameter {name} must be one of {choices}, got {value!r}')
    return value


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
    if not rig_file:
        try:
            from ament_index_python.packages import get_package_share_directory
            rig_file = os.path.join(get_package_share_directory('helio_optics'), 'config',
                                    'rig.yaml')
        except (ImportError, LookupError, OSError) as error:
            node.get_logger().warn(f'no helio_optics share ({error}): default rig geometry')
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
