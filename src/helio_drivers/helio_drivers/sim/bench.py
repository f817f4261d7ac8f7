"""
Benchmarks of the simulated world (issue 6): per-step costs and the real-time factor.

    python -m helio_drivers.sim.bench --json PATH

Figures (flat JSON, units in the names):

- ``sim_heat_step_ms_median``: one wood solver step (default grid, Douglas ADI);
- ``sim_flux_trace_ms_median``: re-tracing the lens (all spectral bands) after a move;
- ``sim_flux_bin_ms_median``: binning the rays and the shadow onto the heat patch;
- ``sim_thermal_frame_ms_median``, ``sim_rgb_frame_ms_median``: rendering one frame;
- ``sim_world_step_ms_median``: one world step with the lens held (heating a dot);
- ``sim_core_real_time_factor``: the world alone, lens focused, thermal frames at 8.7 Hz and
  RGB frames at 5 Hz of simulated time, stepping as fast as it can;
- ``sim_node_real_time_factor``: the ``sim_world`` node (real rclpy, Fast DDS) at
  ``real_time_factor`` 0 with subscribers on both cameras, over ``--node-seconds`` of wall
  time (skipped with ``--skip-node``).

Target (issue 6): at least 10x real time on the 2-core machine.
"""

import argparse
import os
import tempfile
import time

from helio_drivers.sim.flux import irradiance_on_cells, lens_pose_in_world
from helio_drivers.sim.truth import true_sun_focus_joints
from helio_drivers.sim.world import SimSettings, SimWorld
from helio_optics.bench_report import add_json_option, median_call_ms, report
from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters
from helio_optics.rig_kinematics import RigParameters


def _rig():
    path = default_rig_file()
    return (load_rig_parameters(path) if path else RigParameters()), path


def bench_costs(rig, repeats=30):
    """Return the per-step and per-frame costs [ms] of the world's parts."""
    world = SimWorld(SimSettings(), rig)
    world.set_joints(true_sun_focus_joints(world, (0.07, 0.07, 0.0), 0.082))
    world.run(2.0)
    figures = {}
    irradiance = world._dni * world._unit_irradiance
    figures['sim_heat_step_ms_median'] = median_call_ms(
        lambda: world.panel.step(world.settings.step, irradiance, 900.0), repeats)
    s0 = world.sun_ray_world()
    poses = [lens_pose_in_world(world.T_robot_world,
                                world.rig.forward(true_sun_focus_joints(
                                    world, (0.07, 0.07 + 1e-3 * k, 0.0), 0.082)).T_robot_lens)
             for k in range(repeats)]
    fields = []
    figures['sim_flux_trace_ms_median'] = median_call_ms(
        lambda: fields.append(world.flux.field(poses[len(fields)], s0)), repeats)
    figures['sim_flux_bin_ms_median'] = median_call_ms(
        lambda: irradiance_on_cells(fields[-1], world.panel.x_edges, world.panel.y_edges,
                                    900.0), repeats)
    figures['sim_thermal_frame_ms_median'] = median_call_ms(world.thermal_image, repeats)
    figures['sim_rgb_frame_ms_median'] = median_call_ms(world.rgb_image, repeats)
    world.set_joints(true_sun_focus_joints(world, (0.07, 0.07, 0.0), 0.082))
    figures['sim_world_step_ms_median'] = median_call_ms(world.step, 4 * repeats)
    return figures


def bench_core_real_time_factor(rig, seconds=20.0, thermal_rate=8.7, rgb_rate=5.0):
    """Return the real-time factor of the world loop with both cameras rendering."""
    world = SimWorld(SimSettings(), rig)
    world.set_joints(true_sun_focus_joints(world, (0.07, 0.07, 0.0), 0.082))
    next_thermal = next_rgb = 0.0
    start = time.perf_counter()
    while world.time < seconds:
        world.step()
        if world.time >= next_thermal:
            world.thermal_image()
            next_thermal += 1.0 / thermal_rate
        if world.time >= next_rgb:
            world.rgb_image()
            next_rgb += 1.0 / rgb_rate
    return {'sim_core_real_time_factor': world.time / (time.perf_counter() - start)}


def bench_node_real_time_factor(rig_file, wall_seconds=15.0):
    """Run sim_world (real rclpy) as fast as it goes with camera subscribers; return its RTF."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image
    from helio_drivers.sim.world_node import SimWorldNode

    context = rclpy.context.Context()
    rclpy.init(context=context)
    counts = {'rgb': 0, 'thermal': 0}
    try:
        with tempfile.TemporaryDirectory(prefix='helio_bench_') as ports:
            overrides = [Parameter('real_time_factor', value=0.0),
                         Parameter('dobot_port', value=os.path.join(ports, 'dobot')),
                         Parameter('servo_port', value=os.path.join(ports, 'servo'))]
            if rig_file:
                overrides.append(Parameter('rig_file', value=rig_file))
            node = SimWorldNode(context=context, parameter_overrides=overrides)
            probe = rclpy.create_node('sim_bench_probe', context=context)
            for name in counts:
                probe.create_subscription(
                    Image, f'/{name}/image_raw',
                    lambda _, name=name: counts.__setitem__(name, counts[name] + 1),
                    qos_profile_sensor_data, raw=True)  # another process would deserialise
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(node)
            executor.add_node(probe)
            end = time.monotonic() + wall_seconds
            try:
                while time.monotonic() < end:
                    executor.spin_once(timeout_sec=0.1)
                factor = node.achieved_real_time_factor
                simulated = node.world.time
            finally:
                executor.shutdown()
                node.destroy_node()
                probe.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    return {'sim_node_real_time_factor': factor,
            'sim_node_rgb_frames_per_sim_s': counts['rgb'] / max(simulated, 1e-9),
            'sim_node_thermal_frames_per_sim_s': counts['thermal'] / max(simulated, 1e-9)}


def bench_sim(skip_node=False, node_seconds=15.0):
    """Run every sim benchmark and return the flat figures."""
    rig, rig_file = _rig()
    figures = bench_costs(rig)
    figures.update(bench_core_real_time_factor(rig))
    if not skip_node:
        figures.update(bench_node_real_time_factor(rig_file, node_seconds))
    return figures


def main(argv=None):
    """Run the benchmarks, print the figures and write them as flat JSON."""
    parser = argparse.ArgumentParser(description='Benchmarks of the simulated world.')
    add_json_option(parser)
    parser.add_argument('--skip-node', action='store_true',
                        help='skip the sim_world node run (needs the built workspace)')
    parser.add_argument('--node-seconds', type=float, default=15.0,
                        help='wall time of the node run [s] (default 15)')
    args = parser.parse_args(argv)
    figures = bench_sim(args.skip_node, args.node_seconds)
    return report({name: round(float(value), 6) for name, value in figures.items()}, args.json)


if __name__ == '__main__':
    raise SystemExit(main())
