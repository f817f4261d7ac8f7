"""The sim benchmark runs end to end (briefly) and writes flat JSON with units in the keys."""

import json

from helio_drivers.sim import bench


def test_sim_bench_reports_heating_moving_and_a_whole_painting(tmp_path):
    path = tmp_path / 'sim_bench.json'
    assert bench.main(['--quick', '--skip-node', '--skip-busy', '--json', str(path)]) == 0
    figures = json.loads(path.read_text())
    for phase in ('heating', 'moving', 'painting'):
        for clock in ('wall', 'cpu'):
            assert figures[f'sim_{phase}_rtf_{clock}'] > 0.0
    # the painting ran Algorithm 1 to the end: a dot heats ~18 s and cools ~3 s
    assert figures['sim_painting_simulated_s'] > 15.0
    for part in ('sim_heat_step', 'sim_thermal_frame', 'sim_rgb_frame',
                 'sim_rgb_frame_moving', 'sim_flux_trace'):
        assert figures[f'{part}_ms_median'] > 0.0
    # the machine it ran on (helio_optics.bench_report.machine_figures)
    assert figures['machine_python_loop_ns'] > 0.0 and figures['machine_memory_copy_gb_s'] > 0.0
    assert all(isinstance(value, float) for value in figures.values())


def test_the_node_bench_keeps_the_arm_moving_and_counts_the_frames_it_receives():
    figures = bench.bench_node(bench._rig()[1], wall_seconds=1.5, busy=False)
    for phase in ('heating', 'moving'):
        assert figures[f'sim_node_{phase}_rtf_wall'] > 0.0
        assert figures[f'sim_node_{phase}_thermal_hz'] > 0.0
    # the drivers' poll cadence (every 20 ms of wall time) over 1.5 s: at most 80 polls; at
    # least one (a loaded machine gave 9 of the 75 an idle one gives: a count, not a target)
    assert 1.0 <= figures['sim_node_moving_polls'] <= 80.0
    assert 'sim_node_moving_queue_drained' in figures
    assert all(isinstance(value, float) for value in figures.values())
