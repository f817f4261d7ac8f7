"""
``helio calibrate camera`` on the simulated graph (issue 29, item 5), every node its own process.

The world is a drawn build (seed 12) whose RGB camera's true intrinsics differ from the
nominal ones by more than the calibration must reach (focal length -0.33 %, principal point
(2.2, 3.3) px), and it publishes ``rgb/camera_info`` with K = 0, as ``usb_cam`` does for a
webcam without a calibration file. A ChArUco board lies on the panel beside the marker; the
world's pixels integrate their light over 2 x 2 points (``rgb.supersample``). The procedure
(``calibrate_on_graph``, what ``helio calibrate camera`` runs) moves the rig through the
drivers' actions, takes the camera's frames and writes ``camera_info/rgb.yaml``; the fit is
compared with the world's TRUE intrinsics (``sim/truth/rgb_camera_info``). Then
``spot_detector``, given the file, takes it for the uncalibrated camera.
"""

import math
import time

from conftest import graph_of_processes
from helio_control.bringup import wait_for_devices
from helio_control.camera_calibration_graph import calibrate_on_graph
from helio_msgs.msg import SpotObservation
from helio_optics.calibration_board import BoardSpec
from helio_optics.node_kit.conversions import camera_from_info
from helio_optics.node_kit.in_process_graph import TRANSIENT_LOCAL_QOS
from helio_optics.rig_kinematics import default_rig_file
from helio_perception.camera_calibration import intrinsics_error, read_camera_info
from helio_perception.spot_detector_node import SpotDetectorNode
import numpy as np
from sensor_msgs.msg import CameraInfo

NODES = ('sim_world', 'dobot_driver', 'servo_driver')
BOARD = BoardSpec((7, 5), 0.014, 0.0105)
BOARD_POSE = (0.095, 0.0, 0.0)
LIMITS = {'fx': 0.003, 'fy': 0.003, 'cx': 1.5, 'cy': 1.5, 'k1': 0.01}


def test_the_rig_calibrates_its_camera_and_the_spot_detector_takes_the_file(tmp_path):
    squares = [int(v) for v in BOARD.squares]
    overrides = {'sim_world': {
        'real_time_factor': 0.0, 'build': 'drawn', 'build_seed': 12,
        'board_pose': list(BOARD_POSE), 'board_squares': squares,
        'board_square': BOARD.square, 'board_marker': BOARD.marker,
        'rgb.supersample': 2, 'rgb_uncalibrated': True}}
    with graph_of_processes(tmp_path, NODES, overrides) as (_, graph):
        wait_for_devices(graph, 60.0)
        truth = camera_from_info(graph.collect(
            CameraInfo, 'sim/truth/rgb_camera_info', TRANSIENT_LOCAL_QOS).wait_for_count(
                1, 30.0)[0])
        started = time.monotonic()
        done = calibrate_on_graph(graph, BOARD, BOARD_POSE[:2], BOARD_POSE[2],
                                  calibration_dir=str(tmp_path / 'calibration'),
                                  rig_file=default_rig_file())
        seconds = time.monotonic() - started
        run = done.run
        errors = intrinsics_error(run.calibration.camera, truth)
        print(f'\n{run.calibration.summary()}; {len(run.collected.views)} of {run.planned} '
              f'poses seen, {run.collected.frames} frames; {seconds:.1f} s wall; errors: fx '
              f'{errors["fx"] * 100:+.3f} %, cx {errors["cx"]:+.2f} px, cy '
              f'{errors["cy"]:+.2f} px, k1 {errors["k1"]:+.4f}')
        assert run.planned <= 25
        assert 'K = 0 (uncalibrated)' in done.notes[1]
        for name, limit in LIMITS.items():
            assert abs(errors[name]) <= limit, (name, errors)
        assert done.path == str(tmp_path / 'calibration' / 'camera_info' / 'rgb.yaml')
        written, _ = read_camera_info(done.path)
        np.testing.assert_allclose(written.matrix, run.calibration.camera.matrix)

        # the spot detector, given the file, takes it for the camera sent uncalibrated
        detector = graph.add(SpotDetectorNode(**graph.node_options(
            camera_info_file=done.path, use_sim_time=True)))
        spots = graph.collect(SpotObservation, 'spot')
        graph.wait_until(lambda: detector.camera is not None, 30.0,
                         'the spot detector taking the file')
        np.testing.assert_allclose(detector.camera.matrix, written.matrix)
        assert detector.file_refused == ''
        spots.wait_for_count(1, 30.0)        # its frames are processed with the file's camera
        assert math.isfinite(detector.camera.matrix[0, 0])
