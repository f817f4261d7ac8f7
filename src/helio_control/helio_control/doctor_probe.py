"""
What ``helio doctor`` hears from a running graph: the facts ``helio_control.doctor`` checks.

A client node (``ClientGraph``, the graph's namespace) listens for `window` seconds:
the drivers' latched ``dobot/status`` and ``servo/status``, ``emergency_stop``, each
camera's ``image_raw`` (raw CDR: only the header stamp is read, so images cost no
conversion) and ``camera_info``, ``thermal/stats``, ``spot`` and ``/clock``. Meanwhile it
asks the nodes' parameter services for ``site_file`` (sun_estimator, lens_planner, painter),
``calibration_dir`` and ``rig_file`` (lens_planner) and ``home_on_connect`` (dobot_driver).
It calls nothing that moves the rig.
"""

import datetime
import os
import shutil
import struct
import subprocess
import threading
import time

from helio_control.calibration_store import list_calibrations
from helio_control.calibration_store import rig_description
from helio_control.doctor import (
    CalibrationFacts, ClockFacts, DeviceFacts, Facts, SpotFacts, StreamFacts, ThermalFacts)
from helio_optics.node_kit import topics

PARAMETER_TIMEOUT = 5.0        # [s] wall, for each node's get_parameters
# Discovery: a new participant in a busy graph hears its first messages 2-3 s after it
# subscribed (measured on 2 loaded cores, 2026-11-27): the window starts once the count of
# matched publishers has not changed for SETTLE seconds (at most `discovery` seconds).
SETTLE = 1.0                   # [s] wall
ASKED = {'sun_estimator': ('site_file',),
         'painter': ('site_file',),
         'lens_planner': ('site_file', 'calibration_dir', 'rig_file'),
         'dobot_driver': ('home_on_connect',)}


def stamp_of_cdr(data):
    """Return the header stamp [s] of a serialized message that starts with a Header."""
    little = len(data) > 1 and data[1] & 1
    seconds, nanoseconds = struct.unpack_from('<iI' if little else '>iI', data, 4)
    return seconds + nanoseconds * 1e-9


def build_date():
    """Return the date this helio was built (installed): its doctor module's file time."""
    from helio_control import doctor
    return datetime.datetime.fromtimestamp(os.path.getmtime(doctor.__file__),
                                           datetime.timezone.utc)


def ntp_synchronized():
    """Return whether timedatectl says the clock is NTP synchronised (None: not known)."""
    if shutil.which('timedatectl') is None:
        return None
    try:
        done = subprocess.run(['timedatectl', 'show', '-p', 'NTPSynchronized', '--value'],
                              capture_output=True, text=True, timeout=5.0)
    except (OSError, subprocess.SubprocessError):
        return None
    value = done.stdout.strip()
    return {'yes': True, 'no': False}.get(value) if done.returncode == 0 else None


def settle(graph, subscriptions, timeout, timeout_error):
    """
    Wait until the publishers matched to `subscriptions` stay the same for ``SETTLE`` s.

    Return the seconds it took (`timeout` when discovery did not settle: a graph still
    starting, or nothing to discover).
    """
    started = time.monotonic()
    state = {'count': -1, 'since': started}

    def settled():
        count = sum(subscription.get_publisher_count() for subscription in subscriptions)
        now = time.monotonic()
        if count != state['count']:
            state.update(count=count, since=now)
        return count > 0 and now - state['since'] >= SETTLE

    try:
        graph.wait_until(settled, timeout, 'discovery of the graph')
    except timeout_error:
        return timeout
    return time.monotonic() - started


def _parameter_value(value):
    """Return the Python value of an rcl_interfaces ParameterValue (None when not set)."""
    from rcl_interfaces.msg import ParameterType
    return {ParameterType.PARAMETER_BOOL: lambda v: v.bool_value,
            ParameterType.PARAMETER_STRING: lambda v: v.string_value,
            ParameterType.PARAMETER_DOUBLE: lambda v: v.double_value,
            ParameterType.PARAMETER_INTEGER: lambda v: v.integer_value}.get(
                value.type, lambda v: None)(value)


def gather(namespace='', window=3.0, calibration_dir=None, site_file=None, discovery=10.0):
    """
    Listen to the graph for `window` s and ask its nodes' parameters; return the Facts.

    The window starts once discovery has settled (the publishers matched to the doctor's
    subscriptions stay the same for ``SETTLE`` s, `discovery` s at most); what arrived
    before is forgotten, except the latched device statuses and emergency stop.
    `calibration_dir` and `site_file` (when given) replace what the nodes' parameters say.
    """
    from helio_msgs.msg import DeviceStatus, SpotObservation, ThermalStats
    from helio_optics.config_files import config_path
    from helio_optics.node_kit import emergency_stop
    from helio_optics.node_kit.deployment import calibration_dir_or_default, rig_file_or_default
    from helio_optics.node_kit.client_graph import ClientGraph, GraphTimeout
    from helio_optics.node_kit.client_graph import TRANSIENT_LOCAL_QOS
    from rcl_interfaces.srv import GetParameters
    from rclpy.qos import qos_profile_sensor_data
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import CameraInfo, Image, JointState
    from std_msgs.msg import Bool

    facts = Facts(window=window, namespace=namespace,
                  domain=os.environ.get('ROS_DOMAIN_ID', ''))
    lock = threading.Lock()
    with ClientGraph('helio_doctor', namespace=namespace) as graph:
        node = graph.helper

        def keep(store, convert):
            def callback(message):
                with lock:
                    store.append(convert(message))
            return callback

        def on_status(device):
            def callback(message):
                with lock:
                    facts.devices[device] = DeviceFacts(
                        bool(message.connected), list(message.alarms), message.message,
                        message.port)
            return callback

        subscriptions = []
        for device in ('dobot', 'servo'):
            node.create_subscription(DeviceStatus, topics.device_status(device), on_status(device),
                                     TRANSIENT_LOCAL_QOS)
        stop = []
        node.create_subscription(Bool, emergency_stop.TOPIC,
                                 keep(stop, lambda m: bool(m.data)), emergency_stop.QOS)
        for kind in ('rgb', 'thermal'):
            stream = facts.images[kind] = StreamFacts(node.resolve_topic_name(
                f'{kind}/image_raw'))

            def on_image(data, stream=stream):
                arrived = time.monotonic()
                with lock:
                    stream.arrivals.append(arrived)
                    stream.stamps.append(stamp_of_cdr(data))
            subscriptions.append(node.create_subscription(
                Image, f'{kind}/image_raw', on_image, qos_profile_sensor_data, raw=True))
            facts.camera_infos[kind] = []
            subscriptions.append(node.create_subscription(
                CameraInfo, f'{kind}/camera_info',
                keep(facts.camera_infos[kind], lambda m: list(m.k)), qos_profile_sensor_data))
        subscriptions.append(node.create_subscription(
            ThermalStats, topics.THERMAL_STATS, keep(facts.thermal, lambda m: (
                ThermalFacts(m.t_max, m.threshold, m.camera_cap, m.saturated))),
            qos_profile_sensor_data))
        subscriptions.append(node.create_subscription(
            SpotObservation, topics.SPOT, keep(facts.spots, lambda m: (
                SpotFacts(m.camera_pose_source, m.reason, m.valid))), qos_profile_sensor_data))
        joints = facts.joint_states = StreamFacts(node.resolve_topic_name(topics.JOINT_STATES))
        subscriptions.append(node.create_subscription(JointState, topics.JOINT_STATES, keep(
            joints.stamps, lambda m: m.header.stamp.sec + m.header.stamp.nanosec * 1e-9), 50))
        clock_samples = []
        subscriptions.append(node.create_subscription(Clock, '/clock', keep(
            clock_samples, lambda m: (time.monotonic(), m.clock.sec + m.clock.nanosec * 1e-9)),
            10))

        # the nodes' parameters, asked while the window runs
        futures = {}
        started = time.monotonic()
        for target, names in ASKED.items():
            client = node.create_client(GetParameters, f'{target}/get_parameters')
            futures[target] = (client, names)
        facts.discovery = settle(graph, subscriptions, discovery, GraphTimeout)
        with lock:              # the window starts now: forget what came during discovery
            for stream in facts.images.values():
                stream.stamps.clear()
                stream.arrivals.clear()
            for store in (*facts.camera_infos.values(), facts.thermal, facts.spots,
                          clock_samples, joints.stamps):
                store.clear()
        threading.Event().wait(window)          # the measurement window
        answers = {}
        for target, (client, names) in futures.items():
            remaining = max(0.5, PARAMETER_TIMEOUT - (time.monotonic() - started))
            try:
                response = graph.call(client, GetParameters.Request(names=list(names)),
                                      remaining)
            except GraphTimeout:
                continue
            answers[target] = dict(zip(names, (_parameter_value(v) for v in response.values)))

        with lock:
            facts.emergency_stop = stop[-1] if stop else None
            facts.clock = ClockFacts(
                samples=list(clock_samples),
                now=datetime.datetime.now(datetime.timezone.utc),
                utc_offset=float(time.localtime().tm_gmtoff), not_before=build_date(),
                ntp_synchronized=ntp_synchronized())

    facts.home_on_connect = answers.get('dobot_driver', {}).get('home_on_connect')
    facts.sample_site = config_path('site.yaml')
    if site_file:
        facts.site_files['--site'] = site_file
    else:
        for target in ('sun_estimator', 'lens_planner', 'painter'):
            if target in answers:
                facts.site_files[f'{target}.site_file'] = (answers[target]['site_file'] or
                                                           facts.sample_site)
    planner = answers.get('lens_planner', {})
    if calibration_dir:
        directory, source = calibration_dir, '--calibration-dir'
    elif 'calibration_dir' in planner:
        directory, source = planner['calibration_dir'], 'lens_planner.calibration_dir'
    else:
        directory, source = '', 'the default: lens_planner did not answer'
    directory = calibration_dir_or_default(directory)
    rig_file = rig_file_or_default(planner.get('rig_file') or '')
    description = rig_description(rig_file)
    facts.calibration = CalibrationFacts(directory, source, description, rig_file,
                                         list_calibrations(directory, description))
    return facts
