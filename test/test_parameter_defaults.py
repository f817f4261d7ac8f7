"""
Every node's shipped parameter file says what its code declares (issue 32).

A parameter's default is written twice: in the node's ``declare()`` call and in its package's
``config/<node>.yaml``, the file a user edits and the launch files load. A node run with
``ros2 run`` and no parameter file takes the code's; the two must not drift apart. Each node
is built here in this process, without a parameter file, and every name its YAML sets must
be one the node declares, with the same value. (A driver built without a device retries its
port in the background; the world opens its pseudo-terminals; all are destroyed at once.)
"""

import importlib
import math
import os

from ament_index_python.packages import get_package_share_directory
import pytest
import rclpy
import yaml

# (module, node class, package, node name = its YAML file's name)
NODES = [
    ('helio_drivers.dobot_driver_node', 'DobotDriverNode', 'helio_drivers', 'dobot_driver'),
    ('helio_drivers.servo_driver_node', 'ServoDriverNode', 'helio_drivers', 'servo_driver'),
    ('helio_drivers.sim.world_node', 'SimWorldNode', 'helio_drivers', 'sim_world'),
    ('helio_perception.spot_detector_node', 'SpotDetectorNode', 'helio_perception',
     'spot_detector'),
    ('helio_perception.thermal_monitor_node', 'ThermalMonitorNode', 'helio_perception',
     'thermal_monitor'),
    ('helio_optics.sun_estimator_node', 'SunEstimatorNode', 'helio_optics', 'sun_estimator'),
    ('helio_control.lens_planner_node', 'LensPlannerNode', 'helio_control', 'lens_planner'),
    ('helio_control.painter_node', 'PainterNode', 'helio_control', 'painter'),
]


def flattened(tree, prefix=''):
    """Yield (dotted name, value) of a nested ros__parameters mapping."""
    for key, value in tree.items():
        if isinstance(value, dict):
            yield from flattened(value, f'{prefix}{key}.')
        else:
            yield f'{prefix}{key}', value


def same(declared, written):
    """Tell whether a declared value and a YAML value are the same parameter value."""
    if isinstance(written, list):
        return isinstance(declared, (list, tuple)) and len(declared) == len(written) and all(
            same(d, w) for d, w in zip(declared, written))
    if isinstance(written, bool) or isinstance(declared, bool):
        return declared is written
    if isinstance(written, (int, float)) and isinstance(declared, (int, float)):
        return math.isclose(declared, written, rel_tol=1e-12, abs_tol=0.0)
    return declared == written


@pytest.fixture(scope='module')
def context():
    rclpy.init()
    yield
    rclpy.shutdown()


@pytest.mark.parametrize('module, node_class, package, name', NODES,
                         ids=[entry[3] for entry in NODES])
def test_the_parameter_file_holds_the_code_defaults(context, module, node_class, package,
                                                    name):
    # the installed file, which the launch files and the simulated graph load
    path = os.path.join(get_package_share_directory(package), 'config', f'{name}.yaml')
    with open(path) as stream:
        (section,) = yaml.safe_load(stream).values()
    written = dict(flattened(section['ros__parameters']))
    node = getattr(importlib.import_module(module), node_class)()
    try:
        declared = {key: parameter.value for key, parameter in node._parameters.items()}
    finally:
        node.destroy_node()
    assert not set(written) - set(declared), \
        f'{name}.yaml sets parameters the node does not declare: {set(written) - set(declared)}'
    differ = {key: (declared[key], value) for key, value in written.items()
              if not same(declared[key], value)}
    assert not differ, f'{name}: code default and YAML differ (code, yaml): {differ}'
    assert len(written) >= 10, 'the parameter file was not read'


def test_a_changed_default_is_caught():
    # the comparison itself: a drifted value, a list of another length, a bool for an int
    assert same(0.0001, 1e-4) and same([1.0, 2.0], [1.0, 2.0]) and same('srgb', 'srgb')
    assert not same(0.5, 0.25)
    assert not same([1.0, 2.0], [1.0, 2.0, 3.0])
    assert not same(1, True) and not same(True, 1)
