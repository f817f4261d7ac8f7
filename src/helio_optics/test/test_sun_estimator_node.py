"""The sun_estimator node in-process (private Context): spots in, /estimate_sun answered."""

import math
import os
import time

from helio_msgs.msg import SpotObservation, SunEstimate
from helio_msgs.srv import EstimateSun
from helio_optics.geometry import direction_from_angles, invert_transform, transform_points
from helio_optics.rig_kinematics import JOINT_NAMES, Rig, UnreachableError
from helio_optics.sun_estimator_node import SunEstimatorNode
import numpy as np
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
import yaml

SUN = -direction_from_angles(math.radians(40.0), math.radians(200.0))  # elevation 50 deg
CONFIG = os.path.join(os.path.dirname(__file__), '..', 'config', 'sun_estimator.yaml')
# The documented range of every numeric parameter (README, config/sun_estimator.yaml units):
# what the node declared before and must keep declaring. Ints get integer ranges.
RANGES = {
    'lens.focal_length': (0.01, 1.0), 'lens.refractive_index': (1.01, 3.0),
    'lens.thickness': (0.0, 0.02), 'lens.aperture_diameter': (0.001, 1.0),
    'lens.transmission': (0.01, 1.0), 'rim_points': (8, 4096), 'contour_fraction': (0.05, 1.0),
    'centre_sigma': (1e-6, 0.05), 'max_observations': (1, 10000),
    'max_observation_age': (0.1, 1e6), 'joint_state_tolerance': (0.0, 10.0),
    'gain': (0.01, 2.0), 'delta': (1e-9, 0.1), 'tolerance': (1e-15, 1.0),
    'max_iterations': (1, 10000), 'site.latitude_deg': (-90.0, 90.0),
    'site.longitude_deg': (-180.0, 360.0), 'site.elevation_m': (-500.0, 9000.0),
    'site.temperature_c': (-60.0, 60.0), 'site.pressure_pa': (3e4, 1.2e5),
    'update_period': (0.0, 3600.0)}


def spin_until(executor, condition, timeout=10.0):
    """Spin until `condition()` holds; fail after `timeout` seconds of waiting."""
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, 'timed out waiting'
        executor.spin_once(timeout_sec=0.05)


@pytest.fixture
def graph():
    context = Context()
    rclpy.init(context=context)
    node = SunEstimatorNode(context=context, parameter_overrides=[
        Parameter('update_period', value=0.2)])
    helper = rclpy.create_node('sun_estimator_test_helper', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(helper)
    try:
        yield node, helper, executor
    finally:
        executor.shutdown()
        helper.destroy_node()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def flatten(tree, prefix=''):
    """Flatten a ros__parameters tree into {'a.b': value}."""
    flat = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            flat.update(flatten(value, f'{prefix}{key}.'))
        else:
            flat[f'{prefix}{key}'] = value
    return flat


def wait_for(executor, future, timeout=10.0):
    """Spin until `future` is done and return its result; fail after `timeout` seconds."""
    executor.spin_until_future_complete(future, timeout_sec=timeout)
    assert future.done(), 'timed out waiting for a parameter service'
    return future.result()


def test_parameters_are_described_with_ranges_that_refuse_values_outside(graph):
    node, helper, executor = graph
    with open(CONFIG) as stream:
        shipped = flatten(yaml.safe_load(stream)['/**']['ros__parameters'])
    assert set(RANGES) < set(shipped)
    client = AsyncParameterClient(helper, 'sun_estimator')
    spin_until(executor, client.services_are_ready)
    names = sorted(shipped)
    descriptors = wait_for(executor, client.describe_parameters(names)).descriptors
    values = wait_for(executor, client.get_parameters(names)).values
    for name, descriptor, value in zip(names, descriptors, values):
        assert descriptor.name == name and descriptor.description, name
        if name != 'update_period':  # overridden by the fixture
            assert parameter_value_to_python(value) == shipped[name], name
        if name not in RANGES:
            assert not descriptor.floating_point_range and not descriptor.integer_range, name
            continue
        low, high = RANGES[name]
        assert low <= shipped[name] <= high, name
        if isinstance(shipped[name], int):
            (span,) = descriptor.integer_range
            assert (span.from_value, span.to_value, span.step) == (low, high, 1), name
        else:
            (span,) = descriptor.floating_point_range
            assert (span.from_value, span.to_value) == pytest.approx((low, high)), name

    outside = [Parameter('rim_points', value=4097), Parameter('max_observations', value=0),
               Parameter('site.latitude_deg', value=90.5), Parameter('gain', value=2.5),
               Parameter('centre_sigma', value=0.0)]
    results = wait_for(executor, client.set_parameters(outside)).results
    assert [result.successful for result in results] == [False] * len(outside)
    assert all(result.reason for result in results)
    assert node.get_parameter('rim_points').value == 64
    assert node.get_parameter('site.latitude_deg').value == shipped['site.latitude_deg']
    inside = [Parameter('max_observations', value=10000), Parameter('gain', value=2.0)]
    results = wait_for(executor, client.set_parameters(inside)).results
    assert all(result.successful for result in results)
    assert node.get_parameter('max_observations').value == 10000


def sweep_joints(rig):
    """Joints of a lens yaw sweep viewing a clear spot near the canvas centre."""
    target = transform_points(rig.parameters.T_robot_world, [0.1, 0.1, 0.0])
    centre = target - 0.06 * SUN
    elevation = math.asin(-SUN[2])
    azimuth = math.atan2(-SUN[1], -SUN[0])
    axis = direction_from_angles(0.5 * math.pi - elevation - math.radians(14.0), azimuth)
    joints = []
    for offset in np.radians([-10.0, -5.0, 0.0, 5.0, 10.0]):
        yaw, pitch = rig.yaw_pitch_for_axis(axis)
        try:
            joints.append(rig.inverse(centre, yaw + offset, pitch))
        except UnreachableError:
            continue
    assert len(joints) >= 3
    return joints


def test_service_estimates_the_sun_and_publishes_it_transient_local(graph):
    node, helper, executor = graph
    rig = Rig()
    joint_publisher = helper.create_publisher(JointState, '/joint_states', 50)
    spot_publisher = helper.create_publisher(SpotObservation, '/spot', 20)
    spin_until(executor, lambda: node.count_publishers('/spot') >= 1
               and joint_publisher.get_subscription_count() >= 1
               and spot_publisher.get_subscription_count() >= 1)
    T_world_robot = invert_transform(rig.parameters.T_robot_world)
    # A malformed (invalid) spot first: logged and skipped.
    spot_publisher.publish(SpotObservation(valid=False, reason='no spot'))
    for k, x in enumerate(sweep_joints(rig)):
        stamp = helper.get_clock().now().to_msg()
        joint_state = JointState(name=list(JOINT_NAMES), position=[float(v) for v in x])
        joint_state.header.stamp = stamp
        joint_publisher.publish(joint_state)
        truth = node.estimator.synthetic_observation(
            SUN, rig.forward(x).T_robot_lens, rig.parameters.T_robot_world[:3, 3],
            rig.parameters.T_robot_world[:3, 2])
        centre_world = transform_points(T_world_robot, truth.centre)
        spot = SpotObservation(valid=True)
        spot.header.stamp = stamp
        spot.header.frame_id = 'world'
        spot.center.x, spot.center.y, spot.center.z = (float(v) for v in centre_world)
        spin_until(executor, lambda: len(node._joint_stamps) > k)
        spot_publisher.publish(spot)
        spin_until(executor, lambda: len(node._observations) > k)

    client = helper.create_client(EstimateSun, '/estimate_sun')
    assert client.wait_for_service(timeout_sec=5.0)
    for method in ('levenberg_marquardt', 'interaction_matrix'):
        future = client.call_async(EstimateSun.Request(method=method))
        executor.spin_until_future_complete(future, timeout_sec=20.0)
        response = future.result()
        assert response is not None and response.success, response.message
        direction = np.array([response.estimate.direction.x, response.estimate.direction.y,
                              response.estimate.direction.z])
        assert math.degrees(math.acos(min(1.0, direction @ SUN))) < 0.01
        assert response.estimate.method == method and response.estimate.observations >= 3

    future = client.call_async(EstimateSun.Request(method='guess'))
    executor.spin_until_future_complete(future, timeout_sec=5.0)
    assert not future.result().success and 'unknown method' in future.result().message

    # A late subscriber still gets the estimate (transient local), then the Eq 18 updates.
    received = []
    helper.create_subscription(
        SunEstimate, '/sun/estimate', received.append,
        QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE,
                   durability=DurabilityPolicy.TRANSIENT_LOCAL))
    spin_until(executor, lambda: len(received) >= 2)
    assert received[0].converged and received[0].header.frame_id == 'robot'
    assert received[-1].anchor_stamp == received[0].anchor_stamp
