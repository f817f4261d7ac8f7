"""In-process tests of spot_detector and thermal_monitor with a private rclpy Context."""

from helio_msgs.msg import SpotObservation, ThermalStats
from helio_optics.geometry import invert_transform, transform_points
from helio_optics.lens import LensParameters
from helio_optics.rig_kinematics import JOINT_NAMES, Rig
from helio_perception.ground_plane import GroundMapping
from helio_perception.image_conversion import numpy_to_image
from helio_perception.spot_detector_node import SpotDetectorNode
from helio_perception.spot_observer import optics_from_world
from helio_perception.synthetic_scene import SyntheticScene
from helio_perception.thermal_monitor_node import ThermalMonitorNode
import numpy as np
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import CameraInfo, Image, JointState

JOINTS = np.array([0.1, 0.6, 0.3, 0.2, -0.1])
TIMEOUT = 15.0


@pytest.fixture
def ros():
    """Yield (context, executor, helper node); shut everything down afterwards."""
    context = Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    helper = rclpy.create_node('perception_test_helper', context=context)
    executor.add_node(helper)
    try:
        yield context, executor, helper
    finally:
        executor.shutdown()
        helper.destroy_node()
        rclpy.shutdown(context=context)


def camera_info(camera, stamp, frame_id):
    """Return a CameraInfo message of a PinholeCamera."""
    info = CameraInfo()
    info.header.stamp, info.header.frame_id = stamp, frame_id
    info.width, info.height = camera.width, camera.height
    info.distortion_model = 'plumb_bob'
    info.d = [float(v) for v in camera.distortion]
    info.k = [float(v) for v in camera.matrix.ravel()]
    return info


def joint_state(stamp, joints=JOINTS):
    """Return a JointState with the five rig joints."""
    msg = JointState()
    msg.header.stamp = stamp
    msg.name = list(JOINT_NAMES)
    msg.position = [float(v) for v in joints]
    return msg


class Collector:
    """Collect messages; `wait_for` spins until the n-th one arrived."""

    def __init__(self):
        self.messages = []

    def __call__(self, msg):
        self.messages.append(msg)

    def wait_for(self, executor, count):
        return wait_until(executor, lambda: len(self.messages) >= count)


def wait_until(executor, condition, timeout=TIMEOUT):
    """Spin until `condition()` holds or the timeout passes; return whether it holds."""
    remaining = timeout
    while not condition() and remaining > 0:
        executor.spin_once(timeout_sec=0.05)
        remaining -= 0.05
    return condition()


def stamp_at(_node, seconds):
    """Return a builtin_interfaces/Time at `seconds`."""
    return rclpy.time.Time(seconds=seconds).to_msg()


def test_spot_detector_publishes_observations_and_survives_bad_frames(ros):
    context, executor, helper = ros
    scene = SyntheticScene(640, 480)
    rng = np.random.default_rng(77)
    T_world_camera, (spot,) = scene.random_view(rng)
    frame = scene.render(T_world_camera, [spot], rng=rng)
    node = SpotDetectorNode(context=context, parameter_overrides=[
        Parameter('marker.side', value=scene.marker_side)])
    executor.add_node(node)
    try:
        received = Collector()
        helper.create_subscription(SpotObservation, 'spot', received, 10)
        images = helper.create_publisher(Image, 'rgb/image_raw', 10)
        infos = helper.create_publisher(CameraInfo, 'rgb/camera_info', 10)
        joints = helper.create_publisher(JointState, 'joint_states', 10)
        assert wait_until(executor, lambda: images.get_subscription_count() > 0
                          and infos.get_subscription_count() > 0
                          and joints.get_subscription_count() > 0
                          and helper.count_publishers('spot') > 0)
        infos.publish(camera_info(scene.camera, stamp_at(helper, 10.0), 'rgb'))
        joints.publish(joint_state(stamp_at(helper, 10.0)))
        assert wait_until(executor, lambda: node.camera is not None
                          and node.joints.positions() is not None)
        # a malformed frame first: logged, counted, skipped
        bad = numpy_to_image(frame.image, 'rgb8')
        bad.step = 10
        bad.header.stamp = stamp_at(helper, 10.0)
        images.publish(bad)
        good = numpy_to_image(frame.image, 'rgb8')
        good.header.stamp = stamp_at(helper, 10.1)
        images.publish(good)
        assert received.wait_for(executor, 1)
        first = received.messages[0]
        assert first.valid, first.reason
        assert node.stats.malformed == 1
        assert np.hypot(first.center.x - spot.center[0], first.center.y - spot.center[1]) < 2e-4
        assert first.area == pytest.approx(spot.area, rel=0.03)
        assert first.marker_pose_age == 0.0 and first.header.frame_id == 'world'
        # Eq 10 features in the optics frame of the lens at JOINTS
        rig = node.rig
        T_optics_world = optics_from_world(rig.forward(JOINTS).T_robot_lens,
                                           LensParameters().T_lens_optics,
                                           rig.parameters.T_robot_world)
        truth = transform_points(T_optics_world, [spot.center[0], spot.center[1], 0.0])
        assert first.feature_frame == 'optics'
        assert first.pi_feature == pytest.approx(np.hypot(truth[0], truth[1]), abs=2e-4)
        assert first.theta_feature == pytest.approx(np.arctan2(truth[1], truth[0]), abs=5e-3)
        # the same joints: detected once more (the joints are now known to be still), then
        # the cached marker pose is reused, 0.2 s old
        for seconds in (10.3, 10.5):
            again = numpy_to_image(frame.image, 'rgb8')
            again.header.stamp = stamp_at(helper, seconds)
            images.publish(again)
        assert received.wait_for(executor, 3)
        assert received.messages[1].valid and received.messages[1].marker_pose_age == 0.0
        assert received.messages[2].valid
        assert received.messages[2].marker_pose_age == pytest.approx(0.2, abs=1e-6)
        assert node.observer.tracker.counts['cache'] == 1
        # a frame without the marker, after the joints moved: invalid with the reason
        joints.publish(joint_state(stamp_at(helper, 10.6), JOINTS + 0.05))
        assert wait_until(executor, lambda: np.allclose(node.joints.positions(), JOINTS + 0.05))
        plain = numpy_to_image(scene.render(T_world_camera, [spot], rng=rng,
                                            with_marker=False).image, 'rgb8')
        plain.header.stamp = stamp_at(helper, 10.7)
        images.publish(plain)
        assert received.wait_for(executor, 4)
        third = received.messages[3]
        assert not third.valid and 'marker 0' in third.reason
        assert node.stats.as_dict()['frames_invalid'] == 1
    finally:
        executor.remove_node(node)
        node.destroy_node()


def test_thermal_monitor_publishes_stats_with_the_hottest_ground_point(ros):
    context, executor, helper = ros
    node = ThermalMonitorNode(context=context)
    executor.add_node(node)
    try:
        received = Collector()
        helper.create_subscription(ThermalStats, 'thermal/stats', received, 10)
        images = helper.create_publisher(Image, 'thermal/image_raw', 10)
        infos = helper.create_publisher(CameraInfo, 'thermal/camera_info', 10)
        joints = helper.create_publisher(JointState, 'joint_states', 10)
        assert wait_until(executor, lambda: images.get_subscription_count() > 0
                          and infos.get_subscription_count() > 0
                          and joints.get_subscription_count() > 0
                          and helper.count_publishers('thermal/stats') > 0)
        scene = SyntheticScene(160, 120, horizontal_fov=np.radians(57.0), supersample=1)
        camera = scene.camera
        infos.publish(camera_info(camera, stamp_at(helper, 1.0), 'thermal'))
        joints.publish(joint_state(stamp_at(helper, 1.0)))
        assert wait_until(executor, lambda: node.camera is not None
                          and node.joints.positions() is not None)
        # where does the thermal camera look at JOINTS? put the hot dot on a ground point
        rig = Rig(node.rig.parameters)
        T_world_thermal = invert_transform(rig.parameters.T_robot_world) @ \
            rig.forward(JOINTS).T_robot_thermal
        centre = GroundMapping(camera, T_world_thermal).pixels_to_ground([[80.0, 60.0]])[0]
        target = centre + np.array([0.004, -0.003, 0.0])
        u, v = np.rint(camera.project(transform_points(invert_transform(T_world_thermal),
                                                       target))[0]).astype(int)
        raw = np.full((120, 160), 29815, np.uint16)  # 25 degC
        raw[v - 2:v + 3, u - 2:u + 3] = 40000        # 126.85 degC
        raw[v - 1:v + 2, u - 1:u + 2] = 45405        # at the cap, 180.9 degC: 9 pixels
        raw[v, u] = 45405
        msg = numpy_to_image(raw, '16UC1', is_bigendian=True, step=160 * 2 + 8)
        msg.header.stamp, msg.header.frame_id = stamp_at(helper, 1.1), 'thermal'
        bad = numpy_to_image(raw, '16UC1')
        bad.encoding = 'bayer_rggb16'
        images.publish(bad)
        images.publish(msg)
        assert received.wait_for(executor, 1)
        stats = received.messages[0]
        assert stats.n_p == 9 and stats.t_max == pytest.approx(180.9, abs=1e-9)
        assert stats.saturated and stats.camera_cap == pytest.approx(180.9)
        assert (stats.hottest_u, stats.hottest_v) in {(u + du, v + dv) for du in (-1, 0, 1)
                                                      for dv in (-1, 0, 1)}
        assert stats.hottest_point_valid
        # one thermal pixel covers a few mm here: the hottest pixel is within 1.5 pixels
        footprint = np.linalg.norm(np.subtract(*GroundMapping(camera, T_world_thermal)
                                               .pixels_to_ground([[u, v], [u + 1, v]])))
        error = np.hypot(stats.hottest_point.x - target[0], stats.hottest_point.y - target[1])
        assert error < 1.5 * footprint
        assert node.stats.malformed == 1
    finally:
        executor.remove_node(node)
        node.destroy_node()
