"""Node sim_world in-process: /clock, camera topics on simulated time, canvas, truth, build."""

import datetime
import math
import os
import threading
import time

from geometry_msgs.msg import PoseStamped, Vector3Stamped
from helio_drivers.sim.build import draw_build
from helio_drivers.sim.world import flat_settings, SimSettings
from helio_drivers.sim.world_node import PARAMETER_DOCS, SimWorldNode, TRUTH_QOS
from helio_optics.node_kit.conversions import point_to_array, pose_to_matrix, stamp_to_seconds
from helio_optics.node_kit.in_process_graph import InProcessGraph
from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters
import numpy as np
import pytest
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import String
import yaml


def test_sim_world_publishes_clock_cameras_canvas_and_truth_on_sim_time(tmp_path):
    with InProcessGraph('probe') as graph:
        node = graph.add(SimWorldNode(**graph.node_options(
            real_time_factor=20.0, dobot_port=str(tmp_path / 'dobot'),
            servo_port=str(tmp_path / 'servo'), rig_file=default_rig_file(), flux_rays=5000,
            canvas_rate=2.0, output_dir=str(tmp_path / 'out'), build='drawn', build_seed=5)))
        got = {'clock': graph.collect(Clock, '/clock', QoSProfile(depth=10)),
               'thermal': graph.collect(Image, 'thermal/image_raw', qos_profile_sensor_data),
               'rgb': graph.collect(Image, 'rgb/image_raw', qos_profile_sensor_data),
               'info': graph.collect(CameraInfo, 'rgb/camera_info', qos_profile_sensor_data),
               'canvas': graph.collect(Image, 'sim/canvas', QoSProfile(depth=1)),
               'sun': graph.collect(Vector3Stamped, 'sim/truth/sun_direction', TRUTH_QOS),
               'world': graph.collect(PoseStamped, 'sim/truth/world_pose', TRUTH_QOS),
               'rgb_pose': graph.collect(PoseStamped, 'sim/truth/rgb_pose', TRUTH_QOS),
               'build': graph.collect(String, 'sim/truth/build', TRUTH_QOS)}
        for name, collector in got.items():
            collector.wait_for_count(1 if name == 'build' else 3, timeout=60.0)
        got['thermal'].wait_for_count(12, timeout=60.0)
        got = {name: collector.messages for name, collector in got.items()}
        assert (tmp_path / 'dobot').exists() and (tmp_path / 'servo').exists()
        thermal = got['thermal'][-1]
        assert (thermal.encoding, thermal.width, thermal.height) == ('16UC1', 160, 120)
        assert thermal.header.frame_id == 'thermal'
        # stamps are the simulated date and time: from the configured start, at 8.7 Hz
        start = node.world.clock.start.timestamp()
        stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec - start
                  for m in got['thermal']]
        assert 0.0 <= stamps[0] < 1.0
        # a frame at the first 0.1 s step at or after each due time: 0.1 or 0.2 s apart; a
        # best-effort frame this busy process did not take in time leaves a longer gap
        gaps = [b - a for a, b in zip(stamps, stamps[1:])]
        assert all(gap > 0.05 for gap in gaps), gaps
        whole = [gap for gap in gaps if gap < 0.2 + 1e-6]
        assert len(whole) >= len(gaps) / 2, gaps
        assert len(whole) / sum(whole) == pytest.approx(8.7, rel=0.25)
        rgb, info = got['rgb'][-1], got['info'][-1]
        assert (rgb.encoding, rgb.width, rgb.height) == ('rgb8', info.width, info.height)
        # camera_info: the intrinsics the user's calibration gave, not the build's true ones
        published = SimSettings().rgb.camera()
        assert list(info.k) == pytest.approx(published.matrix.ravel().tolist())
        assert not np.allclose(node.world.rgb.camera.matrix, published.matrix)
        # the build: drawn from the rig file with the seed, published and written once
        build = draw_build(load_rig_parameters(default_rig_file()), seed=5)
        assert yaml.safe_load(got['build'][-1].data) == build.to_dict()
        assert got['canvas'][-1].encoding == 'mono8'
        clock = [m.clock.sec + 1e-9 * m.clock.nanosec for m in got['clock']]
        assert all(b > a for a, b in zip(clock, clock[1:]))
        # the truth: the sun ray the world's own sun gives at that stamp, and T_robot_world
        sun = got['sun'][-1]
        when = sun.header.stamp.sec + 1e-9 * sun.header.stamp.nanosec
        truth = node.world.sun.ray_robot(datetime.datetime.fromtimestamp(
            when, tz=datetime.timezone.utc))
        assert np.degrees(math.acos(min(1.0, point_to_array(sun.vector) @ truth))) < 1e-6
        assert pose_to_matrix(got['world'][-1].pose) == pytest.approx(
            node.world.T_robot_world, abs=1e-12)
        # the RGB optical frame in the world: T_world_robot T_robot_rgb of the rig at its
        # joints (at rest: the emulators' start), restamped per frame, serialised per pose
        rgb_pose = got['rgb_pose'][-1]
        assert rgb_pose.header.frame_id == 'world'
        assert stamp_to_seconds(rgb_pose.header.stamp) > stamp_to_seconds(
            got['rgb_pose'][0].header.stamp)
        rig_pose = node.world.rig.forward(node.devices.joint_positions())
        assert pose_to_matrix(rgb_pose.pose) == pytest.approx(
            np.linalg.inv(node.world.T_robot_world) @ rig_pose.T_robot_rgb, abs=1e-9)
    assert (tmp_path / 'out' / 'canvas.png').exists()
    assert yaml.safe_load((tmp_path / 'out' / 'build.yaml').read_text()) == build.to_dict()
    assert (tmp_path / 'out' / 'dots.csv').exists()


def rgb_frames_of_a_node(tmp_path, count, **parameters):
    """Return {stamp: rgb8 bytes} of the first `count` RGB images of a sim_world node."""
    with InProcessGraph('probe') as graph:
        graph.add(SimWorldNode(**graph.node_options(
            real_time_factor=4.0, lockstep_topic='', dobot_port=str(tmp_path / 'dobot'),
            servo_port=str(tmp_path / 'servo'), rig_file=default_rig_file(), flux_rays=5000,
            **parameters)))
        images = graph.collect(Image, 'rgb/image_raw', QoSProfile(
            depth=100, reliability=ReliabilityPolicy.BEST_EFFORT))
        images.wait_for_count(count, timeout=60.0)
        return {stamp_to_seconds(m.header.stamp): bytes(m.data) for m in images.messages}


def test_rgb_frames_developed_on_the_rgb_thread_are_the_ones_made_before_the_next_clock(
        tmp_path):
    """
    The node's RGB thread (``rgb_thread``) publishes the images the stepping thread makes.

    Two nodes of one seed, the devices at rest: frames published from the RGB thread and
    frames made and published on the stepping thread before the next /clock, the same bytes
    at the same stamps, due frames (5 Hz of simulated time). Without read-out noise: a node
    renders only once its subscriber is matched, which discovery decides, so with noise the
    two runs' frames would draw from the world's generator from different frames on. That
    frames developed on another thread equal frames made at once, noise included, is
    ``test_sim_world``'s test with two worlds stepped alike.
    """
    noise_free = {'rgb.read_noise': 0.0, 'rgb.full_well_electrons': 0.0}
    threaded = rgb_frames_of_a_node(tmp_path / 'a', 10, rgb_thread=True, **noise_free)
    in_line = rgb_frames_of_a_node(tmp_path / 'b', 10, rgb_thread=False, **noise_free)
    stamps = sorted(set(threaded) & set(in_line))
    assert len(stamps) >= 6        # best effort: a frame may be lost on a loaded machine
    # due frames, 0.2 s apart (after the first step's, 0.1 s before the schedule's)
    assert all((b - stamps[-1]) / 0.2 == pytest.approx(round((b - stamps[-1]) / 0.2), abs=1e-5)
               for b in stamps[1:])
    for stamp in stamps:
        assert threaded[stamp] == in_line[stamp], f'the frame at {stamp:.1f} s'


def test_config_file_documents_every_world_setting_with_the_code_defaults():
    # config/sim_world.yaml is what users edit: it must name every world setting, with the
    # defaults SimWorld uses without it, and each must have a description and range.
    path = os.path.join(os.path.dirname(__file__), '..', 'config', 'sim_world.yaml')
    with open(path, encoding='utf-8') as stream:
        config = yaml.safe_load(stream)['/**/sim_world']['ros__parameters']
    defaults = flat_settings(SimSettings())
    # commented out in the file (an empty list has no parameter type): no scheduled cloud,
    # no calibration board
    optional = {'cloud_schedule', 'board_pose'}
    missing = set(defaults) - set(config) - optional
    assert not missing, f'sim_world.yaml lacks {sorted(missing)}'
    undocumented = set(defaults) - set(PARAMETER_DOCS)
    assert not undocumented, f'no description/range for {sorted(undocumented)}'
    for name, default in defaults.items():
        if name in config:
            value = config[name]
            if isinstance(default, float):
                assert value == pytest.approx(default), name
            else:
                assert value == default, name


def test_clouds_and_unplugged_cables_are_set_at_run_time_and_the_rest_is_refused(tmp_path):
    from rclpy.parameter import Parameter
    with InProcessGraph('probe') as graph:
        node = graph.add(SimWorldNode(**graph.node_options(
            real_time_factor=20.0, dobot_port=str(tmp_path / 'dobot'),
            servo_port=str(tmp_path / 'servo'), rig_file=default_rig_file(), flux_rays=5000,
            rgb_rate=0.0)))
        clock = graph.collect(Clock, '/clock', QoSProfile(depth=10))
        clock.wait_for_count(2, timeout=60.0)
        start = node.world.clock.start.timestamp()
        clear = node.world.dni_now()
        assert clear > 0.0
        now = node.world.time
        dark = [now, now + 1e4, 0.0]
        result, = node.set_parameters([Parameter('cloud_schedule', value=dark)])
        assert result.successful, result.reason
        count = len(clock.messages)
        clock.wait_for_count(count + 3, timeout=60.0)       # a few steps later: dark
        assert node.world.dni_now() == 0.0
        result, = node.set_parameters([Parameter('cloud_schedule', value=[now, now + 1.0])])
        assert not result.successful and 'triples' in result.reason
        result, = node.set_parameters([Parameter('cloud_schedule', value=[0.0, 0.0, 1.0])])
        assert not result.successful, 'end > start is checked'
        # an unplugged cable: the port's link goes away (the driver's open fails), and back
        result, = node.set_parameters([Parameter('unplugged', value=['dobot'])])
        assert result.successful, result.reason
        assert not (tmp_path / 'dobot').exists() and (tmp_path / 'servo').exists()
        result, = node.set_parameters([Parameter('unplugged', value=['dobot', 'arm'])])
        assert not result.successful and "unknown device(s) ['arm']" in result.reason
        result, = node.set_parameters([Parameter('unplugged', value=[''])])
        assert result.successful and (tmp_path / 'dobot').exists()
        # an unplugged camera publishes nothing, its images nor its camera_info, until back
        thermal = graph.collect(CameraInfo, 'thermal/camera_info', qos_profile_sensor_data)
        thermal.wait_for_count(1, timeout=60.0)
        result, = node.set_parameters([Parameter('unplugged', value=['thermal_camera'])])
        assert result.successful, result.reason
        unplugged_at = node.world.time
        count = len(clock.messages)
        clock.wait_for_count(count + 10, timeout=60.0)      # 1 s of simulated time on
        graph.wait_until(lambda: node.world.time > unplugged_at + 1.0, 60.0, 'a second more')
        late = [m for m in thermal.messages
                if stamp_to_seconds(m.header.stamp) - start > unplugged_at + 0.2]
        assert not late, f'{len(late)} thermal camera_info after the unplug'
        result, = node.set_parameters([Parameter('unplugged', value=[''])])
        assert result.successful
        count = len(thermal.messages)
        thermal.wait_for_count(count + 2, timeout=60.0)     # plugged back in
        result, = node.set_parameters([Parameter('real_time_factor', value=0.0)])
        assert result.successful and node._pacer.real_time_factor == 0.0
        result, = node.set_parameters([Parameter('dni', value=500.0)])
        assert not result.successful and 'read-only' in result.reason
        assert node.world.sun.dni == clear


def test_a_world_in_lockstep_waits_for_its_consumer_and_paces_itself_once_it_is_silent(tmp_path):
    # A stand-in for the thermal monitor answers each thermal image with ThermalStats of its
    # stamp, then stops answering (a SIGSTOPped process). In lockstep the world never gets
    # more than lockstep_lead (+ one step) past the newest answer; left behind, it neither
    # freezes nor runs free, but at lockstep_fallback_factor.
    from helio_msgs.msg import ThermalStats
    lead, fallback, timeout = 0.3, 2.0, 0.5
    with InProcessGraph('probe') as graph:
        node = graph.add(SimWorldNode(**graph.node_options(
            real_time_factor=0.0, dobot_port=str(tmp_path / 'dobot'),
            servo_port=str(tmp_path / 'servo'), rig_file=default_rig_file(), flux_rays=5000,
            rgb_rate=0.0, lockstep_lead=lead, lockstep_timeout=timeout,
            lockstep_fallback_factor=fallback)))
        start = node.world.clock.start.timestamp()
        answering = threading.Event()
        answering.set()
        answered, ahead = [], []      # stamps answered; world time past the newest one [s]
        stats = graph.helper.create_publisher(ThermalStats, 'thermal/stats', 10)

        def answer(image):
            if not answering.is_set():
                return
            if answered:              # the world has seen answers up to answered[-1] only
                ahead.append(node.world.time - answered[-1])
            out = ThermalStats()
            out.header = image.header
            stats.publish(out)
            answered.append(stamp_to_seconds(image.header.stamp) - start)

        graph.helper.create_subscription(Image, 'thermal/image_raw', answer,
                                         qos_profile_sensor_data)
        graph.wait_until(lambda: len(answered) > 40, timeout=120.0, what='40 answers')
        # in step (the first answers came after a free-running start): within the lead
        assert max(ahead[-20:]) <= lead + node.world.settings.step + 1e-6, ahead[-20:]
        answering.clear()                                # the consumer goes silent
        silent_at, wall = node.world.time, time.monotonic()
        graph.wait_until(lambda: node.world.time > silent_at + 3.0, timeout=60.0,
                         what='the world going on without its consumer')
        elapsed = time.monotonic() - wall
        # held for the timeout, then paced at 2x: 3 s simulated take >= timeout + 1.5 s
        assert elapsed >= timeout + 3.0 / fallback - 0.2, f'{elapsed:.2f} s wall: ran free'
        assert node._was_left_behind


def test_a_world_in_lockstep_never_runs_ahead_of_the_drivers_joint_states(tmp_path):
    # Two stand-in drivers answer /clock with joint states stamped on it, as the drivers do
    # under use_sim_time (one every simulated step); one answers each tick only after a
    # wall-clock delay, as a driver starved of the CPU. The world waits for the slower: it
    # never gets more than lockstep_joint_lead (+ one step) past that driver's newest stamp.
    from sensor_msgs.msg import JointState
    lead = 0.15
    with InProcessGraph('probe') as graph:
        node = graph.add(SimWorldNode(**graph.node_options(
            real_time_factor=0.0, dobot_port=str(tmp_path / 'dobot'),
            servo_port=str(tmp_path / 'servo'), rig_file=default_rig_file(), flux_rays=5000,
            rgb_rate=0.0, thermal_rate=0.0, lockstep_topic='', lockstep_joint_lead=lead,
            lockstep_timeout=5.0)))
        joints = graph.helper.create_publisher(JointState, 'joint_states', 10)
        slow_stamps, ahead = [], []

        def answer(clock, names):
            message = JointState()
            message.header.stamp = clock.clock
            message.name = list(names)
            message.position = [0.0] * len(names)
            joints.publish(message)

        def on_clock(clock):
            answer(clock, ['dobot_j1', 'dobot_j2', 'dobot_j3', 'dobot_j4'])
            stamp = Time.from_msg(clock.clock).nanoseconds * 1e-9
            if slow_stamps:                 # how far the world is past the slow one's newest
                ahead.append(node.world.clock.nanoseconds() * 1e-9 - slow_stamps[-1])
            time.sleep(0.02)                # the slow driver: 20 ms of wall time a tick
            answer(clock, ['lens_yaw', 'lens_pitch'])
            slow_stamps.append(stamp)

        graph.helper.create_subscription(Clock, '/clock', on_clock, QoSProfile(depth=1))
        graph.wait_until(lambda: len(slow_stamps) > 60, timeout=120.0, what='60 answers')
        # (free, the world would step a tick every millisecond or two: 1-2 s ahead)
        assert max(ahead[-40:]) <= lead + node.world.settings.step + 1e-6, ahead[-40:]


def test_a_world_holds_for_a_heartbeat_until_it_says_clear(tmp_path):
    # A stand-in lens planner beats on lens/heating, stamped on the /clock it last heard,
    # 20 ms of wall time late each tick (a process starved of the CPU): the world never gets
    # more than lockstep_heartbeat_lead (+ one step) past its newest beat, so the servo
    # driver's lease on those beats (0.15 s of node clock) cannot run out on a slow beater.
    # Its 'clear' beat (the lens left the heating distance) lets the world run free at once.
    from helio_optics.node_kit.focus_lease import CLEAR, HEATING, HEATING_TOPIC
    from std_msgs.msg import Header
    lead = 0.05
    with InProcessGraph('probe') as graph:
        node = graph.add(SimWorldNode(**graph.node_options(
            real_time_factor=0.0, dobot_port=str(tmp_path / 'dobot'),
            servo_port=str(tmp_path / 'servo'), rig_file=default_rig_file(), flux_rays=5000,
            rgb_rate=0.0, thermal_rate=0.0, lockstep_topic='', lockstep_spot_topic='',
            lockstep_joint_states=False, lockstep_heartbeat_lead=lead,
            lockstep_timeout=60.0)))
        beats = graph.helper.create_publisher(Header, HEATING_TOPIC, 10)
        stamps, ahead, heating = [], [], [True]

        def on_clock(clock):
            if not heating[0]:
                return
            if stamps:                      # how far the world is past the newest beat
                ahead.append(node.world.clock.nanoseconds() * 1e-9 - stamps[-1])
            time.sleep(0.02)
            beats.publish(Header(stamp=clock.clock, frame_id=HEATING))
            stamps.append(Time.from_msg(clock.clock).nanoseconds * 1e-9)

        graph.helper.create_subscription(Clock, '/clock', on_clock, QoSProfile(depth=1))
        graph.wait_until(lambda: len(stamps) > 40, timeout=120.0, what='40 beats')
        assert max(ahead[-30:]) <= lead + node.world.settings.step + 1e-6, ahead[-30:]
        heating[0] = False
        last = stamps[-1]
        beats.publish(Header(stamp=Time(seconds=last).to_msg(), frame_id=CLEAR))
        # free again: far past the last beat long before lockstep_timeout (60 s of wall
        # time) would leave the beater behind
        graph.wait_until(lambda: node.world.clock.nanoseconds() * 1e-9 > last + 2.0,
                         timeout=30.0, what='the world past the clear beat')


def test_a_held_world_sends_its_clock_again_for_a_source_that_missed_it(tmp_path):
    # A stand-in driver that answers only the /clock messages it receives, and whose first
    # answer is old (it stamped before it heard the world): without the world sending its
    # /clock again while it waits, neither would ever move (a system test's graph sat at
    # 0.4 s of simulated time for 120 s so). lockstep_timeout is long: nothing leaves the
    # stand-in behind meanwhile.
    from builtin_interfaces.msg import Time as StampMsg
    from sensor_msgs.msg import JointState
    with InProcessGraph('probe') as graph:
        node = graph.add(SimWorldNode(**graph.node_options(
            real_time_factor=0.0, dobot_port=str(tmp_path / 'dobot'),
            servo_port=str(tmp_path / 'servo'), rig_file=default_rig_file(), flux_rays=5000,
            rgb_rate=0.0, thermal_rate=0.0, lockstep_topic='', lockstep_timeout=60.0,
            lockstep_resend=0.05)))
        joints = graph.helper.create_publisher(JointState, 'joint_states', 10)
        answers = []

        def answer(stamp):
            message = JointState(name=['lens_yaw', 'lens_pitch'], position=[0.0, 0.0])
            message.header.stamp = stamp
            joints.publish(message)
            answers.append(stamp_to_seconds(stamp))

        start = node.world.clock.start.timestamp()
        graph.wait_until(lambda: node.world.time > 0.5, 60.0, 'the world running free')
        answer(StampMsg(sec=int(start)))           # the world's first instant: far behind
        graph.wait_until(lambda: node.resends > 0, 60.0, 'the world held, sending again')
        held_at = node.world.time
        graph.helper.create_subscription(Clock, '/clock', lambda c: answer(c.clock),
                                         QoSProfile(depth=1))
        graph.wait_until(lambda: node.world.time > held_at + 2.0, 60.0,
                         'the world going on in lockstep with the late source')
        # in lockstep from then on: never more than the joint lead (0.05 s) and a step ahead
        assert node.world.time - (answers[-1] - start) <= 0.05 + 0.1 + 1e-6
