"""Building the DeviceStatus message the driver nodes publish."""

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
