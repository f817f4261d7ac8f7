"""
The rig's procedures as plain coroutines, each against one port object (issue 32).

A procedure (a focus, a calibration, the sun sweep: ``lens_rig_port``; a painting run and
its dots: ``painter_port``) awaits its port for every move, observation and answer of the
graph, so it runs inside the node (the port wraps the actions and topics) and in-process in
a test (the port is a model of the rig). No rclpy.
"""
