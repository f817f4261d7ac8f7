"""
The painter when things go wrong, in the whole simulated graph (every node its own process).

Issue 13's cases, each started in the middle of a dot's heating and judged by the simulated
world's ground truth (``sim/truth/light``: the peak irradiance the lens puts on the panel,
and ``sim/canvas``: the char map), never by what the painter says about itself:

- a complete 30 s cloud (``cloud_schedule`` set on ``sim_world`` at run time) is waited out
  and the dot is finished to its N_p target;
- a stale thermal stream (the thermal camera unplugged: ``unplugged`` on ``sim_world``), an
  unplugged Dobot (its pty closes as on a USB unplug) and a cancel each put the focus off
  the wood within 0.5 s of simulated time;
- the painter killed (SIGKILL) mid-painting: the lens planner's focus lease puts the focus
  off the wood within the lease (1 s) plus 0.5 s, and the same goal sent again to a new
  painter completes the picture with no dot lost and none burnt twice;
- the emergency stop (``emergency_stop``, std_srvs/Trigger, the servo driver's) called
  mid-dot (issue 30): the focus off the wood within 0.3 s, no char grows after, and every
  goal is refused naming the stop (the painter's, the lens planner's, the arm's, the
  wrist's) until ``helio reset`` (the command, in its own process) releases it;
- the lens planner killed (SIGKILL) mid-dot, then the painting cancelled (as the graph's
  stop does): the painter's retreat is not accepted by the dead planner, and the wrist turns
  the lens away within 0.5 s (issue 30: the painter used to wait 60 s for the planner);
- last, the whole graph stopped mid-dot as ``helio sim`` and ``helio rig`` stop it on Ctrl-C
  or SIGTERM (``ProcessGroup.stop``: the painter first, its painting ending as a cancel does,
  then the lens planner, which retreats a lens still at the heating distance, and only then
  the drivers, the perception nodes and the world): the focus off the wood within 0.5 s
  (issue 30; before, every node got the signal at once and the lens stayed where it was).

All in one graph, in this order (a graph of its own would start, calibrate robot-world and
sweep for the sun again: the emergency stop's and the graph stop's own modules took 46 s and
38 s of the suite); each test leaves the graph as it found it, but the last.

The world runs as fast as it can between the events and at half real time around each
(``EVENT_PACE``), so that the measured reaction is the graph's and not the pace of the
simulation: free, a world 50x faster than real time turns a 0.1 s wall-clock reaction into 5 s
of simulated time. Half, not real time: on this 2-core machine the graph shares the CPU with
the world's own simulation and with whatever else the machine runs (CI), and at real time
the graph's wall-clock hops (test -> painter -> lens planner -> drivers -> emulators) took
0.3-0.7 s under two busy processes, against 0.05 s alone. The bounds are on simulated time,
in which the arm's retreat itself takes 0.2-0.3 s.
"""

import math
import signal
import subprocess
import sys
import threading

from action_msgs.msg import GoalStatus
from conftest import graph_of_processes
from geometry_msgs.msg import Point
from helio_control.run_journal import read_journal
from helio_drivers.sim.world import charred_dots_of, SimSettings
from helio_msgs.action import FocusLens, MoveArm, MoveWrist, PaintPattern
from helio_msgs.msg import DeviceStatus, LightTruth, ThermalStats
from helio_optics.node_kit.conversions import image_to_numpy, stamp_to_seconds
from helio_optics.node_kit.in_process_graph import GraphTimeout, TRANSIENT_LOCAL_QOS
import numpy as np
import pytest
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Image, JointState
from std_srvs.srv import Trigger

NODES = ('sim_world', 'dobot_driver', 'servo_driver', 'spot_detector', 'thermal_monitor',
         'sun_estimator', 'lens_planner', 'painter')
TIMEOUT = 900.0
PITCH = 0.008                 # between dots [m]: outside each other's hot region
# Rows at world y >= 0.07: below it, at this sun, the servo yaw limit forces the wrist branch
# whose thermal camera grazes the panel from 3 cm up, where N_p (a pixel count) stays ~12.
OFF_BOUND = 0.5               # issue 13: focus off the wood within this [s of sim time]
# The focus is off the wood when the peak irradiance on the panel is below this share of
# the peak while heating (the 3 cm retreat spreads the light over ~20x the area).
OFF_SHARE = 0.25
THERMAL_STALE = 0.5           # the painter's default thermal_stale [s]
TRAVEL_D_LP = 0.112           # the painter's travel distance over the wood [m]: no heat
EMERGENCY_BOUND = 0.3         # issue 30: the emergency stop's focus off the wood [s of sim time]
ANSWER_TIMEOUT = 60.0         # [s] wall, a loaded machine
END_TIMEOUT = 120.0           # [s] wall: a goal ending on a dead driver (1 s of silence)
HELIO = [sys.executable, '-m', 'helio_control.cli']
EVENT_PACE = 0.5              # the world's real-time factor around each event (see above)
ENDED = (GoalStatus.STATUS_SUCCEEDED, GoalStatus.STATUS_CANCELED, GoalStatus.STATUS_ABORTED)


def dots_along(y, count, x=0.05):
    """Return `count` world points along x from `x` at height y [m]."""
    return [Point(x=x + i * PITCH, y=y, z=0.0) for i in range(count)]


class Rig:
    """The test's handles on the running graph: the world's controls and truths, /paint."""

    def __init__(self, group, graph, runs):
        """Subscribe to the truths and the devices; connect to /paint."""
        self.group, self.graph, self.runs = group, graph, runs
        self.handles = []            # the goals sent by the present test
        self.world = AsyncParameterClient(graph.helper, 'sim_world')
        self.clock = graph.collect(Clock, '/clock', QoSProfile(depth=10))
        self.light = graph.collect(LightTruth, 'sim/truth/light',
                                   QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE))
        self.stats = graph.collect(ThermalStats, 'thermal/stats', QoSProfile(depth=50))
        self.dobot = graph.collect(DeviceStatus, 'dobot/status', TRANSIENT_LOCAL_QOS)
        self.joints = graph.collect(JointState, 'joint_states', QoSProfile(depth=50))
        self.canvas = graph.collect(Image, 'sim/canvas', QoSProfile(depth=1))
        self.client = graph.action_client(PaintPattern, 'paint', 120.0)
        self.focus = graph.action_client(FocusLens, 'focus', 120.0)
        settings = SimSettings()
        self.start = settings.start_datetime().timestamp()     # the world's time zero
        self.origin = (settings.panel_extent[0], settings.panel_extent[2])
        self.cell = settings.grid.fine_cell

    def process(self, label):
        """Return the NodeProcess of the node `label`."""
        return next(p for p in self.group.processes if p.label == label)

    def set_world(self, **values):
        """Set sim_world parameters at run time; fail on a refusal."""
        self.graph.wait_until(self.world.services_are_ready, 60.0, 'sim_world parameters')
        response = self.graph.on_executor(
            lambda: self.world.set_parameters([Parameter(k, value=v) for k, v in values.items()]),
            60.0, 'the parameter response')
        for name, result in zip(values, response.results):
            assert result.successful, f'{name}: {result.reason}'

    def now(self):
        """Return the latest simulated time seen on /clock (epoch seconds)."""
        self.clock.wait_for_count(1, 60.0)
        return stamp_to_seconds(self.clock.messages[-1].clock)

    def wait_sim(self, seconds):
        """Wait until /clock has advanced by `seconds` of simulated time."""
        self.wait_sim_until(self.now() + seconds, f'{seconds} s further')

    def wait_sim_until(self, until, what=''):
        """Wait until /clock reaches `until` (epoch seconds)."""
        self.clock.wait_until(lambda m: m and stamp_to_seconds(m[-1].clock) >= until, 60.0,
                              f'/clock to pass {what or until}')

    def send(self, points, name, fresh=True, on_feedback=None):
        """Send a PaintPattern goal for `points`; return its accepted handle."""
        goal = PaintPattern.Goal(points=points, fresh=fresh, run_dir=str(self.runs / name)
                                 if name else '')
        handle = self.graph.send_goal(self.client, goal, on_feedback, 60.0)
        assert handle.accepted
        self.handles.append(handle)
        return handle

    def tidy(self):
        """After a test: cancel a painting it left running, and set the world back."""
        try:
            for handle in self.handles:
                if handle.status not in ENDED:
                    self.graph.cancel_goal(handle, 60.0)
                    self.graph.goal_result(handle, TIMEOUT)
        finally:
            self.handles.clear()
            self.set_world(real_time_factor=0.0, unplugged=[''])

    def assert_no_char_grows(self, seconds=3.0):
        """Assert that the char map `seconds` of sim time from now is the char map now."""
        burnt = self.charred_dots()
        self.wait_sim(seconds)
        assert [round(d.area, 9) for d in self.charred_dots()] == \
            [round(d.area, 9) for d in burnt]

    def heating(self, index=0, n_p=5):
        """Return (feedback callback, event set once dot `index` heats with N_p >= n_p)."""
        event = threading.Event()

        def on_feedback(message):
            feedback = message.feedback
            if feedback.phase == 'heating' and feedback.index == index and feedback.n_p >= n_p:
                event.set()
        return on_feedback, event

    def wait(self, event, what, handle):
        """Wait for `event` (set by a feedback callback) while the goal of `handle` runs."""
        self.graph.wait_until(lambda: event.is_set() or handle.status in ENDED, TIMEOUT, what)
        if not event.is_set():
            result = self.graph.goal_result(handle, 60.0).result
            raise AssertionError(f'the goal ended before {what}: {result.message}\n'
                                 + self.logs(('painter', 'lens_planner')))

    def logs(self, labels=('painter', 'lens_planner', 'dobot_driver', 'servo_driver')):
        """Return the last log lines of the nodes `labels` (for a failure's message)."""
        return '\n'.join(f'{p.label}:\n{p.tail()}' for p in self.group.processes
                         if p.label in labels)

    def heating_peak(self):
        """Return the highest peak irradiance on the panel seen so far [W/m^2]."""
        return max(m.peak_irradiance for m in self.light.messages)

    def off_after(self, since, reference):
        """Return the first sim time after `since` at which the focus is off the wood."""
        first = self.light.wait_for_message(
            lambda m: stamp_to_seconds(m.header.stamp) >= since
            and m.peak_irradiance < OFF_SHARE * reference, 60.0)
        return stamp_to_seconds(first.header.stamp), first.peak_irradiance / reference

    def charred_dots(self):
        """Return the world's charred dots from a sim/canvas image published after now."""
        already = len(self.canvas.messages)
        image = image_to_numpy(self.canvas.wait_for_count(already + 1, 60.0)[already])
        return charred_dots_of(np.flipud(image) <= 127, self.origin, self.cell)


@pytest.fixture(scope='module')
def rig(tmp_path_factory):
    """Run the whole graph once for the module; the painter may be killed by a test."""
    tmp_path = tmp_path_factory.mktemp('safety')
    # pace_max_lag 0: paced around the events (and at the lockstep fallback's 1x while the
    # thermal monitor is stopped), the world must not race to catch up, which would stretch
    # the graph's wall-clock reaction over more simulated seconds
    overrides = {'sim_world': {'real_time_factor': 0.0, 'flux_rays': 20000,
                               'canvas_rate': 1.0, 'truth_period': 0.05, 'pace_max_lag': 0.0},
                 'lens_planner': {'calibration_dir': str(tmp_path / 'calibration')},
                 'painter': {'runs_dir': str(tmp_path / 'runs')}}
    with graph_of_processes(tmp_path, NODES, overrides,
                            may_die=('painter', 'lens_planner')) as (group, graph):
        yield Rig(group, graph, tmp_path / 'runs')


@pytest.fixture(autouse=True)
def tidy(rig):
    """Isolate the tests sharing the graph: none leaves a painting or an event behind."""
    yield
    if rig.group.processes and all(p.alive() for p in rig.group.processes):
        rig.tidy()


def nearest(dots, target, radius=1.5e-3):
    """Return the charred dot nearest `target` within `radius` [m], or None."""
    near = [d for d in dots if math.hypot(d.x - target.x, d.y - target.y) <= radius]
    return min(near, key=lambda d: math.hypot(d.x - target.x, d.y - target.y), default=None)


def test_a_30_s_cloud_mid_dot_is_waited_out_and_the_dot_finished_to_its_target(rig):
    targets = dots_along(0.07, 2)
    heating, mid_dot = rig.heating(index=0, n_p=15)
    waiting, back = threading.Event(), threading.Event()

    def on_feedback(message):
        heating(message)
        if message.feedback.phase == 'waiting_for_sun':
            waiting.set()
        elif waiting.is_set():
            back.set()
    handle = rig.send(targets, 'cloud', on_feedback=on_feedback)
    rig.wait(mid_dot, 'dot 0 half way to its N_p target', handle)
    heard = len(rig.light.messages)
    # the two events paced (EVENT_PACE), so that they take the graph's time and not the
    # free-running world's: the loss seen and the retreat, and the sun's return seen (5
    # spot images in a row); the dark between them runs free
    rig.set_world(real_time_factor=EVENT_PACE)
    try:
        rig.wait_sim(0.3)                          # paced from here on
        now = rig.now() - rig.start
        rig.set_world(cloud_schedule=[now, now + 30.0, 0.0])    # complete: no direct sun
        rig.wait(waiting, 'the painter waiting for the sun', handle)
        rig.set_world(real_time_factor=0.0)
        rig.wait_sim_until(rig.start + now + 28.0, 'the last 2 s of the cloud')
        rig.set_world(real_time_factor=EVENT_PACE)
        rig.wait(back, 'the painter seeing the sun again', handle)
    finally:
        rig.set_world(real_time_factor=0.0)
    result = rig.graph.goal_result(handle, TIMEOUT).result
    # the world takes the schedule some simulated time after `now`, so the cloud it cast is
    # measured on its truth, not assumed to be 30 s
    truth = rig.light.messages[heard:]
    clear = max(m.dni for m in truth)
    dark = [stamp_to_seconds(m.header.stamp) for m in truth if m.dni <= 0.01 * clear]
    cloud = max(dark) - min(dark) if dark else 0.0
    print(f'\ncloud: {result.message}; the world was dark for {cloud:.1f} s')
    assert result.success, result.message
    assert 15.0 <= cloud <= 30.0
    # the loss is seen within a few seconds of the cloud, and the sun's return after it
    assert result.dots_burnt == 2 and cloud - 5.0 <= result.cloud_wait <= cloud + 30.0
    dots = read_journal(str(rig.runs / 'cloud' / 'journal.jsonl')).dots
    assert [d.outcome for d in dots] == ['burnt', 'burnt']
    assert dots[0].peak_n_p >= dots[0].n_p_target
    charred = [nearest(rig.charred_dots(), t) for t in targets]
    assert all(dot is not None for dot in charred), 'a dot is not charred'
    diameters = [dot.diameter for dot in charred]
    print(f'cloud: dot under the cloud {diameters[0] * 1e3:.2f} mm, clear one '
          f'{diameters[1] * 1e3:.2f} mm')
    assert diameters[0] == pytest.approx(diameters[1], rel=0.15)


def painting_interrupted(rig, name, y, interrupt, restore=lambda: None, dots=1, x=0.05):
    """
    Interrupt a painting while its first dot heats; return (focus-off delay [s sim], handle).

    The painting is `dots` dots from `x` at height `y` [m], interrupted at EVENT_PACE.
    `interrupt(handle)` does it and returns the simulated time it counts from; `restore`
    undoes the interruption's cause before the world runs fast again.
    """
    on_feedback, heating = rig.heating(index=0, n_p=5)
    handle = rig.send(dots_along(y, dots, x), name, on_feedback=on_feedback)
    rig.wait(heating, f'{name}: dot 0 heating', handle)
    rig.set_world(real_time_factor=EVENT_PACE)      # the graph's reaction, not the pace
    try:
        rig.wait_sim(0.3)                          # paced from here on
        reference = rig.heating_peak()
        since = interrupt(handle)
        off, share = rig.off_after(since, reference)
    finally:
        try:
            restore()
        finally:
            if all(p.alive() for p in rig.group.processes if p.label == 'sim_world'):
                rig.set_world(real_time_factor=0.0)
    print(f'\n{name}: focus off the wood {off - since:.2f} s (sim) after it, peak '
          f'irradiance down to {share * 100:.1f} % of the heating peak')
    return off - since, handle


def killed_driver_mid_dot(rig, label, y, x=0.074):
    """
    SIGKILL the driver `label` while a dot heats at (x, y); return (delay [s sim], result).

    A killed driver says nothing: the painter hears its joint states stop
    (``device_silence`` of wall time) and retreats with the other device (a dead Dobot
    driver: the wrist turns the lens away; a dead servo driver: the arm alone lifts the lens
    straight up). Meanwhile the world, in lockstep with the drivers' joint states, holds its
    time until it leaves the silent driver behind (``lockstep_timeout``). No char grows after
    (the char map 3 s of simulated time after the painting ended). The driver is not
    started again (a restarted driver went unheard by the painter for seconds, session 40):
    only a module's last test calls this, with the driver in its graph's ``may_die``.
    """
    driver = rig.process(label)
    rig.set_world(truth_period=0.05)         # the focus-off time to 0.05 s, not to the period

    def kill(_handle):
        driver.signal(signal.SIGKILL)
        driver.process.wait(30.0)
        return rig.now()

    delay, handle = painting_interrupted(rig, f'{label}_killed', y, kill, x=x)
    # it ends: a goal waiting on the killed driver gives up once its joint states stop
    # (device_silence, 1 s of wall time); CI once waited 900 s here for a retreat that the
    # lens planner had sent to the dead driver
    try:
        result = rig.graph.goal_result(handle, END_TIMEOUT).result
    except GraphTimeout as error:
        raise AssertionError(f'{error}; the nodes said:\n{rig.logs()}') from None
    print(f'{label} killed: {result.message}')
    device = 'dobot' if label == 'dobot_driver' else 'servo'
    assert not result.success and device in result.message, result.message
    rig.assert_no_char_grows()
    # a focus goal sent straight to the lens planner ends too, saying which driver is gone
    # (silent, or no longer discovered): it never waits on a dead server
    goal = FocusLens.Goal(d_lp=TRAVEL_D_LP)
    goal.target.header.frame_id = 'world'
    goal.target.point.x, goal.target.point.y = x, y
    focus = rig.graph.run_goal(rig.focus, goal, timeout=END_TIMEOUT).result
    print(f'focus with the {label} gone: {focus.message}')
    names = {'dobot': ('dobot', 'move_arm'), 'servo': ('servo', 'move_wrist', 'lens_')}
    assert not focus.success and any(name in focus.message for name in names[device]), \
        focus.message
    return delay, result


def one_graph_overrides(tmp_path):
    """Return the parameter overrides of a graph started for one painting interrupted."""
    return {'sim_world': {'real_time_factor': 0.0, 'flux_rays': 20000,
                          'truth_period': 0.05, 'pace_max_lag': 0.0},
            'lens_planner': {'calibration_dir': str(tmp_path / 'calibration')},
            'painter': {'runs_dir': str(tmp_path / 'runs')}}


def test_a_stale_thermal_stream_puts_the_focus_off_the_wood_within_half_a_second(rig):
    # The thermal camera's cable pulled out (the world publishes no thermal frame): the
    # thermal monitor has nothing to answer. (Not the monitor stopped with SIGSTOP: once, both
    # drivers fell silent from the moment of the SIGSTOP, most likely because a process
    # stopped inside Fast DDS's shared-memory transport can hold its port's lock.)
    def unplug_thermal(_handle):
        rig.set_world(unplugged=['thermal_camera'])
        rig.wait_sim(1.5 * THERMAL_STALE)
        rig.stats.wait_for_count(1, 60.0)
        last = stamp_to_seconds(rig.stats.messages[-1].header.stamp)
        return last + THERMAL_STALE                  # stale from here on (the watchdog)

    def plug_thermal():
        count = len(rig.stats.messages)
        rig.set_world(unplugged=[''])
        rig.stats.wait_for_count(count + 1, 60.0)    # answering again: back in lockstep

    delay, handle = painting_interrupted(rig, 'stale', 0.08, unplug_thermal,
                                         restore=plug_thermal)
    assert delay <= OFF_BOUND, rig.logs()
    result = rig.graph.goal_result(handle, TIMEOUT).result    # it comes back: heated again
    print(f'stale: {result.message}')
    assert result.success and 'stale thermal stream' in result.message, result.message


def unplugged_mid_dot(rig, device, x):
    """
    Unplug `device` ('dobot' or 'servo') while a dot heats at (x, 0.09), plug it back in.

    Return (focus-off delay [s sim], result message) once the driver is heard again (the
    painter refuses to paint while a driver is silent).
    """
    def unplug(_handle):
        # the world unplugs in its parameter callback, before it answers: the reaction is
        # counted from the answer, not from the request (whose trip to the world is the
        # test's, not the graph's: 1 s of wall time once under two busy processes)
        rig.set_world(unplugged=[device])
        return rig.now()

    try:
        delay, handle = painting_interrupted(rig, f'unplug_{device}', 0.09, unplug, x=x)
        result = rig.graph.goal_result(handle, TIMEOUT).result
    finally:
        rig.set_world(unplugged=[''])
    print(f'unplugged {device}: {result.message}')
    assert not result.success and device in result.message
    # heard again by the painter too, which refuses a goal while a driver is silent: its
    # goal can reach it before the first joint states after the reconnection (a fresh run
    # failed the next test so, 0.5 s after this one); ten of them are a second of the world
    joint = 'dobot_j1' if device == 'dobot' else 'lens_yaw'
    heard = len(rig.joints.messages)
    rig.joints.wait_until(lambda m: sum(joint in j.name for j in m[heard:]) >= 10, 60.0,
                          f"the {device}'s joint states again")
    return delay, result.message


def test_an_unplugged_dobot_puts_the_focus_off_the_wood_within_half_a_second(rig):
    delay, message = unplugged_mid_dot(rig, 'dobot', 0.05)
    assert delay <= OFF_BOUND, rig.logs()
    assert 'wrist turned the lens away' in message


def test_an_unplugged_maestro_puts_the_focus_off_the_wood_within_half_a_second(rig):
    # issue 35: the wrist's device falls silent mid-dot (its pty closes as on a USB unplug);
    # the lens planner's retreat would move the wrist too, so the arm alone lifts the lens
    delay, message = unplugged_mid_dot(rig, 'servo', 0.06)
    assert delay <= OFF_BOUND, rig.logs()
    assert 'the arm lifted the lens' in message


def test_a_cancel_puts_the_focus_off_the_wood_within_half_a_second(rig):
    def cancel(handle):
        since = rig.now()
        response = rig.graph.cancel_goal(handle, 60.0)
        assert response.goals_canceling, 'the cancel was refused'
        return since

    delay, handle = painting_interrupted(rig, 'cancel', 0.10, cancel)
    response = rig.graph.goal_result(handle, TIMEOUT)
    print(f'cancel: {response.result.message}')
    assert delay <= OFF_BOUND, rig.logs()
    assert response.result.message.startswith('canceled: retreated')


def test_a_killed_painter_resumes_with_no_dot_lost_or_burnt_twice(rig):
    targets = dots_along(0.11, 4)
    painter = rig.process('painter')
    on_feedback, third_dot = rig.heating(index=2, n_p=10)
    first = rig.send(targets, 'killed', on_feedback=on_feedback)
    rig.wait(third_dot, 'dot 2 heating', first)
    # A killed painter cannot retreat its lens: its heartbeat stops, and the lens planner's
    # focus lease (lease_timeout 0.15 s of node clock and 0.3 s wall) retreats the lens
    rig.set_world(real_time_factor=EVENT_PACE)
    try:
        rig.wait_sim(0.3)                         # paced from here on
        reference = rig.heating_peak()
        since = rig.now()
        painter.signal(signal.SIGKILL)
        painter.process.wait(30.0)
        rig.handles.remove(first)                 # its server is gone: no result will come
        off, share = rig.off_after(since, reference)
        print(f'\nkilled: focus off the wood {off - since:.2f} s (sim) after the kill, peak '
              f'irradiance down to {share * 100:.1f} % of the heating peak')
        assert off - since <= OFF_BOUND          # issue 30: as for every other stop
        # a request sent before the new server matched would be lost: the old one must be
        # gone from the graph first (DDS notices a killed participant within its lease)
        rig.graph.wait_until(lambda: not rig.client.server_is_ready(), 120.0,
                             'the killed painter gone from the graph')
        painter.start()                           # a new painter, the same parameters
        rig.graph.wait_until(rig.client.server_is_ready, 120.0, 'the new painter')
    finally:
        rig.set_world(real_time_factor=0.0)
    handle = rig.send(targets, '', fresh=False)   # the same goal: resume
    result = rig.graph.goal_result(handle, TIMEOUT).result
    print(f'\nresume: {result.message}')
    assert result.success, result.message
    assert result.dots_resumed == 2 and result.dots_burnt == 2
    burnt = [d.index for d in read_journal(str(rig.runs / 'killed' / 'journal.jsonl')).dots
             if d.outcome == 'burnt']
    burnt += [d.index for d in read_journal(result.run_dir + '/journal.jsonl').dots
              if d.outcome == 'burnt']
    assert sorted(burnt) == [0, 1, 2, 3], f'burnt per journal: {burnt}'
    charred = rig.charred_dots()
    found = [nearest(charred, t) for t in targets]
    assert all(dot is not None for dot in found), 'a planned dot is not charred'
    row = [d for d in charred if abs(d.y - 0.11) < 2e-3]
    assert len(row) == 4, f'{len(row)} charred dots on the row, 4 planned'
    print('resume: diameters ' + ', '.join(f'{d.diameter * 1e3:.2f}' for d in found) + ' mm')


def test_the_emergency_stop_takes_the_focus_off_and_refuses_goals_until_reset(rig):
    graph, answers = rig.graph, []
    stop = graph.helper.create_client(Trigger, 'emergency_stop')

    def emergency_stop(_handle):
        since = rig.now()
        answers.append(graph.call(stop, Trigger.Request(), ANSWER_TIMEOUT))
        return since

    delay, handle = painting_interrupted(rig, 'stopped', 0.07, emergency_stop, dots=2, x=0.074)
    print(f'emergency stop: {answers[0].message}')
    assert answers[0].success and 'EMERGENCY STOP engaged' in answers[0].message
    assert delay <= EMERGENCY_BOUND, rig.logs()
    ended = graph.goal_result(handle, ANSWER_TIMEOUT).result
    print(f'painting: {ended.message}')
    assert not ended.success and 'stopped by the EMERGENCY STOP' in ended.message
    rig.assert_no_char_grows()
    # every goal is refused, naming the stop
    refused = graph.run_goal(rig.client, PaintPattern.Goal(
        points=dots_along(0.09, 1), fresh=True, run_dir=str(rig.runs / 'next')),
        timeout=ANSWER_TIMEOUT)
    arm = graph.action_client(MoveArm, 'move_arm', ANSWER_TIMEOUT)
    wrist = graph.action_client(MoveWrist, 'move_wrist', ANSWER_TIMEOUT)
    target = [0.1, 0.5, 0.5, 0.0]
    moves = [graph.run_goal(arm, MoveArm.Goal(mode=MoveArm.Goal.MOVJ_ANGLE, target=target),
                            timeout=ANSWER_TIMEOUT),
             graph.run_goal(wrist, MoveWrist.Goal(yaw=0.0, pitch=0.1), timeout=ANSWER_TIMEOUT)]
    focus = graph.action_client(FocusLens, 'focus', ANSWER_TIMEOUT)
    moves.append(graph.run_goal(focus, FocusLens.Goal(), timeout=ANSWER_TIMEOUT))
    for reply in (refused, *moves):
        assert not reply.result.success
        assert 'EMERGENCY STOP is engaged' in reply.result.message, reply.result.message
        assert 'helio reset' in reply.result.message
    # helio reset, as a user types it: goals are taken again (the arm moves; the next
    # tests paint)
    reset = subprocess.run(HELIO + ['reset', '--timeout', '30'], capture_output=True,
                           text=True, timeout=120)
    print(f'helio reset: {reset.stdout.strip()} {reset.stderr.strip()}')
    assert reset.returncode == 0 and 'reset' in reset.stdout
    graph.wait_until(lambda: not any('EMERGENCY' in m.message for m in rig.dobot.messages[-1:]),
                     ANSWER_TIMEOUT, 'dobot/status without the emergency stop')
    moved = graph.run_goal(arm, MoveArm.Goal(mode=MoveArm.Goal.MOVJ_ANGLE, target=target),
                           timeout=ANSWER_TIMEOUT)
    assert moved.result.success, moved.result.message
    assert math.isclose(moved.result.achieved_joints[0], target[0], abs_tol=1e-3)


def test_a_killed_lens_planner_leaves_the_retreat_to_the_wrist_within_half_a_second(rig):
    planner = rig.process('lens_planner')

    def kill_and_cancel(handle):
        planner.signal(signal.SIGKILL)
        planner.process.wait(30.0)
        since = rig.now()
        response = rig.graph.cancel_goal(handle, 60.0)
        assert response.goals_canceling, 'the cancel was refused'
        return since

    delay, handle = painting_interrupted(rig, 'planner_killed', 0.12, kill_and_cancel)
    result = rig.graph.goal_result(handle, TIMEOUT).result
    print(f'planner killed: {result.message}')
    assert delay <= OFF_BOUND, rig.logs()
    # the dead planner still discovered (not accepted in time) or already gone from the graph
    assert 'did not accept the goal' in result.message or 'no focus server' in result.message
    assert 'the wrist turned the lens away' in result.message
    # a new lens planner (the same parameters; it reads the robot-world calibration back)
    # for the graph's stop below, started at once: the killed one stays discovered until
    # its participant's lease runs out (about 20 s), and a goal request reaches both, of
    # which only the new one answers. A CI run once saw the painter's first focus goal after
    # the restart go unanswered for 5 s (the test's own client had been served): the painter
    # is restarted too (Ctrl-C, then the same parameters), and a new process never learns
    # of the killed one, which announces nothing (waiting out the lease cost 10 s). The new
    # planner's own endpoints found first, then it is ready when it serves a goal: a
    # service's first answers can be lost while its new endpoints are being matched
    # (ros2/ros2#1253), and the planner's first focus waits for the sun estimate and the
    # joint states; one focus well above the wood (no heat)

    def status_publishers(action):
        return {bytes(info.endpoint_gid) for info in
                rig.graph.helper.get_publishers_info_by_topic(f'/{action}/_action/status')}
    killed, stopped = status_publishers('focus'), status_publishers('paint')
    planner.start()
    painter = rig.process('painter')
    painter.signal(signal.SIGINT)
    painter.process.wait(30.0)
    painter.start()
    rig.graph.wait_until(lambda: status_publishers('focus') - killed, 120.0,
                         'the new lens planner')
    goal = FocusLens.Goal(d_lp=TRAVEL_D_LP)
    goal.target.header.frame_id = 'world'
    goal.target.point.x, goal.target.point.y = 0.074, 0.08
    served = rig.graph.run_goal(rig.focus, goal, timeout=ANSWER_TIMEOUT)
    assert served.result.success, served.result.message
    rig.graph.wait_until(lambda: status_publishers('paint') - stopped
                         and not stopped & status_publishers('paint'), 120.0, 'the new painter')


def test_stopping_the_graph_mid_dot_puts_the_focus_off_the_wood_within_half_a_second(rig):
    # the module's last test: the graph is stopped
    outcomes = {}

    def stop(_handle):
        since = rig.now()
        outcomes.update(rig.group.stop())           # what Ctrl-C of helio sim does
        return since

    delay, _ = painting_interrupted(rig, 'graph_stopped', 0.08, stop, x=0.074)
    print(f'stop: {outcomes}')
    assert delay <= OFF_BOUND, rig.logs()
    assert outcomes['painter'] == 'SIGINT' and outcomes['lens_planner'] == 'SIGINT'
    journal = read_journal(str(rig.runs / 'graph_stopped' / 'journal.jsonl'))
    assert journal.result is not None and not journal.result.success
    assert journal.result.message.startswith('stopped by a stop signal: retreated')
