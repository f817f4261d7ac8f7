"""Hosted emulators: the real driver libraries over the ptys move the simulated cameras."""

import cv2
from helio_drivers.dobot_client import DobotClient
from helio_drivers.dobot_protocol import PtpMode
from helio_drivers.maestro_client import MaestroClient
from helio_drivers.sim.devices import DeviceSettings, SimDevices
from helio_drivers.sim.world import SimWorld
from helio_optics.geometry import invert_transform, transform_points
import numpy as np
import pytest
from test_sim_world import FAST, rig_parameters


def test_moving_the_arm_through_the_drivers_moves_both_camera_views(tmp_path):
    world = SimWorld(FAST, rig_parameters())
    settings = DeviceSettings(dobot_port=str(tmp_path / 'dobot'),
                              servo_port=str(tmp_path / 'servo'))
    devices = SimDevices(world.clock, settings)
    world.attach_joint_source(devices.joint_positions)
    dobot = DobotClient(settings.dobot_port)
    servo = MaestroClient(settings.servo_port)
    try:
        dobot.connect()
        servo.connect()
        before_rgb, before_thermal = world.camera_poses()
        # Lens level, 8.2 cm above a point beside the marker: the RGB camera sees the marker.
        above = transform_points(world.T_robot_world, [0.01, 0.01, 0.082])
        goal = world.rig.inverse(above, yaw=0.3, pitch=0.0)
        target = np.array([*goal[:3], 0.0])
        index = dobot.move(PtpMode.MOVJ_ANGLE, target)
        yaw, pitch = goal[3], goal[4]
        for calibration, angle in zip(devices.calibrations, (yaw, pitch)):
            servo.set_target(calibration.channel, round(4 * calibration.pulse_us(angle)))
        for _ in range(200):  # simulated time moves only when the world steps
            world.step()
            if dobot.executed_index() >= index and not servo.moving():
                break
        assert dobot.executed_index() >= index
        x = world.joint_positions()
        assert x == pytest.approx([*target[:3], yaw, pitch], abs=2e-3)
        expected = world.rig.forward(x)
        T_world_robot = invert_transform(world.T_robot_world)
        rgb, thermal = world.camera_poses()
        assert rgb == pytest.approx(T_world_robot @ expected.T_robot_rgb, abs=1e-9)
        assert thermal == pytest.approx(T_world_robot @ expected.T_robot_thermal, abs=1e-9)
        assert np.linalg.norm(rgb[:3, 3] - before_rgb[:3, 3]) > 0.02
        assert np.linalg.norm(thermal[:3, 3] - before_thermal[:3, 3]) > 0.02
        # The rendered view follows: the marker centre appears where the new pose projects it.
        image = cv2.cvtColor(world.rgb_image(), cv2.COLOR_RGB2GRAY)
        corners, ids, _ = cv2.aruco.ArucoDetector(
            cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)).detectMarkers(image)
        assert ids is not None and list(ids.ravel()) == [0]
        half = world.settings.marker_side / 2
        world_corners = [[-half, half, 0.0], [half, half, 0.0], [half, -half, 0.0],
                         [-half, -half, 0.0]]
        predicted = world.rgb.camera.project(
            transform_points(invert_transform(rgb), world_corners))
        assert np.max(np.linalg.norm(corners[0][0] - predicted, axis=1)) < 1.5
    finally:
        dobot.close()
        servo.close()
        devices.close()
