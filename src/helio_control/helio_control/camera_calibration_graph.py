"""
``helio calibrate camera`` on the running graph: the drivers' actions, the camera's topic.

``camera_calibration_run`` holds the procedure; this module gives it the graph (through a
``ClientGraph`` of the caller: the ``helio`` command's, or a test's):

- ``GraphRig.move(x)``: ``move_arm`` (MOVJ_ANGLE, j1..j3) and ``move_wrist`` (yaw, pitch)
  together, both results asked for at once; a failed or refused move raises RuntimeError
  with the driver's message;
- ``GraphRig.grab()``: the next ``rgb/image_raw`` frame, never the one in flight while the
  last move ended (the procedure then waits for still frames);
- ``GraphRig.nominal_camera``: ``rgb/camera_info``'s camera, or, when it says K = 0 (a
  webcam without a calibration), the pinhole of the image size and a field of view.

``calibrate_on_graph`` plans the views with the rig file (and the robot-world calibration
saved in the calibration directory, when there is one for this rig), runs the procedure,
and writes ``camera_info/rgb.yaml`` into the calibration directory: the lens planner's
``calibration_dir`` (asked of the running lens planner; ``~/.helio/calibration`` on a real
rig, the simulated graph's own directory in simulation) unless one is given.
"""

from dataclasses import dataclass
import math
import threading

from helio_control.calibration_store import (CalibrationRefused, load_calibration,
                                             rig_description)
from helio_control.camera_calibration_run import (calibrate_camera, plan_views,
                                                  save_camera_calibration)
from helio_optics.geometry import PinholeCamera
from helio_optics.node_kit import topics
from helio_optics.node_kit.conversions import camera_from_info, image_to_numpy
from helio_optics.node_kit.deployment import calibration_dir_or_default, rig_file_or_default
from helio_optics.rig_kinematics import load_rig_parameters, Rig


class GraphRig:
    """The rig as the procedure sees it: moves through the drivers, frames from the camera."""

    def __init__(self, graph, timeout=30.0, move_timeout=120.0, frame_timeout=10.0):
        """Connect the driver actions and the camera topics of `graph` (a ClientGraph)."""
        from helio_msgs.action import MoveArm, MoveWrist
        from rclpy.qos import qos_profile_sensor_data
        from sensor_msgs.msg import CameraInfo, Image
        self.graph = graph
        self.MoveArm, self.MoveWrist = MoveArm, MoveWrist
        self.move_timeout, self.frame_timeout = move_timeout, frame_timeout
        self._frames = threading.Condition()
        self._frame = None
        self._count = 0           # frames received
        self._first_new = 1       # the first frame counted after the last move
        self.info = graph.collect(CameraInfo, topics.RGB_CAMERA_INFO, qos_profile_sensor_data)
        graph.helper.create_subscription(Image, topics.RGB_IMAGE, self._on_image,
                                         qos_profile_sensor_data)
        self.arm = graph.action_client(MoveArm, 'move_arm', timeout)
        self.wrist = graph.action_client(MoveWrist, 'move_wrist', timeout)

    def _on_image(self, message):
        with self._frames:
            self._frame = message
            self._count += 1
            self._frames.notify_all()

    def nominal_camera(self, horizontal_fov, timeout=10.0):
        """Return (the camera to plan with, whether camera_info was calibrated)."""
        message = self.info.wait_for_count(1, timeout)[-1]
        if any(message.k):
            return camera_from_info(message), True
        if not (message.width and message.height):
            raise RuntimeError('rgb/camera_info gives neither intrinsics nor the image size')
        return PinholeCamera.from_fov(int(message.width), int(message.height),
                                      horizontal_fov), False

    def move(self, x):
        """Move arm and wrist to joints x together; return when both drivers report it."""
        arm = self.MoveArm.Goal(mode=self.MoveArm.Goal.MOVJ_ANGLE,
                                target=[float(v) for v in x[:3]] + [0.0])
        wrist = self.MoveWrist.Goal(yaw=float(x[3]), pitch=float(x[4]))
        handles = []
        for client, goal, name in ((self.arm, arm, 'move_arm'), (self.wrist, wrist,
                                                                 'move_wrist')):
            handle = self.graph.send_goal(client, goal, timeout=self.move_timeout)
            if not handle.accepted:
                raise RuntimeError(f'{name} refused the goal (another move running?)')
            handles.append((handle, name))
        # both results asked for at once (a result asked for late can find its goal expired)
        asked = [self.graph.executor.create_task(handle.get_result_async)
                 for handle, _ in handles]
        for task, (_, name) in zip(asked, handles):
            reply = self.graph.result_of(self.graph.result_of(task), self.move_timeout,
                                         f'the result of {name}')
            if not reply.result.success:
                raise RuntimeError(f'{name} failed: {reply.result.message}')
        with self._frames:       # a frame in flight as the move ended is not a still one
            self._first_new = self._count + 2

    def grab(self):
        """Return the next frame of rgb/image_raw (H, W, C) or (H, W) uint8."""
        with self._frames:
            wanted = max(self._count + 1, self._first_new)
            if not self._frames.wait_for(lambda: self._count >= wanted, self.frame_timeout):
                raise RuntimeError(f'no rgb/image_raw frame within {self.frame_timeout:g} s')
            message = self._frame
        return image_to_numpy(message, copy=True)


def planner_parameters(graph, names, timeout=3.0):
    """Return {name: value} of the running lens planner's parameters ({} if it is silent)."""
    return node_parameters(graph, 'lens_planner', names, timeout)


def node_parameters(graph, node, names, timeout=3.0):
    """Return {name: value} of the running `node`'s parameters ({} if it is silent)."""
    from rclpy.parameter import parameter_value_to_python
    from rclpy.parameter_client import AsyncParameterClient
    client = AsyncParameterClient(graph.helper, node)
    if not client.wait_for_services(timeout_sec=timeout):
        return {}
    response = graph.result_of(client.get_parameters(list(names)), timeout,
                               f"the {node.replace('_', ' ')}'s parameters")
    return {name: parameter_value_to_python(value)
            for name, value in zip(names, response.values)}


def rig_with_saved_world(rig_file, calibration_dir):
    """Return (Rig of the rig file, note): T_robot_world from robot_world.yaml when saved."""
    rig = Rig(load_rig_parameters(rig_file))
    try:
        saved = load_calibration(calibration_dir, 'robot_world.yaml', rig_description(rig_file))
    except CalibrationRefused as refused:
        return rig, f'robot-world calibration not used: {refused}'
    if saved is None:
        return rig, "the rig file's T_robot_world"
    world = saved[0]['rig']
    rig.set_world(world['world_in_robot'], world['world_yaw'])
    return rig, 'T_robot_world of the saved robot-world calibration'


@dataclass
class GraphCalibration:
    """What ``calibrate_on_graph`` did (``run``: the CameraCalibrationRun)."""

    run: object
    path: str
    calibration_dir: str
    notes: list


def calibrate_on_graph(graph, spec, centre, yaw=0.0, views=25, calibration_dir=None,
                       rig_file=None, horizontal_fov=math.radians(70.0),
                       camera_name='rgb_camera', apply=True, frames=2,
                       progress=lambda index, total, note: None, graph_rig=None):
    """
    Calibrate the RGB camera on the running `graph` over the board `spec` at `centre`, `yaw`.

    Returns GraphCalibration (``path`` '' when not `apply`); raises ValueError or
    RuntimeError saying what failed.
    """
    asked = {} if calibration_dir and rig_file else planner_parameters(
        graph, ('calibration_dir', 'rig_file'))
    directory = calibration_dir_or_default(calibration_dir or asked.get('calibration_dir'))
    rig_file = rig_file_or_default(rig_file or asked.get('rig_file') or '')
    planning, where = rig_with_saved_world(rig_file, directory)
    device = graph_rig or GraphRig(graph)
    camera, calibrated = device.nominal_camera(horizontal_fov)
    notes = [f'rig file {rig_file} ({where}); calibration directory {directory}',
             'rgb/camera_info: ' + ('calibrated, its intrinsics the starting point'
                                    if calibrated else 'K = 0 (uncalibrated): a pinhole of '
                                    f'{math.degrees(horizontal_fov):g} deg the starting point')]
    plan = plan_views(planning, camera, spec, centre, yaw, views)
    run = calibrate_camera(plan, device.move, device.grab, spec, (camera.width, camera.height),
                           guess=camera, frames=frames, progress=progress)
    path = save_camera_calibration(directory, run, spec, camera_name) if apply else ''
    return GraphCalibration(run, path, directory, notes)


__all__ = ['calibrate_on_graph', 'GraphCalibration', 'GraphRig', 'node_parameters',
           'planner_parameters',
           'rig_with_saved_world']
