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
    assert all(isinstance(value, float) for value in figures.values())
