"""
Node spot_detector: the light spot on the ground plane from the RGB camera (paper Eqs 7-10).

Subscribes (sensor-data QoS) ``rgb/image_raw`` (rgb8, bgr8, rgba8, bgra8 or mono8) and
``rgb/camera_info``; (reliable) ``joint_states`` (the drivers' partial messages, merged by
``JointStateBuffer``; the joints at each image's stamp) for the marker-pose cache and the
optics frame of the Eq 10 features. Publishes (reliable) ``spot``
(helio_msgs/SpotObservation, one per processed image, valid or with its reason) and the
global ``/diagnostics``
(diagnostic_msgs/DiagnosticArray: frames received, published, malformed, invalid by reason,
dropped (estimated from stamp gaps), marker searches, processing time; ERROR when no image
arrived for `input_timeout` on the node clock or `input_wall_timeout` of wall time, WARN for
malformed frames or no camera info), published on wall time.

The logic is `helio_perception.spot_observer.SpotObserver`; this file declares the
parameters (config/spot_detector.yaml), converts messages and calls it. A malformed frame is
logged with its reason and skipped.
"""

import math
import time

import cv2
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Point
from helio_msgs.msg import SpotObservation
from helio_optics.geometry import invert_transform, quaternion_from_matrix
from helio_optics.node_kit import topics
from helio_optics.node_kit.conversions import camera_from_info, image_to_numpy
from helio_optics.node_kit.conversions import ImageConversionError, stamp_to_seconds
from helio_optics.node_kit.deployment import camera_info_file_or_default
from helio_optics.node_kit.deployment import declare_calibration_dir, declare_lens, declare_rig
from helio_optics.node_kit.deployment import follow_world_calibration, RGB_CAMERA_INFO_FILE
from helio_optics.node_kit.diagnostics import diagnostic_array, OK
from helio_optics.node_kit.joint_states import CAMERA_NODE_JOINT_STATE_DEPTH, JointStateBuffer
from helio_optics.node_kit.parameters import declare, declare_joint_lookup
from helio_optics.node_kit.process_tuning import frozen_after_start_up, keep_large_buffers
from helio_optics.node_kit.runner import run_node
from helio_perception.camera_calibration import read_camera_info
from helio_perception.frame_statistics import FrameStatistics, InputFreshness
from helio_perception.ground_plane import MarkerConfig, RESPONSES
from helio_perception.spot_detection import SpotConfig, THRESHOLD_MODES
from helio_perception.spot_observer import optics_from_world, SpotObserver
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image, JointState

CHANNEL_ORDER = {'rgb8': 'rgb', 'rgba8': 'rgb', 'bgr8': 'bgr', 'bgra8': 'bgr', 'mono8': 'rgb'}

# joints at rest only between two equal samples: an image newer than every sample may show
# the arm already moving off to the next pose
REST_AFTER_NEWEST = False


class SpotDetectorNode(Node):
    """Detect the light spot in each RGB image and publish a SpotObservation."""

    def __init__(self, **kwargs):
        super().__init__('spot_detector', **kwargs)
        response = declare(self, 'camera_response', 'srgb',
                           "The camera's tone curve, undone before edges and spots are "
                           "measured: 'srgb' (webcams) or 'linear'.", choices=RESPONSES)
        marker = MarkerConfig(
            dictionary=declare(self, 'marker.dictionary', 'DICT_4X4_50',
                               'cv2.aruco predefined dictionary of the ground marker.'),
            marker_id=declare(self, 'marker.id', 0, 'ArUco id of the ground marker.', 0, 999),
            side=declare(self, 'marker.side', 0.04,
                         "Side of the marker's black square [m].", 0.001, 2.0),
            max_reprojection_error=declare(
                self, 'marker.max_reprojection_error', 1.5,
                'Largest plausible RMS corner reprojection error [px].', 0.01, 50.0),
            min_side_pixels=declare(self, 'marker.min_side_pixels', 20.0,
                                    'Smallest plausible marker side in the image [px].',
                                    4.0, 4096.0),
            min_distance=declare(self, 'marker.min_distance', 0.03,
                                 'Closest plausible camera-marker distance [m].', 0.0, 10.0),
            max_distance=declare(self, 'marker.max_distance', 2.0,
                                 'Farthest plausible camera-marker distance [m].', 0.0, 100.0),
            max_view_angle_deg=declare(self, 'marker.max_view_angle_deg', 60.0,
                                       'Refuse the marker seen farther off its normal: so '
                                       'slanted a pose misplaces the ground by up to '
                                       'millimetres [deg].', 0.0, 90.0),
            roi_margin=declare(self, 'marker.roi_margin', 0.5,
                               'Re-detection ROI around the last corners, as a fraction of '
                               'their extent [-].', 0.0, 10.0),
            roi_search=declare(self, 'marker.roi_search', True,
                               'Re-detect the marker first in that ROI (false: always in the '
                               'whole frame, so that each pose depends on its own image '
                               'alone, as a replay that skips images needs).'),
            joint_tolerance=declare(self, 'marker.joint_tolerance', 1e-4,
                                    'Joint change below which the camera counts as still and '
                                    'the marker pose is reused [rad].', 0.0, 1.0),
            max_pose_age=declare(self, 'marker.max_pose_age', 0.0,
                                 'Re-detect the marker after this long even when still '
                                 '(0: never) [s].', 0.0, 3600.0),
            miss_retry_period=declare(self, 'marker.miss_retry_period', 1.0,
                                      'A marker not found while the joints stay still is '
                                      'searched for again only this often (0: every frame) '
                                      '[s].', 0.0, 3600.0),
            out_of_view_margin=declare(self, 'marker.out_of_view_margin', 1.0,
                                       'The marker is not searched for where the kinematic '
                                       'camera pose puts it wholly outside the image, grown '
                                       'by this many of its sides all round (negative: '
                                       'always search) [-].', -1.0, 100.0),
            refine_edges=declare(self, 'marker.refine_edges', True,
                                 'Take the corners from lines fitted to the outer edges.'),
            detect_max_width=declare(self, 'marker.detect_max_width', 640,
                                     'Wider images are downscaled for detection, then '
                                     'searched at full size if that fails (0: never) [px].',
                                     0, 8192),
            max_edge_width=declare(self, 'marker.max_edge_width_pixels', 4.5,
                                   "Sharpest acceptable frames: the marker's outer edges "
                                   'rise (10-90 %) within this; wider is BLURRED [px].',
                                   1.0, 100.0),
            max_clipped_fraction=declare(self, 'marker.max_clipped_fraction', 0.5,
                                         "Refuse the marker when more of its outline's white "
                                         'is at full scale (over-exposed) [-].', 0.0, 1.0),
            max_edge_residual=declare(self, 'marker.max_edge_residual_pixels', 1.0,
                                      "Refuse the marker when its outer edges' crossings lie "
                                      'farther (rms) from their fitted lines: a shadow or glare '
                                      'across them [px].', 0.05, 10.0),
            shadow_levels=tuple(declare(
                self, 'marker.shadow_levels', list(MarkerConfig.shadow_levels),
                'Global grey levels tried when the adaptive threshold finds no marker (the '
                "lens' shadow across it), as fractions of the frame's bright level in linear "
                'light (empty: none) [-].')),
            response=response)
        spot = SpotConfig(
            threshold_mode=declare(self, 'spot.threshold_mode', 'auto',
                                   "Binary threshold for the candidates: 'auto' follows the "
                                   "frame's light, 'fixed' or 'otsu'.",
                                   choices=THRESHOLD_MODES),
            threshold=declare(self, 'spot.threshold', 220.0,
                              "Grey level of the 'fixed' threshold, ceiling of 'auto' "
                              '[0-255].', 0.0, 255.0),
            relative_threshold=declare(self, 'spot.relative_threshold', 1.5,
                                       "'auto': candidates brighter than this many times the "
                                       "frame's bright diffuse light (95th percentile, "
                                       'linear) [-].', 1.0, 100.0),
            min_threshold=declare(self, 'spot.min_threshold', 100.0,
                                  "Floor of the 'auto' and Otsu thresholds [0-255].",
                                  0.0, 255.0),
            blur_kernel=declare(self, 'spot.blur_kernel', 5,
                                'Gaussian blur before thresholding (odd; <= 1: none) [px].',
                                0, 31),
            min_pixels=declare(self, 'spot.min_pixels', 12, 'Smallest spot [px].', 1, 100000),
            min_area=declare(self, 'spot.min_area', 2e-7, 'Smallest spot on the ground [m^2].',
                             0.0, 1.0),
            max_area=declare(self, 'spot.max_area', 2e-3, 'Largest spot on the ground [m^2].',
                             0.0, 1.0),
            min_fill=declare(self, 'spot.min_fill', 0.8,
                             'Contour area / fitted ellipse area, lower bound [-].', 0.0, 1.0),
            max_fill=declare(self, 'spot.max_fill', 1.2,
                             'Contour area / fitted ellipse area, upper bound [-].', 1.0, 10.0),
            min_solidity=declare(self, 'spot.min_solidity', 0.9,
                                 'Contour area / convex hull area, lower bound [-].', 0.0, 1.0),
            marker_margin=declare(self, 'spot.marker_margin', 0.008,
                                  'Masked border around the marker (quiet zone) [m].',
                                  0.0, 1.0),
            sheet_level=declare(self, 'spot.sheet_level', 0.6,
                                "The marker's paper, masked: the region connected to its "
                                'quiet zone brighter than this x its light (0: off) [-].',
                                0.0, 1.0),
            max_jump=declare(self, 'spot.max_jump', 0.02,
                             'Largest move from the last spot to count as the same spot [m].',
                             0.0, 1.0),
            expected_max_age=declare(self, 'spot.expected_max_age', 2.0,
                                     'How long the last spot predicts the next [s].',
                                     0.0, 3600.0),
            dominance=declare(self, 'spot.dominance', 4.0,
                              'A candidate with this many times the light of each other one '
                              'is the spot (0: off) [-].', 0.0, 1000.0),
            saturation_level=declare(self, 'spot.saturation_level', 250.0,
                                     'Grey level counted as saturated [0-255].', 0.0, 255.0),
            refine_margin=declare(self, 'spot.refine_margin', 4,
                                  'Pixels around the region for the half-level measure [px].',
                                  1, 100),
            edge_band=declare(self, 'spot.edge_band', 2,
                              'Band around the contour measured fractionally (0: off) [px].',
                              0, 20),
            border_margin=declare(self, 'spot.border_margin_pixels', 2,
                                  'A spot whose light comes this close to the image border is '
                                  'CUT_BY_BORDER [px].', 0, 100),
            occlusion_level=declare(self, 'spot.occlusion_level', 0.5,
                                    "Neighbours of the spot's outline darker than this x its "
                                    'background occlude it [-].', 0.0, 1.0),
            max_occluded_fraction=declare(self, 'spot.max_occluded_fraction', 0.1,
                                          'OCCLUDED when more of the outline borders them [-].',
                                          0.0, 1.0),
            response=response)
        self.observer = SpotObserver(marker, spot)
        self.features_in_optics = declare(
            self, 'features_in_optics_frame', True,
            'Compute the Eq 10 features in the optics frame from /joint_states and the rig '
            'kinematics (else, or without joint states, in the world frame).')
        self.joint_state_tolerance, self.joint_rest_hold = declare_joint_lookup(
            self, rest_after_newest=REST_AFTER_NEWEST)
        self.max_image_lag = declare(
            self, 'max_image_lag', 0.5,
            'Under use_sim_time, an image stamped more than this before the node clock is '
            'skipped: a detector that falls behind its camera (a simulated clock running '
            'several times faster than real time) otherwise works through old images while '
            'the joint states queue behind them, and has none for the image it is on. On the '
            'system clock images are never skipped (a replay without its /clock has old '
            'stamps); 0: never [s].', 0.0, 60.0)
        self.sim_time = bool(self.get_parameter('use_sim_time').value)
        self.joint_wait = declare(
            self, 'joint_wait', 0.25,
            'An image waits at most this long (wall time) for joint states stamped at or '
            'after it, so that its joints are interpolated around it rather than taken from '
            'a sample before it, when the arm may already have moved (the marker pose cache '
            'and the kinematic camera pose depend on them). The drivers publish at 20 Hz: a '
            'wait is usually one joint-state period; 0: never wait [s].', 0.0, 5.0)
        self._waiting = None          # (image message, wall time it came) waiting for joints
        lens, _ = declare_lens(self)
        self.T_lens_optics = lens.T_lens_optics
        self.rig, _ = declare_rig(self)
        self.kinematic_fallback = declare(
            self, 'kinematic_pose_fallback', True,
            'When the marker is not in view, map the spot through the camera pose of the '
            "joints' forward kinematics, once a robot-world calibration has arrived on "
            'calibration/world_pose (camera_pose_source says which pose was used).')
        self.world_calibrated = False
        follow_world_calibration(self, self.rig, self._calibrated)   # T_robot_world
        self.diagnostics_period = declare(self, 'diagnostics_period', 1.0,
                                          'Period of /diagnostics and the log summary, on '
                                          'wall time [s].', 0.0, 3600.0)
        self.freshness = InputFreshness.declared(self, topics.RGB_IMAGE, time.monotonic())

        calibration_dir = declare_calibration_dir(
            self, f'its {RGB_CAMERA_INFO_FILE} (helio calibrate camera) is the camera_info '
            'file when camera_info_file is empty')
        self.camera_info_file = declare(
            self, 'camera_info_file', '',
            'A camera_info YAML (camera_calibration_parsers\' format, as "helio calibrate '
            'camera" writes it) used while rgb/camera_info is uncalibrated (K all zero, as '
            'usb_cam sends without a calibration file); a file for another image size than '
            "rgb/camera_info's is refused with the reason. A calibrated rgb/camera_info is "
            f"used as it comes ('': calibration_dir's {RGB_CAMERA_INFO_FILE} if there is "
            "one; 'none': no file).")
        self.camera_info_file = camera_info_file_or_default(self.camera_info_file,
                                                            calibration_dir)
        self.stats = FrameStatistics()
        self.joints = JointStateBuffer()
        self.camera = None
        self._info_key = None
        self._file_camera = None     # (PinholeCamera or None, why not) of camera_info_file
        self.file_refused = ''       # why camera_info_file was refused last ('' if it was not)
        self.spot_pub = self.create_publisher(SpotObservation, topics.SPOT,
                                              QoSProfile(depth=10,
                                                         reliability=ReliabilityPolicy.RELIABLE))
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(Image, topics.RGB_IMAGE, self.on_image, qos_profile_sensor_data)
        self.create_subscription(CameraInfo, topics.RGB_CAMERA_INFO, self.on_camera_info,
                                 qos_profile_sensor_data)
        self.create_subscription(JointState, topics.JOINT_STATES, self.on_joint_state,
                                 CAMERA_NODE_JOINT_STATE_DEPTH)
        if self.joint_wait > 0.0:
            # wall time: under a held simulated clock the joints it waits for may never come
            self.create_timer(min(0.05, self.joint_wait), self._flush_waiting,
                              clock=Clock(clock_type=ClockType.STEADY_TIME))
        if self.diagnostics_period > 0:
            # wall time: the node clock stops with /clock, and that must be reported too
            self.create_timer(self.diagnostics_period, self.publish_diagnostics,
                              clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(
            f'spot_detector: marker {marker.dictionary} id {marker.marker_id} side '
            f'{marker.side} m, threshold {spot.threshold_mode}, features in '
            f"{'optics (from /joint_states)' if self.features_in_optics else 'world'} frame; "
            + (f'camera_info file {self.camera_info_file} while rgb/camera_info is '
               'uncalibrated' if self.camera_info_file else 'no camera_info file'))

    def _calibrated(self, _rig):
        self.world_calibrated = True

    def on_joint_state(self, msg):
        """Merge a (partial) joint state into the buffer; take a waiting image it completes."""
        problem = self.joints.add_message(msg)
        if problem:
            self.get_logger().warn(problem, throttle_duration_sec=5.0)
        if self._waiting is not None and self.joints.reaches(
                stamp_to_seconds(self._waiting[0].header.stamp)):
            self._take_waiting()

    def on_camera_info(self, msg):
        """Keep the intrinsics; a change of intrinsics drops the cached marker pose."""
        key = (tuple(msg.k), tuple(msg.d), msg.width, msg.height)
        if key == self._info_key:
            return
        if self.camera_info_file and not any(msg.k):
            self._take_file_camera(msg, key)
            return
        try:
            camera = camera_from_info(msg)
        except ValueError as error:
            self.stats.bad_frame('bad camera_info')
            self.get_logger().warn(f'ignoring /rgb/camera_info: {error}',
                                   throttle_duration_sec=5.0)
            return
        if msg.distortion_model not in ('plumb_bob', 'rational_polynomial', '') and any(msg.d):
            self.get_logger().warn(f'distortion model {msg.distortion_model!r}: using its first '
                                   'five coefficients as plumb_bob', once=True)
        if self.camera_info_file and self._info_key is None:
            self.get_logger().info(f'rgb/camera_info is calibrated: using it, not '
                                   f'camera_info_file {self.camera_info_file}')
        self.camera, self._info_key = camera, key
        self.observer.reset()

    def _take_file_camera(self, msg, key):
        """Use camera_info_file for an uncalibrated rgb/camera_info, or refuse it with why."""
        if self._file_camera is None or self._file_camera[0] is None:
            try:
                self._file_camera = (read_camera_info(self.camera_info_file)[0], '')
            except ValueError as error:
                self._file_camera = (None, str(error))
        camera, why = self._file_camera
        if camera is not None and msg.width and msg.height and \
                (msg.width, msg.height) != (camera.width, camera.height):
            why = (f'{self.camera_info_file} is for {camera.width}x{camera.height} images, '
                   f'rgb/camera_info says {msg.width}x{msg.height}: calibrate this camera at '
                   'this size ("helio calibrate camera")')
            camera = None
        self.file_refused = why if camera is None else ''
        if camera is None:
            self.camera, self._info_key = None, None
            self.stats.bad_frame('uncalibrated camera_info')
            self.get_logger().error(f'rgb/camera_info is uncalibrated (K = 0) and '
                                    f'camera_info_file is refused: {why}',
                                    throttle_duration_sec=10.0)
            return
        self.camera, self._info_key = camera, key
        self.observer.reset()
        m = camera.matrix
        self.get_logger().info(
            f'rgb/camera_info is uncalibrated (K = 0): using {self.camera_info_file} '
            f'({camera.width}x{camera.height}, fx {m[0, 0]:.2f} fy {m[1, 1]:.2f} cx '
            f'{m[0, 2]:.2f} cy {m[1, 2]:.2f} px, k1 {camera.distortion[0]:.4f})')

    def on_image(self, msg):
        """
        Take one image: process it now if the joints reach its stamp, else let it wait.

        The drivers read the joints after the camera's frame is taken, so the joint states
        at or after an image usually come just after it. An image waits for them (at most
        ``joint_wait`` of wall time, one image at a time: a newer image takes the older one
        through first).
        """
        if self._waiting is not None:
            if self._waiting[0].header.stamp == msg.header.stamp:
                self._waiting = (msg, self._waiting[1])       # the same frame sent again
                return
            self._take_waiting()
        heard = self.joints.newest_stamp() is not None
        if self.joint_wait > 0.0 and heard and \
                not self.joints.reaches(stamp_to_seconds(msg.header.stamp)):
            self._waiting = (msg, time.monotonic())
            return
        self.process_image(msg)

    def _take_waiting(self):
        msg, _ = self._waiting
        self._waiting = None
        self.process_image(msg)

    def _flush_waiting(self):
        """Process an image that waited ``joint_wait`` for joints, with the joints known."""
        if self._waiting is not None and time.monotonic() - self._waiting[1] >= self.joint_wait:
            self._take_waiting()

    def process_image(self, msg):
        """Process one image: observe the spot and publish the observation."""
        started = time.perf_counter()
        self.freshness.seen(self.node_seconds(), time.monotonic())
        stamp = stamp_to_seconds(msg.header.stamp)
        dropped = self.stats.frame(stamp)
        if dropped:
            self.get_logger().debug(f'{dropped} frame(s) dropped before this one')
        lag = self.node_seconds() - stamp
        if self.sim_time and self.max_image_lag > 0.0 and lag > self.max_image_lag:
            self.stats.late_frame()
            self.get_logger().warn(
                f'image {lag:.2f} s behind the clock skipped (max_image_lag '
                f'{self.max_image_lag:g} s): the detector does not keep up with the camera; '
                f'{self.stats.late} skipped so far', throttle_duration_sec=5.0)
            return
        if self.camera is None:
            self.stats.bad_frame('no camera_info yet')
            self.get_logger().warn('no /rgb/camera_info yet: image skipped',
                                   throttle_duration_sec=5.0)
            return
        try:
            image = image_to_numpy(msg)
            order = CHANNEL_ORDER.get(msg.encoding)
            if order is None:
                raise ImageConversionError(f'{msg.encoding} is not a colour or 8-bit mono '
                                           'encoding')
            lookup = self.joints.at(stamp, self.joint_state_tolerance, self.joint_rest_hold,
                                    rest_after_newest=REST_AFTER_NEWEST)
            joints = lookup.positions
            if joints is None and (self.features_in_optics or self.world_calibrated):
                self.get_logger().warn(
                    f'no joint states at the image of {stamp:.3f} s ({lookup.reason}): no '
                    'optics-frame features, no kinematic camera pose', throttle_duration_sec=5.0)
            T_optics_world = T_world_camera_kinematic = None
            if joints is not None:
                pose = self.rig.forward(joints)
                if self.features_in_optics:
                    T_optics_world = optics_from_world(pose.T_robot_lens, self.T_lens_optics,
                                                       self.rig.parameters.T_robot_world)
                if self.kinematic_fallback and self.world_calibrated:
                    T_world_camera_kinematic = invert_transform(
                        self.rig.parameters.T_robot_world) @ pose.T_robot_rgb
            observation = self.observer.observe(image, self.camera, stamp, joints,
                                                T_optics_world, order,
                                                T_world_camera_kinematic)
        except (ImageConversionError, ValueError, cv2.error) as error:
            self.stats.bad_frame(str(error))
            self.get_logger().warn(f'image skipped: {error}', throttle_duration_sec=2.0)
            return
        out = to_message(observation, msg.header.stamp)
        self.spot_pub.publish(out)
        self.stats.result(True, observation.valid, observation.reason,
                          (time.perf_counter() - started) * 1e3)

    def node_seconds(self):
        """Return the node clock's time [s] (simulated time under use_sim_time)."""
        return self.get_clock().now().nanoseconds * 1e-9

    def publish_diagnostics(self):
        """Publish the frame counters and the input's health on /diagnostics; log them."""
        node_now, wall_now = self.node_seconds(), time.monotonic()
        values = self.stats.as_dict()
        values.update({f'marker_{k}': v for k, v in self.observer.tracker.counts.items()})
        node_age, wall_age = self.freshness.ages(node_now, wall_now)
        values['input_age_node_clock'], values['input_age_wall'] = node_age, wall_age
        level, message = self.stats.health(
            self.freshness.stale(node_now, wall_now),
            '' if self.camera is not None else 'no rgb/camera_info yet')
        self.diagnostics_pub.publish(diagnostic_array(
            self.get_name(), 'spot_detector: frames', values, self.get_clock().now().to_msg(),
            level, message))
        if level != OK:
            self.get_logger().warn(message, throttle_duration_sec=10.0)
        self.get_logger().debug(self.stats.summary())


def to_message(observation, stamp):
    """
    Build a SpotObservation from an Observation (world frame, features' own frame).

    A measured spot's fields are filled whatever its quality (only a FULL one is valid).
    """
    msg = SpotObservation()
    msg.header.stamp = stamp
    msg.header.frame_id = 'world'
    msg.valid = bool(observation.valid)
    msg.reason = observation.reason
    spot = observation.spot
    msg.marker_pose_age = float(observation.marker_pose_age)
    msg.camera_pose_source = observation.pose_source
    if observation.T_world_camera is not None:
        position, rotation = observation.T_world_camera[:3, 3], observation.T_world_camera[:3, :3]
        msg.camera_pose.position = Point(x=float(position[0]), y=float(position[1]),
                                         z=float(position[2]))
        q = quaternion_from_matrix(rotation)
        msg.camera_pose.orientation.x, msg.camera_pose.orientation.y = float(q[0]), float(q[1])
        msg.camera_pose.orientation.z, msg.camera_pose.orientation.w = float(q[2]), float(q[3])
    msg.quality = int(observation.quality)
    msg.quality_reason = observation.quality_reason
    if not spot.measured:
        msg.feature_frame = ''
        msg.pi_feature = msg.theta_feature = msg.axis_angle = math.nan
        return msg
    msg.center = Point(x=float(spot.center[0]), y=float(spot.center[1]), z=0.0)
    msg.semi_major, msg.semi_minor = float(spot.semi_major), float(spot.semi_minor)
    msg.orientation = float(spot.orientation)
    msg.area = float(spot.area)
    msg.contour = [Point(x=float(x), y=float(y), z=0.0) for x, y, _ in spot.contour]
    features = observation.features
    msg.feature_frame = features.frame
    msg.pi_feature, msg.theta_feature = float(features.pi), float(features.theta)
    msg.axis_angle, msg.eccentricity = float(features.axis_angle), float(features.eccentricity)
    msg.pixel_count = int(spot.pixel_count)
    msg.saturated = bool(spot.saturated)
    return msg


def main(args=None):
    """Run the spot_detector node (freed frame buffers reused, start-up objects frozen)."""
    keep_large_buffers()
    run_node(frozen_after_start_up(SpotDetectorNode), args)


if __name__ == '__main__':
    main()
