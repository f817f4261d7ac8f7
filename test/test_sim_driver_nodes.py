"""
dobot_driver and servo_driver on the simulated world's ports move both camera views (issue 6).

The world (sun, lens flux, wood, cameras) hosts the emulated Dobot and Maestro on ptys and
steps its simulated clock on a thread at a real-time factor; the real driver nodes connect
to those ptys, and goals go to ``move_arm`` and ``move_wrist`` through action clients. The
truth the views are held against is independent of the world's own bookkeeping: the
forward kinematics (helio_optics.rig_kinematics) of the COMMANDED joints, the ArUco marker's
known corners in the world frame, and a panel point the lens is aimed to focus the sun on.
"""

import os
import threading
import time

import cv2
from helio_drivers.dobot_driver_node import DobotDriverNode
from helio_drivers.servo_driver_node import ServoDriverNode
from helio_drivers.sim.clock import Pacer
from helio_drivers.sim.devices import DeviceSettings, SimDevices
from helio_drivers.sim.truth import true_sun_focus_joints
from helio_drivers.sim.world import SimSettings, SimWorld
from helio_msgs.action import MoveArm, MoveWrist
from helio_optics.geometry import invert_transform, transform_points
from helio_optics.ground_render import decode_srgb8
from helio_optics.node_kit.in_process_graph import InProcessGraph
from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters, Rig
import numpy as np
import pytest
import yaml

SERVO_YAML = os.path.join(os.path.dirname(__file__), '..', 'src', 'helio_drivers', 'config',
                          'servo_driver.yaml')
FAST = SimSettings(flux_rays=5000, step=0.1)
CALIBRATION_KEYS = ('channel', 'min_pulse_us', 'max_pulse_us', 'centre_pulse_us',
                    'us_per_rad', 'direction', 'zero_offset')
# Wall seconds for a goal's result, and the drivers' own (wall-clock) move timeouts: on a
# loaded 2-core machine the world may step far slower than real time.
MOVE_TIMEOUT = 120.0
DRIVER_MOVE_TIMEOUT = 300.0
# The Maestro sets pulses in quarter microseconds: each servo angle is within 0.125 us of
# us_per_rad (0.2 mrad) of the command, so a rotation entry within 0.4 mrad (twice that as
# margin); translations (camera lever arms ~5 cm) are far better.
POSE_TOLERANCE = 2.0 * 0.25 / 636.6197723675814


class WorldStepper:
    """Step the world on a thread at a real-time factor; readers hold `lock` between steps."""

    def __init__(self, world, real_time_factor=10.0):
        """Start stepping `world` (paced by helio_drivers.sim.clock.Pacer)."""
        self.world = world
        self.lock = threading.Lock()
        self.error = None
        self._stepped = threading.Condition(self.lock)
        self._stop = threading.Event()
        self._pacer = Pacer(real_time_factor)
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        try:
            while not self._stop.is_set():
                delay = self._pacer.delay(time.monotonic(), self.world.time)
                if delay > 0.0 and self._stop.wait(delay):   # pacing, not synchronisation
                    break
                with self._stepped:
                    self.world.step()
                    self._stepped.notify_all()
        except BaseException as error:   # reported to the waiting test
            self.error = error
            with self._stepped:
                self._stepped.notify_all()

    def wait_until(self, sim_time, timeout=60.0):
        """Wait until the simulated clock reaches `sim_time` [s]; assert it did in time."""
        with self._stepped:
            reached = self._stepped.wait_for(
                lambda: self.error is not None or self.world.time >= sim_time, timeout)
        assert self.error is None, f'world step failed: {self.error!r}'
        assert reached, f'simulated time {self.world.time:.2f} s never reached {sim_time} s'

    def stop(self):
        """Stop stepping and join the thread."""
        self._stop.set()
        self._thread.join(timeout=10.0)


def servo_parameters_from_config():
    """Return config/servo_driver.yaml's yaw.* and pitch.* parameters, flattened."""
    with open(SERVO_YAML) as stream:
        tree = yaml.safe_load(stream)['/**/servo_driver']['ros__parameters']
    return {f'{axis}.{key}': value for axis in ('yaw', 'pitch')
            for key, value in tree[axis].items()}


def marker_corners(rgb_image):
    """Return the ArUco marker's four corners (4, 2) [px] found in an RGB image, or None."""
    # the world's camera delivers sRGB, as a webcam: cv2.aruco finds an oblique marker's
    # thin black border in linear light (as helio_perception's MarkerDetector searches)
    gray = np.rint(255.0 * decode_srgb8(cv2.cvtColor(rgb_image, cv2.COLOR_RGB2GRAY)))
    gray = gray.astype(np.uint8)
    detector = cv2.aruco.ArucoDetector(
        cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    corners, ids, _ = detector.detectMarkers(gray)
    if ids is None or list(ids.ravel()) != [0]:
        return None
    return corners[0][0]


def hot_spot_centroid(temperatures):
    """Return the (u, v) [px] centroid of the hottest blob: pixels above half the peak rise."""
    ambient = np.median(temperatures)
    rise = temperatures - ambient
    mask = (rise > 0.5 * rise.max()).astype(np.uint8)
    _, labels = cv2.connectedComponents(mask, connectivity=8)
    blob = labels == labels[np.unravel_index(np.argmax(temperatures), temperatures.shape)]
    rows, columns = np.nonzero(blob)
    weights = rise[rows, columns]
    return np.array([np.average(columns, weights=weights), np.average(rows, weights=weights)])


def rig_parameters():
    """Return the workspace's config/rig.yaml."""
    return load_rig_parameters(default_rig_file())


class SimRig:
    """The world with its devices, both driver nodes in one InProcessGraph, two clients."""

    def __init__(self, port_dir):
        """Host the world and its emulators, start the drivers on their ports, connect."""
        self.world = SimWorld(FAST, rig_parameters())
        self.devices = SimDevices(self.world.clock, DeviceSettings(
            dobot_port=os.path.join(port_dir, 'dobot'),
            servo_port=os.path.join(port_dir, 'servo')))
        self.world.attach_joint_source(self.devices.joint_positions)   # as sim_world_node does
        self.stepper = WorldStepper(self.world)
        self.graph = None
        dobot_port, servo_port = self.devices.ports
        try:
            self.graph = InProcessGraph('sim_driver_test_client')
            # Brisk motion (within the emulated motors' caps): fewer steps while moving.
            self.graph.add(DobotDriverNode(**self.graph.node_options(
                port=dobot_port, timeout=0.5, move_timeout=DRIVER_MOVE_TIMEOUT,
                joint_velocity_dps=[300.0] * 4, joint_acceleration_dps2=[1000.0] * 4)))
            overrides = {'port': servo_port, 'timeout': 0.5,
                         'move_timeout': DRIVER_MOVE_TIMEOUT, **servo_parameters_from_config(),
                         'yaw.speed_us_per_s': 4000.0, 'yaw.acceleration_us_per_s2': 40000.0,
                         'pitch.speed_us_per_s': 4000.0,
                         'pitch.acceleration_us_per_s2': 40000.0}
            self.graph.add(ServoDriverNode(**self.graph.node_options(**overrides)))
            self.arm_client = self.graph.action_client(MoveArm, 'move_arm')
            self.wrist_client = self.graph.action_client(MoveWrist, 'move_wrist')
        except BaseException:
            self.close()
            raise

    def move(self, arm_goal, yaw, pitch):
        """Send the arm and the wrist goals together; return both results once done."""
        arm = self.graph.send_goal(self.arm_client, arm_goal)
        wrist = self.graph.send_goal(self.wrist_client, MoveWrist.Goal(yaw=yaw, pitch=pitch))
        assert arm.accepted and wrist.accepted
        arm_result = self.graph.goal_result(arm, MOVE_TIMEOUT).result
        wrist_result = self.graph.goal_result(wrist, MOVE_TIMEOUT).result
        assert arm_result.success, arm_result.message
        assert wrist_result.success, wrist_result.message
        return arm_result, wrist_result

    def observe(self):
        """Return joints, (T_world_rgb, T_world_thermal), RGB image, thermal [degC] at once."""
        with self.stepper.lock:
            return (self.world.joint_positions(), self.world.camera_poses(),
                    self.world.rgb_image(), self.world.thermal_temperatures())

    def close(self):
        """Stop the stepping, the drivers (they leave the devices stopped), the emulators."""
        self.stepper.stop()
        if self.graph is not None:
            self.graph.close()
        self.devices.close()


@pytest.fixture
def sim_rig(tmp_path):
    rig = SimRig(str(tmp_path))
    try:
        yield rig
    finally:
        rig.close()


def test_moving_the_arm_through_the_driver_nodes_moves_both_camera_views(sim_rig):
    world, kinematics = sim_rig.world, Rig(rig_parameters())
    # The driver runs with config/servo_driver.yaml's calibration: it must be the sim's wiring.
    config = servo_parameters_from_config()
    for axis, wiring in zip(('yaw', 'pitch'), sim_rig.devices.calibrations):
        for key in CALIBRATION_KEYS:
            assert config[f'{axis}.{key}'] == pytest.approx(getattr(wiring, key)), \
                f'config/servo_driver.yaml {axis}.{key} differs from the simulated wiring'
    T_world_robot = invert_transform(kinematics.parameters.T_robot_world)
    camera = world.rgb.camera
    half = world.settings.marker_side / 2.0   # the marker is centred on the world origin
    marker_world = [[-half, half, 0.0], [half, half, 0.0], [half, -half, 0.0],
                    [-half, -half, 0.0]]

    def predicted_poses(x):
        pose = kinematics.forward(x)
        return T_world_robot @ pose.T_robot_rgb, T_world_robot @ pose.T_robot_thermal

    def check_views_follow(x, poses, image):
        """Assert the sim's camera poses and the marker in view are where FK(x) says."""
        rgb, thermal = predicted_poses(x)
        assert poses[0] == pytest.approx(rgb, abs=POSE_TOLERANCE)
        assert poses[1] == pytest.approx(thermal, abs=POSE_TOLERANCE)
        found = marker_corners(image)
        assert found is not None, 'the marker is not in the rendered RGB view'
        predicted = camera.project(transform_points(invert_transform(rgb), marker_world))
        assert np.max(np.linalg.norm(found - predicted, axis=1)) < 1.5
        return found.mean(axis=0), predicted.mean(axis=0)

    # Before: the devices' starting joints.
    start = DeviceSettings()
    x0 = np.array([*np.radians(start.initial_joints_deg[:3]), 0.0, 0.0])
    _, poses0, _, _ = sim_rig.observe()
    assert poses0[0] == pytest.approx(predicted_poses(x0)[0], abs=POSE_TOLERANCE)
    assert poses0[1] == pytest.approx(predicted_poses(x0)[1], abs=POSE_TOLERANCE)

    # Move 1, joint angles: the lens level 8.2 cm above a point beside the marker.
    above = transform_points(kinematics.parameters.T_robot_world, [0.01, 0.01, 0.082])
    xa = kinematics.inverse(above, yaw=0.3, pitch=0.0)
    arm, wrist = sim_rig.move(MoveArm.Goal(mode=MoveArm.Goal.MOVJ_ANGLE,
                                           target=[*xa[:3], 0.0]), xa[3], xa[4])
    assert list(arm.achieved_joints) == pytest.approx([*xa[:3], 0.0], abs=1e-4)
    assert (wrist.achieved_yaw, wrist.achieved_pitch) == pytest.approx(xa[3:], abs=1e-3)
    joints_a, poses_a, image_a, _ = sim_rig.observe()
    assert joints_a == pytest.approx(xa, abs=1e-3)
    seen_a, predicted_a = check_views_follow(xa, poses_a, image_a)

    # Move 2, Cartesian: the flange where FK puts it for the joints that focus the sun on a
    # panel point (test shortcut: the world's true sun), r = j1 so that j4 stays 0.
    target = np.array([0.06, 0.06, 0.0])
    xb = true_sun_focus_joints(world, target, 0.082)
    flange = kinematics.arm.forward(xb[:3])
    arm, wrist = sim_rig.move(MoveArm.Goal(mode=MoveArm.Goal.MOVJ_XYZ,
                                           target=[*flange, xb[0]]), xb[3], xb[4])
    assert list(arm.achieved_cartesian) == pytest.approx([*flange, xb[0]], abs=1e-4)
    sim_rig.stepper.wait_until(world.time + 3.0)   # let the focused sun heat the wood
    joints_b, poses_b, image_b, thermal_b = sim_rig.observe()
    assert joints_b == pytest.approx(xb, abs=1e-3)
    seen_b, predicted_b = check_views_follow(xb, poses_b, image_b)

    # Both views moved, by what the kinematics predicts.
    rgb_a, thermal_a = predicted_poses(xa)
    rgb_b, thermal_b_pose = predicted_poses(xb)
    assert np.linalg.norm(rgb_b[:3, 3] - rgb_a[:3, 3]) > 0.02
    assert np.linalg.norm(thermal_b_pose[:3, 3] - thermal_a[:3, 3]) > 0.02
    assert np.linalg.norm(predicted_b - predicted_a) > 50.0
    assert seen_b - seen_a == pytest.approx(predicted_b - predicted_a, abs=2.0)
    # The thermal view: the focused spot is hot where FK's thermal pose projects the target.
    assert thermal_b.max() > np.median(thermal_b) + 100.0
    spot = world.thermal.camera.project(
        transform_points(invert_transform(thermal_b_pose), [target]))[0]
    assert hot_spot_centroid(thermal_b) == pytest.approx(spot, abs=0.5)
    spot_from_a = world.thermal.camera.project(
        transform_points(invert_transform(thermal_a), [target]))[0]
    assert np.linalg.norm(spot_from_a - spot) > 10.0   # the view did move over the panel
