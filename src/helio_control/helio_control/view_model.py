"""
What the Foxglove view knows of a run, fed by the graph's messages (issue 33).

``ViewModel`` keeps the latest of each input (camera infos, the spot with the RGB camera's
pose, thermal statistics, the merged joint states, the sun estimate and the simulated truth,
the painter's heating window) and answers the view's messages as plain dicts
(``view_scene``): the RGB and thermal image annotations, the 3D scene, the true sun and the
painting's figures. It imports no rclpy and no foxglove: the live bridge (``view_bridge``)
and the recorder (``recorder.ViewRecording``) feed it deserialized messages and log its
answers, so the live view and the recording show the same drawings. ``PlanFile`` gives it
the run's plan.json (every dot by state, the next targets) when there is one.

``INPUTS`` names the topics it reads (relative names) with their types; ``OUTPUTS`` the
topics it writes with their Foxglove schema names. Inputs that never come leave their part
out (no spot: no ellipse; no joints: no camera poses in the scene).
"""

import json
import math
import os

from helio_control.view_scene import ground_circle, IMAGE_ANNOTATIONS, project_to_image
from helio_control.view_scene import ray_entity, ray_line, rgb_annotations, SCENE_UPDATE
from helio_control.view_scene import scene_update, schema_bytes, SUN_TRUTH_COLOUR
from helio_control.view_scene import thermal_annotations, time_dict
from helio_optics.geometry import invert_transform
from helio_optics.node_kit import topics
from helio_optics.node_kit.conversions import camera_from_info, pose_to_matrix
from helio_optics.node_kit.conversions import stamp_to_nanoseconds
from helio_optics.node_kit.joint_states import JointStateBuffer
from helio_perception.ground_plane import marker_object_points
import numpy as np

RGB_IMAGE = topics.RGB_IMAGE
THERMAL_IMAGE = topics.THERMAL_IMAGE
INPUTS = {                      # topic: (type, ViewModel method)
    topics.RGB_CAMERA_INFO: ('sensor_msgs/msg/CameraInfo', 'on_rgb_info'),
    topics.THERMAL_CAMERA_INFO: ('sensor_msgs/msg/CameraInfo', 'on_thermal_info'),
    topics.SPOT: ('helio_msgs/msg/SpotObservation', 'on_spot'),
    topics.THERMAL_STATS: ('helio_msgs/msg/ThermalStats', 'on_stats'),
    topics.JOINT_STATES: ('sensor_msgs/msg/JointState', 'on_joints'),
    topics.SUN_ESTIMATE: ('helio_msgs/msg/SunEstimate', 'on_sun'),
    'sim/truth/sun_direction': ('geometry_msgs/msg/Vector3Stamped', 'on_sun_truth'),
    topics.THERMAL_WINDOW: ('geometry_msgs/msg/PointStamped', 'on_window'),
    'paint/_action/feedback': ('helio_msgs/action/PaintPattern_FeedbackMessage',
                               'on_feedback'),
}
VIEW_METRICS = 'helio.ViewMetrics'
OUTPUTS = {                     # topic (absolute, under the graph's namespace): schema
    '/view/rgb/annotations': IMAGE_ANNOTATIONS,
    '/view/thermal/annotations': IMAGE_ANNOTATIONS,
    '/view/scene': SCENE_UPDATE,
    '/view/sun_truth': SCENE_UPDATE,
    '/view/metrics': VIEW_METRICS,
}
METRICS_SCHEMA = {'type': 'object', 'properties': {
    'timestamp': {'type': 'object', 'properties': {'sec': {'type': 'integer'},
                                                   'nsec': {'type': 'integer'}}},
    't_max': {'type': 'number'}, 'n_p': {'type': 'integer'},
    'dwell': {'type': 'number'}, 'placement': {'type': 'number'},
    'dots_burnt': {'type': 'integer'}},
    'required': ['timestamp', 't_max', 'n_p', 'dwell', 'placement', 'dots_burnt']}
RAY_LENGTH = 0.25               # drawn length of a sun ray, ending on the focus [m]


def output_schema_bytes(schema_name):
    """Return the JSON schema (UTF-8 bytes) of an ``OUTPUTS`` schema name."""
    return json.dumps(METRICS_SCHEMA).encode() if schema_name == VIEW_METRICS \
        else schema_bytes(schema_name)


class ViewModel:
    """The view's state (see the module docstring); `rig` a helio_optics Rig."""

    def __init__(self, rig, marker_side=0.04, panel_extent=(-0.04, 0.16, -0.04, 0.16),
                 next_count=3):
        """Start with nothing seen; the marker's side and the panel's extent in metres."""
        self.rig = rig
        self.marker = marker_object_points(marker_side)
        self.panel_extent = tuple(float(v) for v in panel_extent)
        self.next_count = int(next_count)
        self.rgb_camera = self.thermal_camera = None
        self.spot = None                 # dict for view_scene, or None
        self.T_world_rgb = None          # from the spot's camera pose
        self.stats = None
        self.joints = JointStateBuffer()
        self.sun = None                  # unit s0, world frame
        self.sun_truth = None
        self.target = None               # (3,) world, the dot being heated
        self.target_since_ns = None
        self.burnt = []                  # earlier targets, in order
        self.plan = None                 # (N, 3) the painting's dots in order, when known
        self.dot_index = None            # the painter's feedback: the dot worked on
        self.phase = ''

    # ---- inputs ------------------------------------------------------------------------------
    def feed(self, topic, message):
        """Give a message of an ``INPUTS`` topic to its handler."""
        getattr(self, INPUTS[topic][1])(message)

    def on_rgb_info(self, message):
        """Take the RGB camera's intrinsics (an invalid info is ignored)."""
        self.rgb_camera = _camera(message) or self.rgb_camera

    def on_thermal_info(self, message):
        """Take the thermal camera's intrinsics."""
        self.thermal_camera = _camera(message) or self.thermal_camera

    def on_spot(self, message):
        """Take a spot observation: the ellipse when measured, the camera pose when known."""
        if message.camera_pose_source:
            self.T_world_rgb = pose_to_matrix(message.camera_pose)
        self.spot = None
        if message.valid or message.quality:
            self.spot = {'center': (message.center.x, message.center.y, message.center.z),
                         'semi_major': message.semi_major, 'semi_minor': message.semi_minor,
                         'orientation': message.orientation}

    def on_stats(self, message):
        """Take the thermal statistics."""
        self.stats = message

    def on_joints(self, message):
        """Take a (partial) joint state."""
        self.joints.add_message(message)

    def on_sun(self, message):
        """Take the controller's sun estimate (robot frame) as a world direction."""
        self.sun = self._robot_to_world(message.direction)

    def on_sun_truth(self, message):
        """Take the simulated world's true sun ray (robot frame)."""
        self.sun_truth = self._robot_to_world(message.vector)

    def on_window(self, message):
        """Take the painter's heating window: a new target; the last one counts as burnt."""
        point = message.point
        target = None if math.isnan(point.x) else np.array([point.x, point.y, 0.0])
        if self.target is not None and (target is None
                                        or np.linalg.norm(target - self.target) > 1e-6):
            self.burnt.append(self.target)
        if target is not None and (self.target is None
                                   or np.linalg.norm(target - self.target) > 1e-6):
            self.target_since_ns = stamp_to_nanoseconds(message.header.stamp)
        self.target = target

    def on_feedback(self, message):
        """Take the painter's feedback: which dot of the plan it works on, in which phase."""
        feedback = message.feedback
        if feedback.phase == 'heating' and self.phase != 'heating' and self.stats is not None:
            self.target_since_ns = stamp_to_nanoseconds(self.stats.header.stamp)
        self.dot_index, self.phase = int(feedback.index), feedback.phase

    @property
    def current(self):
        """Return the dot being worked on (3,): the heating window, else the plan's, or None."""
        if self.target is not None:
            return self.target
        index = self._current_index()
        if index is None or self.phase == 'done' or not 0 <= index < len(self.plan):
            return None
        return self.plan[index]

    def set_plan(self, dots):
        """Take the painting's dots in burn order ((N, 2) world x, y [m]; plan.json)."""
        dots = np.asarray(dots, dtype=float).reshape(-1, 2)
        self.plan = np.column_stack([dots, np.zeros(len(dots))])

    def _current_index(self):
        """Return the plan index of the current target (-1: before the first; None: no plan)."""
        if self.plan is None or not len(self.plan):
            return None
        if self.dot_index is not None:   # the painter says which
            return len(self.plan) if self.phase == 'done' else min(self.dot_index,
                                                                   len(self.plan) - 1)
        if self.target is None:
            return len(self.plan) - 1 if self.burnt else -1
        return int(np.argmin(np.linalg.norm(self.plan[:, :2] - self.target[:2], axis=1)))

    @property
    def planned(self):
        """Return the plan's dots after the current one ([] without a plan)."""
        index = self._current_index()
        return [] if index is None else list(self.plan[index + 1:])

    def _robot_to_world(self, vector):
        direction = np.array([vector.x, vector.y, vector.z], dtype=float)
        norm = np.linalg.norm(direction)
        if not norm > 0 or not np.isfinite(norm):
            return None
        return self.rig.parameters.T_robot_world[:3, :3].T @ (direction / norm)

    # ---- outputs ------------------------------------------------------------------------------
    def frames(self):
        """Return the world poses of the lens and both cameras at the latest joints ({})."""
        latest = self.joints.latest(self.joints.newest_stamp() or 0.0)
        if not latest:
            return {}
        pose = self.rig.forward(latest.positions)
        T_world_robot = invert_transform(self.rig.parameters.T_robot_world)
        return {'lens': T_world_robot @ pose.T_robot_lens,
                'rgb_camera': T_world_robot @ pose.T_robot_rgb,
                'thermal_camera': T_world_robot @ pose.T_robot_thermal}

    def rgb_annotations(self, stamp_ns):
        """Return the RGB image's annotations, or None without camera info or pose."""
        if self.rgb_camera is None or self.T_world_rgb is None:
            return None
        return rgb_annotations(stamp_ns, self.rgb_camera, self.T_world_rgb, self.marker,
                               self.spot, self.current, self.planned[:self.next_count],
                               self.burnt)

    def thermal_annotations(self, stamp_ns):
        """Return the thermal image's annotations, or None before any statistics."""
        stats = self.stats
        if stats is None:
            return None
        window = None
        T_world_thermal = self.frames().get('thermal_camera')
        if stats.window_valid and self.thermal_camera is not None \
                and T_world_thermal is not None:
            centre = (stats.window_centre.x, stats.window_centre.y, 0.0)
            outline, front = project_to_image(self.thermal_camera, T_world_thermal,
                                              ground_circle(centre, stats.window_radius))
            if np.all(front):
                window = (outline, stats.window_n_p)
        return thermal_annotations(stamp_ns, (stats.hottest_u, stats.hottest_v), stats.t_max,
                                   stats.n_p, window)

    def targets(self):
        """Return the known target points (N, 3) and their states, for the 3D view."""
        index = self._current_index()
        if index is not None:          # the plan's order: before the current one is done
            working = self.current is not None
            states = ['burnt' if i < index else 'current' if i == index and working
                      else 'planned' for i in range(len(self.plan))]
            if self.dot_index is None and self.target is None and self.burnt:
                states = ['burnt'] * len(self.plan)
            return list(self.plan), states
        points = [*self.burnt, *([self.target] if self.target is not None else [])]
        states = ['burnt'] * len(self.burnt) + ['current'] * (self.target is not None)
        return points, states

    def _focus(self):
        if self.current is not None:
            return self.current
        if self.spot is not None:
            return np.asarray(self.spot['center'])
        return np.zeros(3)

    def scene(self, stamp_ns):
        """Return the 3D view as a SceneUpdate dict."""
        points, states = self.targets()
        ray = None if self.sun is None else ray_line(self._focus(), self.sun, RAY_LENGTH)
        return scene_update(stamp_ns, self.marker, self.panel_extent, points, states,
                            self.frames(), ray)

    def sun_truth_scene(self, stamp_ns):
        """Return the simulated true sun ray as a SceneUpdate, or None outside simulation."""
        if self.sun_truth is None:
            return None
        ends = ray_line(self._focus(), self.sun_truth, RAY_LENGTH)
        return {'deletions': [],
                'entities': [ray_entity(stamp_ns, 'sun_truth', ends, SUN_TRUTH_COLOUR)]}

    def metrics(self, stamp_ns):
        """Return the painting's figures for the plots, or None before any statistics."""
        if self.stats is None:
            return None
        dwell = 0.0 if self.target_since_ns is None or self.current is None \
            else max(0.0, (stamp_ns - self.target_since_ns) * 1e-9)
        placement = math.nan
        if self.current is not None and self.spot is not None:
            placement = float(np.linalg.norm(np.asarray(self.spot['center'])[:2]
                                             - self.current[:2]))
        return {'timestamp': time_dict(stamp_ns), 't_max': float(self.stats.t_max),
                'n_p': int(self.stats.n_p), 'dwell': dwell,
                'placement': placement if math.isfinite(placement) else -1.0,
                'dots_burnt': len(self.burnt) if self.dot_index is None
                else self.dot_index + (self.phase == 'done')}

    def outputs_for_image(self, topic, stamp_ns):
        """
        Return [(output topic, dict)] to log beside an image of `topic` at `stamp_ns`.

        The RGB frame brings its annotations, the scene, the true sun and the figures; the
        thermal frame its annotations. Parts not known yet are left out.
        """
        if topic == RGB_IMAGE:
            produced = [('/view/rgb/annotations', self.rgb_annotations(stamp_ns)),
                        ('/view/scene', self.scene(stamp_ns)),
                        ('/view/sun_truth', self.sun_truth_scene(stamp_ns)),
                        ('/view/metrics', self.metrics(stamp_ns))]
        elif topic == THERMAL_IMAGE:
            produced = [('/view/thermal/annotations', self.thermal_annotations(stamp_ns))]
        else:
            produced = []
        return [(name, message) for name, message in produced if message is not None]


class PlanFile:
    """The painting's plan.json, given to a ViewModel when it appears or changes."""

    def __init__(self, path):
        """Watch `path` ('' : no plan)."""
        self.path = path
        self._stamp = None

    def refresh(self, model):
        """Give `model` the plan if the file is new or changed; return a problem or ''."""
        if not self.path:
            return ''
        try:
            stamp = os.stat(self.path).st_mtime_ns
        except FileNotFoundError:
            return ''                    # not written yet: the goal has not started
        if stamp == self._stamp:
            return ''
        from helio_control.plan import Plan     # its planning imports, only when used
        try:
            with open(self.path) as stream:
                model.set_plan(Plan.from_json(stream.read()).dots)
        except (OSError, ValueError, KeyError) as error:
            return f'{self.path} not read: {error}'
        self._stamp = stamp
        return ''


def _camera(message):
    try:
        return camera_from_info(message)
    except ValueError:
        return None


def cdr_stamp_ns(data):
    """
    Return the header stamp [ns] of a serialized message that starts with a std_msgs/Header.

    CDR: a 4-byte encapsulation (byte 1: 0 big, 1 little endian), then int32 sec and
    uint32 nanosec.
    """
    order = '<' if data[1] == 1 else '>'
    sec, nanosec = np.frombuffer(bytes(data[4:12]), dtype=order + 'i4,' + order + 'u4')[0]
    return int(sec) * 10**9 + int(nanosec)
