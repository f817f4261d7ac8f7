"""
Replay the recorded bags of ``bags/`` through the perception nodes and hold their outputs.

``helio replay`` (its own process) publishes a fixture's camera images, camera infos, joint
states and ``/clock``; ``spot_detector`` and ``thermal_monitor`` run as processes on that
clock, as a user runs them. Their outputs are compared, image by image (matched by the
source image's stamp):

- with the RECORDED outputs of the same nodes: a change that moves a perception result fails
  here. Tolerances (the recorded values are from the same code on the same images, so only
  floating-point noise is allowed): ThermalStats T_max within ``SAME_T_MAX`` degC, N_p and
  the hottest pixel equal, the hottest ground point within ``SAME_POINT`` m; SpotObservation
  valid flag equal, centre within ``SAME_POINT`` m, area within ``SAME_AREA_RATIO``. A
  recorded spot that used the marker pose of an EARLIER image (``marker_pose_age`` > 0) is
  not compared: the bag keeps one RGB image in 25, so the replayed node never saw that one.
- with the world's ground truth: while the lens held a dot in focus (``fixture.yaml``: aimed
  with the true sun), the hottest ground point is within ``TRUTH_HOTTEST`` m of the dot;
  while the lens is aimed at a dot (in focus or retreated along the sun ray) every
  valid spot centre is within ``TRUTH_SPOT`` m of it.

After a deliberate change of the detector or the simulated cameras, re-record the bags with
``python -m helio_control.fixture_bags --out bags`` (bags/README.md).
"""

import importlib.util
import os
import re
import subprocess
import sys

from conftest import graph_of_processes, REPO
from helio_control.bag_files import decode_messages
from helio_control.bringup import node_environment
from helio_msgs.msg import SpotObservation, ThermalStats
from helio_optics.node_kit.conversions import point_to_array, stamp_to_nanoseconds
import numpy as np
import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
import yaml

BAGS = sorted(os.path.join(REPO, 'bags', name) for name in os.listdir(os.path.join(REPO, 'bags'))
              if os.path.isfile(os.path.join(REPO, 'bags', name, 'metadata.yaml')))
SAME_T_MAX = 1e-6          # degC
SAME_POINT = 1e-5          # m
SAME_SPOT = 1e-5           # m: the fixture's detector searches the whole of every image
#                            (``marker.roi_search`` false), so a spot depends on its image alone
SAME_AREA_RATIO = 1e-3
TRUTH_HOTTEST = 2.0e-3     # m: the hottest pixel's footprint on the panel is ~1 mm wide
TRUTH_SPOT = 2.0e-3        # m: the light spot's centre vs the focus point
STARTUP = 2 * 10**9       # ns of bag time in which joint states may still be missing
MIN_FRACTION = 0.8         # of the replayed images that must come out of each node (rounded
#                            down: an image that arrives before its camera info has no output)
REPLAY_RATE = 2.0
OUTPUTS = ('/spot', '/thermal/stats', '/diagnostics', '/rosout')


def enough(images):
    """Return how many outputs the replay of `images` images must give at least."""
    return max(1, int(MIN_FRACTION * images))


def recorded(bag, topic):
    """Return {source image stamp [ns]: message} of a recorded output topic."""
    return {stamp_to_nanoseconds(m.header.stamp): m for _, _, m in decode_messages(bag, [topic])}


def image_stamps(bag, topic):
    """Return the stamps [ns] of the recorded images of `topic`."""
    return {stamp_to_nanoseconds(m.header.stamp) for _, _, m in decode_messages(bag, [topic])}


@pytest.fixture(scope='module', params=BAGS, ids=os.path.basename)
def replayed(request, tmp_path_factory):
    """Replay one bag through the two perception nodes; return what they published."""
    bag = request.param
    tmp_path = tmp_path_factory.mktemp(os.path.basename(bag))
    reliable = QoSProfile(depth=500, reliability=ReliabilityPolicy.RELIABLE)
    with open(os.path.join(bag, 'fixture.yaml')) as stream:
        fixture = yaml.safe_load(stream)
    # the perception nodes with the parameters the recording's nodes had
    overrides = fixture.get('parameters', {})
    with graph_of_processes(tmp_path, ('spot_detector', 'thermal_monitor'),
                            overrides) as (_, graph):
        spots = graph.collect(SpotObservation, 'spot', reliable)
        stats = graph.collect(ThermalStats, 'thermal/stats', reliable)
        graph.wait_until(lambda: graph.helper.count_publishers('/spot') >= 1 and
                         graph.helper.count_publishers('/thermal/stats') >= 1, 60.0,
                         'the perception nodes')
        replay = subprocess.run(
            [sys.executable, '-m', 'helio_control.cli', 'replay', bag, '--rate',
             str(REPLAY_RATE), '--delay', '3', '--exclude', *OUTPUTS],
            capture_output=True, text=True, timeout=300, env=node_environment())
        assert replay.returncode == 0, replay.stderr[-2000:]
        rgb = image_stamps(bag, '/rgb/image_raw')
        thermal = image_stamps(bag, '/thermal/image_raw')
        stats.wait_until(lambda messages: len(messages) >= enough(len(thermal)), 60.0)
        spots.wait_until(lambda messages: len(messages) >= enough(len(rgb)), 60.0)
        joints = [(stamp_to_nanoseconds(m.header.stamp), dict(zip(m.name, m.position)))
                  for _, _, m in decode_messages(bag, ['/joint_states'])]
        names = sorted({name for _, positions in joints for name in positions})
        merged, current = [], {}
        for t, positions in joints:
            current.update(positions)
            if len(current) == len(names):
                merged.append((t, [current[name] for name in names]))
        return {'bag': bag, 'fixture': fixture, 'joints': merged, 'rgb': rgb, 'thermal': thermal,
                'spots': {stamp_to_nanoseconds(m.header.stamp): m for m in spots.messages},
                'stats': {stamp_to_nanoseconds(m.header.stamp): m for m in stats.messages}}


def moving(joints, stamp_ns, window=0.5e9, threshold=1e-4):
    """Return whether any joint moved more than `threshold` rad within `window` ns."""
    near = [positions for t, positions in joints if abs(t - stamp_ns) <= window]
    if len(near) < 2:
        return True
    spread = np.ptp(np.asarray(near), axis=0)
    return bool(np.max(spread) > threshold)


def aimed_at(fixture, stamp_ns):
    """
    Return the dot the lens' chief ray was aimed at at `stamp_ns`, or None.

    From a dot's focus until the next dot's approach (the retreat moves the lens along the
    sun ray, so the spot stays centred on the dot, only wider).
    """
    t = stamp_ns * 1e-9
    dots = fixture['dots']
    for dot, following in zip(dots, dots[1:] + [None]):
        end = following['focus_start'] - 5.0 if following else float('inf')
        if dot['focus_start'] + 1.0 <= t <= end:
            return np.array(dot['target'])
    return None


def in_focus(fixture, stamp_ns):
    """Return the dot (world x, y) held in focus at `stamp_ns`, or None."""
    t = stamp_ns * 1e-9
    for dot in fixture['dots']:
        if dot['focus_start'] + 1.0 <= t <= dot['focus_end']:
            return np.array(dot['target'])
    return None


def test_thermal_monitor_on_the_replay_gives_the_recorded_statistics(replayed):
    reference = recorded(replayed['bag'], '/thermal/stats')
    start = min(replayed['thermal'])
    compared = 0
    first, last = min(reference), max(reference)
    for stamp, new in replayed['stats'].items():
        old = reference.get(stamp)
        if old is None and not first <= stamp <= last:
            continue      # the recorder subscribed after this image, or stopped before
        assert old is not None, f'no recorded stats for thermal image {stamp}'
        assert abs(new.t_max - old.t_max) <= SAME_T_MAX
        assert (new.n_p, new.hottest_u, new.hottest_v) == (old.n_p, old.hottest_u,
                                                           old.hottest_v)
        if new.hottest_point_valid != old.hottest_point_valid:
            # the replay starts with the bag's first message: the node may lack the joint
            # states of its first images (the recording's node had them from before), until
            # the bag has given every joint once (its first complete set: 3.1 s after the
            # first image in the recording of 2026-11-28); while the lens moves, whether a
            # joint state lies within the tolerance of the image depends on which had
            # arrived when the image was processed
            joints_known = max(start, replayed['joints'][0][0])
            assert stamp < joints_known + STARTUP or moving(replayed['joints'], stamp), \
                'hottest point validity differs while the lens holds still'
            continue
        if new.hottest_point_valid and not moving(replayed['joints'], stamp):
            # while the lens moves, the joints looked up at the image's stamp depend on
            # which joint states had arrived: compared only while it holds still
            assert np.linalg.norm(point_to_array(new.hottest_point) -
                                  point_to_array(old.hottest_point)) <= SAME_POINT
        compared += 1
    assert compared >= enough(len(replayed['thermal']))


def test_spot_detector_on_the_replay_gives_the_recorded_spots(replayed):
    reference = recorded(replayed['bag'], '/spot')
    first, last = min(reference), max(reference)
    valid = 0
    for stamp, new in replayed['spots'].items():
        old = reference.get(stamp)
        if old is None and not first <= stamp <= last:
            continue      # the recorder subscribed after this image, or stopped before
        assert old is not None, f'no recorded spot for image {stamp}'
        if old.marker_pose_age > 0.0:
            continue      # it used the marker of an earlier image, which the bag decimated
        assert new.valid == old.valid, (new.reason, old.reason)
        if new.valid:
            valid += 1
            assert np.linalg.norm(point_to_array(new.center) - point_to_array(old.center)) \
                <= SAME_SPOT
            assert abs(new.area - old.area) <= SAME_AREA_RATIO * old.area
    assert valid >= 1, 'the fixture should show the spot with its marker in an image'


def test_the_hottest_point_is_on_the_dot_held_in_focus(replayed):
    checked = 0
    for stamp, stats in replayed['stats'].items():
        dot = in_focus(replayed['fixture'], stamp)
        if dot is None or stats.n_p == 0 or not stats.hottest_point_valid:
            continue
        error = np.linalg.norm(point_to_array(stats.hottest_point)[:2] - dot)
        assert error <= TRUTH_HOTTEST, f'hottest point {error * 1e3:.2f} mm off the dot'
        checked += 1
    assert checked >= 2


def test_valid_spots_lie_on_the_dot_held_in_focus(replayed):
    checked = 0
    for stamp, spot in replayed['spots'].items():
        dot = aimed_at(replayed['fixture'], stamp)
        if dot is None or not spot.valid:
            continue
        error = np.linalg.norm(point_to_array(spot.center)[:2] - dot)
        assert error <= TRUTH_SPOT, f'spot centre {error * 1e3:.2f} mm off the dot'
        checked += 1
    assert checked >= 1


def test_no_controller_node_subscribes_to_the_ground_truth(tmp_path):
    """Every node of the simulated graph but the world runs; none reads sim/truth/*."""
    with graph_of_processes(tmp_path, None) as (group, graph):
        names = {process.label for process in group.processes} - {'sim_world'}
        graph.wait_until(lambda: names <= set(graph.helper.get_node_names()), 60.0,
                         'every node of the graph')
        graph.wait_until(lambda: graph.helper.count_publishers('/sim/truth/sun_direction'),
                         60.0, 'the truth publisher')
        for topic in ('/sim/truth/sun_direction', '/sim/truth/world_pose', '/sim/truth/build'):
            readers = {info.node_name for info in
                       graph.helper.get_subscriptions_info_by_topic(topic)}
            assert not readers & names, f'{topic} is read by {readers & names}'


CONTROLLER_NODES = ('helio_control.lens_planner_node', 'helio_control.painter_node',
                    'helio_drivers.dobot_driver_node', 'helio_drivers.servo_driver_node',
                    'helio_optics.sun_estimator_node', 'helio_perception.spot_detector_node',
                    'helio_perception.thermal_monitor_node')


@pytest.mark.parametrize('module', CONTROLLER_NODES)
def test_no_controller_node_loads_the_simulated_world_or_its_build(module):
    """The drawn build lives in helio_drivers.sim and its outputs; no controller loads them."""
    probe = (f'import sys, {module}\n'
             "print(sorted(m for m in sys.modules if m.startswith('helio_drivers.sim')))")
    loaded = subprocess.run([sys.executable, '-c', probe], capture_output=True, text=True,
                            env=node_environment(), timeout=120)
    assert loaded.returncode == 0, loaded.stderr
    assert loaded.stdout.strip() == '[]', f'{module} loads {loaded.stdout.strip()}'
    with open(importlib.util.find_spec(module).origin) as stream:
        source = stream.read()
    for hidden in (r'sim/truth', r'(?<!\w)build\.yaml', r'build_seed'):
        assert not re.search(hidden, source), f'{module} mentions {hidden!r}'
