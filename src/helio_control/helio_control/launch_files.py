"""
``ros2 launch`` descriptions built from the graphs of ``helio_control.bringup``.

``launch/sim.launch.py`` and ``launch/rig.launch.py`` (installed to
``share/helio_control/launch``) call ``generate('sim' | 'rig')``: the nodes, their parameter
files, overrides, remaps and namespace come from ``bringup.node_entries``, the same entries
the project's own runner starts as processes, so the two ways to start a graph cannot drift
apart. Launch arguments: ``namespace``; sim: ``port_dir`` (where ``sim_world`` puts the
emulated devices' pseudo-terminals), ``real_time_factor``, ``output_dir``; rig:
``dobot_port``, ``servo_port``.

``launch`` and ``launch_ros`` are imported only when a description is generated (they come
with a ROS 2 installation; the pip wheels used in this workspace's CI have neither).
"""

from helio_control.bringup import DDS_PROFILE_ENV, hardware_graph, node_entries
from helio_control.bringup import node_environment, simulated_graph

LAUNCH_ARGUMENTS = {
    'sim': {'namespace': ('', 'namespace of every node (e.g. /rig1)'),
            'port_dir': ('/tmp/helio_sim', "directory of the emulated devices' ports"),
            'real_time_factor': ('1.0', 'simulated seconds per wall second (0: as fast as '
                                        'the graph keeps up)'),
            'output_dir': ('', 'sim_world writes canvas.png and dots.csv here at shutdown')},
    'rig': {'namespace': ('', 'namespace of every node (e.g. /rig1)'),
            'dobot_port': ('/dev/ttyUSB0', "the Dobot's serial port"),
            'servo_port': ('/dev/ttyACM0', "the servo controller's serial port")},
}


def graph_entries(graph, arguments):
    """Return the node entries of `graph` ('sim' or 'rig') for launch `arguments` (strings)."""
    namespace = arguments.get('namespace', '')
    if graph == 'sim':
        overrides = {'sim_world': {'real_time_factor': float(arguments['real_time_factor'])}}
        if arguments.get('output_dir'):
            overrides['sim_world']['output_dir'] = arguments['output_dir']
        return node_entries(simulated_graph(arguments['port_dir'], overrides=overrides),
                            namespace)
    if graph == 'rig':
        return node_entries(hardware_graph(arguments['dobot_port'], arguments['servo_port']),
                            namespace)
    raise ValueError(f'unknown graph {graph!r} (sim or rig)')


def launch_node_arguments(entry):
    """Return the keyword arguments of ``launch_ros.actions.Node`` for one node entry."""
    return {'package': entry['package'], 'executable': entry['executable'],
            'name': entry['name'], 'namespace': entry['namespace'] or None,
            'parameters': list(entry['parameter_files']) + [entry['parameters']],
            'remappings': list(entry['remaps'].items()), 'output': 'screen',
            'emulate_tty': True}


def generate(graph):
    """Return the LaunchDescription of `graph` ('sim' or 'rig')."""
    try:
        from launch import LaunchDescription
        from launch.actions import DeclareLaunchArgument, OpaqueFunction, SetEnvironmentVariable
        from launch.substitutions import LaunchConfiguration
        from launch_ros.actions import Node
    except ImportError as error:
        raise ImportError(f'ros2 launch needs the launch and launch_ros packages of a ROS 2 '
                          f'installation ({error}); without them run "helio {graph}"') \
            from None
    declared = LAUNCH_ARGUMENTS[graph]

    def nodes(context):
        values = {name: LaunchConfiguration(name).perform(context) for name in declared}
        return [Node(**launch_node_arguments(entry)) for entry in graph_entries(graph, values)]

    actions = [DeclareLaunchArgument(name, default_value=default, description=description)
               for name, (default, description) in declared.items()]
    profile = node_environment({}).get(DDS_PROFILE_ENV)
    if profile:
        actions.append(SetEnvironmentVariable(DDS_PROFILE_ENV, profile))
    return LaunchDescription(actions + [OpaqueFunction(function=nodes)])
