"""
The in-process graph of the node tests: a ``ClientGraph`` with the nodes under test in it.

``ClientGraph`` (``client_graph``) is the client side of a graph, as the ``helio`` command
uses it; a node test also spins the nodes it tests with the same executor, in the same
private Context: ``node_options`` builds a node there, ``add`` spins it.

Usage::

    with InProcessGraph() as graph:
        node = graph.add(SunEstimatorNode(**graph.node_options(rig_file=path)))
        estimates = graph.collect(SunEstimate, 'sun/estimate', TRANSIENT_LOCAL_QOS)
        response = graph.call(graph.helper.create_client(EstimateSun, 'estimate_sun'), request)
        estimates.wait_for_count(1)

The waits, ``GraphTimeout``/``GraphFailure``, ``Collector`` and the QoS are the client
graph's, imported here under their old home for the tests that name them from it.
"""

from helio_optics.node_kit.client_graph import ClientGraph
from helio_optics.node_kit.client_graph import Collector  # noqa: F401 - the tests' names
from helio_optics.node_kit.client_graph import DEFAULT_TIMEOUT  # noqa: F401
from helio_optics.node_kit.client_graph import GraphFailure, GraphTimeout  # noqa: F401
from helio_optics.node_kit.client_graph import TRANSIENT_LOCAL_QOS  # noqa: F401
from helio_optics.node_kit.client_graph import wait_for_future  # noqa: F401
from rclpy.parameter import Parameter


class InProcessGraph(ClientGraph):
    """See the module docstring."""

    def __init__(self, helper_name='helio_test_helper', namespace=''):
        """Start the client graph with a test's helper node (`helper_name`)."""
        super().__init__(helper_name, namespace)

    def node_options(self, **parameters):
        """Keyword arguments that build a node in this graph with `parameters` overridden."""
        options = {'context': self.context, 'parameter_overrides': [
            Parameter(name, value=value) for name, value in parameters.items()]}
        if self.namespace:
            options['namespace'] = self.namespace
        return options

    def add(self, node):
        """Spin `node` (built with ``node_options()``) with the graph; return it."""
        self.nodes.append(node)
        self.executor.add_node(node)
        return node
