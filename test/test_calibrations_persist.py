"""
Calibrations read back at start (issue 30): each node that uses one, as its own process.

Every calibration lives in one ``calibration_dir`` (``helio_control.calibration_store``,
with the digest of the rig file it was made for): the lens planner's robot-world, rig-build
and focal calibrations, the painter's dot-size calibration (``dots.yaml``, helio calibrate
dots) and the RGB camera's camera_info file (``camera_info/rgb.yaml``, helio calibrate
camera). Started again on that directory, the lens planner must publish and use its three
(``calibration/rig``, ``calibration/world_pose``, ``calibration/focus``, latched, which the
other nodes follow), the painter must read the dot size back, and the spot detector must
use the camera_info file for a camera that sends an uncalibrated camera_info (K = 0, as
usb_cam without a calibration file), all without calibrating again. Files made for another
rig description are refused, named in the logs, and not used.
"""

import math
import shutil

from conftest import graph_of_processes
from geometry_msgs.msg import PoseStamped
from helio_control.calibration_store import rig_description, save_calibration
from helio_control.dot_size_calibration import DotSizeCalibration, save_dot_calibration
from helio_msgs.msg import FocalCalibration, FocusDistances
from helio_optics.config_files import config_path
from helio_optics.geometry import PinholeCamera
from helio_optics.node_kit.conversions import camera_info_from_camera, pose_to_matrix
from helio_optics.node_kit.deployment import RGB_CAMERA_INFO_FILE
from helio_optics.node_kit.in_process_graph import GraphTimeout, TRANSIENT_LOCAL_QOS
from helio_perception.camera_calibration import write_camera_info
import numpy as np
import pytest
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo
from std_msgs.msg import String
import yaml

WORLD = {'world_in_robot': [0.1472, -0.0981, -0.1403], 'world_yaw': 0.0123}
BUILD = {'arm.forearm': 0.1483, 'joint_offsets': [0.001, -0.002, 0.0015, 0.0, 0.01]}
HEATING_DISTANCE = 0.0846
# a dot-size law d^2 = a + b N_p (helio calibrate dots): 1.6 mm at N_p 15, 2.4 mm at N_p 40
DOTS = DotSizeCalibration(
    area_intercept=1.6e-3 ** 2 - 15 * (2.4e-3 ** 2 - 1.6e-3 ** 2) / 25,
    area_per_n_p=(2.4e-3 ** 2 - 1.6e-3 ** 2) / 25, dwell_n_p=(15.0, 40.0),
    dwell_s=(5.0, 30.0), n_p_min=15, n_p_max=40, residual_rms=3e-5, residual_max=6e-5,
    dwell_residual_rms=0.4, samples=8)
# a webcam's intrinsics (helio calibrate camera), not the simulated camera's
CAMERA = PinholeCamera(matrix=np.array([[611.0, 0.0, 318.5], [0.0, 611.0, 241.0],
                                        [0.0, 0.0, 1.0]]), width=640, height=480,
                       distortion=np.array([0.081, -0.19, 0.0, 0.0, 0.0]))


def saved(directory, rig_file):
    """Save every calibration in `directory` as the nodes and commands do, for `rig_file`."""
    description = rig_description(rig_file)
    save_calibration(directory, 'rig_build.yaml', {'rig': BUILD, 'calibration_id': 'built'},
                     description, 'lens_planner', {'residual_position_m': 2e-4})
    save_calibration(directory, 'robot_world.yaml', {'rig': WORLD}, description,
                     'lens_planner', {'residual_position_m': 1e-5})
    save_calibration(directory, 'focus.yaml', {'heating_distance': HEATING_DISTANCE,
                                               'min_area': 1.9e-6, 'samples': 35},
                     description, 'lens_planner')
    save_dot_calibration(str(directory), DOTS, description)
    camera_info = directory / RGB_CAMERA_INFO_FILE
    camera_info.parent.mkdir(parents=True, exist_ok=True)
    write_camera_info(str(camera_info), CAMERA, 'webcam')


def started(tmp_path, name, rig_file, calibrations):
    """Start the nodes that read calibrations on `calibrations`; return the graph context."""
    common = {'calibration_dir': str(calibrations), 'rig_file': str(rig_file)}
    overrides = {'lens_planner': dict(common), 'painter': dict(common),
                 'spot_detector': dict(common)}
    return graph_of_processes(tmp_path / name, ('spot_detector', 'lens_planner', 'painter'),
                              overrides)


def log_of(tmp_path, run, node):
    """Return the text of `node`'s log in the graph `run` ('' before it exists)."""
    log = tmp_path / run / 'logs' / f'{node}.log'
    return log.read_text() if log.exists() else ''


def uncalibrated_camera_info():
    """Return the camera_info a webcam sends without a calibration file: K all zero."""
    info = camera_info_from_camera(CAMERA, frame_id='rgb_optical')
    info.k = [0.0] * 9
    info.d = []
    info.p = [0.0] * 12
    return info


def test_every_calibration_survives_a_restart_and_another_rigs_are_refused(tmp_path):
    rig_file = tmp_path / 'rig.yaml'
    shutil.copy(config_path('rig.yaml'), rig_file)
    calibrations = tmp_path / 'calibration'
    saved(calibrations, rig_file)
    for run in ('first', 'restarted'):         # read back, and again after a restart
        with started(tmp_path, run, rig_file, calibrations) as (_, graph):
            world = graph.collect(PoseStamped, 'calibration/world_pose', TRANSIENT_LOCAL_QOS)
            focus = graph.collect(FocalCalibration, 'calibration/focus', TRANSIENT_LOCAL_QOS)
            distances = graph.collect(FocusDistances, 'focus/distances', TRANSIENT_LOCAL_QOS)
            build = graph.collect(String, 'calibration/rig', TRANSIENT_LOCAL_QOS)
            published = yaml.safe_load(build.wait_for_count(1, 60.0)[0].data)
            assert published['arm.forearm'] == pytest.approx(BUILD['arm.forearm'])
            assert published['joint_offsets'] == pytest.approx(BUILD['joint_offsets'])
            graph.wait_until(lambda: world.messages and pose_to_matrix(
                world.messages[-1].pose)[0, 3] == pytest.approx(WORLD['world_in_robot'][0]),
                60.0, 'the saved robot-world calibration')
            transform = pose_to_matrix(world.messages[-1].pose)
            assert transform[:3, 3] == pytest.approx(WORLD['world_in_robot'], abs=1e-9)
            assert math.atan2(transform[1, 0], transform[0, 0]) == pytest.approx(
                WORLD['world_yaw'], abs=1e-9)
            assert focus.wait_for_count(1, 60.0)[0].heating_distance == pytest.approx(
                HEATING_DISTANCE)
            # the distances the painter plans with follow it: the retreat the paper's 3 cm on
            said = distances.wait_for_count(1, 60.0)[-1]
            assert (said.calibrated, said.heating_distance, said.retreat_distance) == (
                True, pytest.approx(HEATING_DISTANCE), pytest.approx(HEATING_DISTANCE + 0.03))
            # the painter reads the dot size back (and again at each goal)
            graph.wait_until(lambda: 'dot-size calibration read back' in log_of(
                tmp_path, run, 'painter'), 60.0, 'the painter reading dots.yaml')
            law = DOTS.summary()[0]
            assert law in log_of(tmp_path, run, 'painter')
            # the spot detector takes the saved intrinsics for an uncalibrated camera_info
            camera_info = graph.helper.create_publisher(CameraInfo, 'rgb/camera_info',
                                                        qos_profile_sensor_data)
            graph.wait_until(lambda: camera_info.get_subscription_count() > 0, 60.0,
                             'the spot detector subscribed')

            def taken():
                camera_info.publish(uncalibrated_camera_info())
                text = log_of(tmp_path, run, 'spot_detector')
                return 'is uncalibrated (K = 0): using' in text
            graph.wait_until(taken, 60.0, 'the spot detector using the saved camera_info')
            text = log_of(tmp_path, run, 'spot_detector')
            assert str(calibrations / RGB_CAMERA_INFO_FILE) in text
            assert 'fx 611.00 fy 611.00 cx 318.50 cy 241.00' in text, text
    # the rig file edited (a link measured again): the saved calibrations are another rig's
    with open(rig_file, 'a') as stream:
        stream.write('# j2 link measured again\n')
    with started(tmp_path, 'edited', rig_file, calibrations) as (group, graph):
        focus = graph.collect(FocalCalibration, 'calibration/focus', TRANSIENT_LOCAL_QOS)
        distances = graph.collect(FocusDistances, 'focus/distances', TRANSIENT_LOCAL_QOS)
        world = graph.collect(PoseStamped, 'calibration/world_pose', TRANSIENT_LOCAL_QOS)
        build = graph.collect(String, 'calibration/rig', TRANSIENT_LOCAL_QOS)
        graph.wait_until(lambda: 'lens_planner: rig from' in log_of(
            tmp_path, 'edited', 'lens_planner'), 60.0, 'the lens planner started')
        text = log_of(tmp_path, 'edited', 'lens_planner')
        assert text.count('calibration not used') == 3, text
        assert 'was made for rig description' in text and 'calibrate again' in text
        graph.wait_until(lambda: 'dot-size calibration not used' in log_of(
            tmp_path, 'edited', 'painter'), 60.0, "the painter refusing another rig's dots")
        assert 'was made for rig description' in log_of(tmp_path, 'edited', 'painter')
        with pytest.raises(GraphTimeout):
            focus.wait_for_count(1, 3.0)
        # no focal calibration: the lens planner's parameter, the paper's 8.2 and 11.2 cm
        said = distances.wait_for_count(1, 60.0)[-1]
        assert (said.calibrated, said.heating_distance, said.retreat_distance) == (
            False, pytest.approx(0.082), pytest.approx(0.112))
        assert world.messages == [] and build.messages == []
