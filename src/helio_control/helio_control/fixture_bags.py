"""
Record the regression bags of ``bags/`` in the simulated world.

Run ``python -m helio_control.fixture_bags --out bags``.

Each fixture is the simulated graph (``sim_world``, the real driver nodes, ``spot_detector``,
``thermal_monitor``) run as processes with the recorder (``helio_control.recorder``) while a
client moves the lens and heats dots: per dot, move so that the focus lands on the dot at
d_lp = 8.2 cm (Eqs 14-15, aimed with the world's TRUE sun from ``sim/truth/*``: the fixture
shows the perception nodes a known focus, it does not test aiming), hold until N_p reaches
the target (or a time limit), retreat by 3 cm until N_p is 0. Both cameras are decimated
(the RGB camera's 640 x 480 frames to one in 25, 5 s of simulated time),
``/sim/canvas`` and ``/rosout`` are left out to keep the bag small. Beside each bag,
``fixture.yaml`` says what was done: the dots (world, m), when the lens held each dot in
focus (bag time, s), and the command that made it.

When a change moves a perception result on purpose (e.g. the detector or the simulated
camera changed), re-record with this command and commit the new bags; the replay tests
(``test/test_replay_regression.py``) then hold the new outputs.
"""

import argparse
import os
import shutil
import sys
import tempfile

from geometry_msgs.msg import PoseStamped, Vector3Stamped
from helio_control.bringup import simulated_graph, start_graph, wait_until_up
from helio_control.recorder import Recorder, recorder_subscribed
from helio_msgs.action import MoveArm, MoveWrist
from helio_msgs.msg import DeviceStatus, ThermalStats
from helio_optics.geometry import transform_points
from helio_optics.node_kit import topics
from helio_optics.node_kit.client_graph import ClientGraph, TRANSIENT_LOCAL_QOS
from helio_optics.node_kit.conversions import point_to_array, pose_to_matrix
from helio_optics.node_kit.conversions import stamp_to_seconds
from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters, Rig
from rclpy.qos import QoSProfile, ReliabilityPolicy
import yaml

FIXTURES = {
    # name: dots (world x, y [m]), N_p target, heating limit [sim s]
    'sim_one_dot': {'dots': [(0.062, 0.062)], 'n_p_target': 30, 'heat_limit': 40.0},
}
D_LP, RETREAT = 0.082, 0.03
NODES = ('sim_world', 'dobot_driver', 'servo_driver', 'spot_detector', 'thermal_monitor')
WORLD = {'real_time_factor': 3.0, 'flux_rays': 20000}
# The drivers poll on the wall clock: at 3x a 20 Hz joint state is 0.15-0.4 s of sim time
# apart, and whether an image finds one within the nodes' 0.3 s tolerance would then depend
# on which message the node happened to hear first (a race a replay cannot reproduce).
DRIVERS = {'joint_state_rate': 60.0}
# The spot detector re-detects the marker in every image (by default it reuses a pose while
# the joints stand still, and a marker not found while they stand still is searched again
# only once a second), each time in the whole frame (by default first in a window around
# the last corners, which the replay, seeing one image in 25, places elsewhere): each
# recorded spot then rests on its own recorded image alone, and the replay (with these
# parameters) can be compared image by image. The fixture aims the lens
# without a robot-world calibration, so the detector has no kinematic camera pose, and
# while it holds the dot the camera sees the marker 79 deg off its normal, beyond the
# detector's default limit (60 deg): the fixture keeps the marker's pose there.
PERCEPTION = {'spot_detector': {'marker.max_pose_age': 0.001, 'marker.miss_retry_period': 0.0,
                                'marker.roi_search': False, 'marker.max_view_angle_deg': 90.0}}
RECORDING = {'camera_decimation': 8,
             'topic_decimation': ['/rgb/image_raw=25', '/rgb/camera_info=1',
                                  '/thermal/camera_info=1'],
             'exclude': ['/parameter_events', '/rosout', '/sim/canvas']}
TIMEOUT = 180.0
# topics a fixture is worthless without: the recorder subscribes as it discovers topics
# (every 0.5 s), so the lens waits until it listens to all of them
NEEDED = ('/clock', '/joint_states', '/rgb/image_raw', '/thermal/image_raw', '/spot',
          '/thermal/stats')


def move_joints(graph, arm, wrist, x, timeout):
    """
    Move the arm (MOVJ_ANGLE) and the wrist to joints x together through the drivers.

    `graph` is a ClientGraph, `arm` and `wrist` its clients of move_arm and move_wrist.
    Raise RuntimeError naming the driver that refused or failed.
    """
    handles = [graph.send_goal(arm, MoveArm.Goal(
        mode=MoveArm.Goal.MOVJ_ANGLE, target=[float(v) for v in x[:3]] + [0.0])),
        graph.send_goal(wrist, MoveWrist.Goal(yaw=float(x[3]), pitch=float(x[4])))]
    for handle, name in zip(handles, ('move_arm', 'move_wrist')):
        if not handle.accepted:
            raise RuntimeError(f'{name} refused the goal')
        result = graph.goal_result(handle, timeout).result
        if not result.success:
            raise RuntimeError(f'{name} failed: {result.message}')


class FixtureClient:
    """Move the lens through the driver actions and watch the thermal statistics."""

    def __init__(self, graph, rig):
        """Connect to the drivers and the truth topics."""
        self.graph, self.rig = graph, rig
        self.arm = graph.action_client(MoveArm, 'move_arm', TIMEOUT)
        self.wrist = graph.action_client(MoveWrist, 'move_wrist', TIMEOUT)
        self.sun = graph.collect(Vector3Stamped, 'sim/truth/sun_direction', TRANSIENT_LOCAL_QOS)
        self.pose = graph.collect(PoseStamped, 'sim/truth/world_pose', TRANSIENT_LOCAL_QOS)
        self.stats = graph.collect(ThermalStats, topics.THERMAL_STATS,
                                   QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
        for device in ('dobot', 'servo'):
            graph.collect(DeviceStatus, topics.device_status(device), TRANSIENT_LOCAL_QOS) \
                .wait_for_message(lambda status: status.connected, TIMEOUT)

    def focus_joints(self, dot, d_lp):
        """Joints focusing the TRUE sun on world `dot` at `d_lp` (Eqs 14-15)."""
        sun = point_to_array(self.sun.wait_for_count(1, TIMEOUT)[-1].vector)
        T_robot_world = pose_to_matrix(self.pose.wait_for_count(1, TIMEOUT)[-1].pose)
        target = transform_points(T_robot_world, [dot[0], dot[1], 0.0])
        lens = self.rig.lens_pose_for_target(target, sun, d_lp)
        if lens.x is None:
            raise RuntimeError(f'dot {dot} unreachable: {lens.reason}')
        return lens.x

    def move(self, x):
        """Move arm and wrist to joints x; wait for both."""
        move_joints(self.graph, self.arm, self.wrist, x, TIMEOUT)

    def wait_stats(self, predicate, limit):
        """Wait for thermal stats matching `predicate` or `limit` sim s; return (t, stats)."""
        already = len(self.stats.messages)

        def first_match(messages):
            fresh = messages[already:]
            if not fresh:
                return None
            start = stamp_to_seconds(fresh[0].header.stamp)
            return next((m for m in fresh if predicate(m) or
                         stamp_to_seconds(m.header.stamp) - start > limit), None)
        message = first_match(self.stats.wait_until(
            lambda messages: first_match(messages) is not None, TIMEOUT,
            'the thermal statistics'))
        return stamp_to_seconds(message.header.stamp), message


def record_fixture(name, out_dir, work_dir):
    """Record one fixture bag into out_dir/name; return its fixture.yaml content."""
    spec = FIXTURES[name]
    bag = os.path.join(out_dir, name)
    if os.path.exists(bag):
        shutil.rmtree(bag)
    rig = Rig(load_rig_parameters(default_rig_file()))
    specs = simulated_graph(os.path.join(work_dir, 'ports'), NODES,
                            {'sim_world': WORLD, 'dobot_driver': DRIVERS,
                             'servo_driver': DRIVERS, **PERCEPTION})
    record = {'command': 'python -m helio_control.fixture_bags --out bags', 'dots': [],
              'd_lp': D_LP, 'retreat': RETREAT, 'world': WORLD, 'drivers': DRIVERS,
              'parameters': PERCEPTION, 'recording': RECORDING}
    logs = os.path.join(work_dir, 'logs')
    with ClientGraph(f'fixture_{name}') as graph:
        group = start_graph(specs, log_dir=logs, on_death=lambda process: graph.fail(
            f'{process.label} died: {process.tail()}'))
        try:
            wait_until_up(graph, specs, TIMEOUT)
            client = FixtureClient(graph, rig)
            recorder = Recorder(bag, use_sim_time=True, log_dir=logs, chunk_period=1.0,
                                **RECORDING).start()
            graph.wait_until(lambda: recorder_subscribed(graph.helper, NEEDED), TIMEOUT,
                             f'the recorder subscribing to {", ".join(NEEDED)}')
            try:
                for dot in spec['dots']:
                    client.move(client.focus_joints(dot, D_LP + RETREAT))
                    client.move(client.focus_joints(dot, D_LP))
                    start, _ = client.wait_stats(lambda m: True, 1.0)
                    end, hottest = client.wait_stats(
                        lambda m: m.n_p >= spec['n_p_target'], spec['heat_limit'])
                    client.move(client.focus_joints(dot, D_LP + RETREAT))
                    client.wait_stats(lambda m: m.n_p == 0, 30.0)
                    record['dots'].append({'target': [float(v) for v in dot],
                                           'focus_start': start, 'focus_end': end,
                                           'peak_n_p': int(hottest.n_p)})
                    print(f'[fixture_bags] {name}: dot {dot} in focus {start:.1f}..{end:.1f} '
                          f's, N_p {hottest.n_p}', file=sys.stderr)
            finally:
                recorder.stop()
        finally:
            group.stop()
    with open(os.path.join(bag, 'fixture.yaml'), 'w') as stream:
        yaml.safe_dump(record, stream, default_flow_style=None, sort_keys=False)
    return record


def main(argv=None):
    """Record every fixture (or those named) into --out."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', required=True, help='directory of the bags (bags/)')
    parser.add_argument('names', nargs='*', help=f'fixtures (default all: {list(FIXTURES)})')
    arguments = parser.parse_args(argv)
    for name in arguments.names or FIXTURES:
        if name not in FIXTURES:
            parser.error(f'unknown fixture {name!r}')
        with tempfile.TemporaryDirectory(prefix='helio_fixture_') as work_dir:
            record_fixture(name, arguments.out, work_dir)
        size = sum(os.path.getsize(os.path.join(arguments.out, name, f))
                   for f in os.listdir(os.path.join(arguments.out, name)))
        print(f'[fixture_bags] wrote {os.path.join(arguments.out, name)} ({size / 1e6:.2f} MB)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
