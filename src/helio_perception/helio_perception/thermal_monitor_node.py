"""
Node thermal_monitor: pyrolysis statistics of each thermal image (paper Sec. IV-B, Fig. 8).

Subscribes (sensor-data QoS) ``thermal/image_raw`` (16UC1 centikelvin as a radiometric
FLIR Lepton sends it, 32FC1 degC, or mono16 with a linear calibration) and
``thermal/camera_info``; (reliable) ``joint_states`` (partial messages merged by
``JointStateBuffer``). Publishes (reliable) ``thermal/stats`` (helio_msgs/ThermalStats:
T_max, N_p at or above T_p, the hottest pixel and, when the thermal camera's pose is known
from the joints and the rig kinematics, the ground point it sees; saturated when T_max is at
the camera cap; N_p and T_max inside the window set on ``thermal/window``) and the global
``/diagnostics`` (on wall time; ERROR when no image arrived for ``input_timeout`` on the
node clock or ``input_wall_timeout`` of wall time, WARN for malformed frames or pixels that
are no reading).

``thermal/window`` (geometry_msgs/PointStamped, reliable, transient local; the painter
sets it): a world-frame disc, centre (x, y) and radius in z [m], NaN to clear. While it is
set and the camera pose is known, each ThermalStats also counts N_p and T_max within it
(``window_*`` fields): the dot being heated only, without the previous dot's afterglow.

The statistics are `helio_perception.thermal.ThermalAnalyzer`; parameters in
config/thermal_monitor.yaml. A malformed frame is logged with its reason and skipped.
"""

import math
import time

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Point, PointStamped
from helio_msgs.msg import ThermalStats
from helio_optics.geometry import invert_transform
from helio_optics.node_kit import topics
from helio_optics.node_kit.conversions import camera_from_info, image_to_numpy
from helio_optics.node_kit.conversions import ImageConversionError, stamp_to_seconds
from helio_optics.node_kit.deployment import declare_rig, follow_world_calibration
from helio_optics.node_kit.diagnostics import diagnostic_array, ERROR
from helio_optics.node_kit.joint_states import CAMERA_NODE_JOINT_STATE_DEPTH, JointStateBuffer
from helio_optics.node_kit.parameters import declare, declare_joint_lookup
from helio_optics.node_kit.process_tuning import frozen_after_start_up
from helio_optics.node_kit.qos import LATCHED, reliable
from helio_optics.node_kit.runner import run_node
from helio_optics.thermal_cameras import thermal_camera
from helio_perception.frame_statistics import FrameStatistics, InputFreshness
from helio_perception.ground_plane import GroundMapping
from helio_perception.thermal import (camera_range_report, FreezeDetector, ThermalAnalyzer,
                                      ThermalConfig, window_mask)
import numpy as np
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image, JointState


class ThermalMonitorNode(Node):
    """Publish ThermalStats for every thermal image."""

    def __init__(self, **kwargs):
        super().__init__('thermal_monitor', **kwargs)
        profile = declare(
            self, 'camera_profile', '',
            "The thermal camera by its datasheet (helio_optics.thermal_cameras: 'paper', "
            "'lepton35_high_gain', 'lepton35_low_gain'): sets camera_cap to its read-out cap; "
            "'': camera_cap as given.")
        camera_cap = declare(self, 'camera_cap', 180.9,
                             'Read-out cap of the thermal camera [degC] (camera_profile, when '
                             'set, replaces it).', -273.15, 2000.0)
        if profile:
            try:
                camera_cap = thermal_camera(profile).cap
            except ValueError as error:
                raise ValueError(f'camera_profile: {error}') from None
        config = ThermalConfig(
            threshold=declare(self, 'threshold', 180.9,
                              'Pyrolysis threshold T_p for N_p [degC] (paper: the camera cap '
                              '180.9); a camera that reads less counts its saturated pixels.',
                              -273.15, 2000.0),
            camera_cap=camera_cap,
            saturation_tolerance=declare(self, 'saturation_tolerance', 0.05,
                                         'T_max within this of the cap is saturated [K].',
                                         0.0, 100.0),
            mono16_gain=declare(self, 'mono16.gain', 0.01,
                                'mono16 calibration: degC per count.', 1e-9, 100.0),
            mono16_offset=declare(self, 'mono16.offset', -273.15,
                                  'mono16 calibration: degC at count 0.', -1000.0, 1000.0),
            cap_margin=declare(self, 'cap_margin', 1.0,
                               'Readings more than this above camera_cap are no readings '
                               '(stuck or dead pixels) and are ignored [K].', 0.0, 1000.0),
            min_visible=declare(self, 'min_visible', 100.0,
                                'A camera_cap below this cannot tell charring from warm wood: '
                                'the node refuses to start [degC].', -273.15, 2000.0))
        range_warning = camera_range_report(config)      # ValueError: refused at start
        if range_warning:
            self.get_logger().warning(range_warning)
        self.analyzer = ThermalAnalyzer(config)
        self.detect_freezes = declare(
            self, 'detect_freezes', True,
            'Flag a frame that repeats the last one bit for bit under a newer stamp as frozen '
            "(a Lepton's flat-field correction); needs a camera with noise, as every real "
            'one has.')
        self.freezes = FreezeDetector()
        self.locate_hottest = declare(
            self, 'locate_hottest_point', True,
            'Map the hottest pixel to the ground (needs /thermal/camera_info, /joint_states '
            'and the rig kinematics).')
        self.joint_state_tolerance, self.joint_rest_hold = declare_joint_lookup(self)
        self.rig, _ = declare_rig(self)
        follow_world_calibration(self, self.rig)     # T_robot_world from the marker
        self.frame_id = declare(self, 'frame_id', 'thermal',
                                'frame_id of /thermal/stats (the thermal optical frame).')
        self.diagnostics_period = declare(self, 'diagnostics_period', 1.0,
                                          'Period of /diagnostics, on wall time [s].',
                                          0.0, 3600.0)
        self.freshness = InputFreshness.declared(self, topics.THERMAL_IMAGE, time.monotonic())
        self.ignored_pixels = 0
        self.stats = FrameStatistics()
        self.joints = JointStateBuffer()
        self.camera = None
        self.stats_pub = self.create_publisher(
            ThermalStats, topics.THERMAL_STATS,
            reliable(10))
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(Image, topics.THERMAL_IMAGE, self.on_image,
                                 qos_profile_sensor_data)
        self.create_subscription(CameraInfo, topics.THERMAL_CAMERA_INFO, self.on_camera_info,
                                 qos_profile_sensor_data)
        self.create_subscription(JointState, topics.JOINT_STATES, self.on_joint_state,
                                 CAMERA_NODE_JOINT_STATE_DEPTH)
        self.window = None           # (x, y, radius) [m] in the world frame, or None
        self._window_mask = (None, None)   # (key, mask) of the last pose and window
        self.create_subscription(
            PointStamped, topics.THERMAL_WINDOW, self.on_window, LATCHED)
        if self.diagnostics_period > 0:
            # wall time: the node clock stops with /clock, and that must be reported too
            self.create_timer(self.diagnostics_period, self.publish_diagnostics,
                              clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f'thermal_monitor: T_p {config.threshold} degC, cap '
                               f'{config.camera_cap} degC; N_p counts from '
                               f'{config.counting_level} degC')

    def on_joint_state(self, msg):
        """Merge a (partial) joint state into the buffer."""
        problem = self.joints.add_message(msg)
        if problem:
            self.get_logger().warn(problem, throttle_duration_sec=5.0)

    def on_window(self, msg):
        """Set (or, with NaN, clear) the N_p window: centre x, y and radius z [m], world."""
        values = (msg.point.x, msg.point.y, msg.point.z)
        if any(math.isnan(v) for v in values):
            self.window = None
        elif not all(math.isfinite(v) for v in values) or msg.point.z <= 0.0 or \
                (msg.header.frame_id or 'world') != 'world':
            self.get_logger().warn(f'thermal/window ignored (want a finite world point, '
                                   f'radius z > 0, frame world): {values} in '
                                   f'{msg.header.frame_id!r}; the window is cleared')
            self.window = None
        else:
            self.window = values

    def on_camera_info(self, msg):
        """Keep the thermal intrinsics (for the hottest pixel's ground point)."""
        try:
            self.camera = camera_from_info(msg)
        except ValueError as error:
            self.get_logger().warn(f'ignoring /thermal/camera_info: {error}',
                                   throttle_duration_sec=5.0)

    def on_image(self, msg):
        """Compute and publish the statistics of one thermal image."""
        started = time.perf_counter()
        self.freshness.seen(self.get_clock().now().nanoseconds * 1e-9, time.monotonic())
        stamp = stamp_to_seconds(msg.header.stamp)
        self.stats.frame(stamp)
        try:
            image = image_to_numpy(msg)
            mapping, key = self.ground_mapping(image.shape, stamp)
            window = self.window_pixels(mapping, key, image.shape)
            result = self.analyzer.statistics(image, msg.encoding, window)
        except (ImageConversionError, ValueError) as error:
            self.stats.bad_frame(str(error))
            self.get_logger().warn(f'thermal image skipped: {error}', throttle_duration_sec=2.0)
            return
        self.ignored_pixels = result.ignored
        if result.ignored:
            self.get_logger().warn(f'{result.ignored} thermal pixel(s) ignored: no reading '
                                   f'(non-finite, or above the {result.camera_cap:g} degC cap)',
                                   throttle_duration_sec=10.0)
        out = ThermalStats()
        out.frozen = self.detect_freezes and self.freezes.frozen(image, stamp)
        out.header.stamp = msg.header.stamp
        out.header.frame_id = msg.header.frame_id or self.frame_id
        out.t_max, out.threshold, out.n_p = result.t_max, result.threshold, result.n_p
        out.hottest_u, out.hottest_v = result.hottest_u, result.hottest_v
        out.saturated, out.camera_cap = result.saturated, result.camera_cap
        if mapping is not None and self.locate_hottest:
            point = mapping.pixels_to_ground([[result.hottest_u, result.hottest_v]])[0]
            if not np.any(np.isnan(point)):
                out.hottest_point_valid = True
                out.hottest_point = Point(x=float(point[0]), y=float(point[1]), z=0.0)
        if window is not None:
            out.window_valid = True
            out.window_n_p, out.window_t_max = result.window_n_p, result.window_t_max
            out.window_centre = Point(x=self.window[0], y=self.window[1], z=0.0)
            out.window_radius = self.window[2]
        self.stats_pub.publish(out)
        self.stats.result(True, milliseconds=(time.perf_counter() - started) * 1e3)

    def ground_mapping(self, shape, stamp):
        """
        Return (GroundMapping, key) of the thermal camera at `stamp` [s], (None, None) if unknown.

        Known with the camera info (of this image size) and joint states within the tolerance;
        the key (joints, world pose, intrinsics) changes when the pose does. Not made when
        nothing needs it (no hottest point asked, no window set).
        """
        if not (self.locate_hottest or self.window is not None):
            return None, None
        if self.camera is None or (self.camera.height, self.camera.width) != tuple(shape):
            return None, None
        lookup = self.joints.at(stamp, self.joint_state_tolerance, self.joint_rest_hold)
        joints = lookup.positions
        if joints is None:
            self.get_logger().warn(f'thermal camera pose unknown (no window, no hottest point): '
                                   f'{lookup.reason}', throttle_duration_sec=10.0)
            return None, None
        T_robot_world = self.rig.parameters.T_robot_world
        pose = self.rig.forward(joints)
        mapping = GroundMapping(self.camera,
                                invert_transform(T_robot_world) @ pose.T_robot_thermal)
        # by value: every camera_info message makes a new camera object
        intrinsics = (np.asarray(self.camera.matrix).tobytes(),
                      np.asarray(self.camera.distortion).tobytes())
        return mapping, (np.asarray(joints).tobytes(), T_robot_world.tobytes(), intrinsics)

    def window_pixels(self, mapping, key, shape):
        """Return the window's pixel mask at this pose (cached while still), None if unset."""
        if self.window is None or mapping is None:
            return None
        key = (key, self.window)
        if self._window_mask[0] != key:
            self._window_mask = (key, window_mask(mapping, shape, self.window[:2],
                                                  self.window[2]))
        return self._window_mask[1]

    def publish_diagnostics(self):
        """Publish the frame counters and the input's health on /diagnostics."""
        node_now, wall_now = self.get_clock().now().nanoseconds * 1e-9, time.monotonic()
        values = self.stats.as_dict()
        node_age, wall_age = self.freshness.ages(node_now, wall_now)
        values['input_age_node_clock'], values['input_age_wall'] = node_age, wall_age
        values['pixels_ignored_last_frame'] = self.ignored_pixels
        values['frozen_frames'] = self.freezes.frozen_frames
        warning = f'{self.ignored_pixels} pixel(s) of the last frame are no reading' \
            if self.ignored_pixels else ''
        level, message = self.stats.health(self.freshness.stale(node_now, wall_now), warning)
        self.diagnostics_pub.publish(diagnostic_array(
            self.get_name(), 'thermal_monitor: frames', values, self.get_clock().now().to_msg(),
            level, message))
        if level == ERROR:
            self.get_logger().warn(message, throttle_duration_sec=10.0)


def main(args=None):
    """Run the thermal_monitor node (start-up objects frozen)."""
    run_node(frozen_after_start_up(ThermalMonitorNode), args)


if __name__ == '__main__':
    main()
