"""The sun_estimator node in-process (private Context): spots in, /estimate_sun answered."""

import math
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
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

SUN = -direction_from_angles(math.radians(40.0), math.radians(200.0))  # elevation 50 deg


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
