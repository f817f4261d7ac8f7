"""servo_driver in-process against the Maestro emulator on a pty."""

import math
import threading
import time

from helio_drivers import maestro_protocol as proto
from helio_drivers.maestro_emulator import CONFIGURED_SETTINGS as CONFIGURED
from helio_drivers.maestro_emulator import MaestroEmulator
from helio_drivers.servo_driver_node import ServoDriverNode
from helio_msgs.action import MoveWrist
from node_harness import ClockPublisher, driver_on, DriverGraph
import pytest
from std_msgs.msg import Header

# yaw reversed and offset, as a mounted servo may be; pitch on channel 3
YAW = proto.ServoCalibration('lens_yaw', 0, min_pulse_us=700.0, max_pulse_us=2300.0,
                             direction=-1, zero_offset=0.1)
PITCH = proto.ServoCalibration('lens_pitch', 3)


class FreezableClock:
    """Monotonic seconds that stand still between freeze() and thaw() (the emulator's clock)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._offset = 0.0
        self._frozen_at = None

    def __call__(self):
        with self._lock:
            if self._frozen_at is not None:
                return self._frozen_at
            return time.monotonic() - self._offset

    def freeze(self):
        with self._lock:
            if self._frozen_at is None:
                self._frozen_at = time.monotonic() - self._offset

    def thaw(self):
        with self._lock:
            if self._frozen_at is not None:
                self._offset = time.monotonic() - self._frozen_at
                self._frozen_at = None


@pytest.fixture
def clock():
    return FreezableClock()


def wrist_parameters(emulator):
    """Return the driver parameters for the emulated wrist (fast, short timeouts)."""
    return {'port': emulator.port_path, 'timeout': 0.1, 'retries': 1,
            'joint_state_rate': 50.0, 'status_period': 0.2,
            'reconnect_initial': 0.05, 'reconnect_max': 0.2,
            'position_tolerance_us': 0.25,
            'yaw.channel': 0, 'yaw.min_pulse_us': 700.0, 'yaw.max_pulse_us': 2300.0,
            'yaw.direction': -1, 'yaw.zero_offset': 0.1,
            'yaw.speed_us_per_s': 4000.0, 'yaw.acceleration_us_per_s2': 40000.0,
            'pitch.channel': 3, 'pitch.speed_us_per_s': 1000.0,
            'pitch.acceleration_us_per_s2': 40000.0}


def wrist_graph(**overrides):
    """Return a function starting servo_driver on an emulator, with parameter overrides."""
    def make_graph(emulator):
        return DriverGraph(ServoDriverNode, MoveWrist, 'move_wrist', 'servo/status',
                           {**wrist_parameters(emulator), **overrides})
    return make_graph


@pytest.fixture
def wrist(clock):
    emulator = MaestroEmulator(calibrations=[YAW, PITCH], clock=clock, **CONFIGURED)
    with driver_on(emulator, wrist_graph()) as emulator_and_graph:
        yield emulator_and_graph


def test_wrist_moves_to_calibrated_angles(wrist):
    emulator, graph = wrist
    feedback = []
    response = graph.run(MoveWrist.Goal(yaw=0.4, pitch=-0.3), feedback=feedback.append)
    assert response.result.success, response.result.message
    # quarter-microsecond resolution: 0.25 us / 636.6 us/rad ~ 0.0004 rad
    assert response.result.achieved_yaw == pytest.approx(0.4, abs=1e-3)
    assert response.result.achieved_pitch == pytest.approx(-0.3, abs=1e-3)
    # independent: the pulse the emulator outputs follows the calibration formula
    pulses = emulator.pulse_widths_us()
    assert pulses[0] == pytest.approx(1500.0 - 0.3 * 2000.0 / math.pi, abs=0.25)
    assert pulses[3] == pytest.approx(1500.0 - 0.3 * 2000.0 / math.pi, abs=0.25)
    assert feedback, 'no feedback during the move'
    assert graph.joint_states.wait_for_count(1)[-1].name == ['lens_yaw', 'lens_pitch']
    assert graph.wait_status(lambda s: s.connected and s.device == 'servo')


def test_an_escape_goal_lifts_the_per_axis_limits_for_its_move_only(wrist):
    emulator, graph = wrist
    configured = [(4000.0, 40000.0), (1000.0, 40000.0)]        # wrist_parameters: yaw, pitch
    assert [emulator.motion_limits()[c] for c in (0, 3)] == configured
    response = graph.run(MoveWrist.Goal(yaw=0.1, pitch=1.2, escape=True))
    assert response.result.success, response.result.message
    # the escape defaults (4000 us/s, unlimited acceleration) on both channels
    assert [emulator.motion_limits()[c] for c in (0, 3)] == [(4000.0, math.inf)] * 2
    assert response.result.achieved_pitch == pytest.approx(1.2, abs=1e-3)
    assert graph.run(MoveWrist.Goal(yaw=0.0, pitch=0.0)).result.success
    assert [emulator.motion_limits()[c] for c in (0, 3)] == configured


def test_out_of_range_angle_is_refused_naming_the_joint(wrist):
    emulator, graph = wrist
    response = graph.run(MoveWrist.Goal(yaw=2.0, pitch=0.0))
    assert not response.result.success and 'lens_yaw' in response.result.message
    assert emulator.pulse_widths_us()[0] == pytest.approx(1500.0)
    for yaw, pitch in ((math.nan, 0.0), (0.0, math.inf)):
        response = graph.run(MoveWrist.Goal(yaw=yaw, pitch=pitch))
        assert not response.result.success
        assert 'not a finite angle' in response.result.message
    assert emulator.pulse_widths_us()[:2] == pytest.approx([1500.0, 1500.0])


def test_cancel_holds_the_servos_mid_move(wrist, clock):
    emulator, graph = wrist
    started = threading.Event()

    def on_feedback(message):
        if message.feedback.current_pitch > 0.1:
            # Stop the emulator's time mid-move, so however late the cancel arrives on a
            # loaded machine, the servo is still on its way to 1.5 rad when it does.
            clock.freeze()
            started.set()
    handle = graph.send(MoveWrist.Goal(yaw=0.1, pitch=1.5), feedback=on_feedback)
    assert started.wait(5.0)
    frozen_pitch = PITCH.angle(emulator.pulse_widths_us()[3])
    assert 0.1 < frozen_pitch < 1.4
    graph.cancel_goal(handle, 10.0)
    response = graph.goal_result(handle, 10.0)
    clock.thaw()
    assert response.status == 5      # GoalStatus.STATUS_CANCELED
    # the new target is where the servo was when cancelled: it stops there, not at 1.5 rad
    held = PITCH.angle(emulator.target_pulse_widths_us()[3])
    assert held == pytest.approx(frozen_pitch, abs=1e-3)
    assert response.result.achieved_pitch == pytest.approx(held, abs=0.05)


def test_unplug_aborts_and_reconnects(wrist):
    emulator, graph = wrist
    response, seconds = graph.unplug_mid_move(
        emulator, MoveWrist.Goal(yaw=0.1, pitch=1.5),
        lambda feedback: feedback.current_pitch > 0.1)
    assert seconds < 0.5
    assert not response.result.success and 'link lost' in response.result.message
    assert graph.wait_status(lambda s: not s.connected)
    # goals fail fast while the port is gone
    response, seconds = graph.timed_run(MoveWrist.Goal(yaw=0.0, pitch=0.0))
    assert not response.result.success and 'not connected' in response.result.message
    assert seconds < 0.5
    assert graph.replug(emulator)
    assert graph.run(MoveWrist.Goal(yaw=0.0, pitch=0.0)).result.success


def test_a_stopped_sim_clock_cannot_hold_a_move_past_its_wall_clock_guard():
    make_graph = wrist_graph(use_sim_time=True, move_timeout=1.0, move_wall_timeout=0.4)
    emulator = MaestroEmulator(calibrations=[YAW, PITCH], **CONFIGURED)
    with driver_on(emulator, make_graph) as (emulator, graph):
        clock = ClockPublisher(graph.node, rate=0.0)        # /clock published, never advancing
        try:
            started = time.monotonic()
            # pitch to 1.5 rad at 1000 us/s: 0.95 s of motion, longer than the 0.4 s guard
            response = graph.run(MoveWrist.Goal(yaw=0.1, pitch=1.5))
            wall = time.monotonic() - started
            assert not response.result.success
            assert 'within 0.40 s of wall time' in response.result.message
            assert '/clock' in response.result.message
            assert 0.4 < wall < 5.0
            # held short of the target, where it was
            held = PITCH.angle(emulator.target_pulse_widths_us()[3])
            assert held < 1.4
            assert response.result.achieved_pitch == pytest.approx(held, abs=0.05)
        finally:
            clock.stop()


def test_an_unexpected_error_aborts_the_goal_holds_the_servos_and_the_driver_goes_on(wrist):
    emulator, graph = wrist
    poll_move = graph.driver.poll_move
    calls = []

    def failing_once(move):
        calls.append(move)
        if len(calls) == 3:
            raise RuntimeError('injected bug')
        return poll_move(move)
    graph.driver.poll_move = failing_once
    response = graph.run(MoveWrist.Goal(yaw=0.1, pitch=1.5))
    assert not response.result.success
    # (the hold may take a second attempt: the servo moved on between reading and holding)
    assert response.result.message.startswith('driver error, move aborted: injected bug; '
                                              'servos held where they were (confirmed)')
    held = PITCH.angle(emulator.target_pulse_widths_us()[3])
    assert held < 1.4                       # held where it was, not left moving to 1.5
    response = graph.run(MoveWrist.Goal(yaw=0.0, pitch=0.2))
    assert response.result.success, response.result.message


# ---- issue 17: a factory-new Maestro, a silent device ---------------------------------------

def test_a_factory_maestro_shows_no_bogus_angle_and_its_limit_fails_fast_then_refuses():
    # A new Maestro sends no pulses and limits each channel to 992..2000 us; the driver is
    # configured for 500..2500 us (yaw 700..2300 us).
    emulator = MaestroEmulator(calibrations=[YAW, PITCH])          # factory settings
    with driver_on(emulator, wrist_graph()) as (emulator, graph):
        assert graph.wait_status(lambda s: 'lens_pitch (Maestro channel 3) sends no pulses'
                                 in s.message)
        graph.statuses.wait_for_count(len(graph.statuses.messages) + 2)   # 0.4 s on
        assert graph.joint_states.messages == []       # no angle while the servos are limp
        # within the factory range: works, and the joints appear
        response = graph.run(MoveWrist.Goal(yaw=0.1, pitch=0.5))          # pitch 1818 us
        assert response.result.success, response.result.message
        names = graph.joint_states.wait_for_message(lambda m: len(m.name) == 2).name
        assert names == ['lens_yaw', 'lens_pitch']
        # beyond it (pitch 1.2 rad = 2264 us): the device stops at 2000 us; no 10 s timeout
        response, seconds = graph.timed_run(MoveWrist.Goal(yaw=0.1, pitch=1.2))
        assert not response.result.success and seconds < 2.0
        message = response.result.message
        assert 'lens_pitch: the Maestro stopped at 2000.0 us, short of the target 2264.0 us' \
            in message
        assert 'factory-new Maestro allows 992..2000 us' in message and 'Min and Max' in message
        assert emulator.pulse_widths_us()[3] == pytest.approx(2000.0)
        # the limit is remembered: the next goal beyond it is refused before anything moves
        before = emulator.target_pulse_widths_us()
        response = graph.run(MoveWrist.Goal(yaw=0.1, pitch=1.0))          # 2137 us
        assert not response.result.success
        assert 'beyond the 0.0..2000.0 us the Maestro allows on channel 3' in \
            response.result.message
        assert emulator.target_pulse_widths_us() == before


def test_noise_on_the_line_never_puts_an_impossible_angle_on_joint_states(wrist):
    # issue 35: random bytes read as Get Position replies (the compact protocol has no
    # checksum) put wrist angles up to 22.7 rad on /joint_states (16 of 118 values). Here 7
    # random bytes come before a fifth of the replies, while the wrist is held and moves
    emulator, graph = wrist
    assert graph.run(MoveWrist.Goal(yaw=0.2, pitch=-0.2)).result.success
    heard = len(graph.joint_states.messages)
    emulator.inject(garbage_rate=0.2)
    graph.joint_states.wait_for_count(heard + 60, 20.0)
    held = graph.joint_states.messages[heard:]
    moved = graph.run(MoveWrist.Goal(yaw=-0.3, pitch=0.4))
    emulator.clear_faults()
    assert moved.result.success, moved.result.message
    # held: every published angle is the held one (quarter-us resolution ~ 0.0004 rad)
    for message in held:
        assert list(message.position) == pytest.approx([0.2, -0.2], abs=1e-3), message
    # moving: every angle between where the servo was and where it went
    for message in graph.joint_states.messages[heard + len(held):]:
        yaw, pitch = message.position
        assert -0.3 - 1e-3 <= yaw <= 0.2 + 1e-3 and -0.2 - 1e-3 <= pitch <= 0.4 + 1e-3
    driver = graph.driver
    print(f'\n{driver.client.impossible_replies} impossible replies and '
          f'{driver.readings_dropped} possible ones dropped; {len(held)} joint states held')
    assert driver.client.impossible_replies + driver.readings_dropped > 0
    assert graph.wait_status(lambda s: s.connected and 'dropped as not the' in s.message)


def test_a_device_silent_mid_move_aborts_and_holds_the_servos_when_it_answers(wrist, clock):
    emulator, graph = wrist
    started = threading.Event()

    def on_feedback(message):
        if message.feedback.current_pitch > 0.1:
            clock.freeze()              # mid-move, however late the test reacts
            emulator.inject(deaf=True)
            started.set()
    handle = graph.send(MoveWrist.Goal(yaw=0.1, pitch=1.5), feedback=on_feedback)
    assert started.wait(5.0)
    threading.Timer(0.4, emulator.clear_faults).start()    # the length of the fault
    response = graph.goal_result(handle, 10.0)
    clock.thaw()
    assert not response.result.success
    assert 'servo controller silent, move aborted' in response.result.message
    assert 'stopped as soon as it answers again' in response.result.message
    # the reconnection holds the servos where they are
    heard = len(graph.statuses.messages)
    graph.statuses.wait_until(lambda m: any(s.connected for s in m[heard:]), 5.0,
                              'the servo controller connected again')
    # the target is where the servo was (to the protocol's quarter microsecond), not 1.5 rad
    target_us, position_us = emulator.target_pulse_widths_us()[3], emulator.pulse_widths_us()[3]
    assert 0.1 < PITCH.angle(target_us) < 1.4
    assert target_us == pytest.approx(position_us, abs=0.25)


@pytest.fixture
def patient_wrist(clock):
    """
    Start the wrist with a heating guard of 1 s on both clocks (shipped: 0.15 s, 0.3 s).

    The test's beats come from the test process, which a loaded machine can pause for more
    than 0.3 s between two beats: the guard then rightly fired mid-beating (fresh run s46a).
    """
    emulator = MaestroEmulator(calibrations=[YAW, PITCH], clock=clock, **CONFIGURED)
    with driver_on(emulator, wrist_graph(heating_guard_timeout=1.0,
                                         heating_guard_timeout_wall=1.0)) as emulator_and_graph:
        yield emulator_and_graph


def test_the_lens_planner_silent_while_heating_turns_the_lens_off_the_sun_and_clear_does_not(
        patient_wrist):
    # issue 30: a lens planner that dies with the lens at the heating distance cannot
    # retreat it; its lens/heating beats stop without a 'clear', and the driver turns the
    # lens pitch emergency_turn (0.6 rad) off the sun by itself, within the guard's
    # timeouts (here 1 s on both clocks; no /clock here: both are the wall)
    emulator, graph = patient_wrist
    assert graph.run(MoveWrist.Goal(yaw=0.2, pitch=-0.2)).result.success
    beats = graph.helper.create_publisher(Header, 'lens/heating', 10)

    def pitch_now():
        return graph.joint_states.wait_for_count(len(graph.joint_states.messages) + 1)[-1] \
            .position[1]

    def beat(frame_id, count):
        for _ in range(count):
            beats.publish(Header(frame_id=frame_id))
            graph.joint_states.wait_for_count(len(graph.joint_states.messages) + 1)
    # beats, then 'clear': the lens left the heating distance as planned; nothing moves
    beat('heating', 10)
    beat('clear', 1)
    held_until = time.monotonic() + 1.0
    while time.monotonic() < held_until:
        assert pitch_now() == pytest.approx(-0.2, abs=1e-3)
    # beats, then silence: the lens is turned away, and later goals are still taken
    beat('heating', 10)
    silent_at = time.monotonic()
    graph.joint_states.wait_for_message(lambda m: abs(m.position[1] + 0.2) >= 0.59, 5.0)
    print(f'\nturned 0.6 rad {time.monotonic() - silent_at:.2f} s (wall) after the last beat')
    assert time.monotonic() - silent_at >= 0.9      # not before the guard's 1 s
    assert graph.driver.heating_guard.armed is False
    assert graph.wait_status(lambda s: s.connected)
    assert graph.run(MoveWrist.Goal(yaw=0.0, pitch=0.0)).result.success
    graph.helper.destroy_publisher(beats)


def test_the_heating_guard_lets_an_escape_goal_already_running_finish(clock):
    # the painter's wrist escape (the lens planner dead, the arm not answering) and the
    # guard act on the same silence: aborting the escape would stop the lens on its way
    # off the sun (seen in a fresh run: the painter then reported RETREAT FAILED)
    emulator = MaestroEmulator(calibrations=[YAW, PITCH], clock=clock, **CONFIGURED)
    with driver_on(emulator, wrist_graph(escape_speed_us_per_s=200.0)) as (_, graph):
        assert graph.run(MoveWrist.Goal(yaw=0.2, pitch=-0.2)).result.success
        beats = graph.helper.create_publisher(Header, 'lens/heating', 10)
        for _ in range(10):
            beats.publish(Header(frame_id='heating'))
            graph.joint_states.wait_for_count(len(graph.joint_states.messages) + 1)
        escape = graph.send(MoveWrist.Goal(yaw=0.2, pitch=0.4, escape=True))  # ~2 s
        result = graph.goal_result(escape, 10.0).result
        assert result.success, result.message
        assert not graph.driver.heating_guard.armed        # the guard fired meanwhile
        graph.joint_states.wait_for_message(lambda m: abs(m.position[1] - 0.4) < 1e-3, 5.0)
