"""
``helio doctor`` against the simulated rig, as a user runs it (issue 30, item 6).

The simulated rig starts once for the module: the world (its emulated Dobot and Maestro and
its cameras) and, on the emulators' ports, ``helio rig`` as a user types it (both drivers,
the perception nodes, the sun estimator and the lens planner, each its own process, on the
world's clock), with a site file that is not the sample's and a calibration directory holding
calibrations made for this rig. ``helio doctor`` runs as its own process: on the healthy
rig it passes; then each fault is injected into the running graph (or given to the doctor
as a user would point it at a file) and must be reported with its fix:

- an uncalibrated camera_info (K = 0, as usb_cam sends without a calibration file): the
  world's camera_info cannot be changed at run time, so this test publishes one on
  ``rgb/camera_info`` beside the world's, as a second, uncalibrated camera driver would;
- no thermal stream: the world's thermal camera unplugged (``sim_world``'s ``unplugged``);
- the sample site file (``--site`` the shipped config/site.yaml);
- the marker out of view: the arm turned away with a ``move_arm`` goal;
- a Dobot alarm: an emulated Dobot in this process, which raises the alarm as the firmware
  does, under a dobot_driver process of its own namespace;
- no calibration (``--calibration-dir`` an empty directory).
"""

import signal
import subprocess
import sys

from conftest import graph_of_processes
from helio_control.bringup import SIMULATED_DEVICE_REPLY_TIMEOUT, SIMULATED_SILENCE_TIMEOUT
from helio_control.bringup import wait_for_devices
from helio_control.calibration_store import rig_description, save_calibration
from helio_drivers import dobot_protocol as proto
from helio_drivers.dobot_emulator import DobotEmulator
from helio_msgs.action import FocusLens, MoveArm, MoveWrist
from helio_msgs.msg import DeviceStatus, SpotObservation, ThermalStats
from helio_optics.config_files import config_path
from helio_optics.node_kit.deployment import rig_file_or_default
from helio_optics.node_kit.in_process_graph import TRANSIENT_LOCAL_QOS
from helio_optics.rig_kinematics import load_rig_parameters, Rig
import pytest
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo

HELIO = [sys.executable, '-m', 'helio_control.cli']
RIG_NODES = ('dobot_driver', 'servo_driver', 'spot_detector', 'thermal_monitor',
             'sun_estimator', 'lens_planner')
TIMEOUT = 60.0          # [s] wall, for anything of a graph on a loaded 2-core machine
WINDOW = '3'            # [s] the doctor's listening window
SPOTS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
# Zurich: not the sample's site (Munich, the simulated world's), 0.8 deg away
SITE = """/**:
  ros__parameters:
    site:
      latitude_deg: 47.3769
      longitude_deg: 8.5417
      elevation: 408.0
      temperature: 12.0
      pressure: 101325.0
"""


class Doctor:
    """The running simulated rig and ``helio doctor`` against it."""

    def __init__(self, group, graph, tmp):
        self.group, self.graph, self.tmp = group, graph, tmp
        self.spots = graph.collect(SpotObservation, 'spot', SPOTS)
        self.thermal = graph.collect(ThermalStats, 'thermal/stats', SPOTS)
        self.arm = graph.action_client(MoveArm, 'move_arm', TIMEOUT)
        self.wrist = graph.action_client(MoveWrist, 'move_wrist', TIMEOUT)
        self.world = AsyncParameterClient(graph.helper, 'sim_world')
        self.rig = Rig(load_rig_parameters(rig_file_or_default('')))

    def run(self, *arguments, namespace=''):
        """Run ``helio doctor``; return (exit status, {check name: (level, line)}, stdout)."""
        done = subprocess.run(HELIO + ['doctor', '--window', WINDOW, '--namespace', namespace,
                                       *arguments], capture_output=True, text=True,
                              timeout=120)
        print(f'\n$ helio doctor {" ".join(arguments)}\n{done.stdout}{done.stderr}')
        lines = {}
        for line in done.stdout.replace('\n       fix:', ' fix:').splitlines():
            level, _, rest = line.partition(' ')
            name, colon, _ = rest.strip().partition(':')
            if level in ('OK', 'WARN', 'FAIL') and colon:
                lines[name] = (level, line)
        return done.returncode, lines, done.stdout

    def move(self, joints):
        """Move arm and wrist to `joints` (j1, j2, j3, yaw, pitch); wait until they are."""
        arm = self.graph.run_goal(self.arm, MoveArm.Goal(
            mode=MoveArm.Goal.MOVJ_ANGLE, target=[*joints[:3], 0.0]), timeout=TIMEOUT)
        wrist = self.graph.run_goal(self.wrist, MoveWrist.Goal(yaw=joints[3], pitch=joints[4]),
                                    timeout=TIMEOUT)
        assert arm.result.success and wrist.result.success, (arm.result.message,
                                                             wrist.result.message)

    def wait_for_the_rig(self):
        """
        Wait until every rig node is up: perception publishing, the lens planner serving.

        `helio rig` starts the six nodes at once; their imports and warm-ups take both cores
        for seconds, and the emulated devices answer from a thread of the world's process in
        wall time: a first move sent into that start, beside two busy processes, found the
        emulated Maestro silent past the simulated graph's silence limit (session 43).
        """
        self.spots.wait_for_count(1, TIMEOUT)
        self.thermal.wait_for_count(1, TIMEOUT)
        self.graph.action_client(FocusLens, 'focus', TIMEOUT)

    def look_at_marker(self):
        """Put the lens level 8.2 cm over a point beside the marker: the camera sees it."""
        above = self.rig.parameters.T_robot_world @ [0.01, 0.01, 0.082, 1.0]
        self.move(self.rig.inverse(above[:3], yaw=0.3, pitch=0.0))
        self.wait_for_spot(lambda spot: spot.camera_pose_source == 'marker', 'the marker seen')

    def wait_for_spot(self, predicate, what):
        """Wait for a spot observation (of an image taken after now) satisfying `predicate`."""
        self.spots.clear()
        self.spots.wait_until(lambda spots: sum(map(predicate, spots)) >= 2, TIMEOUT, what)

    def set_world(self, **values):
        """Set sim_world parameters at run time; fail on a refusal."""
        self.graph.wait_until(self.world.services_are_ready, TIMEOUT, 'sim_world parameters')
        response = self.graph.on_executor(lambda: self.world.set_parameters(
            [Parameter(k, value=v) for k, v in values.items()]), TIMEOUT, 'set_parameters')
        for name, result in zip(values, response.results):
            assert result.successful, f'{name}: {result.reason}'


@pytest.fixture(scope='module')
def rig(tmp_path_factory):
    """Start the simulated rig once: its own site file, calibrations made for this rig."""
    tmp = tmp_path_factory.mktemp('doctor')
    site = tmp / 'site.yaml'
    site.write_text(SITE)
    calibrations = tmp / 'calibration'
    rig_file = rig_file_or_default('')
    description = rig_description(rig_file)
    parameters = load_rig_parameters(rig_file)
    save_calibration(str(calibrations), 'robot_world.yaml', {'rig': {
        'world_in_robot': [float(v) for v in parameters.world_in_robot],
        'world_yaw': float(parameters.world_yaw)}}, description, 'test_doctor',
        {'residual_position_m': 0.0002})
    save_calibration(str(calibrations), 'focus.yaml', {'heating_distance': 0.082},
                     description, 'test_doctor')
    world = {'sim_world': {'flux_rays': 2000, 'flux_rays_moving': 1000}}
    with graph_of_processes(tmp, ('sim_world',), world, client_name='doctor_test') \
            as (group, graph), open(tmp / 'helio_rig.log', 'w') as log:
        ports = tmp / 'ports'
        graph.collect(Clock, '/clock').wait_for_count(1, TIMEOUT)     # the world stepping
        assert (ports / 'dobot').exists() and (ports / 'servo').exists()
        # the rig's nodes as a user starts them: helio rig on the emulators' ports (with the
        # reply timeouts of the simulated graph: the emulators answer from a loaded process),
        # on the world's clock: on wall time they cannot match its images, stamped in
        # simulated time, to the joint states (the doctor's time base check says so)
        settings = {'sun_estimator.site_file': site, 'lens_planner.site_file': site,
                    'lens_planner.calibration_dir': calibrations}
        settings.update({f'{node}.use_sim_time': 'true' for node in RIG_NODES})
        for driver in ('dobot_driver', 'servo_driver'):
            settings.update({f'{driver}.timeout': SIMULATED_DEVICE_REPLY_TIMEOUT,
                             f'{driver}.silence_timeout': SIMULATED_SILENCE_TIMEOUT})
        command = HELIO + ['rig', '--dobot-port', str(ports / 'dobot'), '--servo-port',
                           str(ports / 'servo'), '--log-dir', str(tmp / 'rig_logs'),
                           '--stop-timeout', '5', '--nodes', *RIG_NODES]
        for name, value in settings.items():
            command += ['--set', f'{name}={value}']
        helio_rig = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT,
                                     start_new_session=True)
        try:
            wait_for_devices(graph, TIMEOUT)
            doctor = Doctor(group, graph, tmp)
            doctor.wait_for_the_rig()
            doctor.look_at_marker()
            yield doctor
        finally:
            helio_rig.send_signal(signal.SIGINT)          # Ctrl-C: helio rig stops its nodes
            helio_rig.wait(timeout=TIMEOUT)


def test_the_healthy_simulated_rig_passes(rig):
    status, lines, output = rig.run('--json', str(rig.tmp / 'doctor.json'))
    assert status == 0, output
    failed = [line for level, line in lines.values() if level == 'FAIL']
    assert failed == []
    warned = {name for name, (level, _) in lines.items() if level == 'WARN'}
    assert warned <= {'dobot homed'}, warned          # the Dobot does not report homing
    for name in ('dobot connected', 'servo connected', 'dobot alarms', 'servo alarms',
                 'emergency stop', 'rgb camera rate', 'thermal camera rate',
                 'rgb camera_info calibrated', 'thermal camera_info calibrated',
                 'thermal range for charring', 'marker visible', 'site file',
                 'simulated clock', 'system clock', 'time base', 'calibration robot_world.yaml',
                 'calibration focus.yaml'):
        assert lines[name][0] == 'OK', lines.get(name)
    assert 'lens_planner.site_file' in lines['site file'][1]            # asked the nodes
    assert 'lens_planner.calibration_dir' in lines['calibration focus.yaml'][1]
    assert (rig.tmp / 'doctor.json').is_file()


def test_an_uncalibrated_camera_info_is_reported_with_its_fix(rig):
    publisher = rig.graph.helper.create_publisher(CameraInfo, 'rgb/camera_info', 10)
    uncalibrated = CameraInfo(width=640, height=480)              # K = 0, as usb_cam sends
    timer = rig.graph.helper.create_timer(0.1, lambda: publisher.publish(uncalibrated))
    try:
        status, lines, output = rig.run()
    finally:
        rig.graph.helper.destroy_timer(timer)
        rig.graph.helper.destroy_publisher(publisher)
    level, line = lines['rgb camera_info calibrated']
    assert status == 1 and level == 'FAIL', output
    assert 'K is all zero' in line and 'helio calibrate camera' in line
    assert lines['thermal camera_info calibrated'][0] == 'OK'


def test_no_thermal_stream_is_reported_with_its_fix(rig):
    rig.set_world(unplugged=['thermal_camera'])
    try:
        status, lines, output = rig.run()
    finally:
        rig.set_world(unplugged=[''])
    assert status == 1, output
    level, line = lines['thermal camera rate']
    assert level == 'FAIL' and 'no image on /thermal/image_raw' in line
    assert 'fix: check the thermal camera: plugged in' in line
    assert lines['thermal range for charring'][0] == 'FAIL'
    assert lines['rgb camera rate'][0] == 'OK'                  # only the thermal stream
    rig.thermal.clear()
    rig.thermal.wait_for_count(2, TIMEOUT)       # plugged back in: the stream flows again


def test_the_sample_site_file_is_reported_with_its_fix(rig):
    status, lines, output = rig.run('--site', config_path('site.yaml'))
    level, line = lines['site file']
    assert status == 1 and level == 'FAIL', output
    assert 'the shipped sample site' in line and '--site' in line
    assert 'fix: copy config/site.yaml' in line and 'site_file=PATH' in line


def test_no_calibration_is_reported_with_how_to_make_each(rig):
    empty = rig.tmp / 'no_calibration'
    empty.mkdir()
    status, lines, output = rig.run('--calibration-dir', str(empty))
    assert status == 0, output           # the painter calibrates robot-world by itself
    for name, fix in (('robot_world.yaml', 'calibrate_world'),
                      ('focus.yaml', 'calibrate_focus')):
        level, line = lines[f'calibration {name}']
        assert level == 'WARN' and f'none in {empty}' in line and fix in line


def test_the_marker_out_of_view_is_reported_with_its_fix(rig):
    above = rig.rig.parameters.T_robot_world @ [0.01, 0.01, 0.082, 1.0]
    joints = list(rig.rig.inverse(above[:3], yaw=0.3, pitch=0.0))
    turned = [joints[0] + 0.9, *joints[1:]]             # the base turned 52 deg away
    rig.move(turned)
    try:
        rig.wait_for_spot(lambda spot: spot.camera_pose_source != 'marker', 'the marker gone')
        status, lines, output = rig.run()
    finally:
        rig.look_at_marker()
    level, line = lines['marker visible']
    assert level == 'WARN' and 'the marker is in none of' in line, output
    assert 'fix: move the arm so the RGB camera looks at the marker' in line


def test_a_dobot_alarm_is_reported_with_its_fix(tmp_path):
    # an emulated Dobot in this process raises the alarm as the firmware does; its driver
    # runs as its own process in a namespace of its own
    with DobotEmulator() as emulator, graph_of_processes(
            tmp_path, ('dobot_driver',), {'dobot_driver': {'port': emulator.port_path}},
            namespace='/alarmed', client_name='doctor_alarm') as (_, graph):
        status_of = graph.collect(DeviceStatus, 'dobot/status', TRANSIENT_LOCAL_QOS)
        status_of.wait_for_message(lambda status: status.connected, TIMEOUT)
        emulator.raise_alarm(proto.Alarm.LIMIT_AXIS2_POS)
        status_of.wait_for_message(lambda status: status.alarms, TIMEOUT)
        done = subprocess.run(HELIO + ['doctor', '--window', WINDOW, '--namespace', '/alarmed'],
                              capture_output=True, text=True, timeout=120)
    print(f'\n$ helio doctor --namespace alarmed\n{done.stdout}{done.stderr}')
    alarm = [line for line in done.stdout.split('\nFAIL ') if line.startswith('dobot alarms')]
    assert done.returncode == 1 and len(alarm) == 1, done.stdout
    assert 'j2 beyond its upper limit' in alarm[0]
    assert 'fix: remove the cause' in alarm[0] and '/dobot/clear_alarms' in alarm[0]
    assert 'OK   dobot connected' in done.stdout
