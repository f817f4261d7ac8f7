"""JointStateBuffer: partial messages merged by name, lookups at a stamp, staleness."""

import math

from helio_optics.node_kit.conversions import stamp_from_seconds
from helio_optics.node_kit.joint_states import JointStateBuffer
from helio_optics.rig_kinematics import JOINT_NAMES
import numpy as np
import pytest
from sensor_msgs.msg import JointState

ARM = ('dobot_j1', 'dobot_j2', 'dobot_j3', 'dobot_j4')
WRIST = ('lens_yaw', 'lens_pitch')


def moving_joints(t):
    """Joints x(t) of a move at constant joint speeds (the truth lookups are held against)."""
    return np.array([0.1, 0.5, 0.3, -0.2, 0.4]) + t * np.array([0.2, -0.1, 0.05, 0.3, -0.15])


def feed_drivers(buffer, times_arm, times_wrist):
    """Feed the buffer as the two drivers do: arm and wrist parts on their own stamps."""
    for t in times_arm:
        x = moving_joints(t)
        buffer.add(t, ARM, [x[0], x[1], x[2], 0.0])
    for t in times_wrist:
        buffer.add(t, WRIST, moving_joints(t)[3:])


def test_partial_messages_merge_into_the_five_joints():
    buffer = JointStateBuffer()
    buffer.add(10.0, ARM, [0.1, 0.2, 0.3, 0.0])
    lookup = buffer.at(10.0, 0.1)
    assert not lookup and 'lens_yaw' in lookup.reason       # the wrist has not spoken yet
    buffer.add(10.0, WRIST, [0.4, 0.5])
    assert buffer.at(10.0, 0.0).positions.tolist() == [0.1, 0.2, 0.3, 0.4, 0.5]
    assert buffer.names == JOINT_NAMES


def test_lookup_interpolates_a_move_between_the_drivers_own_stamps():
    buffer = JointStateBuffer()
    # 20 Hz from the arm, 20 Hz from the wrist, offset by 23 ms, pairs arriving swapped
    arm_times = np.arange(0.0, 2.0, 0.05)
    wrist_times = np.arange(0.023, 2.0, 0.05).reshape(-1, 2)[:, ::-1].ravel()
    feed_drivers(buffer, arm_times, wrist_times)
    for t in (0.5, 0.517, 1.26, 1.949):
        lookup = buffer.at(t, 0.06)
        assert lookup, lookup.reason
        assert lookup.positions == pytest.approx(moving_joints(t), abs=1e-12)
        assert lookup.gap <= 0.05


def test_a_joint_farther_than_the_tolerance_fails_the_lookup_naming_it():
    buffer = JointStateBuffer()
    feed_drivers(buffer, [0.0, 0.05, 0.10], [0.0])
    lookup = buffer.at(0.10, 0.05)
    assert not lookup
    assert 'lens_yaw' in lookup.reason and '0.100 s' in lookup.reason
    assert lookup.gap == pytest.approx(0.10)
    # past the newest sample of each joint but within the tolerance: the newest values
    feed_drivers(buffer, [], [0.10])
    lookup = buffer.at(0.13, 0.05)
    assert lookup.positions == pytest.approx(moving_joints(0.10), abs=1e-12)
    assert lookup.gap == pytest.approx(0.03)


def still_then_moving(buffer, times, start_moving):
    """Feed samples of an arm held at moving_joints(0) until `start_moving` [s], then moving."""
    for t in times:
        x = moving_joints(max(0.0, t - start_moving))
        buffer.add(t, ARM, [x[0], x[1], x[2], 0.0])
        buffer.add(t, WRIST, x[3:])


def test_a_joint_at_rest_is_known_across_gaps_up_to_rest_hold():
    # joint states every 0.4 s of the stamps' clock (20 Hz of wall time beside a world at
    # 8x), the arm still until 2.0 s: an image between two equal samples has their pose
    buffer = JointStateBuffer()
    still_then_moving(buffer, [0.0, 0.4, 0.8, 1.2, 1.6, 2.0, 2.4], start_moving=2.0)
    assert not buffer.at(1.0, 0.1)                                 # the plain tolerance
    lookup = buffer.at(1.0, 0.1, rest_hold=0.5)
    assert lookup.positions == pytest.approx(moving_joints(0.0), abs=1e-12)
    assert lookup.gap == pytest.approx(0.2)
    # between two different samples the arm moved: no pose, whatever the hold
    lookup = buffer.at(2.2, 0.1, rest_hold=0.5)
    assert not lookup and 'at rest 0.5 s' in lookup.reason
    # and a gap longer than the hold is not bridged
    assert not buffer.at(1.0, 0.1, rest_hold=0.15)


def test_an_image_newer_than_the_joint_states_has_the_pose_of_an_arm_at_rest():
    buffer = JointStateBuffer()
    still_then_moving(buffer, [0.0, 0.4, 0.8], start_moving=10.0)
    lookup = buffer.at(1.1, 0.1, rest_hold=0.5)                   # 0.3 s after the newest
    assert lookup.positions == pytest.approx(moving_joints(0.0), abs=1e-12)
    assert not buffer.at(1.4, 0.1, rest_hold=0.5)                 # past the hold
    # the newest two samples differ: the arm was moving, its pose now is unknown
    moving = JointStateBuffer()
    still_then_moving(moving, [0.0, 0.4, 0.8], start_moving=0.5)
    assert not moving.at(1.1, 0.1, rest_hold=0.5)
    # one sample says nothing about rest
    single = JointStateBuffer()
    still_then_moving(single, [0.0], start_moving=10.0)
    assert not single.at(0.3, 0.1, rest_hold=0.5)


def test_still_at_takes_an_image_only_with_the_joints_unchanged_around_it():
    # 20 Hz of joint states, the arm held until 2.0 s, then moving
    buffer = JointStateBuffer()
    times = np.arange(0.0, 3.0, 0.05)
    still_then_moving(buffer, times, start_moving=2.0)
    lookup = buffer.still_at(1.0, 0.3, 1.0)
    assert lookup.positions == pytest.approx(moving_joints(0.0), abs=1e-12)
    # 0.1 s before the move: the margin of 0.3 s sees it, whichever clock was late
    lookup = buffer.still_at(1.9, 0.3, 1.0)
    assert not lookup and not lookup.waiting and lookup.moving
    assert lookup.reason.startswith('moving: dobot_j1 changed by')
    # the plain lookup pairs a moving image with some joints: the pose of another instant
    assert buffer.at(2.5, 0.3)
    assert not buffer.still_at(2.5, 0.3, 1.0)


def test_still_at_waits_for_the_joints_after_the_image_then_decides():
    buffer = JointStateBuffer()
    still_then_moving(buffer, np.arange(0.0, 1.05, 0.05), start_moving=10.0)
    lookup = buffer.still_at(0.9, 0.3, 1.0)          # the newest sample is at 1.0 s
    assert not lookup and lookup.waiting and 'after the image yet' in lookup.reason
    # nothing more will come: the newest sample, after the image, stands for them
    assert buffer.still_at(0.9, 0.3, 1.0, complete=True).positions == pytest.approx(
        moving_joints(0.0), abs=1e-12)
    # but not an image newer than every sample: that one still waits
    lookup = buffer.still_at(1.1, 0.3, 1.0, complete=True)
    assert not lookup and lookup.waiting and 'no dobot_j1 sample after' in lookup.reason
    still_then_moving(buffer, [1.25], start_moving=10.0)
    assert buffer.still_at(0.9, 0.3, 1.0)


def test_still_at_bridges_gaps_up_to_the_hold_and_needs_history_before_the_image():
    buffer = JointStateBuffer()
    still_then_moving(buffer, [0.0, 0.6, 1.2], start_moving=10.0)
    assert buffer.still_at(0.6, 0.3, 0.7).gap == pytest.approx(0.6)
    lookup = buffer.still_at(0.6, 0.3, 0.5)
    assert not lookup and not lookup.moving and 'hold 0.5 s' in lookup.reason
    lookup = buffer.still_at(0.2, 0.3, 1.0)
    assert not lookup and not lookup.waiting and 'before the image' in lookup.reason
    assert JointStateBuffer().still_at(0.0, 0.3, 1.0).waiting     # nothing received yet


def test_latest_is_refused_when_a_driver_went_quiet():
    buffer = JointStateBuffer()
    feed_drivers(buffer, [1.0, 2.0, 3.0], [1.0])
    lookup = buffer.latest(now=3.1, max_age=0.5)
    assert not lookup and 'lens_yaw last received 2.100 s ago' in lookup.reason
    assert buffer.latest(now=3.1, max_age=0.0)       # 0: any age
    buffer.add(3.05, WRIST, [0.0, 0.0])
    assert buffer.latest(now=3.1, max_age=0.5).positions[3:].tolist() == [0.0, 0.0]


def test_latest_forgives_an_old_stamp_while_the_driver_is_heard_on_the_wall_clock():
    # a world 20x faster than real time: the wrist driver's last message, 0.3 s of wall time
    # ago, is 6 s old on the simulated clock; the arm's came 2 s of wall time ago
    buffer = JointStateBuffer()
    buffer.add(100.0, WRIST, [0.1, 0.2], received=50.0)
    buffer.add(105.5, ARM, [0.0] * 4, received=48.3)
    fresh = buffer.latest(now=106.0, max_age=5.0, wall_now=50.3, max_wall_age=1.0)
    assert fresh and fresh.positions[3:].tolist() == [0.1, 0.2]
    assert fresh.gap == pytest.approx(6.0)
    # silent on both clocks: stale, saying both ages
    lookup = buffer.latest(now=106.0, max_age=5.0, wall_now=51.5, max_wall_age=1.0)
    assert not lookup
    assert lookup.reason == ('lens_yaw last received 6.000 s ago (limit 5 s) and 1.500 s of '
                             'wall time ago (limit 1 s)')
    # young on the stamps' clock: fresh whatever the wall clock says (a paused world)
    assert buffer.latest(now=104.0, max_age=5.0, wall_now=60.0, max_wall_age=1.0)
    # without receipt times or a wall limit: the stamps' clock alone
    assert not buffer.latest(now=106.0, max_age=5.0, wall_now=50.3)
    assert not buffer.latest(now=106.0, max_age=5.0)
    untimed = JointStateBuffer()
    feed_drivers(untimed, [100.0], [100.0])
    assert not untimed.latest(now=106.0, max_age=5.0, wall_now=50.3, max_wall_age=1.0)
    buffer.clear()
    buffer.add(100.0, JOINT_NAMES, [0.0] * 5)            # receipts forgotten with the samples
    assert not buffer.latest(now=106.0, max_age=5.0, wall_now=50.3, max_wall_age=1.0)


def test_non_finite_positions_are_skipped_and_said():
    buffer = JointStateBuffer()
    problem = buffer.add(1.0, ('dobot_j1', 'lens_yaw'), [math.nan, 0.2])
    assert 'dobot_j1 = nan' in problem
    assert buffer.add(1.0, ('lens_pitch',), []) == \
        'joint state partly skipped: 1 names but 0 positions'
    assert 'non-finite stamp' in buffer.add(math.inf, ARM, [0.0] * 4)
    assert buffer.latest(1.0).reason == 'no dobot_j1 received yet'


def test_a_clock_that_jumps_back_clears_the_history():
    buffer = JointStateBuffer(restart_jump=1.0)
    feed_drivers(buffer, [100.0, 100.05], [100.0, 100.05])
    assert buffer.at(100.05, 0.01)
    feed_drivers(buffer, [0.0], [0.0])                    # a simulation restarted at 0
    assert not buffer.at(100.05, 0.01)
    assert buffer.at(0.0, 0.0).positions == pytest.approx(moving_joints(0.0), abs=1e-12)
    assert buffer.newest_stamp() == 0.0


def test_history_older_than_its_span_is_dropped_but_the_newest_kept():
    buffer = JointStateBuffer(history=1.0)
    feed_drivers(buffer, np.arange(0.0, 5.0, 0.1), [0.0])
    assert not buffer.at(1.0, 0.01)                       # dropped
    assert buffer.at(4.9, 10.0).positions[0] == pytest.approx(moving_joints(4.9)[0])
    lookup = buffer.latest(now=5.0)
    assert lookup.positions[3] == pytest.approx(moving_joints(0.0)[3])


def test_a_joint_state_message_is_read_from_its_header_stamp():
    buffer = JointStateBuffer()
    message = JointState(name=list(WRIST), position=[0.25, -0.5])
    message.header.stamp = stamp_from_seconds(1700000000.5)
    assert buffer.add_message(message) == ''
    buffer.add(1700000000.5, ARM, [0.0, 0.1, 0.2, 0.0])
    assert buffer.at(1700000000.5, 0.0).positions.tolist() == [0.0, 0.1, 0.2, 0.25, -0.5]


def test_reaches_a_stamp_when_every_joint_heard_of_has_a_sample_there_or_later():
    buffer = JointStateBuffer()
    assert not buffer.reaches(0.0)                        # nothing heard yet
    feed_drivers(buffer, [1.0, 1.05], [1.0])              # the wrist lags behind the arm
    assert buffer.reaches(1.0) and not buffer.reaches(1.02)
    feed_drivers(buffer, [], [1.05])
    assert buffer.reaches(1.05) and not buffer.reaches(1.06)
    only_arm = JointStateBuffer()
    feed_drivers(only_arm, [2.0], [])                     # a wrist never heard of
    assert only_arm.reaches(2.0)                          # is not waited for
