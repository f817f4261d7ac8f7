"""ros2 launch helio_control sim.launch.py: the simulated graph of helio_control.bringup."""

from helio_control.launch_files import generate


def generate_launch_description():
    """Return the launch description built from the bringup description."""
    return generate('sim')
