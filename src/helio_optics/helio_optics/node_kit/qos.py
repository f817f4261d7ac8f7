"""
The graph's quality-of-service profiles, written once (issue 32).

- ``latched(depth)``: reliable and transient local, for state a late joiner must get (the
  sun estimate, the calibrations, device status, the emergency stop, the world's truth);
  ``LATCHED`` keeps the last one.
- ``reliable(depth)``: reliable and volatile, for every message of a stream a node must not
  miss (spots, thermal statistics, joint states where each counts).

Sensor streams use rclpy's ``qos_profile_sensor_data`` (best effort) as ROS drivers publish
them.
"""

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy


def latched(depth=1):
    """Return a reliable, transient-local profile keeping the last `depth` messages."""
    return QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def reliable(depth):
    """Return a reliable, volatile profile with a queue of `depth` messages."""
    return QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE)


LATCHED = latched()
