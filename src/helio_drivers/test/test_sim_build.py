"""The rig as built (sim/build.py): drawn within its tolerances, moved and seen as built."""

from dataclasses import fields
import math

import cv2
from helio_drivers.dobot_client import DobotClient
from helio_drivers.dobot_protocol import PtpMode
from helio_drivers.maestro_client import MaestroClient
from helio_drivers.maestro_protocol import ServoCalibration
from helio_drivers.sim.build import (ARM_LINKS, build_from_name, BuiltJoints, BuiltRig,
                                     draw_build, ideal_build, play, Tolerances, WRIST_OFFSETS)
from helio_drivers.sim.devices import DeviceSettings, SimDevices
from helio_drivers.sim.truth import true_sun_focus_joints
from helio_drivers.sim.world import SimWorld
from helio_optics.geometry import invert_transform, transform_points
from helio_optics.rig_kinematics import Rig
import numpy as np
import pytest
from test_sim_world import FAST, rig_parameters


def test_a_drawn_build_is_reproducible_and_within_its_tolerances():
    nominal, tolerances = rig_parameters(), Tolerances()
    for scale in (1.0, 1.0 / 3.0):
        build = draw_build(nominal, seed=11, scale=scale)
        assert build == draw_build(nominal, seed=11, scale=scale)
        assert build != draw_build(nominal, seed=12, scale=scale)
        for name in WRIST_OFFSETS:
            error = np.subtract(getattr(build.rig, name), getattr(nominal, name))
            assert np.all(np.abs(error) <= tolerances.mount_offset * scale), name
        for name in ARM_LINKS:
            error = getattr(build.rig.arm, name) - getattr(nominal.arm, name)
            assert abs(error) <= tolerances.dobot_link * scale, name
        angles = [*build.rig.lens_tilt, *build.rig.rgb_rotation, *build.rig.thermal_rotation]
        assert np.all(np.abs(angles) <= tolerances.mount_angle * scale)
        assert np.all(np.abs(build.dobot_zero) <= tolerances.dobot_zero * scale)
        assert abs(build.marker_scale - 1.0) <= tolerances.marker_scale * scale
        for servo in build.servos:
            assert abs(servo.centre_us - 1500.0) <= tolerances.servo_neutral_us * scale
            assert abs(servo.us_per_rad * math.pi / 2000.0 - 1.0) <= tolerances.servo_scale * scale
            # the play is the deadband (in angle) plus the backlash, whatever the scale
            low = tolerances.servo_deadband_us[0] / servo.us_per_rad + tolerances.servo_backlash[0]
            high = tolerances.servo_deadband_us[1] / servo.us_per_rad + \
                tolerances.servo_backlash[1]
            assert low <= servo.play <= high
    # scale 0: the rig file's geometry, only the specified play and scatter left
    exact = draw_build(nominal, seed=11, scale=0.0)
    assert exact.rig == nominal and exact.marker_scale == 1.0
    with pytest.raises(ValueError, match='build must be one of ideal, drawn'):
        build_from_name('printed', nominal)


def test_the_ideal_build_moves_exactly_as_the_rig_file():
    nominal = rig_parameters()
    built, plain = BuiltRig(ideal_build(nominal)), Rig(nominal)
    rng = np.random.default_rng(3)
    for x in rng.uniform([-1.0, 0.1, 0.1, -1.0, -1.0], [1.0, 1.2, 1.2, 1.0, 1.0], (5, 5)):
        for name in ('T_robot_flange', 'T_robot_lens', 'T_robot_rgb', 'T_robot_thermal'):
            assert np.array_equal(getattr(built.forward(x), name), getattr(plain.forward(x), name))
        joints = BuiltJoints(ideal_build(nominal))
        assert np.array_equal(joints.true_joints([*x[:3], 0.0], {'lens_yaw': x[3],
                                                                 'lens_pitch': x[4]}), x)


def test_the_play_of_a_shaft_is_a_hysteresis_loop():
    width = 0.01
    shaft = play(0.0, 0.004, width)         # inside the play: the shaft stays
    assert shaft == 0.0
    shaft = play(shaft, 0.02, width)        # pushed up: it trails the drive by half the play
    assert shaft == pytest.approx(0.015)
    shaft = play(shaft, 0.012, width)       # back by less than the play: it stays
    assert shaft == pytest.approx(0.015)
    shaft = play(shaft, 0.0, width)         # pushed down: it leads by half the play
    assert shaft == pytest.approx(0.005)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_the_true_aim_of_a_drawn_build_lands_where_the_rig_file_aim_misses(seed):
    """The world's ray tracer, a second method, judges both aims; the build matters."""
    nominal = rig_parameters()
    build = draw_build(nominal, seed)
    world = SimWorld(FAST, build=build)
    target = np.array([0.07, 0.07])
    world.set_joints(true_sun_focus_joints(world, target, 0.082))
    world.step()
    assert np.linalg.norm(world.flux_field.centroid() - target) < 5e-5
    # the rig file's closed form, given the true sun and the true marker place, misses
    believed = Rig(nominal)
    believed.set_world(build.rig.world_in_robot, build.rig.world_yaw)
    aim = believed.lens_pose_for_target(
        transform_points(world.T_robot_world, [*target, 0.0]),
        world.sun.ray_robot(world.clock.datetime()), 0.082)
    world.set_joints(aim.x - [*build.dobot_zero, 0.0, 0.0])   # the Dobot's own angles
    world.step()
    assert np.linalg.norm(world.flux_field.centroid() - target) > 5e-4


def test_a_drawn_build_moves_and_shows_as_built_through_the_real_drivers(tmp_path):
    """Nominal pulses turn the true servos; the camera renders the true intrinsics and print."""
    nominal = rig_parameters()
    build = draw_build(nominal, seed=4)
    world = SimWorld(FAST, build=build)
    settings = DeviceSettings(dobot_port=str(tmp_path / 'dobot'),
                              servo_port=str(tmp_path / 'servo'))
    devices = SimDevices(world.clock, settings, build)
    world.attach_joint_source(devices.joint_positions)
    dobot = DobotClient(settings.dobot_port)
    servo = MaestroClient(settings.servo_port)
    # what servo_driver believes: the nominal pulse constants
    believed = [ServoCalibration(name, channel) for name, channel in
                (('lens_yaw', settings.yaw_channel), ('lens_pitch', settings.pitch_channel))]
    try:
        dobot.connect()
        servo.connect()
        above = transform_points(Rig(nominal).parameters.T_robot_world, [0.01, 0.01, 0.082])
        goal = Rig(nominal).inverse(above, yaw=0.3, pitch=0.1)
        index = dobot.move(PtpMode.MOVJ_ANGLE, np.array([*goal[:3], 0.0]))
        pulses = [round(4 * calibration.pulse_us(angle))
                  for calibration, angle in zip(believed, goal[3:])]
        for calibration, quarter_us in zip(believed, pulses):
            servo.set_target(calibration.channel, quarter_us)
        for _ in range(300):
            world.step()
            if dobot.executed_index() >= index and not servo.moving():
                break
        x = world.joint_positions()
        # the Maestro reports the pulse it sends, which the driver turns into its belief
        reported = [believed[i].angle(servo.get_position(believed[i].channel) / 4.0)
                    for i in range(2)]
        assert reported == pytest.approx(goal[3:], abs=2e-3)
        for i, name in enumerate(('lens_yaw', 'lens_pitch')):
            truth = build.servo(name)
            angle = (pulses[i] / 4.0 - truth.centre_us) / truth.us_per_rad
            assert abs(x[3 + i] - angle) <= truth.play / 2 + 1e-9
        # the arm's true angles: the Dobot's own plus its zero offsets (and a scatter)
        scatter = x[:3] - (np.asarray(goal[:3]) + build.dobot_zero)
        assert np.all(np.abs(scatter) < build.dobot_repeatability / 0.28 * 2.0)
        # the rendered marker: where the true camera (distortion included) sees the print
        rgb, _ = world.camera_poses()
        image = cv2.cvtColor(world.rgb_image(), cv2.COLOR_RGB2GRAY)
        refined = cv2.aruco.DetectorParameters()
        refined.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        corners, ids, _ = cv2.aruco.ArucoDetector(
            cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), refined).detectMarkers(image)
        assert ids is not None and list(ids.ravel()) == [0]
        half = world.settings.marker_side * build.marker_scale / 2
        printed = [[-half, half, 0.0], [half, half, 0.0], [half, -half, 0.0],
                   [-half, -half, 0.0]]
        in_camera = transform_points(invert_transform(rgb), printed)
        true_miss = np.linalg.norm(corners[0][0] - world.rgb.camera.project(in_camera), axis=1)
        published_miss = np.linalg.norm(
            corners[0][0] - world.published_cameras['rgb'].project(in_camera), axis=1)
        assert np.max(true_miss) < 1.0
        assert np.mean(published_miss) > np.mean(true_miss) + 0.5
    finally:
        dobot.close()
        servo.close()
        devices.close()


def test_the_build_round_trips_through_plain_numbers():
    build = draw_build(rig_parameters(), seed=9, scale=0.5)
    plain = build.to_dict()
    assert plain['name'] == 'drawn' and plain['seed'] == 9 and plain['scale'] == 0.5
    assert [s['name'] for s in plain['servos']] == ['lens_yaw', 'lens_pitch']
    assert plain['rig']['lens_offset'] == pytest.approx(list(build.rig.lens_offset))
    assert plain['rgb_camera']['centre_shift'] == pytest.approx(
        list(build.rgb_camera.centre_shift))
    assert {f.name for f in fields(build)} == set(plain)
