"""
Stopping the whole graph mid-dot takes the focus off the wood first (issue 30, item 1).

The graph of processes is stopped as ``helio sim`` and ``helio rig`` stop it on Ctrl-C or
SIGTERM (``ProcessGroup.stop`` of ``bringup.start_graph``): the painter first (its running
painting ends as a cancel does: the lens retreated through the lens planner), then the lens
planner (it retreats a lens still at the heating distance), and only then the drivers, the
perception nodes and the world. Judged by the world's truth (``sim/truth/light``: the peak
irradiance on the panel), which runs to the end: the focus is off the wood within 0.5 s of
simulated time of the stop. Before, every node got the signal at once and the lens stayed
where it was.
"""

from conftest import graph_of_processes
from helio_control.run_journal import read_journal
from test_painter_safety import dots_along, EVENT_PACE, NODES, OFF_BOUND, Rig


def test_stopping_the_graph_mid_dot_puts_the_focus_off_the_wood_within_half_a_second(
        tmp_path):
    overrides = {'sim_world': {'real_time_factor': 0.0, 'flux_rays': 20000,
                               'truth_period': 0.05, 'pace_max_lag': 0.0},
                 'lens_planner': {'calibration_dir': str(tmp_path / 'calibration')},
                 'painter': {'runs_dir': str(tmp_path / 'runs')}}
    with graph_of_processes(tmp_path, NODES, overrides) as (group, graph):
        rig = Rig(group, graph, tmp_path / 'runs')
        on_feedback, heating = rig.heating(index=0, n_p=5)
        handle = rig.send(dots_along(0.08, 1), 'stopped', on_feedback=on_feedback)
        rig.wait(heating, 'dot 0 heating', handle)
        rig.set_world(real_time_factor=EVENT_PACE)      # the graph's reaction, not the pace
        rig.wait_sim(0.3)
        reference = rig.heating_peak()
        since = rig.now()
        outcomes = group.stop()                         # what Ctrl-C of helio sim does
        off, share = rig.off_after(since, reference)
    print(f'\nstop: {outcomes}; focus off the wood {off - since:.2f} s (sim) after it, peak '
          f'irradiance down to {share * 100:.1f} % of the heating peak')
    assert off - since <= OFF_BOUND
    assert outcomes['painter'] == 'SIGINT' and outcomes['lens_planner'] == 'SIGINT'
    journal = read_journal(str(tmp_path / 'runs' / 'stopped' / 'journal.jsonl'))
    assert journal.result is not None and not journal.result.success
    assert journal.result.message.startswith('stopped by a stop signal: retreated')
