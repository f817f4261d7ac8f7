"""InProcessGraph.wait_for_nodes: a node counts as up only once it spins."""

import time

from helio_optics.node_kit.in_process_graph import GraphTimeout, InProcessGraph
import pytest
import rclpy


def test_a_spinning_node_is_up_and_a_constructed_one_is_not():
    with InProcessGraph('wait_for_nodes_test') as graph:
        graph.add(rclpy.create_node('spinning_node', context=graph.context))
        graph.wait_for_nodes(['spinning_node'], 10.0)
        # in the graph (discoverable) but not spinning: its constructor has not returned yet,
        # as a node process still importing or warming up
        idle = rclpy.create_node('idle_node', context=graph.context)
        try:
            graph.wait_until(lambda: 'idle_node' in graph.helper.get_node_names(), 10.0,
                             'idle_node discovered')
            started = time.monotonic()
            with pytest.raises(GraphTimeout, match='idle_node did not answer within 1 s'):
                graph.wait_for_nodes(['spinning_node', 'idle_node'], 1.0)
            assert time.monotonic() - started < 5.0
        finally:
            idle.destroy_node()


def test_a_missing_node_is_named_when_the_wait_ends():
    with InProcessGraph('wait_for_nodes_missing') as graph:
        with pytest.raises(GraphTimeout, match='no_such_node did not answer'):
            graph.wait_for_nodes(['no_such_node'], 0.5)
