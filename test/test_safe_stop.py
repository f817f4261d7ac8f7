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
from test_painter_safety import NODES, OFF_BOUND, one_graph_overrides, painting_interrupted
from test_painter_safety import Rig


def test_stopping_the_graph_mid_dot_puts_the_focus_off_the_wood_within_half_a_second(
        tmp_path):
    outcomes = {}

    def stop(_handle):
        since = rig.now()
        outcomes.update(group.stop())               # what Ctrl-C of helio sim does
        return since

    with graph_of_processes(tmp_path, NODES, one_graph_overrides(tmp_path)) as (group, graph):
        rig = Rig(group, graph, tmp_path / 'runs')
        delay, _ = painting_interrupted(rig, 'stopped', 0.08, stop)
    print(f'stop: {outcomes}')
    assert delay <= OFF_BOUND
    assert outcomes['painter'] == 'SIGINT' and outcomes['lens_planner'] == 'SIGINT'
    journal = read_journal(str(tmp_path / 'runs' / 'stopped' / 'journal.jsonl'))
    assert journal.result is not None and not journal.result.success
    assert journal.result.message.startswith('stopped by a stop signal: retreated')
