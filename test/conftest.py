"""Shared pieces of the system tests: the simulated graph as processes, and a client."""

import contextlib
import os
import signal

from helio_control.bringup import simulated_graph, start_graph, wait_until_up
from helio_optics.node_kit.in_process_graph import InProcessGraph

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# The node processes run in their own sessions (a terminal's Ctrl-C is for the test, which
# then stops them). SIGTERM, as test.sh's HELIO_TEST_TIMEOUT sends it, would end pytest at
# once and leave every started graph running; as Ctrl-C it runs the fixtures' teardown.
signal.signal(signal.SIGTERM, signal.default_int_handler)

# a started graph's nodes all spin and its drivers hold their devices within this [s]
GRAPH_UP_TIMEOUT = 120.0


@contextlib.contextmanager
def graph_of_processes(tmp_path, nodes, overrides=None, namespace='',
                       client_name='system_test_client', may_die=()):
    """
    Start the simulated graph's `nodes` as processes and yield (ProcessGroup, client graph).

    The client graph (an InProcessGraph in the test's process, same namespace) fails every
    wait at once when a node process dies, naming it with its last log lines, except the
    nodes named in `may_die` (a test that kills one). Everything is stopped on exit
    (SIGINT, then SIGTERM, then SIGKILL).
    """
    # a test's painter paints the ideal world without the rig calibration (issue 28) unless
    # it asks for it: the calibration costs a minute of rig time per graph
    overrides = {node: dict(values) for node, values in (overrides or {}).items()}
    overrides.setdefault('painter', {}).setdefault('calibrate_rig', 'never')
    # nor the dot-size test row (issue 29): a test that wants it sets calibrate_dots
    overrides['painter'].setdefault('calibrate_dots', 'never')
    specs = simulated_graph(str(tmp_path / 'ports'), nodes, overrides)

    def on_death(process):
        if process.label not in may_die:
            client.fail(f'{process.label} exited with status {process.returncode()}; '
                        f'last log lines:\n{process.tail()}')

    with InProcessGraph(client_name, namespace=namespace) as client:
        group = start_graph(specs, namespace, log_dir=str(tmp_path / 'logs'),
                            on_death=on_death)
        try:
            wait_until_up(client, specs, GRAPH_UP_TIMEOUT)
            yield group, client
        finally:
            outcomes = group.stop()
            late = {label: how for label, how in outcomes.items() if how != 'SIGINT'}
            if late:        # a node that ignores Ctrl-C costs every test the 10 s wait
                print(f'\nnodes not stopped by SIGINT: {late}')
