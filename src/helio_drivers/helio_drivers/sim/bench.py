"""
Benchmarks of the simulated world (issues 6, 16): per-part costs and real-time factors.

    python -m helio_drivers.sim.bench --json PATH [--quick] [--skip-node] [--skip-busy]

Every real-time factor is simulated seconds per wall second (``_rtf_wall``) and per CPU
second of the process that simulates (``_rtf_cpu``: what the world gets out of the core it
runs on, which swings less with the machine's load), with the thermal camera at 8.7 Hz and
the RGB camera at 5 Hz of simulated time. Each is measured on a quiet machine and with a
competing busy process (``_busy``: a child spinning on a core, as the rest of the graph
would), and reported with the load average before the run (``load_average_1min``).

World alone (in this process, lockstep, as fast as it goes; the joints are set directly,
aiming with the world's TRUE sun, ``truth.py``):

- ``sim_heating_*``: the lens held on a dot at d_lp 8.2 cm;
- ``sim_moving_*``: the lens moving all the time between two dots 4 mm apart (a move of
  about 0.8 s, smooth in joint space), so every step traces the lens anew;
- ``sim_painting_*``: a whole painting of ``--dots`` dots 4 mm apart as Algorithm 1 does
  it: move to the dot, heat until N_p >= 30 (thermal pixels at the cap), retreat by 3 cm,
  wait for N_p = 0, move to the next; also ``sim_painting_simulated_s``.

Node (``--skip-node`` leaves it out): ``python -m helio_drivers.sim.world_node`` as its own
process at ``real_time_factor`` 0 with this process subscribed to both cameras and
``/clock``, both with the graph's Fast DDS profile for camera images
(``fastdds_large_images.xml``, as ``helio_control.bringup`` starts every node); this
process drives the emulated Dobot and Maestro over their pseudo-terminals as the drivers
would: each device's joints read at 20 Hz of wall time (their ``joint_states``), a running
move polled as the drivers poll it (the arm's alarms, pose and executed index, the servos'
moving state and positions, every 20 ms of wall time: ``device_action_node``'s
``poll_period``), and at every turn of the probe's loop the arm's executed index and the
servos' moving state (two round trips): the next move starts at once, as the painter starts
it, so the lens moves all the time however fast the world runs. (An earlier bench ran the
drivers' whole poll at every turn, hundreds of times a second: the emulators then took 8 ms
of CPU per simulated second; docs/measurements/simulation-speed-history.md, "Memory traffic".)
``sim_node_heating_*`` holds the lens on a dot, ``sim_node_moving_*`` commands the next of
two dots as soon as the last move ended; CPU is the node process's (``/proc``), and
``sim_node_*_rgb_hz`` / ``_thermal_hz`` count the frames received per simulated second.

Per-part costs (``*_ms_median``, CPU time): ``sim_heat_step``, ``sim_flux_trace``
(re-trace after the sun turned), ``sim_flux_carry`` (the moving lens's rays carried along
after a move without turning), ``sim_flux_bin``, ``sim_thermal_frame``, ``sim_rgb_frame``
(unchanged scene), ``sim_rgb_frame_heating`` (the char changing between frames),
``sim_rgb_frame_moving`` (a new pose every frame), ``sim_world_step``.

Targets (issue 16): heating >= 50x and moving >= 20x with both cameras publishing and a
competing busy process.
"""

import argparse
import contextlib
import math
import multiprocessing
import os
import subprocess
import sys
import tempfile
import time

from helio_drivers.sim.flux import irradiance_on_cells, lens_pose_in_world
from helio_drivers.sim.truth import true_sun_focus_joints
from helio_drivers.sim.world import SimSettings, SimWorld
from helio_optics.bench_report import add_json_option, median_call_ms, report
from helio_optics.config_files import config_path
from helio_optics.node_kit.process_tuning import keep_large_buffers
from helio_optics.node_kit.process_tuning import single_threaded_numerics
from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters
from helio_optics.rig_kinematics import RigParameters
import numpy as np

THERMAL_RATE = 8.7    # [Hz simulated]
RGB_RATE = 5.0
DOT = (0.07, 0.07)
SPACING = 0.004       # [m] between dots
D_LP = 0.082          # heating distance [m]
RETREAT = 0.03        # [m]
N_P_TARGET = 30
DDS_PROFILE_ENV = 'FASTRTPS_DEFAULT_PROFILES_FILE'
JOINT_STATE_RATE = 20.0   # [Hz wall] each driver's joint_states (device_action_node)
MOVE_POLL_PERIOD = 0.02   # [s wall] the drivers' polling of a running move (poll_period)
# Dobot moves kept queued ahead of the one running, so that the arm never waits for the next
# poll (a 20 ms poll is 0.5 s simulated at 25x; with 4 legs the queue ran out at 13-17 % of
# the polls, with 12 at none; the emulated Dobot queues 32)
LEGS_AHEAD = 12


def _rig():
    path = default_rig_file()
    return (load_rig_parameters(path) if path else RigParameters()), path


def _cpu_ms(call, repeats):
    """Return the median CPU time of `call` [ms]."""
    return median_call_ms(call, repeats, clock=time.process_time)


def _spin():
    """Keep one core busy until killed (the competing process)."""
    while True:
        pass


@contextlib.contextmanager
def busy_process(enabled=True):
    """Run a child process spinning on a core for the duration of the block."""
    if not enabled:
        yield None
        return
    child = multiprocessing.get_context('spawn').Process(target=_spin, daemon=True)
    child.start()
    try:
        time.sleep(0.2)     # let it get onto a core before anything is measured
        yield child
    finally:
        child.terminate()
        child.join(timeout=5.0)


class CameraSchedule:
    """Renders the world's thermal and RGB frames when due (as the node does)."""

    def __init__(self, world):
        """Start both cameras' schedules at the world's present time."""
        self.world = world
        self._next_thermal = self._next_rgb = world.time
        self.last_n_p = 0

    def after_step(self):
        """Render what is due; return the N_p of a new thermal frame, else None."""
        world, n_p = self.world, None
        if world.time + 1e-9 >= self._next_thermal:
            image = world.thermal_image()
            cap_counts = round((world.settings.thermal.cap + 273.15) * 100.0)
            n_p = self.last_n_p = int(np.count_nonzero(image >= cap_counts))
            self._next_thermal += 1.0 / THERMAL_RATE
        if world.time + 1e-9 >= self._next_rgb:
            world.rgb_image()
            self._next_rgb += 1.0 / RGB_RATE
        return n_p


def _smooth_move(world, cameras, start, end, joint_speed=1.0, settle=0.2, duration=None):
    """Step the world while the joints go from `start` to `end` (cosine in joint space)."""
    if duration is None:
        duration = float(np.max(np.abs(end - start))) / joint_speed + settle
    begin = world.time
    while world.time < begin + duration:
        phase = min((world.time - begin) / duration, 1.0)
        world.set_joints(start + (0.5 - 0.5 * math.cos(math.pi * phase)) * (end - start))
        world.step()
        cameras.after_step()
    world.set_joints(end)


def _timed(run):
    """Run `run()` -> simulated seconds; return (simulated, wall, cpu) seconds."""
    wall, cpu = time.perf_counter(), time.process_time()
    simulated = run()
    return simulated, time.perf_counter() - wall, time.process_time() - cpu


def _factors(name, simulated, wall, cpu):
    return {f'{name}_rtf_wall': simulated / wall, f'{name}_rtf_cpu': simulated / cpu}


def world_heating(rig, seconds):
    """Return the world's (simulated, wall, cpu) while the lens holds on a dot."""
    world = SimWorld(SimSettings(), rig)
    world.set_joints(true_sun_focus_joints(world, DOT, D_LP))
    cameras = CameraSchedule(world)

    def run():
        start = world.time
        while world.time < start + seconds:
            world.step()
            cameras.after_step()
        return world.time - start
    return _timed(run)


def world_moving(rig, seconds):
    """Return the world's (simulated, wall, cpu) while the lens keeps moving between dots."""
    world = SimWorld(SimSettings(), rig)
    a = true_sun_focus_joints(world, DOT, D_LP)
    b = true_sun_focus_joints(world, (DOT[0] + SPACING, DOT[1]), D_LP)
    world.set_joints(a)
    cameras = CameraSchedule(world)

    def run():
        start, here, there = world.time, a, b
        while world.time < start + seconds:
            _smooth_move(world, cameras, here, there, duration=0.8)
            here, there = there, here
        return world.time - start
    return _timed(run)


def world_painting(rig, dots, timeout=120.0):
    """Paint `dots` dots 4 mm apart (Algorithm 1 with the true sun); (simulated, wall, cpu)."""
    world = SimWorld(SimSettings(), rig)
    targets = [(DOT[0] + SPACING * (k % 4), DOT[1] + SPACING * (k // 4)) for k in range(dots)]
    here = true_sun_focus_joints(world, targets[0], D_LP + RETREAT)
    world.set_joints(here)
    cameras = CameraSchedule(world)

    def wait_for(condition):
        end = world.time + timeout
        while world.time < end:
            world.step()
            n_p = cameras.after_step()
            if n_p is not None and condition(n_p):
                return
        raise RuntimeError(f'N_p condition not met within {timeout} s simulated')

    def run():
        nonlocal here
        for target in targets:
            focus = true_sun_focus_joints(world, target, D_LP)
            _smooth_move(world, cameras, here, focus)
            wait_for(lambda n_p: n_p >= N_P_TARGET)
            here = true_sun_focus_joints(world, target, D_LP + RETREAT)
            _smooth_move(world, cameras, focus, here)
            wait_for(lambda n_p: n_p == 0)
        return world.time
    simulated, wall, cpu = _timed(run)
    charred = len(world.charred_dots())
    if charred != dots:
        raise RuntimeError(f'the painting has {charred} charred dots, not {dots}')
    return simulated, wall, cpu


def bench_world(rig, seconds, dots, busy):
    """Return heating, moving and painting figures of the world alone, +/- a busy process."""
    figures = {}
    for suffix, with_busy in (('', False), ('_busy', True)):
        if with_busy and not busy:
            continue
        figures[f'load_average_1min{suffix}'] = os.getloadavg()[0]
        with busy_process(with_busy):
            figures.update(_factors(f'sim_heating{suffix}', *world_heating(rig, seconds)))
            figures.update(_factors(f'sim_moving{suffix}', *world_moving(rig, seconds / 2)))
            simulated, wall, cpu = world_painting(rig, dots)
            figures.update(_factors(f'sim_painting{suffix}', simulated, wall, cpu))
            figures[f'sim_painting_simulated_s{suffix}'] = simulated
    return figures


# ---------------------------------------------------------------------------- node
def _process_cpu_seconds(pid):
    """Return the user + system CPU time of process `pid` [s] (Linux /proc)."""
    with open(f'/proc/{pid}/stat') as stream:
        fields = stream.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


class NodeRun:
    """The sim_world node in its own process, this process subscribed and driving it."""

    def __init__(self, rig_file, directory):
        """Start the node and this process's probe node; connect the device clients."""
        import rclpy
        from rclpy.qos import qos_profile_sensor_data, QoSProfile
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import Image
        from helio_drivers.dobot_client import DobotClient
        from helio_drivers.maestro_client import MaestroClient
        from helio_drivers.sim.devices import DeviceSettings

        self._rclpy = rclpy
        # as the graph's image subscriber (spot_detector) does: a taken 0.9 MB frame reuses
        # freed heap instead of page-faulting fresh pages in (a subscriber's receipt of an
        # RGB frame 2.6 -> 1.3 ms on a slow machine); said here, not left to the SimWorld
        # built below only to aim with
        keep_large_buffers()
        self.ports = (os.path.join(directory, 'dobot'), os.path.join(directory, 'servo'))
        command = [sys.executable, '-m', 'helio_drivers.sim.world_node', '--ros-args',
                   '-p', 'real_time_factor:=0.0', '-p', f'dobot_port:={self.ports[0]}',
                   '-p', f'servo_port:={self.ports[1]}']
        if rig_file:
            command += ['-p', f'rig_file:={rig_file}']
        # the graph's Fast DDS profile for camera images, as helio_control.bringup gives
        # every node (and this probe: set before its context starts)
        profile = config_path('fastdds_large_images.xml', required=False)
        if profile and DDS_PROFILE_ENV not in os.environ:
            os.environ[DDS_PROFILE_ENV] = profile
        self.dds_profile = os.environ.get(DDS_PROFILE_ENV, '')
        self.process = subprocess.Popen(command, stdout=subprocess.DEVNULL,
                                        stderr=subprocess.DEVNULL)
        self.context = rclpy.context.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('sim_bench_probe', context=self.context)
        self.executor = rclpy.executors.SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.counts = {'rgb': 0, 'thermal': 0}
        self.sim_time = 0.0

        def on_clock(message):
            self.sim_time = message.clock.sec + 1e-9 * message.clock.nanosec
        self.node.create_subscription(Clock, '/clock', on_clock, QoSProfile(depth=1))
        for name in self.counts:
            self.node.create_subscription(
                Image, f'{name}/image_raw',
                lambda _, name=name: self.counts.__setitem__(name, self.counts[name] + 1),
                qos_profile_sensor_data, raw=True)
        deadline = time.monotonic() + 30.0
        while not all(os.path.exists(p) for p in self.ports):
            if time.monotonic() > deadline or self.process.poll() is not None:
                raise RuntimeError('the sim_world node did not open its ports')
            time.sleep(0.05)
        self.dobot, self.servo = DobotClient(self.ports[0]), MaestroClient(self.ports[1])
        self.dobot.connect()
        self.servo.connect()
        self.calibrations = DeviceSettings()
        self.world = SimWorld(SimSettings(), load_rig_parameters(rig_file) if rig_file
                              else RigParameters())   # only to aim with the true sun

    def spin(self, wall_seconds):
        """Let the probe take messages for `wall_seconds`."""
        end = time.monotonic() + wall_seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.01)

    def command(self, x):
        """Send joints x to both emulated devices; return the Dobot queue index."""
        from helio_drivers.dobot_protocol import PtpMode
        from helio_drivers.maestro_protocol import ServoCalibration
        s = self.calibrations
        index = self.dobot.move(PtpMode.MOVJ_ANGLE, (x[0], x[1], x[2], 0.0))
        for name, channel, angle in (('lens_yaw', s.yaw_channel, x[3]),
                                     ('lens_pitch', s.pitch_channel, x[4])):
            calibration = ServoCalibration(name, channel, us_per_rad=s.servo_us_per_rad,
                                           centre_pulse_us=s.servo_centre_us)
            self.servo.set_target(channel, round(4.0 * calibration.pulse_us(angle)))
        return index

    def arrived(self, index):
        """Tell whether both devices finished the last command."""
        return self.dobot.executed_index() >= index and not self.servo.moving()

    def hold_at(self, x, timeout=60.0):
        """Move to joints x after every queued move and wait there until it stands still."""
        index = self.command(x)
        deadline = time.monotonic() + timeout
        while not self.arrived(index):
            if time.monotonic() > deadline:
                raise RuntimeError('the emulated arm did not reach the dot')
            self.spin(0.05)

    def keep_moving(self, targets):
        """
        Return a `between` for ``measure`` that keeps the arm moving among joints `targets`.

        At each poll it queues the next targets in turn while fewer than LEGS_AHEAD Dobot
        moves wait behind the running one (the Dobot runs its queue back to back) and sets
        the servos to the newest target, so the arm moves all the time while the devices
        are asked no more than the drivers ask them. Its `polls` and `drained` count the
        polls and those that found the queue run out (the arm possibly still).
        """
        state = {'k': 0, 'queued': self.dobot.executed_index()}

        def between(executed):
            between.polls += 1
            between.drained += executed >= state['queued']
            while state['queued'] - executed < LEGS_AHEAD:
                state['k'] = (state['k'] + 1) % len(targets)
                state['queued'] = self.command(targets[state['k']])
        between.polls = between.drained = 0
        return between

    def read_joints(self):
        """Read both devices' joints as the drivers' joint_states do (pose; two positions)."""
        self.dobot.get_pose()
        for channel in (self.calibrations.yaw_channel, self.calibrations.pitch_channel):
            self.servo.get_position(channel)

    def poll_move(self):
        """Poll a running move as the drivers' device threads do; return the executed index."""
        self.dobot.get_alarms()
        executed = self.dobot.executed_index()
        self.servo.moving()
        self.read_joints()      # the arm's pose and the servos' positions
        return executed

    def measure(self, wall_seconds, between=None):
        """
        Return (simulated, wall, node cpu, frames) over `wall_seconds`.

        The joints are read as the drivers' joint_states read them (every
        1 / JOINT_STATE_RATE of wall time); with `between` a move is polled as the drivers
        poll it, every MOVE_POLL_PERIOD, and `between(executed Dobot index)` is called after
        each poll (``keep_moving``). Like the drivers' device threads, the next read or poll
        is due a period after the last one, not caught up in a burst when this probe lags.
        """
        self.spin(0.3)
        deadline = time.monotonic() + 30.0
        while self.sim_time == 0.0:     # from the first /clock on, not from time 0
            if time.monotonic() > deadline:
                raise RuntimeError('no /clock from the sim_world node')
            self.executor.spin_once(timeout_sec=0.05)
        sim0, cpu0, wall0 = self.sim_time, _process_cpu_seconds(self.process.pid), \
            time.monotonic()
        counts0 = dict(self.counts)
        end = wall0 + wall_seconds
        next_joints = next_poll = wall0
        while True:
            now = time.monotonic()
            if now >= end:
                break
            if now >= next_joints:
                self.read_joints()
                next_joints = now + 1.0 / JOINT_STATE_RATE
            if between is not None and now >= next_poll:
                between(self.poll_move())
                next_poll = now + MOVE_POLL_PERIOD
            due = min(next_joints, next_poll) if between is not None else next_joints
            self.executor.spin_once(timeout_sec=max(min(due, end) - time.monotonic(), 0.0))
        simulated = self.sim_time - sim0
        frames = {name: self.counts[name] - counts0[name] for name in self.counts}
        return (simulated, time.monotonic() - wall0,
                _process_cpu_seconds(self.process.pid) - cpu0, frames)

    def close(self):
        """Stop the node process and the probe."""
        with contextlib.suppress(Exception):
            self.dobot.close()
            self.servo.close()
        self.process.terminate()
        try:
            self.process.wait(timeout=15.0)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self.executor.shutdown()
        self.node.destroy_node()
        self._rclpy.try_shutdown(context=self.context)


def bench_node(rig_file, wall_seconds, busy):
    """Return heating and moving figures of the sim_world node process, +/- a busy process."""
    figures = {}
    with tempfile.TemporaryDirectory(prefix='helio_sim_bench_') as directory:
        run = NodeRun(rig_file, directory)
        print(f'node: Fast DDS profile {run.dds_profile or "(none: the defaults)"}')
        try:
            focus = [true_sun_focus_joints(run.world, (DOT[0] + SPACING * k, DOT[1]), D_LP)
                     for k in range(2)]
            for suffix, with_busy in (('', False), ('_busy', True)):
                if with_busy and not busy:
                    continue
                with busy_process(with_busy):
                    figures[f'load_average_1min_node{suffix}'] = os.getloadavg()[0]
                    run.hold_at(focus[0])
                    heating = run.measure(wall_seconds)
                    mover = run.keep_moving(focus)
                    moving = run.measure(wall_seconds, mover)
                # polls after the first that found the arm's queue run out: 0 when the arm
                # moved all the time
                figures[f'sim_node_moving{suffix}_queue_drained'] = float(
                    max(mover.drained - 1, 0))
                figures[f'sim_node_moving{suffix}_polls'] = float(mover.polls)
                for name, (simulated, wall, cpu, frames) in (('heating', heating),
                                                             ('moving', moving)):
                    key = f'sim_node_{name}{suffix}'
                    figures.update(_factors(key, simulated, wall, cpu))
                    figures[f'{key}_rgb_hz'] = frames['rgb'] / max(simulated, 1e-9)
                    figures[f'{key}_thermal_hz'] = frames['thermal'] / max(simulated, 1e-9)
        finally:
            run.close()
    return figures


# ---------------------------------------------------------------------------- parts
def bench_costs(rig, repeats=30):
    """Return the per-step and per-frame CPU costs [ms] of the world's parts."""
    world = SimWorld(SimSettings(), rig)
    world.set_joints(true_sun_focus_joints(world, DOT, D_LP))
    world.run(2.0)
    world.rgb_image()
    figures = {}
    irradiance = world.dni_now() * world._unit_irradiance
    figures['sim_heat_step_ms_median'] = _cpu_ms(
        lambda: world.panel.step(world.settings.step, irradiance, 900.0), repeats)
    s0 = world.sun_ray_world()
    poses = [lens_pose_in_world(world.T_robot_world,
                                world.rig.forward(true_sun_focus_joints(
                                    world, (DOT[0], DOT[1] + 1e-3 * k), D_LP)).T_robot_lens)
             for k in range(repeats)]
    fields = []
    # the sun turned 1 mrad more each time: a re-trace (a lens that only moved is carried)
    suns = [s0 + np.array([1e-3 * (k + 1), 0.0, 0.0]) for k in range(repeats)]
    figures['sim_flux_trace_ms_median'] = _cpu_ms(
        lambda: fields.append(world.flux.field(poses[len(fields)], suns[len(fields)])),
        repeats)
    carried = []
    figures['sim_flux_carry_ms_median'] = _cpu_ms(
        lambda: carried.append(world.flux.field(poses[len(carried)], suns[-1], moving=True)),
        repeats)
    figures['sim_flux_bin_ms_median'] = _cpu_ms(
        lambda: irradiance_on_cells(fields[-1], world.panel.x_edges, world.panel.y_edges,
                                    900.0), repeats)
    world.set_joints(true_sun_focus_joints(world, DOT, D_LP))
    world.step()
    figures['sim_thermal_frame_ms_median'] = _cpu_ms(world.thermal_image, repeats)
    figures['sim_rgb_frame_ms_median'] = _cpu_ms(world.rgb_image, repeats)

    def heating_frame():
        world.run(0.2)
        start = time.process_time_ns()
        world.rgb_image()
        return time.process_time_ns() - start
    figures['sim_rgb_frame_heating_ms_median'] = float(np.median(
        [heating_frame() for _ in range(repeats)])) / 1e6
    start_joints = world.joint_positions()

    def moving_frame(k):
        world.set_joints(start_joints + 1e-3 * (k + 1))
        world.step()
        begin = time.process_time_ns()
        world.rgb_image()
        return time.process_time_ns() - begin
    figures['sim_rgb_frame_moving_ms_median'] = float(np.median(
        [moving_frame(k) for k in range(repeats)])) / 1e6
    world.set_joints(true_sun_focus_joints(world, DOT, D_LP))
    figures['sim_world_step_ms_median'] = _cpu_ms(world.step, 4 * repeats)
    return figures


def bench_sim(seconds=20.0, dots=4, skip_node=False, node_seconds=10.0, busy=True):
    """Run every sim benchmark and return the flat figures."""
    rig, rig_file = _rig()
    figures = bench_costs(rig)
    figures.update(bench_world(rig, seconds, dots, busy))
    if not skip_node:
        figures.update(bench_node(rig_file, node_seconds, busy))
    return figures


def main(argv=None):
    """Run the benchmarks, print the figures and write them as flat JSON."""
    parser = argparse.ArgumentParser(description='Benchmarks of the simulated world.')
    add_json_option(parser)
    parser.add_argument('--seconds', type=float, default=20.0,
                        help='simulated seconds of heating (moving: half) [s] (default 20)')
    parser.add_argument('--dots', type=int, default=4,
                        help='dots of the painting (default 4)')
    parser.add_argument('--skip-node', action='store_true',
                        help='skip the sim_world node process (needs the built workspace)')
    parser.add_argument('--node-seconds', type=float, default=10.0,
                        help='wall time of each node measurement [s] (default 10)')
    parser.add_argument('--skip-busy', action='store_true',
                        help='skip the runs with a competing busy process')
    parser.add_argument('--quick', action='store_true',
                        help='short runs (2 s heating, 1 dot, 2 s node): for tests')
    args = parser.parse_args(argv)
    single_threaded_numerics()   # as every helio process (the node's run_node does it too)
    if args.quick:
        args.seconds, args.dots, args.node_seconds = 2.0, 1, 2.0
    figures = bench_sim(args.seconds, args.dots, args.skip_node, args.node_seconds,
                        not args.skip_busy)
    return report({name: round(float(value), 6) for name, value in figures.items()}, args.json,
                  machine=True)


if __name__ == '__main__':
    raise SystemExit(main())
