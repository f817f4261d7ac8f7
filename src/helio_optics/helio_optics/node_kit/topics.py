"""
The graph's topic names, written once (issue 32).

Every name is relative (resolved in the graph's namespace, so two rigs can share a domain),
except ``/clock`` and ``/diagnostics``, which ROS 2 tools expect at the root. Nodes, the
``helio`` command, the recorder, the report and the tests take the names from here; the
parameter files name only what a user remaps (e.g. ``sim_world``'s ``lockstep_topic``).
"""

# the drivers' partial joint states, merged by name (node_kit.joint_states)
JOINT_STATES = 'joint_states'
# the cameras, as ROS camera drivers publish them under the rgb/ and thermal/ prefixes
RGB_IMAGE = 'rgb/image_raw'
RGB_CAMERA_INFO = 'rgb/camera_info'
THERMAL_IMAGE = 'thermal/image_raw'
THERMAL_CAMERA_INFO = 'thermal/camera_info'
# the perception nodes' answers: the spot observation of each RGB image, the thermal
# statistics of each thermal image, and the window N_p is counted in
SPOT = 'spot'
THERMAL_STATS = 'thermal/stats'
THERMAL_WINDOW = 'thermal/window'
# the sun estimator's estimate (latched)
SUN_ESTIMATE = 'sun/estimate'
# the painter's heartbeat: the lens planner's focus lease, and the world's lockstep
PAINTER_HEARTBEAT = 'painter/heartbeat'
# the lens planner's focal calibration (latched)
FOCUS_CALIBRATION = 'calibration/focus'
# the lens planner's heating and retreat distances, calibrated or not (latched)
FOCUS_DISTANCES = 'focus/distances'
# the simulated world's top view of the char map (tests, the report)
SIM_CANVAS = 'sim/canvas'


def device_status(device):
    """Return the latched status topic of the driver of `device` ('dobot', 'servo')."""
    return f'{device}/status'
