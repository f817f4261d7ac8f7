"""
The real graph estimates the sun: every node in its own process, as a user runs them.

``sim_world`` hosts the emulated Dobot and Maestro; the real ``dobot_driver`` and
``servo_driver`` nodes drive them over serial and publish their PARTIAL joint states (the
arm's four joints, the wrist's two); ``spot_detector`` finds the light spot in the simulated
camera's images; ``sun_estimator`` merges the joint states, pairs each spot with the joints
at its image's stamp and estimates the sun on ``estimate_sun``. The truth it is held against
is the world's own sun (``sim/truth/sun_direction``, a topic no controller node reads).

The same graph runs again under a namespace (``/rig1``): relative names keep it whole.
"""

import math

from conftest import graph_of_processes
from geometry_msgs.msg import Vector3Stamped
from helio_control.bringup import wait_for_devices
from helio_control.fixture_bags import move_joints
from helio_control.sun_sweep import sweep_poses, view_points
from helio_msgs.action import MoveArm, MoveWrist
from helio_msgs.msg import SpotObservation
from helio_msgs.srv import EstimateSun
from helio_optics.node_kit.conversions import camera_from_info, point_to_array
from helio_optics.node_kit.conversions import stamp_to_seconds
from helio_optics.node_kit.in_process_graph import TRANSIENT_LOCAL_QOS
from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters, Rig
import numpy as np
import pytest
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo

NODES = ('sim_world', 'dobot_driver', 'servo_driver', 'spot_detector', 'sun_estimator')
START_TIMEOUT = 60.0      # wall seconds for the processes to come up on a loaded machine
MOVE_TIMEOUT = 120.0
MARKER_SIDE = 0.04        # config/sim_world.yaml and config/spot_detector.yaml


class GraphClient:
    """The test's side of the graph: action clients, the spot stream, the truth."""

    def __init__(self, graph):
        self.graph = graph
        self.arm = graph.action_client(MoveArm, 'move_arm', START_TIMEOUT)
        self.wrist = graph.action_client(MoveWrist, 'move_wrist', START_TIMEOUT)
        self.spots = graph.collect(SpotObservation, 'spot',
                                   QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
        self.truth = graph.collect(Vector3Stamped, 'sim/truth/sun_direction',
                                   TRANSIENT_LOCAL_QOS)
        self.camera_info = graph.collect(CameraInfo, 'rgb/camera_info',
                                         qos_profile_sensor_data)
        self.estimate = graph.helper.create_client(EstimateSun, 'estimate_sun')
        wait_for_devices(graph, START_TIMEOUT)

    def true_sun(self, at=None):
        """
        Return the world's sun ray in the robot frame: its truth message nearest `at` [s].

        The sun moves about 0.25 deg a minute of simulated time, so the truth is taken at
        the time the estimate describes. Without `at`: the latest message.
        """
        messages = self.truth.wait_for_count(1, START_TIMEOUT)
        if at is None:
            return point_to_array(messages[-1].vector)
        nearest = min(messages, key=lambda m: abs(stamp_to_seconds(m.header.stamp) - at))
        assert abs(stamp_to_seconds(nearest.header.stamp) - at) < 5.0, 'no truth near then'
        return point_to_array(nearest.vector)

    def valid_spot_times(self):
        """Return the image stamps of the valid spots seen so far [s]."""
        return [stamp_to_seconds(m.header.stamp) for m in self.spots.messages if m.valid]

    def camera(self):
        """Return the RGB camera model from its camera_info."""
        return camera_from_info(self.camera_info.wait_for_count(1, START_TIMEOUT)[-1])

    def move(self, x):
        """Move both devices to joints x; return once both report success."""
        move_joints(self.graph, self.arm, self.wrist, x, MOVE_TIMEOUT)

    def observe(self, frames=6):
        """Wait for the next `frames` spot observations; return how many were valid."""
        already = len(self.spots.messages)
        messages = self.spots.wait_for_count(already + frames, MOVE_TIMEOUT)
        return sum(m.valid for m in messages[already:already + frames])


def estimate_in_graph(tmp_path, namespace=''):
    """Run the graph, sweep the lens, estimate; return (estimate response, true sun)."""
    rig = Rig(load_rig_parameters(default_rig_file()))
    # free: in lockstep with every consumer of the world (issue 31)
    overrides = {'sim_world': {'real_time_factor': 0.0, 'flux_rays': 20000}}
    with graph_of_processes(tmp_path, NODES, overrides, namespace) as (_, graph):
        client = GraphClient(graph)
        sun = client.true_sun()
        valid = []
        poses = sweep_poses(rig, rig.parameters.T_robot_world, sun, client.camera(),
                            MARKER_SIDE, view_points(), count=6)
        for x in poses:
            client.move(x)
            valid.append(client.observe())
        print(f'\nvalid spot observations per pose: {valid}')
        assert sum(v > 0 for v in valid) >= 4, 'fewer than 4 poses gave a valid spot'
        response = graph.call(client.estimate, EstimateSun.Request(), timeout=60.0)
        # the truth is for tests and recordings: no node of the graph listens to it
        for topic in ('sim/truth/sun_direction', 'sim/truth/world_pose'):
            listeners = {info.node_name for info in graph.helper.get_subscriptions_info_by_topic(
                graph.helper.resolve_topic_name(topic))}
            assert listeners == {graph.helper.get_name()} or \
                listeners <= {graph.helper.get_name()}, f'{topic} is read by {listeners}'
        # one sun over the sweep: the estimate describes the middle of the observations
        times = client.valid_spot_times()
        return response, client.true_sun(at=0.5 * (min(times) + max(times)))


def angle_deg(a, b):
    """Return the angle between two directions [deg]."""
    cosine = float(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)))
    return math.degrees(math.acos(min(1.0, max(-1.0, cosine))))


@pytest.mark.parametrize('namespace', ['', '/rig1'])
def test_the_graph_of_processes_estimates_the_true_sun_within_half_a_degree(
        tmp_path, namespace):
    response, sun = estimate_in_graph(tmp_path, namespace)
    assert response.success, response.message
    estimate = point_to_array(response.estimate.direction)
    error = angle_deg(estimate, sun)
    print(f'\n[{namespace or "/"}] {response.message}\nerror against the true sun: '
          f'{error:.3f} deg')
    assert response.estimate.observations >= 12
    assert error < 0.5
