"""The Foxglove view's state (view_model) fed with the graph's messages, no rclpy.init."""

import math
import os

from geometry_msgs.msg import PointStamped, Vector3Stamped
from helio_control.view_model import cdr_stamp_ns, METRICS_SCHEMA, OUTPUTS, ViewModel
from helio_control.view_scene import schema_errors, SCHEMAS
from helio_msgs.msg import SpotObservation, SunEstimate, ThermalStats
from helio_optics.geometry import PinholeCamera, quaternion_from_matrix
from helio_optics.node_kit.conversions import camera_info_from_camera
from helio_optics.rig_kinematics import JOINT_NAMES, Rig
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Image, JointState

CAMERA = PinholeCamera(matrix=np.array([[400.0, 0, 320.0], [0, 400.0, 240.0], [0, 0, 1.0]]),
                       width=640, height=480)
HEIGHT = 0.25


def window(x, y, sec):
    message = PointStamped()
    message.header.stamp.sec = sec
    message.point.x, message.point.y, message.point.z = x, y, 0.003
    return message


def spot_seen_from_above():
    spot = SpotObservation(valid=True, quality=SpotObservation.FULL, semi_major=0.002,
                           semi_minor=0.001, camera_pose_source='marker')
    spot.center.x, spot.center.y = 0.06, 0.05
    pose = spot.camera_pose            # looking straight down from HEIGHT over the origin
    pose.position.z = HEIGHT
    x, y, z, w = quaternion_from_matrix(np.diag([1.0, -1.0, -1.0]))
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = x, y, z, w
    return spot


def test_targets_move_from_current_to_burnt_and_dwell_counts_from_the_new_target():
    model = ViewModel(Rig())
    model.on_window(window(0.05, 0.05, 100))
    model.on_window(window(0.05, 0.05, 101))       # the same target again: still current
    model.on_window(window(0.06, 0.05, 130))
    points, states = model.targets()
    assert states == ['burnt', 'current']
    assert points[0] == pytest.approx((0.05, 0.05, 0.0))
    model.on_stats(ThermalStats(t_max=150.0, n_p=7))
    model.on_spot(spot_seen_from_above())
    metrics = model.metrics(134 * 10**9)
    assert schema_errors(metrics, METRICS_SCHEMA) == []
    assert metrics['dwell'] == pytest.approx(4.0)
    assert metrics['placement'] == pytest.approx(0.0, abs=1e-12)   # spot on the target
    assert (metrics['dots_burnt'], metrics['n_p']) == (1, 7)
    nan = window(0.0, 0.0, 140)
    nan.point.x = math.nan
    model.on_window(nan)                          # the painting ended
    assert model.targets()[1] == ['burnt', 'burnt']


def test_the_rgb_annotations_put_the_spot_where_the_camera_model_sees_it():
    model = ViewModel(Rig())
    model.on_rgb_info(camera_info_from_camera(CAMERA))
    model.on_spot(spot_seen_from_above())
    message = model.rgb_annotations(5)
    # world (x, y, 0) seen from HEIGHT straight down: u = cx + f x / h, v = cy - f y / h
    centre = message['circles'][0]['position']
    assert (centre['x'], centre['y']) == pytest.approx(
        (320.0 + 400.0 * 0.06 / HEIGHT, 240.0 - 400.0 * 0.05 / HEIGHT))
    assert schema_errors(message, SCHEMAS[OUTPUTS['/view/rgb/annotations']]) == []


def test_the_scene_places_the_cameras_by_the_kinematics_and_the_sun_in_the_world():
    rig = Rig()
    model = ViewModel(rig)
    x = np.array([0.1, 0.3, 0.2, 0.4, -0.3])
    joints = JointState(name=list(JOINT_NAMES), position=[float(v) for v in x])
    model.on_joints(joints)
    sun = SunEstimate()
    sun.direction.x, sun.direction.y, sun.direction.z = 0.0, 0.6, -0.8
    model.on_sun(sun)
    truth = Vector3Stamped()
    truth.vector.z = -2.0
    model.on_sun_truth(truth)
    scene = model.scene(7)
    assert schema_errors(scene, SCHEMAS[OUTPUTS['/view/scene']]) == []
    by_id = {entity['id']: entity for entity in scene['entities']}
    # the lens frame's origin: the rig's forward kinematics, moved into the world
    T_world_lens = np.linalg.inv(rig.parameters.T_robot_world) @ rig.forward(x).T_robot_lens
    origin = by_id['lens']['lines'][0]['points'][0]
    assert (origin['x'], origin['y'], origin['z']) == pytest.approx(T_world_lens[:3, 3])
    ends = by_id['sun_estimate']['lines'][0]['points']
    ray = np.array([[p['x'], p['y'], p['z']] for p in ends])
    direction = (ray[1] - ray[0]) / np.linalg.norm(ray[1] - ray[0])
    expected = rig.parameters.T_robot_world[:3, :3].T @ np.array([0.0, 0.6, -0.8])
    assert direction == pytest.approx(expected)
    (truth_entity,) = model.sun_truth_scene(7)['entities']
    points = truth_entity['lines'][0]['points']
    assert points[1]['z'] - points[0]['z'] < 0          # straight down


def test_the_stamp_of_a_serialized_image_is_read_from_its_header():
    image = Image()
    image.header.stamp.sec, image.header.stamp.nanosec = 1782028813, 200000000
    assert cdr_stamp_ns(serialize_message(image)) == 1782028813200000000


def test_with_the_plan_the_targets_are_its_dots_by_state_and_the_next_ones_are_drawn():
    model = ViewModel(Rig(), next_count=2)
    model.set_plan([(0.05, 0.05), (0.06, 0.05), (0.07, 0.05), (0.08, 0.05)])
    assert model.targets()[1] == ['planned'] * 4 and len(model.planned) == 4
    model.on_window(window(0.05, 0.05, 100))
    model.on_window(window(0.06, 0.05, 110))
    points, states = model.targets()
    assert states == ['burnt', 'current', 'planned', 'planned']
    assert points[1] == pytest.approx((0.06, 0.05, 0.0))
    assert [p[0] for p in model.planned] == pytest.approx([0.07, 0.08])
    model.on_rgb_info(camera_info_from_camera(CAMERA))
    model.on_spot(spot_seen_from_above())
    circles = model.rgb_annotations(0)['circles']
    # spot centre, one burnt dot, the next two (of next_count), the current target
    assert len(circles) == 1 + 1 + 2 + 1
    nan = window(0.0, 0.0, 140)
    nan.point.x = math.nan
    model.on_window(nan)
    assert model.targets()[1] == ['burnt'] * 4


def test_the_plan_file_is_read_when_it_appears_and_again_when_it_changes(tmp_path):
    from helio_control.plan import plan_dots
    from helio_control.view_model import PlanFile
    path = tmp_path / 'plan.json'
    model, plan_file = ViewModel(Rig()), PlanFile(str(path))
    assert plan_file.refresh(model) == '' and model.plan is None     # not written yet
    path.write_text(plan_dots([(0.05, 0.05), (0.06, 0.05)]).to_json())
    assert plan_file.refresh(model) == ''
    assert model.plan[:, :2] == pytest.approx(np.array([(0.05, 0.05), (0.06, 0.05)]))
    path.write_text('{"broken": ')
    os.utime(path, ns=(1, 1))        # a new modification time, as a rewrite gives
    assert 'not read' in plan_file.refresh(model)
    assert len(model.plan) == 2                                      # the last good one


def test_the_painters_feedback_says_which_dot_of_the_plan_is_worked_on():
    from helio_msgs.action import PaintPattern
    model = ViewModel(Rig())
    model.set_plan([(0.05, 0.05), (0.06, 0.05), (0.07, 0.05)])

    def feedback(index, phase, stamp_sec):
        model.on_stats(ThermalStats(t_max=100.0, n_p=3))
        model.stats.header.stamp.sec = stamp_sec
        message = PaintPattern.Impl.FeedbackMessage()
        message.feedback.index, message.feedback.phase = index, phase
        model.on_feedback(message)

    feedback(1, 'moving', 10)
    assert model.targets()[1] == ['burnt', 'current', 'planned']
    assert model.current == pytest.approx((0.06, 0.05, 0.0))
    feedback(1, 'heating', 12)
    feedback(1, 'heating', 15)
    metrics = model.metrics(15 * 10**9)
    assert (metrics['dwell'], metrics['dots_burnt']) == (pytest.approx(3.0), 1)
    feedback(2, 'done', 30)
    assert model.targets()[1] == ['burnt'] * 3 and model.current is None
    assert model.metrics(30 * 10**9)['dots_burnt'] == 3
