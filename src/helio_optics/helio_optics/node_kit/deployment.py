"""
The deployment data a node needs, loaded the same way everywhere: one parameter per file.

A node that needs the rig's kinematics (paper Sec. II-B: joints x, the lens, the cameras,
T_robot_world) declares ``rig_file``; one that traces the lens declares ``lens_file``; one
that needs the sun's ephemeris declares ``site_file``. Each is a ROS 2 parameter file with a
``rig``, ``lens`` or ``site`` section; empty means the workspace's ``config/rig.yaml``,
``config/lens.yaml`` or ``config/site.yaml`` (found by ``helio_optics.config_files``).

What the rig's calibrations measured lives in one directory (issue 30), declared by every
node that reads or writes one as ``calibration_dir`` (``declare_calibration_dir``; empty:
``~/.helio/calibration``): the robot-world, rig-build and focal calibrations (lens
planner), the dot-size one (painter) and the RGB camera's camera_info file (spot detector).
"""

import math
import os

from geometry_msgs.msg import PoseStamped
from helio_optics.config_files import config_path
from helio_optics.ephemeris import load_site
from helio_optics.lens import load_lens_parameters
from helio_optics.node_kit.conversions import pose_to_matrix
from helio_optics.node_kit.parameters import declare
from helio_optics.node_kit.qos import LATCHED
from helio_optics.rig_kinematics import load_rig_parameters, Rig

WORLD_CALIBRATION_TOPIC = 'calibration/world_pose'
RIG_CALIBRATION_TOPIC = 'calibration/rig'
RIG_FILE_PARAMETER = 'rig_file'
LENS_FILE_PARAMETER = 'lens_file'
SITE_FILE_PARAMETER = 'site_file'
DEFAULT_CALIBRATION_DIR = '~/.helio/calibration'
# the RGB camera's camera_info file in the calibration directory (helio calibrate camera)
RGB_CAMERA_INFO_FILE = os.path.join('camera_info', 'rgb.yaml')


def calibration_dir_or_default(path):
    """Return the calibration directory `path` (user-expanded), or the default when empty."""
    return os.path.expanduser(path or DEFAULT_CALIBRATION_DIR)


def camera_info_file_or_default(path, calibration_dir):
    """
    Return the RGB camera_info file a node uses ('' for none).

    `path` itself; when empty, the calibration directory's RGB_CAMERA_INFO_FILE if it exists
    (else none); 'none': none.
    """
    if path == 'none':
        return ''
    if path:
        return os.path.expanduser(path)
    saved = os.path.join(calibration_dir, RGB_CAMERA_INFO_FILE)
    return saved if os.path.isfile(saved) else ''


def declare_calibration_dir(node, reads):
    """Declare ``calibration_dir`` on `node`, saying what it `reads`; return the directory."""
    return calibration_dir_or_default(declare(
        node, 'calibration_dir', '',
        f'The calibration directory (empty: {DEFAULT_CALIBRATION_DIR}): {reads}.'))


def deployment_file_or_default(path, default_name, parameter):
    """Return `path`, or config/`default_name` when empty; FileNotFoundError naming both."""
    if path:
        return path
    try:
        return config_path(default_name)
    except FileNotFoundError as error:
        raise FileNotFoundError(f'parameter {parameter} is empty and {error}') from None


def rig_file_or_default(path):
    """Return `path`, or the workspace's config/rig.yaml when empty."""
    return deployment_file_or_default(path, 'rig.yaml', RIG_FILE_PARAMETER)


def _declare_file(node, parameter, default_name, what):
    return deployment_file_or_default(
        declare(node, parameter, '',
                f"{what} YAML (empty: the workspace's config/{default_name})."),
        default_name, parameter)


def declare_rig(node):
    """Declare ``rig_file`` on `node`; return (Rig, the file it was read from)."""
    path = _declare_file(node, RIG_FILE_PARAMETER, 'rig.yaml', "Rig geometry ('rig' section)")
    return Rig(load_rig_parameters(path)), path


def declare_lens(node):
    """Declare ``lens_file`` on `node`; return (LensParameters, the file it was read from)."""
    path = _declare_file(node, LENS_FILE_PARAMETER, 'lens.yaml',
                         "Controller's lens model ('lens' section)")
    return load_lens_parameters(path), path


def declare_site(node):
    """Declare ``site_file`` on `node`; return (Site, the file it was read from)."""
    path = _declare_file(node, SITE_FILE_PARAMETER, 'site.yaml', "Site ('site' section)")
    return load_site(path), path


def follow_world_calibration(node, rig, on_update=None):
    """
    Keep `rig` on the robot-world and rig calibrations (``calibration/world_pose``, ``/rig``).

    The lens planner publishes the transform it measured from the ArUco marker (paper
    Sec. II-B) with a transient-local QoS, so a node started later gets it too. A pose whose
    z axis is not vertical within 5 deg is refused with a warning (the rig model holds the
    panel level). The rig calibration (issue 28, ``helio_control.rig_calibration``) is a
    std_msgs/String holding the YAML of the rig parameters it measured (flat names of
    config/rig.yaml) and its ``calibration_id``; a malformed one is refused with a warning
    and changes nothing.
    `on_update(rig)` is called after each change. Return the two subscriptions.
    """
    from std_msgs.msg import String
    import yaml

    def apply(message):
        transform = pose_to_matrix(message.pose)
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, transform[2, 2]))))
        if message.header.frame_id not in ('', 'robot') or tilt > 5.0:
            node.get_logger().warning(
                f'{WORLD_CALIBRATION_TOPIC} ignored: frame {message.header.frame_id!r}, '
                f'marker z {tilt:.1f} deg from vertical')
            return
        rig.set_world(transform[:3, 3], math.atan2(transform[1, 0], transform[0, 0]))
        node.get_logger().info(
            f'robot-world calibration applied: marker at '
            f'{[round(v * 1000, 2) for v in transform[:3, 3]]} mm, yaw '
            f'{math.degrees(rig.parameters.world_yaw):.3f} deg')
        if on_update is not None:
            on_update(rig)

    def apply_rig(message):
        try:
            values = yaml.safe_load(message.data)
            if not isinstance(values, dict):
                raise ValueError(f'not a mapping of rig parameters: {message.data[:80]!r}')
            identity = values.pop('calibration_id', '')
            rig.apply_calibration(values, identity)
        except (ValueError, TypeError, yaml.YAMLError) as error:
            node.get_logger().warning(f'{RIG_CALIBRATION_TOPIC} ignored: {error}')
            return
        node.get_logger().info(f'rig calibration applied: {", ".join(sorted(values))}')
        if on_update is not None:
            on_update(rig)

    qos = LATCHED
    return (node.create_subscription(PoseStamped, WORLD_CALIBRATION_TOPIC, apply, qos),
            node.create_subscription(String, RIG_CALIBRATION_TOPIC, apply_rig, qos))
