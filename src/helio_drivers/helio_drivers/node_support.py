"""Small helpers the driver nodes share: declaring described parameters, building status."""

from builtin_interfaces.msg import Time
from helio_msgs.msg import DeviceStatus
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor


def declare(node, name, default, description, minimum=None, maximum=None):
    """Declare a parameter with a descriptor (and a range for numbers) and return its value."""
    descriptor = ParameterDescriptor(description=description)
    if minimum is not None and isinstance(default, float):
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(minimum), to_value=float(maximum), step=0.0)]
    elif minimum is not None and isinstance(default, int) and not isinstance(default, bool):
        descriptor.integer_range = [IntegerRange(
            from_value=int(minimum), to_value=int(maximum), step=1)]
    return node.declare_parameter(name, default, descriptor).value


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
