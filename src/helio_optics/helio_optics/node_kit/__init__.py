"""
The node kit: what every helio node and node test shares, in one place.

helio_optics is the lowest Python package of the workspace, so every other package imports
this without importing upward.

- ``runner.run_node``: the ``main()`` of every node (spin until Ctrl-C, clean up).
- ``parameters.declare``: parameters with descriptors, ranges, read-only after start-up
  unless dynamic, and the one rule for units in parameter names.
- ``joint_states.JointStateBuffer``: partial ``/joint_states`` merged by name, history on the
  node clock, "joints at stamp t" with a staleness bound.
- ``rig.declare_rig``: the rig model from the ``rig_file`` parameter.
- ``conversions``: Image, CameraInfo, stamps, points and poses <-> numpy.
- ``diagnostics.diagnostic_array``: one status on ``/diagnostics``.
- ``process_tuning``: buffer reuse and frozen start-up objects for frame-rate nodes.
- ``client_graph.ClientGraph``: a client's graph (private Context, helper node, executor
  thread, waits that never sleep): how the ``helio`` command talks to a running graph.
- ``in_process_graph.InProcessGraph``: a ClientGraph with the nodes under test spun in it,
  the in-process graph every node test uses.
- ``processes``: nodes as separate processes (tests, bringup).
"""
