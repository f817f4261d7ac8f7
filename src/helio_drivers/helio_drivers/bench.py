"""
Benchmarks of the device drivers over pseudo-terminals (run in the built environment).

    python -m helio_drivers.bench --json PATH

Figures: command round-trip latency (GetPose on the Dobot emulator, Get Position on the
Maestro emulator) median and p99; the pose polling rate one client achieves; and for arm
moves, the time from sending a MoveArm goal to receiving its result against the motion time
the emulator planned (their difference is the driver's completion overhead), plus the same
at the library level (queue a move, wait for its executed index). The simulated world has
its own benchmark: ``python -m helio_drivers.sim.bench``.
"""

import argparse
import statistics
import threading
import time

from helio_drivers import dobot_protocol as proto
from helio_drivers.dobot_client import DobotClient
from helio_drivers.dobot_emulator import DobotEmulator
from helio_drivers.maestro_client import MaestroClient
from helio_drivers.maestro_emulator import CONFIGURED_SETTINGS, MaestroEmulator
from helio_optics.bench_report import add_json_option, call_durations, report
import numpy as np

MOVES = [(0.0, 20.0, 20.0, 0.0), (30.0, 30.0, 10.0, 0.0), (-20.0, 15.0, 35.0, 10.0),
         (0.0, 10.0, 10.0, 0.0)]


def percentile_ms(samples, q):
    """Return the q-th percentile of samples [s] in milliseconds."""
    return float(np.percentile(np.array(samples) * 1000.0, q))


def dobot_link_figures(samples, poll_seconds, warm_up=20, suffix='', **emulator_options):
    """Round trip of GetPose [ms] and the pose polling rate [Hz] on one emulated Dobot link."""
    figures = {}
    with DobotEmulator(**emulator_options) as emulator:
        client = DobotClient(emulator.port_path, timeout=0.5, retries=0)
        client.connect()
        call_durations(client.get_pose, warm_up)
        durations = call_durations(client.get_pose, samples)
        figures[f'dobot_roundtrip{suffix}_ms_median'] = percentile_ms(durations, 50)
        figures[f'dobot_roundtrip{suffix}_ms_p99'] = percentile_ms(durations, 99)
        count, started = 0, time.perf_counter()
        while time.perf_counter() - started < poll_seconds:
            client.get_pose()
            count += 1
        figures[f'dobot_pose_poll{suffix}_hz'] = count / (time.perf_counter() - started)
        client.close()
    return figures


def bench_round_trips(samples, poll_seconds=2.0):
    """Round-trip latency of one command on each device, and the pose polling rate."""
    figures = dobot_link_figures(samples, poll_seconds)
    # the same with the replies held back by their time on a 115200 baud line
    figures.update(dobot_link_figures(max(100, samples // 10), poll_seconds, warm_up=0,
                                      suffix='_115200baud', line_baudrate=115200))
    with MaestroEmulator(**CONFIGURED_SETTINGS) as emulator:
        client = MaestroClient(emulator.port_path, timeout=0.5, retries=0)
        client.connect()
        call_durations(lambda: client.get_position(0), 20)
        durations = call_durations(lambda: client.get_position(0), samples)
        figures['maestro_roundtrip_ms_median'] = percentile_ms(durations, 50)
        figures['maestro_roundtrip_ms_p99'] = percentile_ms(durations, 99)
        client.close()
    return figures


def bench_client_moves(poll_period):
    """Queue a move and wait for its executed index; overhead over the planned motion."""
    overheads, motions = [], []
    with DobotEmulator() as emulator:
        client = DobotClient(emulator.port_path, timeout=0.5, retries=0)
        client.connect()
        client.set_ptp_joint_params(proto.PtpJointParams((200.0,) * 4, (800.0,) * 4))
        for target in MOVES:
            started = time.perf_counter()
            index = client.ptp(proto.PtpMode.MOVJ_ANGLE, target)
            client.wait_for_index(index, timeout=30.0, poll_period=poll_period)
            elapsed = time.perf_counter() - started
            motion = emulator.motion_durations.get(index, 0.0)
            motions.append(motion)
            overheads.append(elapsed - motion)
        client.close()
    return {'client_move_motion_s_mean': statistics.mean(motions),
            'client_move_overhead_ms_median': percentile_ms(overheads, 50),
            'client_move_overhead_ms_max': percentile_ms(overheads, 100)}


def bench_node_moves():
    """Time MoveArm goal -> result through dobot_driver (real rclpy) vs the planned motion."""
    import rclpy
    from rclpy.action import ActionClient
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from helio_drivers.dobot_driver_node import DobotDriverNode
    from helio_msgs.action import MoveArm

    context = rclpy.context.Context()
    rclpy.init(context=context)
    overheads, motions, totals = [], [], []
    with DobotEmulator() as emulator:
        driver = DobotDriverNode(context=context, parameter_overrides=[
            Parameter('port', value=emulator.port_path),
            Parameter('joint_velocity_dps', value=[200.0] * 4),
            Parameter('joint_acceleration_dps2', value=[800.0] * 4)])
        node = rclpy.create_node('dobot_bench_client', context=context)
        client = ActionClient(node, MoveArm, 'move_arm')
        executor = SingleThreadedExecutor(context=context)  # as rclpy.spin runs the node
        executor.add_node(driver)
        executor.add_node(node)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()
        try:
            if not client.wait_for_server(timeout_sec=10.0):
                raise RuntimeError('move_arm server not available')
            for target in MOVES:
                goal = MoveArm.Goal(mode=MoveArm.Goal.MOVJ_ANGLE,
                                    target=[float(np.radians(v)) for v in target])
                before = set(emulator.motion_durations)
                started = time.perf_counter()
                handle = _wait(client.send_goal_async(goal))
                response = _wait(handle.get_result_async())
                elapsed = time.perf_counter() - started
                if not response.result.success:
                    raise RuntimeError(response.result.message)
                new = set(emulator.motion_durations) - before
                motion = sum(emulator.motion_durations[i] for i in new)
                motions.append(motion)
                totals.append(elapsed)
                overheads.append(elapsed - motion)
        finally:
            executor.shutdown(timeout_sec=5.0)
            driver.destroy_node()
            node.destroy_node()
            rclpy.try_shutdown(context=context)
            spinner.join(timeout=5.0)
    return {'node_move_goal_to_result_s_mean': statistics.mean(totals),
            'node_move_motion_s_mean': statistics.mean(motions),
            'node_move_overhead_ms_median': percentile_ms(overheads, 50),
            'node_move_overhead_ms_max': percentile_ms(overheads, 100)}


def _wait(future, timeout=30.0):
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    if not done.wait(timeout):
        raise TimeoutError('future not done in time')
    return future.result()


def main(argv=None):
    """Run the benchmarks, print the figures and write them as flat JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    add_json_option(parser)
    parser.add_argument('--samples', type=int, default=2000,
                        help='round trips per device (default 2000)')
    parser.add_argument('--poll-seconds', type=float, default=2.0,
                        help='duration of each pose polling run [s] (default 2)')
    parser.add_argument('--skip-node', action='store_true',
                        help='skip the MoveArm benchmark (needs the built workspace)')
    args = parser.parse_args(argv)
    figures = bench_round_trips(args.samples, args.poll_seconds)
    figures.update(bench_client_moves(poll_period=0.02))
    if not args.skip_node:
        figures.update(bench_node_moves())
    return report(figures, args.json, machine=True)


if __name__ == '__main__':
    raise SystemExit(main())
