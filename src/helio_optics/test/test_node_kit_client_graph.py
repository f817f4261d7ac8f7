"""ClientGraph: the helio command's graph reaches nodes that run outside it."""

from helio_optics.node_kit.client_graph import ClientGraph, GraphFailure
from helio_optics.node_kit.in_process_graph import InProcessGraph
import pytest
from rcl_interfaces.srv import GetParameters
import rclpy


def test_a_client_graph_calls_a_service_of_a_node_in_another_graph():
    with InProcessGraph('served_graph') as served, ClientGraph('helio_client') as client:
        node = served.add(rclpy.create_node('served_node', context=served.context))
        node.declare_parameter('answer', 42)
        client.wait_for_nodes(['served_node'], 10.0)
        reply = client.call(client.helper.create_client(GetParameters,
                                                        'served_node/get_parameters'),
                            GetParameters.Request(names=['answer']), 10.0)
        assert [value.integer_value for value in reply.values] == [42]
        assert client.nodes == []          # a client graph spins no node but its helper


def test_a_failed_graph_ends_a_wait_at_once_with_the_reason():
    with ClientGraph('helio_client_failing') as graph:
        graph.fail('dobot_driver died')
        with pytest.raises(GraphFailure, match='dobot_driver died'):
            graph.wait_until(lambda: False, 30.0, 'nothing')
