"""
The sun_estimator node in the kit's InProcessGraph: spots in, estimate_sun answered.

The joint states arrive as the real drivers send them: the arm's four joints and the wrist's
two in separate messages, each stamped on its own clock. The spots are the model's own for a
known sun (the truth), put on the ground in the world frame as spot_detector sends them.
"""

import datetime
import math
import os
import time

from helio_msgs.msg import SpotObservation, SunEstimate
from helio_msgs.srv import EstimateSun
from helio_optics.ephemeris import ray_angles_from_sun, sun_position
from helio_optics.geometry import direction_from_angles, invert_transform, transform_points
from helio_optics.node_kit.conversions import stamp_from_seconds, stamp_to_seconds
from helio_optics.node_kit.in_process_graph import InProcessGraph, TRANSIENT_LOCAL_QOS
from helio_optics.node_kit.in_process_graph import wait_for_future
from helio_optics.rig_kinematics import Rig, UnreachableError
from helio_optics.sun_estimator_node import SunEstimatorNode
import numpy as np
import pytest
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
import yaml

SUN = -direction_from_angles(math.radians(40.0), math.radians(200.0))  # elevation 50 deg
HELD = 0.4    # a test's lens is held still this long before and after each image [s]
CONFIG = os.path.join(os.path.dirname(__file__), '..', 'config', 'sun_estimator.yaml')
# The documented range of every numeric parameter (README, config/sun_estimator.yaml units):
# what the node declared before and must keep declaring. Ints get integer ranges.
RANGES = {
    'rim_points': (8, 4096), 'contour_fraction': (0.05, 1.0),
    'centre_sigma': (1e-6, 0.05), 'max_observations': (1, 10000),
    'max_observation_age': (0.1, 1e6), 'joint_state_tolerance': (0.0, 10.0),
    'gain': (0.01, 2.0), 'delta': (1e-9, 0.1), 'tolerance': (1e-15, 1.0),
    'max_iterations': (1, 10000), 'update_period': (0.0, 3600.0),
    'fit_alpha': (1e-12, 0.5), 'outlier_alpha': (1e-15, 0.5),
    'max_outlier_fraction': (0.01, 1.0), 'step_tolerance': (1e-6, 1.0),
    'ambiguity_chi2': (0.01, 1000.0), 'ambiguity_separation_deg': (1e-4, 10.0),
    'plane_tolerance': (1e-6, 1.0), 'min_chief_ray_elevation_deg': (0.0, 80.0),
    'still_margin': (0.0, 10.0), 'still_hold': (0.0, 10.0), 'still_epsilon': (0.0, 0.1),
    'still_wait': (0.0, 60.0), 'request_queue_depth': (1, 10000),
    'busy_budget': (0.05, 1.0), 'busy_window': (0.1, 3600.0),
    # the noise of a hold's centre (issue 35, centre_noise)
    'centre_sigma_per_cot': (0.0, 0.05), 'frame_sigma': (0.0, 0.05),
    'hold_frame_tolerance': (1e-6, 0.05), 'max_chief_ray_tilt_deg': (1.0, 180.0)}
# Read each time an estimate is made: may change while the node runs. Every other parameter
# is read at start-up and declared read-only.
DYNAMIC = {'method', 'centre_sigma', 'max_observations', 'max_observation_age',
           'joint_state_tolerance', 'gain', 'delta', 'tolerance', 'max_iterations',
           'fit_alpha', 'outlier_alpha', 'max_outlier_fraction', 'step_tolerance',
           'ambiguity_chi2', 'ambiguity_separation_deg', 'plane_tolerance',
           'min_chief_ray_elevation_deg', 'still_only', 'still_margin', 'still_hold',
           'still_epsilon', 'still_wait', 'busy_budget', 'busy_window', 'centre_sigma_per_cot',
           'frame_sigma', 'hold_frame_tolerance', 'max_chief_ray_tilt_deg'}


@pytest.fixture
def graph():
    """Yield (node, InProcessGraph) with the Eq 18 update every 0.2 s."""
    with InProcessGraph('sun_estimator_test_helper') as in_process:
        node = in_process.add(SunEstimatorNode(**in_process.node_options(update_period=0.2)))
        yield node, in_process


def flatten(tree, prefix=''):
    """Flatten a ros__parameters tree into {'a.b': value}."""
    flat = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            flat.update(flatten(value, f'{prefix}{key}.'))
        else:
            flat[f'{prefix}{key}'] = value
    return flat


def wait_for(future, timeout=10.0):
    """Wait for a future spun by the graph's thread; return its result."""
    return wait_for_future(future, timeout, 'a parameter service')


def test_parameters_are_described_with_ranges_that_refuse_values_outside(graph):
    node, in_process = graph
    with open(CONFIG) as stream:
        shipped = flatten(yaml.safe_load(stream)['/**']['ros__parameters'])
    assert set(RANGES) < set(shipped)
    client = AsyncParameterClient(in_process.helper, 'sun_estimator')
    in_process.wait_until(client.services_are_ready, what='the parameter services')
    names = sorted(shipped)
    descriptors = wait_for(client.describe_parameters(names)).descriptors
    values = wait_for(client.get_parameters(names)).values
    for name, descriptor, value in zip(names, descriptors, values):
        assert descriptor.name == name and descriptor.description, name
        assert descriptor.read_only == (name not in DYNAMIC), name
        if name != 'update_period':  # overridden by the fixture
            assert parameter_value_to_python(value) == shipped[name], name
        if name not in RANGES:
            assert not descriptor.floating_point_range and not descriptor.integer_range, name
            continue
        low, high = RANGES[name]
        assert low <= shipped[name] <= high, name
        if isinstance(shipped[name], int):
            (span,) = descriptor.integer_range
            assert (span.from_value, span.to_value, span.step) == (low, high, 1), name
        else:
            (span,) = descriptor.floating_point_range
            assert (span.from_value, span.to_value) == pytest.approx((low, high)), name

    outside = [Parameter('max_observations', value=0), Parameter('gain', value=2.5),
               Parameter('centre_sigma', value=0.0)]
    results = wait_for(client.set_parameters(outside)).results
    assert [result.successful for result in results] == [False] * len(outside)
    assert all(result.reason for result in results)
    # a parameter read only at start-up refuses a change, even within its range
    (refused,) = wait_for(client.set_parameters([Parameter('rim_points', value=32)])).results
    assert not refused.successful and 'read-only' in refused.reason.lower()
    assert node.get_parameter('rim_points').value == 64
    inside = [Parameter('max_observations', value=10000), Parameter('gain', value=2.0)]
    results = wait_for(client.set_parameters(inside)).results
    assert all(result.successful for result in results)
    assert node.get_parameter('max_observations').value == 10000


def test_a_start_up_value_outside_its_range_stops_the_node_with_the_reason():
    with InProcessGraph() as in_process:
        with pytest.raises(Exception, match='rim_points'):
            SunEstimatorNode(**in_process.node_options(rim_points=4097))


def sweep_joints(rig, sun=SUN, offsets_deg=(-10.0, -5.0, 0.0, 5.0, 10.0), tilt_deg=10.0):
    """
    Joints of a lens yaw sweep viewing a clear spot near the canvas centre.

    The lens axis is `tilt_deg` more level than the sun's ray: its chief rays stay within the
    node's max_chief_ray_tilt_deg (15), with room for a sun that moves during the sweep.
    """
    target = transform_points(rig.parameters.T_robot_world, [0.1, 0.1, 0.0])
    centre = target - 0.06 * sun
    elevation = math.asin(-sun[2])
    azimuth = math.atan2(-sun[1], -sun[0])
    axis = direction_from_angles(0.5 * math.pi - elevation - math.radians(tilt_deg), azimuth)
    joints = []
    for offset in np.radians(offsets_deg):
        yaw, pitch = rig.yaw_pitch_for_axis(axis)
        try:
            joints.append(rig.inverse(centre, yaw + offset, pitch))
        except UnreachableError:
            continue
    assert len(joints) >= 3
    return joints


class Rigged:
    """The test's side: joint-state and spot publishers, and spots made for a known sun."""

    def __init__(self, node, in_process):
        self.node, self.graph, self.rig = node, in_process, Rig()
        helper = in_process.helper
        self.joints = helper.create_publisher(JointState, 'joint_states', 50)
        self.spots = helper.create_publisher(SpotObservation, 'spot', 20)
        self.client = helper.create_client(EstimateSun, 'estimate_sun')
        in_process.wait_until(lambda: self.joints.get_subscription_count() >= 1
                              and self.spots.get_subscription_count() >= 1,
                              what='the node subscribing')

    def publish_joints(self, x, seconds):
        """Publish joints x stamped `seconds` [s] as the drivers do: arm, then wrist."""
        arm = JointState(name=['dobot_j1', 'dobot_j2', 'dobot_j3', 'dobot_j4'],
                         position=[float(v) for v in x[:3]] + [0.0])     # the unused j4
        wrist = JointState(name=['lens_yaw', 'lens_pitch'], position=[float(v) for v in x[3:]])
        arm.header.stamp = wrist.header.stamp = stamp_from_seconds(seconds)
        self.joints.publish(arm)
        self.joints.publish(wrist)

    def observe(self, x, seconds, sun, shift=(0.0, 0.0, 0.0), quality=SpotObservation.FULL):
        """
        Hold the lens at joints x around `seconds` [s] and publish the spot `sun` casts then.

        The joints come HELD seconds before, at and after the image (a lens held still, as
        the sweep holds it); poses of one sweep are therefore at least 2 HELD apart.
        """
        stamp = stamp_from_seconds(seconds)
        seconds = stamp_to_seconds(stamp)     # what the node reads from the header
        for offset in (-HELD, 0.0, HELD):
            self.publish_joints(x, seconds + offset)
        spot = self.spot(x, seconds, sun, shift, quality)
        self.graph.wait_until(lambda: self.node.joints.at(seconds + HELD, 1e-6),
                              what=f'both joint-state parts at {seconds + HELD} s')
        count = len(self.node._observations)
        self.spots.publish(spot)
        return stamp, count

    def spot(self, x, seconds, sun, shift=(0.0, 0.0, 0.0), quality=SpotObservation.FULL):
        """Return the spot `sun` casts through the lens at joints x, imaged at `seconds`."""
        T_robot_world = self.rig.parameters.T_robot_world
        truth = self.node.estimator.synthetic_observation(
            sun, self.rig.forward(x).T_robot_lens, T_robot_world[:3, 3], T_robot_world[:3, 2])
        centre_world = transform_points(invert_transform(T_robot_world), truth.centre) + shift
        spot = SpotObservation(valid=True, quality=quality)
        spot.header.stamp = stamp_from_seconds(seconds)
        spot.header.frame_id = 'world'
        spot.center.x, spot.center.y, spot.center.z = (float(v) for v in centre_world)
        return spot

    def recorded(self, count):
        """Wait until the node holds more than `count` observations."""
        self.graph.wait_until(lambda: len(self.node._observations) > count,
                              what=f'observation {count} recorded')

    def estimate(self, method='', timeout=30.0):
        """Call estimate_sun; return the response."""
        return self.graph.call(self.client, EstimateSun.Request(method=method), timeout=timeout)


def vector(message):
    """Return a geometry_msgs/Vector3 as an array."""
    return np.array([message.x, message.y, message.z])


def angle_deg(a, b):
    """Return the angle between two unit vectors [deg]."""
    return math.degrees(math.acos(min(1.0, max(-1.0, float(np.dot(a, b))))))


def test_service_estimates_the_sun_from_partial_joint_states_and_publishes_it(graph):
    node, in_process = graph
    rigged = Rigged(node, in_process)
    # A malformed (invalid) spot first: logged and skipped.
    rigged.spots.publish(SpotObservation(valid=False, reason='no spot'))
    start = in_process.helper.get_clock().now().nanoseconds * 1e-9
    for k, x in enumerate(sweep_joints(rigged.rig)):
        rigged.recorded(rigged.observe(x, start + 2.5 * HELD * k, SUN)[1])

    for method in ('levenberg_marquardt', 'interaction_matrix'):
        response = rigged.estimate(method)
        assert response.success, response.message
        assert angle_deg(vector(response.estimate.direction), SUN) < 0.01
        assert response.estimate.method == method and response.estimate.observations >= 3
        assert response.estimate.converged and not response.estimate.ambiguous
        assert response.estimate.fit_chi2 <= response.estimate.fit_threshold
        assert len(response.estimate.observation_stamps) == response.estimate.observations
        assert len(response.estimate.observation_deviation) == response.estimate.observations

    response = rigged.estimate('guess')
    assert not response.success and 'unknown method' in response.message

    # A late subscriber still gets the estimate (transient local), then the Eq 18 updates.
    received = in_process.collect(SunEstimate, 'sun/estimate', TRANSIENT_LOCAL_QOS)
    messages = received.wait_for_count(2)
    assert messages[0].converged and messages[0].header.frame_id == 'robot'
    assert messages[-1].anchor_stamp == messages[0].anchor_stamp


def test_an_outlier_is_named_by_its_stamp_and_an_untrustworthy_estimate_is_not_published(graph):
    node, in_process = graph
    rigged = Rigged(node, in_process)
    estimates = in_process.collect(SunEstimate, 'sun/estimate', TRANSIENT_LOCAL_QOS)
    start = in_process.helper.get_clock().now().nanoseconds * 1e-9
    joints = sweep_joints(rigged.rig, offsets_deg=np.arange(-10.0, 11.0, 2.5))
    # Every spot 1 cm off alternately: no sun fits, nothing may be published.
    for k, x in enumerate(joints):
        rigged.recorded(rigged.observe(x, start + 2.5 * HELD * k, SUN,
                                       shift=(0.0, 0.01 * (-1) ** k, 0.0))[1])
    response = rigged.estimate()
    assert not response.success
    assert 'not trustworthy' in response.message and 'chi-square' in response.message
    assert not response.estimate.converged and response.estimate.reason
    assert response.estimate.fit_chi2 > response.estimate.fit_threshold
    # The same sweep again, right, with one spot 3 cm off: it is left out and named.
    start += 30.0
    stamps = []
    for k, x in enumerate(joints):
        stamp, count = rigged.observe(x, start + 2.5 * HELD * k, SUN,
                                      shift=(0.03, 0.0, 0.0) if k == 4 else (0.0, 0.0, 0.0))
        rigged.recorded(count)
        stamps.append(stamp)
    wild = stamps[4]
    response = in_process.call(rigged.client, EstimateSun.Request(
        max_observations=len(joints)), timeout=30.0)
    assert response.success, response.message
    assert response.estimate.outliers == 1 and list(response.estimate.outlier_stamps) == [wild]
    assert 'standard deviations' in response.estimate.outlier_reasons[0]
    assert 'left out' in response.message
    assert wild not in list(response.estimate.observation_stamps)
    assert angle_deg(vector(response.estimate.direction), SUN) < 0.05
    # the same observations chosen by time: those imaged since the second sweep began
    since = in_process.call(rigged.client, EstimateSun.Request(since=stamps[0]), timeout=30.0)
    assert since.success, since.message
    assert list(since.estimate.observation_stamps) == list(response.estimate.observation_stamps)
    later = in_process.call(rigged.client, EstimateSun.Request(
        since=stamp_from_seconds(start + 1000.0)), timeout=30.0)
    assert not later.success and 'imaged since' in later.message
    # The first thing ever published on sun/estimate is the trustworthy one.
    first = estimates.wait_for_count(1)[0]
    assert first.converged and first.outliers == 1 and first.anchor_stamp == \
        response.estimate.anchor_stamp


def test_a_sweep_over_ten_minutes_gives_the_ephemeris_sun_at_its_middle():
    """
    Spots over ten minutes of simulated time while the sun moves (pysolar at the site).

    The truth is the ephemeris: at each image stamp the sun the world would have, seen from
    a robot whose x axis points 160 deg east of north. The node moves each observation to
    the middle of the sweep by Eq 18; its estimate must be the sun then, and what it
    publishes the sun at the time of publication.
    """
    start = datetime.datetime(2026, 6, 21, 9, 0, tzinfo=datetime.timezone.utc).timestamp()
    heading = math.radians(160.0)
    with InProcessGraph('sun_estimator_time_helper') as in_process:
        node = in_process.add(SunEstimatorNode(**in_process.node_options(
            use_sim_time=True, update_period=0.0, max_observation_age=3600.0)))
        clock = in_process.helper.create_publisher(Clock, '/clock', 10)

        def sun_at(seconds):
            position = sun_position(node.site, datetime.datetime.fromtimestamp(
                seconds, tz=datetime.timezone.utc))
            return direction_from_angles(*ray_angles_from_sun(position, heading))

        rigged = Rigged(node, in_process)
        times = start + np.linspace(0.0, 600.0, 11)
        assert angle_deg(sun_at(times[0]), sun_at(times[-1])) > 1.5     # the sun moved
        joints = sweep_joints(rigged.rig, sun_at(times[5]),
                              offsets_deg=np.linspace(-12.0, 12.0, 11))
        for seconds, x in zip(times, joints):
            rigged.recorded(rigged.observe(x, seconds, sun_at(seconds))[1])
        end = times[-1] + 1.0
        clock.publish(Clock(clock=stamp_from_seconds(end)))
        in_process.wait_until(lambda: node.get_clock().now().nanoseconds * 1e-9 >= end - 1e-6,
                              what='the node on simulated time')
        estimates = in_process.collect(SunEstimate, 'sun/estimate', TRANSIENT_LOCAL_QOS)
        response = rigged.estimate()
        assert response.success, response.message
        estimate = response.estimate
        middle = 0.5 * (times[0] + times[-1])
        assert stamp_to_seconds(estimate.anchor_stamp) == pytest.approx(middle, abs=1e-6)
        assert estimate.header.stamp == estimate.anchor_stamp
        # noise-free spots: the corrected fit is exact; taken as one fixed sun the same spots
        # give their mean direction, 0.012 deg off
        assert angle_deg(vector(estimate.direction), sun_at(middle)) < 0.001
        assert estimate.ephemeris_corrected and estimate.observation_span == pytest.approx(600.0)
        assert '2026-06-21T09:05:00' in response.message and 'Eq 18' in response.message
        published = estimates.wait_for_count(1)[0]
        assert stamp_to_seconds(published.header.stamp) == pytest.approx(end, abs=1e-3)
        assert angle_deg(vector(published.direction), sun_at(end)) < 0.01


def test_only_full_spots_are_used(graph):
    node, in_process = graph
    rigged = Rigged(node, in_process)
    start = in_process.helper.get_clock().now().nanoseconds * 1e-9
    x = sweep_joints(rigged.rig)[0]
    # a spot cut by the image border is not used; the next, full one is
    rigged.observe(x, start, SUN, quality=SpotObservation.CUT_BY_BORDER)
    rigged.recorded(rigged.observe(x, start + 0.1, SUN)[1])
    assert [b.seconds for b in node._observations] == [pytest.approx(start + 0.1)]


def test_a_spot_imaged_while_the_lens_moved_is_left_out_and_counted(graph):
    node, in_process = graph
    rigged = Rigged(node, in_process)
    start = in_process.helper.get_clock().now().nanoseconds * 1e-9
    poses = sweep_joints(rigged.rig)
    for k, x in enumerate(poses):
        rigged.recorded(rigged.observe(x, start + 2.5 * HELD * k, SUN)[1])
    # the lens moves from the last pose to the first; a spot imaged on the way (with the
    # centre the last pose casts: a camera and drivers on skewed clocks) is not paired
    moved_at = start + 2.5 * HELD * len(poses)
    rigged.publish_joints(poses[-1], moved_at)
    rigged.spots.publish(rigged.spot(poses[-1], moved_at + 0.1, SUN))
    in_process.wait_until(lambda: node._pending, what='the spot waiting for later joints')
    assert len(node._observations) == len(poses)
    rigged.publish_joints(0.5 * (poses[-1] + poses[0]), moved_at + 0.2)
    rigged.publish_joints(poses[0], moved_at + 0.5)
    in_process.wait_until(lambda: not node._pending, what='the spot judged')
    assert len(node._observations) == len(poses)
    response = rigged.estimate()
    assert response.success, response.message
    assert response.estimate.observations == len(poses)
    assert '1 while the lens moved' in response.message


def test_a_spot_still_waiting_for_joints_is_judged_on_those_there_when_asked(graph):
    node, in_process = graph
    rigged = Rigged(node, in_process)
    start = in_process.helper.get_clock().now().nanoseconds * 1e-9
    poses = sweep_joints(rigged.rig)
    for k, x in enumerate(poses[:-1]):
        rigged.recorded(rigged.observe(x, start + 2.5 * HELD * k, SUN)[1])
    # the last pose's image 0.1 s before its newest joints: the estimate is asked for at
    # once, before the joints 0.3 s after it come
    last = start + 2.5 * HELD * (len(poses) - 1)
    for seconds in (last - HELD, last):
        rigged.publish_joints(poses[-1], seconds)
    in_process.wait_until(lambda: node.joints.at(last, 1e-6), what='the last joints')
    rigged.spots.publish(rigged.spot(poses[-1], last - 0.1, SUN))
    # and one imaged after every joint sample: its pose is not known yet, it keeps waiting
    rigged.spots.publish(rigged.spot(poses[-1], last + 0.1, SUN))
    in_process.wait_until(lambda: len(node._pending) == 2, what='both spots waiting')
    response = rigged.estimate()
    assert response.success, response.message
    assert response.estimate.observations == len(poses)
    assert [spot.seconds for spot in node._pending] == [pytest.approx(last + 0.1)]
    rigged.publish_joints(poses[-1], last + 0.5)
    in_process.wait_until(lambda: not node._pending, what='the newer spot judged')
    assert rigged.estimate().estimate.observations == len(poses) + 1


def test_a_flood_of_estimate_requests_is_answered_or_refused_every_one(graph):
    # issue 35: of 50 simultaneous requests, 11 were answered within 60 s and 39 never (the
    # service's request queue held 10; the rest were lost)
    node, in_process = graph
    rigged = Rigged(node, in_process)
    start = in_process.helper.get_clock().now().nanoseconds * 1e-9
    for k, x in enumerate(sweep_joints(rigged.rig)):
        rigged.recorded(rigged.observe(x, start + 2.5 * HELD * k, SUN)[1])
    clients = [in_process.helper.create_client(EstimateSun, 'estimate_sun') for _ in range(50)]
    for client in clients:
        in_process.wait_until(client.service_is_ready, what='the service')

    def flood(requests):
        """Send one request from each client at once; return the responses, all answered."""
        def send_all():
            return [client.call_async(request) for client, request in zip(clients, requests)]
        futures = in_process.result_of(in_process.executor.create_task(send_all), 10.0,
                                       'the requests to be sent')
        began = time.monotonic()
        try:
            in_process.wait_until(lambda: all(f.done() for f in futures), 60.0,
                                  'every answer')
        finally:
            print(f'\n{sum(f.done() for f in futures)} of {len(futures)} requests answered in '
                  f'{time.monotonic() - began:.2f} s')
        responses = [f.result() for f in futures]
        assert all(r.message for r in responses)
        for response in responses:
            if response.success:
                assert angle_deg(vector(response.estimate.direction), SUN) < 0.01
            else:
                assert response.message.startswith('busy: '), response.message
        return responses

    # every other request with a limit of its own: 26 fits, 24 answers of the last fit
    limits = [k % 2 * (k // 2 + 3) for k in range(50)]
    responses = flood([EstimateSun.Request(max_observations=n) for n in limits])
    assert all(r.success for r in responses)
    # with fits allowed 5 % of a 2 s window (0.1 s: about one fit), the rest are refused
    node.set_parameters([Parameter('busy_budget', value=0.05),
                         Parameter('busy_window', value=2.0)])
    responses = flood([EstimateSun.Request(max_observations=3 + k) for k in range(50)])
    refused = [r for r in responses if not r.success]
    print(f'{len(responses) - len(refused)} answered, {len(refused)} refused as busy')
    assert 1 <= len(refused) < len(responses)
