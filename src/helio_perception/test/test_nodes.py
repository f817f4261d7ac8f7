"""
spot_detector and thermal_monitor in the kit's InProcessGraph, fed as the real graph does.

Joint states come in two partial messages (arm from dobot_driver, wrist from servo_driver)
stamped near each image; camera_info comes from the kit's converter.
"""

import math
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PointStamped
from helio_msgs.msg import SpotObservation, ThermalStats
from helio_optics.geometry import invert_transform, transform_points
from helio_optics.lens import LensParameters
from helio_optics.node_kit.conversions import camera_info_from_camera, numpy_to_image
from helio_optics.node_kit.conversions import stamp_from_seconds, stamp_to_seconds
from helio_optics.node_kit.in_process_graph import InProcessGraph
from helio_optics.rig_kinematics import Rig
from helio_perception import spot_detection
from helio_perception.ground_plane import GroundMapping
from helio_perception.spot_detector_node import SpotDetectorNode
from helio_perception.spot_observer import optics_from_world
from helio_perception.synthetic_scene import SyntheticScene
from helio_perception.thermal_monitor_node import ThermalMonitorNode
import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, JointState

JOINTS = np.array([0.1, 0.6, 0.3, 0.2, -0.1])


@pytest.fixture
def graph():
    """Yield an InProcessGraph; close it afterwards."""
    with InProcessGraph('perception_test_helper') as in_process:
        yield in_process


def joint_state_parts(seconds, joints=JOINTS):
    """Return the two partial JointStates the drivers publish for joints x at `seconds`."""
    stamp = stamp_from_seconds(seconds)
    arm, wrist = JointState(), JointState()
    arm.header.stamp = wrist.header.stamp = stamp
    arm.name = ['dobot_j1', 'dobot_j2', 'dobot_j3', 'dobot_j4']
    arm.position = [float(v) for v in joints[:3]] + [0.0]
    wrist.name = ['lens_yaw', 'lens_pitch']
    wrist.position = [float(v) for v in joints[3:]]
    return arm, wrist


class Feeder:
    """Publishers of the helper node for one camera's topics and the joint states."""

    def __init__(self, graph, camera_topic):
        self.graph = graph
        self.images = graph.helper.create_publisher(Image, f'{camera_topic}/image_raw', 10)
        self.infos = graph.helper.create_publisher(CameraInfo, f'{camera_topic}/camera_info',
                                                   10)
        self.joints = graph.helper.create_publisher(JointState, 'joint_states', 10)
        graph.wait_until(lambda: min(p.get_subscription_count() for p in
                                     (self.images, self.infos, self.joints)) > 0,
                         what='the node subscribing to its inputs')

    def until(self, feed, holds, what, timeout=60.0):
        """
        Call `feed()` now and again every 0.5 s (wall) until `holds()`, at most `timeout` s.

        A message published before the node's reader has matched this writer is lost (the
        writer may have matched the reader already), and best-effort camera topics drop
        under load: a first input sent once can never arrive (2 cores under load, s46).
        """
        fed = [-math.inf]

        def again():
            if holds():
                return True
            if time.monotonic() - fed[0] >= 0.5:
                fed[0] = time.monotonic()
                feed()
            return False
        self.graph.wait_until(again, timeout, what)

    def joint_states(self, seconds, joints=JOINTS):
        """Publish joints x at `seconds` as the two drivers would."""
        for part in joint_state_parts(seconds, joints):
            self.joints.publish(part)

    def image(self, array, encoding, seconds, **options):
        """Publish an image stamped `seconds`, with the joints at the same stamp."""
        message = numpy_to_image(array, encoding, **options)
        message.header.stamp = stamp_from_seconds(seconds)
        self.images.publish(message)


def test_spot_detector_publishes_observations_and_survives_bad_frames(graph):
    scene = SyntheticScene(640, 480)
    rng = np.random.default_rng(77)
    T_world_camera, (spot,) = scene.random_view(rng, spot_options={'value': 0.8})
    frame = scene.render(T_world_camera, [spot], rng=rng)
    node = graph.add(SpotDetectorNode(**graph.node_options(**{'marker.side': scene.marker_side})))
    received = graph.collect(SpotObservation, 'spot')
    feed = Feeder(graph, 'rgb')

    def first_inputs():
        feed.infos.publish(camera_info_from_camera(scene.camera, stamp_from_seconds(10.0),
                                                   'rgb'))
        for seconds in (10.0, 10.1):
            feed.joint_states(seconds)
    feed.until(first_inputs, lambda: node.camera is not None and node.joints.at(10.1, 0.0),
               'camera_info and both joint-state parts')
    # a malformed frame first: logged, counted, skipped
    bad = numpy_to_image(frame.image, 'rgb8')
    bad.step = 10
    bad.header.stamp = stamp_from_seconds(10.0)
    feed.images.publish(bad)
    feed.image(frame.image, 'rgb8', 10.1)
    first = received.wait_for_count(1)[0]
    assert first.valid, first.reason
    assert node.stats.malformed == 1
    assert np.hypot(first.center.x - spot.center[0], first.center.y - spot.center[1]) < 2e-4
    assert first.area == pytest.approx(spot.area, rel=0.03)
    assert first.marker_pose_age == 0.0 and first.header.frame_id == 'world'
    assert first.quality == SpotObservation.FULL and first.quality_reason == ''
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
        feed.joint_states(seconds)
    graph.wait_until(lambda: node.joints.at(10.5, 0.0), what='the joints at 10.5 s')
    for seconds in (10.3, 10.5):
        feed.image(frame.image, 'rgb8', seconds)
    received.wait_for_count(3)
    assert received.messages[1].valid and received.messages[1].marker_pose_age == 0.0
    assert received.messages[2].valid
    assert received.messages[2].marker_pose_age == pytest.approx(0.2, abs=1e-6)
    assert node.observer.tracker.counts['cache'] == 1
    # a frame without the marker, after the joints moved: invalid with the reason
    feed.joint_states(10.7, JOINTS + 0.05)
    graph.wait_until(lambda: node.joints.at(10.7, 0.0), what='the moved joints')
    feed.image(scene.render(T_world_camera, [spot], rng=rng, with_marker=False).image,
               'rgb8', 10.7)
    third = received.wait_for_count(4)[3]
    assert not third.valid and 'marker 0' in third.reason
    assert node.stats.as_dict()['frames_invalid'] == 1


def optics_features(rig, joints, point):
    """Return Eq 10's (Pi, Theta) of a world point in the optics frame of the lens at joints."""
    T_optics_world = optics_from_world(rig.forward(joints).T_robot_lens,
                                       LensParameters().T_lens_optics,
                                       rig.parameters.T_robot_world)
    truth = transform_points(T_optics_world, [point[0], point[1], 0.0])
    return np.hypot(truth[0], truth[1]), np.arctan2(truth[1], truth[0])


def detector_seeing_one_spot(graph, seed, joint_wait):
    """Start a spot_detector, give it camera_info and the joints at 10 s; return its inputs."""
    scene = SyntheticScene(640, 480)
    rng = np.random.default_rng(seed)
    T_world_camera, (spot,) = scene.random_view(rng, spot_options={'value': 0.8})
    frame = scene.render(T_world_camera, [spot], rng=rng)
    node = graph.add(SpotDetectorNode(**graph.node_options(
        **{'marker.side': scene.marker_side, 'joint_wait': joint_wait})))
    received = graph.collect(SpotObservation, 'spot')
    feed = Feeder(graph, 'rgb')

    def first_inputs():
        feed.infos.publish(camera_info_from_camera(scene.camera, stamp_from_seconds(10.0),
                                                   'rgb'))
        feed.joint_states(10.0)
    feed.until(first_inputs, lambda: node.camera is not None and node.joints.at(10.0, 0.0),
               'camera_info and both joint-state parts')
    return node, received, feed, frame, spot


def test_spot_detector_waits_for_the_joints_after_its_image(graph):
    """
    An image newer than every joint state waits for the next ones: the arm moved meanwhile.

    Truth: Eq 10's features of the spot in the optics frame of the lens at the joints
    published after the image (the moved ones), not at the older joints before it.
    """
    node, received, feed, frame, spot = detector_seeing_one_spot(graph, 77, 5.0)
    feed.image(frame.image, 'rgb8', 10.2)          # within the lookup's 0.3 s of 10.0
    graph.wait_until(lambda: node._waiting is not None, what='the image waiting for joints')
    assert received.messages == []
    moved = JOINTS + np.array([0.05, -0.04, 0.03, 0.1, 0.05])
    feed.joint_states(10.2, moved)                  # the drivers' reading at the image
    observation = received.wait_for_count(1)[0]
    assert observation.valid, observation.reason
    pi, theta = optics_features(node.rig, moved, spot.center)
    assert observation.pi_feature == pytest.approx(pi, abs=2e-4)
    assert observation.theta_feature == pytest.approx(theta, abs=5e-3)
    old_pi, _ = optics_features(node.rig, JOINTS, spot.center)
    assert abs(old_pi - pi) > 2e-3          # the older joints would have given other features


def test_spot_detector_takes_an_image_whose_joints_never_come_after_joint_wait(graph):
    node, received, feed, frame, spot = detector_seeing_one_spot(graph, 78, 0.3)
    feed.image(frame.image, 'rgb8', 10.2)
    observation = received.wait_for_count(1)[0]      # the drivers stopped: taken anyway
    assert observation.valid, observation.reason
    pi, _ = optics_features(node.rig, JOINTS, spot.center)      # the joints known
    assert observation.pi_feature == pytest.approx(pi, abs=2e-4)


def test_thermal_monitor_publishes_stats_with_the_hottest_ground_point(graph):
    node = graph.add(ThermalMonitorNode(**graph.node_options()))
    received = graph.collect(ThermalStats, 'thermal/stats')
    feed = Feeder(graph, 'thermal')
    scene = SyntheticScene(160, 120, horizontal_fov=np.radians(57.0), supersample=1)
    camera = scene.camera

    def first_inputs():
        feed.infos.publish(camera_info_from_camera(camera, stamp_from_seconds(1.0),
                                                   'thermal'))
        feed.joint_states(1.1)
    feed.until(first_inputs, lambda: node.camera is not None and node.joints.at(1.1, 0.0),
               'camera_info and both joint-state parts')
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
    msg.header.stamp, msg.header.frame_id = stamp_from_seconds(1.1), 'thermal'
    bad = numpy_to_image(raw, '16UC1')
    bad.encoding = 'bayer_rggb16'
    feed.images.publish(bad)
    feed.images.publish(msg)
    stats = received.wait_for_count(1)[0]
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
    assert not stats.window_valid
    # the painter's window (radius in z): N_p counted on the dot it names only
    windows = graph.helper.create_publisher(PointStamped, 'thermal/window', QoSProfile(
        depth=1, reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    for centre, radius, n_p in ((target, 0.003, 9), (target + [0.02, 0.0, 0.0], 0.003, 0),
                                (None, math.nan, None)):
        window = PointStamped()
        window.header.frame_id = 'world'
        window.point.x, window.point.y = (math.nan, math.nan) if centre is None else centre[:2]
        window.point.z = radius
        windows.publish(window)
        graph.wait_until(lambda: node.window == (None if centre is None else
                                                 (centre[0], centre[1], radius)),
                         what='the window set')
        feed.images.publish(msg)
        stats = received.wait_for_count(len(received.messages) + 1)[-1]
        assert stats.n_p == 9
        if centre is None:
            assert not stats.window_valid
        else:
            assert stats.window_valid and stats.window_n_p == n_p
            assert stats.window_radius == radius and stats.window_centre.x == centre[0]


def test_the_quality_constants_are_the_message_constants():
    for name in ('NONE', 'FULL', 'CUT_BY_BORDER', 'OCCLUDED', 'BLURRED'):
        assert getattr(spot_detection, f'QUALITY_{name}') == getattr(SpotObservation, name)


def node_status(graph, name):
    """Collect /diagnostics and return a function giving the statuses named `name`."""
    arrays = graph.collect(DiagnosticArray, '/diagnostics')
    return lambda: [s for array in arrays.messages for s in array.status if s.name == name], \
        arrays


def test_thermal_monitor_counts_a_high_gain_leptons_saturated_pixels_and_flags_a_freeze(graph):
    # issue 29: camera_profile gives the datasheet's cap; a frame repeated under a newer
    # stamp (flat-field correction) is flagged frozen, the same frame sent again is not
    node = graph.add(ThermalMonitorNode(**graph.node_options(
        camera_profile='lepton35_high_gain', locate_hottest_point=False)))
    received = graph.collect(ThermalStats, 'thermal/stats')
    feed = Feeder(graph, 'thermal')
    raw = np.full((120, 160), 29815, np.uint16)            # 25 degC
    raw[50:53, 70:74] = 41315                              # 12 pixels at the 140 degC cap
    rng = np.random.default_rng(1)
    verdicts = []
    for stamp, frame in ((1.0, raw + rng.integers(0, 3, raw.shape).astype(np.uint16)),
                         (1.1, None), (1.1, None), (1.2, raw)):
        if frame is not None:
            image = np.minimum(frame, 41315).astype(np.uint16)
        msg = numpy_to_image(image, 'mono16')
        msg.header.stamp = stamp_from_seconds(stamp)
        feed.images.publish(msg)
        stats = received.wait_for_count(len(verdicts) + 1)[-1]
        verdicts.append(stats.frozen)
    assert stats.camera_cap == 140.0 and stats.threshold == 140.0 and stats.n_p == 12
    assert verdicts == [False, True, True, False]
    assert node.freezes.frozen_frames == 1


def test_thermal_monitor_refuses_a_camera_that_cannot_see_charring(graph):
    with pytest.raises(ValueError, match='low gain'):
        ThermalMonitorNode(**graph.node_options(camera_cap=60.0))
    with pytest.raises(ValueError, match='camera_profile'):
        ThermalMonitorNode(**graph.node_options(camera_profile='lepton2'))


def test_thermal_monitor_reports_its_input_stopped_with_the_clock(graph):
    """Issue 17 item 8: the world dies, /clock stops: the node must not look normal."""
    node = graph.add(ThermalMonitorNode(**graph.node_options(
        use_sim_time=True, diagnostics_period=0.1, input_timeout=1.0,
        input_wall_timeout=0.6)))
    statuses, arrays = node_status(graph, 'thermal_monitor: frames')
    clock = graph.helper.create_publisher(Clock, '/clock', 10)
    feed = Feeder(graph, 'thermal')
    raw = np.full((120, 160), 29815, np.uint16)
    seconds, healthy = 100.0, False
    for _ in range(40):   # images and /clock flowing: OK
        clock.publish(Clock(clock=stamp_from_seconds(seconds)))
        feed.image(raw, '16UC1', seconds)
        count = len(arrays.messages)
        arrays.wait_for_count(count + 1)
        healthy = any(s.level == DiagnosticStatus.OK for s in statuses()[-1:])
        if healthy and node.stats.received > 0:
            break
        seconds += 0.05
    assert healthy
    # the world stops: no image, and the node clock stands still; wall time goes on
    arrays.wait_until(lambda _: any(s.level == DiagnosticStatus.ERROR for s in statuses()),
                      what='an ERROR status')
    error = [s for s in statuses() if s.level == DiagnosticStatus.ERROR][0]
    assert 'stale' in error.message and 'thermal/image_raw' in error.message
    assert '0.0 s of node time' in error.message
    values = {v.key: v.value for v in error.values}
    assert float(values['input_age_wall']) > 0.6


def test_spot_detector_reports_stale_input_and_missing_camera_info(graph):
    graph.add(SpotDetectorNode(**graph.node_options(
        diagnostics_period=0.1, input_timeout=0.4, input_wall_timeout=0.4)))
    statuses, arrays = node_status(graph, 'spot_detector: frames')
    arrays.wait_until(lambda _: any(s.level == DiagnosticStatus.WARN for s in statuses()),
                      what='a WARN status')
    assert 'camera_info' in [s for s in statuses() if s.level == DiagnosticStatus.WARN][0].message
    arrays.wait_until(lambda _: any(s.level == DiagnosticStatus.ERROR for s in statuses()),
                      what='an ERROR status')
    error = [s for s in statuses() if s.level == DiagnosticStatus.ERROR][0]
    assert 'no rgb/image_raw since the start' in error.message


def test_spot_detector_skips_images_far_behind_its_clock(graph):
    """A detector behind its camera skips old images (joint states then catch up)."""
    scene = SyntheticScene(640, 480)
    rng = np.random.default_rng(78)
    T_world_camera, (spot,) = scene.random_view(rng, spot_options={'value': 0.8})
    frame = scene.render(T_world_camera, [spot], rng=rng)
    node = graph.add(SpotDetectorNode(**graph.node_options(
        use_sim_time=True, max_image_lag=0.5, **{'marker.side': scene.marker_side})))
    received = graph.collect(SpotObservation, 'spot')
    clock = graph.helper.create_publisher(Clock, '/clock', 10)
    feed = Feeder(graph, 'rgb')

    def first_inputs():
        feed.infos.publish(camera_info_from_camera(scene.camera, stamp_from_seconds(20.0),
                                                   'rgb'))
        for seconds in (18.0, 20.0):
            feed.joint_states(seconds)
        clock.publish(Clock(clock=stamp_from_seconds(20.0)))
    feed.until(first_inputs, lambda: node.camera is not None and node.node_seconds() >= 20.0
               and node.joints.at(20.0, 0.0), 'camera_info, /clock and the joints')
    feed.image(frame.image, 'rgb8', 19.0)         # 1 s behind the clock: skipped
    feed.image(frame.image, 'rgb8', 19.8)         # 0.2 s: processed
    observation = received.wait_for_count(1)[0]
    assert stamp_to_seconds(observation.header.stamp) == pytest.approx(19.8)
    assert observation.valid, observation.reason
    graph.wait_until(lambda: node.stats.received == 2, what='both images received')
    assert node.stats.late == 1 and node.stats.as_dict()['frames_skipped_late'] == 1
    assert len(received.messages) == 1
    assert observation.feature_frame == 'optics'
    # an image 0.5 s from both samples around it (beyond joint_state_tolerance): the two
    # agree, so the joints were at rest and are known (joint_rest_hold 1 s)
    feed.joint_states(21.0)
    clock.publish(Clock(clock=stamp_from_seconds(20.9)))
    graph.wait_until(lambda: node.node_seconds() >= 20.9 and node.joints.at(21.0, 0.0),
                     what='/clock at 20.9 s and the joints at 21.0 s')
    feed.image(frame.image, 'rgb8', 20.5)
    rested = received.wait_for_count(2)[1]
    assert rested.valid and rested.feature_frame == 'optics', rested.reason
    # an image 0.5 s newer than every sample: the arm may be moving off, the joints unknown
    clock.publish(Clock(clock=stamp_from_seconds(21.6)))
    graph.wait_until(lambda: node.node_seconds() >= 21.6, what='/clock at 21.6 s')
    feed.image(frame.image, 'rgb8', 21.5)
    ahead = received.wait_for_count(3)[2]
    assert ahead.feature_frame == 'world'
