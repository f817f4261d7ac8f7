"""
The graphs helio runs, each described once.

Which nodes, with which parameter files, overrides and remaps, under which namespace.

``simulated_graph`` is the rig without hardware: ``sim_world`` hosts the emulated Dobot and
Maestro on pseudo-terminals and publishes the cameras and ``/clock``; the real driver nodes
connect to its ports; every other node runs on simulated time. ``hardware_graph`` is the
real rig: the drivers on the serial ports of the Dobot and the servo controller, camera
driver nodes the user names (``CameraSpec``), no ``sim_world``, wall time.

The controller's nodes (``CONTROLLER_NODES``) are in both graphs: adding a node to helio
is one line there (or in ``WORLD_NODES``/``DRIVER_NODES``). From a description,
``start_graph`` starts every node as its own process (``helio_optics.node_kit.processes``),
each the installed executable a user would ``ros2 run``, with the workspace's Fast DDS
profile for camera images in its environment; ``supervise`` waits on such a group the way
``helio sim``/``helio rig`` do; ``helio_control.launch_files`` builds the ``ros2 launch``
description from the same entries (``node_entries``).

What the hardware graph expects from the camera drivers (topics relative to the graph's
namespace): ``rgb/image_raw`` (sensor_msgs/Image, rgb8/bgr8/mono8) with
``rgb/camera_info`` (calibrated intrinsics), and ``thermal/image_raw`` (sensor_msgs/Image
16UC1 in centikelvin, as a radiometric FLIR Lepton sends it; 32FC1 in degC also works) with
``thermal/camera_info``. A ``usb_cam`` or ``v4l2_camera`` node publishes ``image_raw`` and
``camera_info``: ``CameraSpec`` remaps those two names into ``rgb/`` or ``thermal/``.
"""

import contextlib
from dataclasses import dataclass, field
import os
import signal
import sys
import threading
import time

from helio_optics.config_files import config_path
from helio_optics.node_kit.processes import NodeProcess, ProcessGroup

DDS_PROFILE_ENV = 'FASTRTPS_DEFAULT_PROFILES_FILE'
# Reply timeout per attempt of both drivers against the emulated devices [s]. A real Dobot
# answers within 0.2 s and a Maestro within 0.1 s (the drivers' defaults); the emulators
# answer from threads of the sim_world process, which shares a 2-core machine with the whole
# graph, and stalled past three such attempts when eight processes started at once: the
# first move of a graph then failed with "no 2-byte reply within 0.100 s after 3 attempts"
# (twice in six full test runs, 2026-11-24). The in-process driver tests use 0.5 s too.
SIMULATED_DEVICE_REPLY_TIMEOUT = 0.5
# ... and no request waits more than this in all, attempts and the Maestro's waits for late
# replies together [s]: with 0.5 s a reply, a frozen world (a stalled sim_world: both devices
# silent) ended the Dobot's move after 1.5 s and the Maestro's after 3.0 s; issue 35 asks
# for 1.5 s at most. Twice the reply timeout still rides out one late reply.
SIMULATED_SILENCE_TIMEOUT = 1.0
# Longest delay between the drivers' attempts to open the emulated devices [s]. The drivers
# start beside the world, which opens its ptys seconds later (it compiles or loads its
# kernels first); with a real device's 5 s cap the doubling delays (0.2, 0.4 ... 3.2 s) left
# a driver up to 3.2 s late. A pty that is not there yet costs a failed open(), nothing more.
SIMULATED_RECONNECT_MAX = 0.5


@dataclass
class NodeSpec:
    """One node of a graph: its executable, its package's parameter file and overrides."""

    package: str
    executable: str
    config: str = ''                    # file under share/<package>/config ('' for none)
    parameters: dict = field(default_factory=dict)
    sim_time: bool = True               # run on /clock (every node but the world itself)
    remaps: dict = field(default_factory=dict)
    node_name: str = ''                 # '' : the executable's name

    @property
    def name(self):
        """Return the node's name: node_name, else the executable's."""
        return self.node_name or self.executable


WORLD_NODES = (
    NodeSpec('helio_drivers', 'sim_world', 'sim_world.yaml', sim_time=False),
)
DRIVER_NODES = (
    NodeSpec('helio_drivers', 'dobot_driver', 'dobot_driver.yaml'),
    NodeSpec('helio_drivers', 'servo_driver', 'servo_driver.yaml'),
)
CONTROLLER_NODES = (
    NodeSpec('helio_perception', 'spot_detector', 'spot_detector.yaml'),
    NodeSpec('helio_perception', 'thermal_monitor', 'thermal_monitor.yaml'),
    NodeSpec('helio_optics', 'sun_estimator', 'sun_estimator.yaml'),
    NodeSpec('helio_control', 'lens_planner', 'lens_planner.yaml'),
    NodeSpec('helio_control', 'painter', 'painter.yaml'),
)
SIMULATED_NODES = WORLD_NODES + DRIVER_NODES + CONTROLLER_NODES
# the nodes that read calibrations back from their calibration_dir at start
CALIBRATED_NODES = ('spot_detector', 'lens_planner', 'painter')
HARDWARE_NODES = DRIVER_NODES + CONTROLLER_NODES


class GraphError(ValueError):
    """A graph description that cannot be built (unknown node, bad camera spec, ...)."""


@dataclass
class CameraSpec:
    """
    A camera driver node of the hardware graph: ``package/executable`` and its remaps.

    `kind` is ``rgb`` or ``thermal``; the driver's ``image_raw`` and ``camera_info`` are
    remapped to ``<kind>/image_raw`` and ``<kind>/camera_info`` unless `remaps` says
    otherwise; `parameters` go to the driver (e.g. ``video_device``).
    """

    kind: str
    driver: str                          # 'usb_cam/usb_cam_node_exe', 'v4l2_camera/...'
    parameters: dict = field(default_factory=dict)
    remaps: dict = field(default_factory=dict)

    def node_spec(self):
        """Return the NodeSpec of this camera driver."""
        if self.kind not in ('rgb', 'thermal'):
            raise GraphError(f'camera kind must be rgb or thermal, not {self.kind!r}')
        package, _, executable = self.driver.partition('/')
        if not package or not executable or '/' in executable:
            raise GraphError(f'camera driver must be PACKAGE/EXECUTABLE, not {self.driver!r}')
        remaps = {'image_raw': f'{self.kind}/image_raw',
                  'camera_info': f'{self.kind}/camera_info', **self.remaps}
        return NodeSpec(package, executable, '', dict(self.parameters), sim_time=False,
                        remaps=remaps, node_name=f'{self.kind}_camera')


def package_config(package, name):
    """Return the installed share/<package>/config/<name>."""
    from ament_index_python.packages import get_package_share_directory
    return os.path.join(get_package_share_directory(package), 'config', name)


def simulated_graph(port_dir, nodes=None, overrides=None):
    """
    Return the NodeSpecs of the simulated rig, its emulated ports in `port_dir`.

    `nodes` picks executables by name (default all); `overrides` maps an executable to extra
    parameters (e.g. ``{'sim_world': {'real_time_factor': 5.0}}``).
    """
    dobot_port = os.path.join(port_dir, 'dobot')
    servo_port = os.path.join(port_dir, 'servo')
    link = {'timeout': SIMULATED_DEVICE_REPLY_TIMEOUT,
            'silence_timeout': SIMULATED_SILENCE_TIMEOUT,
            'reconnect_max': SIMULATED_RECONNECT_MAX}
    # the simulated rig's calibrations stay with its graph: never in the real rig's directory
    # (~/.helio/calibration), which the lens planner, the painter and the spot detector read
    # back at start (issue 30)
    calibrations = {'calibration_dir': os.path.join(port_dir, 'calibration')}
    wiring = {'sim_world': {'dobot_port': dobot_port, 'servo_port': servo_port},
              'dobot_driver': {'port': dobot_port, **link},
              'servo_driver': {'port': servo_port, **link},
              **{node: dict(calibrations) for node in CALIBRATED_NODES}}
    return _select(SIMULATED_NODES, 'simulated', wiring, nodes, overrides)


def hardware_graph(dobot_port, servo_port, cameras=(), nodes=None, overrides=None):
    """
    Return the NodeSpecs of the real rig: drivers on `dobot_port` and `servo_port`.

    `cameras` are CameraSpecs (none: the camera topics come from drivers started
    elsewhere); every node runs on wall time. `nodes` and `overrides` as for
    `simulated_graph`.
    """
    for name, port in (('Dobot', dobot_port), ('servo controller', servo_port)):
        if not port:
            raise GraphError(f'the {name} port is required (e.g. /dev/ttyUSB0)')
    wiring = {'dobot_driver': {'port': dobot_port}, 'servo_driver': {'port': servo_port}}
    specs = _select(HARDWARE_NODES, 'hardware', wiring, nodes, overrides)
    for spec in specs:
        spec.sim_time = False
    return specs + [camera.node_spec() for camera in cameras]


def _select(catalogue, graph, wiring, nodes, overrides):
    """Return copies of `catalogue`'s specs picked by `nodes`, with wiring and overrides."""
    overrides = overrides or {}
    known = {spec.name for spec in catalogue}
    for what, names in (('overrides for', set(overrides)), ('unknown', set(nodes or ()))):
        unknown = names - known
        if unknown:
            raise GraphError(f'{what} nodes not in the {graph} graph: {sorted(unknown)} '
                             f'(nodes: {", ".join(spec.name for spec in catalogue)})')
    specs = []
    for spec in catalogue:
        if nodes is not None and spec.name not in nodes:
            continue
        parameters = {**wiring.get(spec.name, {}), **spec.parameters,
                      **overrides.get(spec.name, {})}
        specs.append(NodeSpec(spec.package, spec.executable, spec.config, parameters,
                              spec.sim_time, dict(spec.remaps), spec.node_name))
    return specs


def node_environment(base=None):
    """Return the environment for node processes: `base` plus the camera DDS profile."""
    environment = dict(os.environ if base is None else base)
    profile = config_path('fastdds_large_images.xml', required=False)
    if profile and DDS_PROFILE_ENV not in environment:
        environment[DDS_PROFILE_ENV] = profile
    return environment


def node_entries(specs, namespace=''):
    """
    Return what starts each node, as plain data: the one source of processes and launch.

    One dict per NodeSpec: package, executable, name, namespace, parameter_files (installed
    paths), parameters (overrides, ``use_sim_time`` included), remaps.
    """
    entries = []
    for spec in specs:
        parameters = dict(spec.parameters)
        if spec.sim_time:
            parameters.setdefault('use_sim_time', True)
        entries.append({
            'package': spec.package, 'executable': spec.executable, 'name': spec.name,
            'namespace': namespace,
            'parameter_files': [package_config(spec.package, spec.config)]
            if spec.config else [],
            'parameters': parameters, 'remaps': dict(spec.remaps)})
    return entries


def node_processes(specs, namespace='', log_dir=None, env=None):
    """Return a NodeProcess per NodeSpec (not started)."""
    environment = node_environment(env)
    return [NodeProcess(entry['package'], entry['executable'], entry['parameters'],
                        entry['parameter_files'], entry['remaps'],
                        namespace=entry['namespace'], name=entry['name'], log_dir=log_dir,
                        env=environment)
            for entry in node_entries(specs, namespace)]


# Stopped first, one after the other, while the rest of the graph runs (issue 30): the
# painter ends a painting as a cancel does (the lens retreated through the lens planner),
# then the lens planner retreats a lens still at the heating distance (a painter that was
# killed); the drivers and the world stop after them.
SAFE_STOP_ORDER = ('painter', 'lens_planner')


def start_graph(specs, namespace='', log_dir=None, env=None, on_death=None):
    """Start the described nodes as processes; return the running ProcessGroup."""
    return ProcessGroup(node_processes(specs, namespace, log_dir, env), on_death,
                        stop_first=SAFE_STOP_ORDER).start()


# the device each driver node holds (its latched ``<device>/status``)
DRIVER_DEVICES = {'dobot_driver': 'dobot', 'servo_driver': 'servo'}


def wait_for_devices(graph, timeout, devices=('dobot', 'servo')):
    """
    Wait until each driver's latched `<device>/status` says it holds its (emulated) device.

    `graph` is a ``ClientGraph``. A driver started before the world retries the world's
    pty with a growing delay (0.2 s, doubled each time up to the simulated graph's
    ``reconnect_max`` of 0.5 s), so it connects up to 0.5 s after the world opened its ports.
    """
    from helio_msgs.msg import DeviceStatus
    from helio_optics.node_kit import topics
    from helio_optics.node_kit.client_graph import TRANSIENT_LOCAL_QOS
    for device in devices:
        graph.collect(DeviceStatus, topics.device_status(device), TRANSIENT_LOCAL_QOS) \
            .wait_for_message(lambda status: status.connected, timeout)


def wait_until_up(graph, specs, timeout):
    """
    Wait until every node of `specs` spins and each of their drivers holds its device.

    Eight node processes starting at once keep a 2-core machine busy for seconds (imports,
    the world's kernels): a goal sent as soon as the painter answers moved the wrist while
    the world's emulators were starved, and the move failed as a silent device (CI,
    2026-11-28: "servo controller not connected ... no valid reply within the silence limit
    of 1.000 s"). A started graph is handed over only once it is up.
    """
    deadline = time.monotonic() + timeout
    graph.wait_for_nodes([spec.name for spec in specs], timeout)
    devices = [DRIVER_DEVICES[spec.name] for spec in specs if spec.name in DRIVER_DEVICES]
    wait_for_devices(graph, max(deadline - time.monotonic(), 0.0), devices)


@contextlib.contextmanager
def interrupts_deferred():
    """
    Hold Ctrl-C (SIGINT) and SIGTERM while processes start; raise KeyboardInterrupt after.

    A KeyboardInterrupt inside ``subprocess.Popen`` can come after the child was forked but
    before its handle is kept, and that child would be left running. Inside this block the
    signals are only noted; on leaving it (the handles kept) a noted one raises
    KeyboardInterrupt. The signal mask is not touched, so started nodes get Ctrl-C as usual.
    """
    noted = []
    previous = {signum: signal.signal(signum, lambda signum, frame: noted.append(signum))
                for signum in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    if noted:
        raise KeyboardInterrupt


def run_supervised(specs, namespace='', log_dir=None, env=None, stream=None,
                   stop_timeouts=(10.0, 5.0), on_started=None):
    """
    Start the described nodes and supervise them until Ctrl-C, SIGTERM or a node's death.

    A node that dies is reported at once on `stream` (default stderr) with its exit status
    and last log lines, and the rest of the graph is stopped: a rig with a dead node is not
    safe to drive. Ctrl-C (SIGINT) and SIGTERM stop every node (SIGINT, then SIGTERM, then
    SIGKILL after `stop_timeouts`); no process is left behind. `on_started(group)` runs once
    all processes are started. Return the exit status: 1 after a death, 130 after Ctrl-C,
    143 after SIGTERM.
    """
    stream = stream or sys.stderr
    ended = threading.Event()
    reason = {}

    def death(process):
        if 'death' not in reason and 'signal' not in reason:
            reason['death'] = process
            print(f'[helio] node {process.label} died (exit status {process.returncode()}); '
                  f'its last log lines ({process.log_path}):\n{process.tail().rstrip()}',
                  file=stream, flush=True)
        ended.set()

    def terminated(signum, frame):
        reason.setdefault('signal', signum)
        ended.set()

    previous = {signum: signal.signal(signum, terminated)
                for signum in (signal.SIGINT, signal.SIGTERM)}
    group = None
    try:
        group = start_graph(specs, namespace, log_dir, env, on_death=death)
        if on_started is not None:
            on_started(group)
        while not ended.wait(0.5):
            pass
    finally:
        if group is not None:
            outcomes = group.stop(*stop_timeouts)
            stopped = ', '.join(f'{label} ({how})' for label, how in outcomes.items())
            print(f'[helio] stopped: {stopped}', file=stream, flush=True)
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    if 'death' in reason:
        return 1
    return 143 if reason.get('signal') == signal.SIGTERM else 130
