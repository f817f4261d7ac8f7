"""
Node spot_detector: the light spot on the ground plane from the RGB camera (paper Eqs 7-10).

Subscribes (sensor-data QoS) ``/rgb/image_raw`` (rgb8, bgr8, rgba8, bgra8 or mono8) and
``/rgb/camera_info``; (reliable) ``/joint_states`` for the marker-pose cache and the optics
frame of the Eq 10 features. Publishes (reliable) ``/spot`` (helio_msgs/SpotObservation,
one per processed image, valid or with its reason) and ``/diagnostics``
(diagnostic_msgs/DiagnosticArray: frames received, published, malformed, invalid by reason,
dropped (estimated from stamp gaps), marker searches, processing time).

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
from helio_optics.geometry import quaternion_from_matrix
from helio_optics.lens import LensParameters
from helio_optics.node_parameters import declare
from helio_optics.node_runner import run_node
from helio_perception.frame_statistics import FrameStatistics
from helio_perception.ground_plane import camera_from_info, MarkerConfig
from helio_perception.image_conversion import image_to_numpy, ImageConversionError
from helio_perception.node_support import (
    diagnostics, JointCache, load_rig, stamp_seconds)
from helio_perception.process_tuning import frozen_after_start_up, keep_large_buffers
from helio_perception.spot_detection import SpotConfig, THRESHOLD_MODES
from helio_perception.spot_observer import optics_from_world, SpotObserver
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image, JointState

CHANNEL_ORDER = {'rgb8': 'rgb', 'rgba8': 'rgb', 'bgr8': 'bgr', 'bgra8': 'bgr', 'mono8': 'rgb'}


class SpotDetectorNode(Node):
    """Detect the light spot in each RGB image and publish a SpotObservation."""

    def __init__(self, **kwargs):
        super().__init__('spot_detector', **kwargs)
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
            roi_margin=declare(self, 'marker.roi_margin', 0.5,
                               'Re-detection ROI around the last corners, as a fraction of '
                               'their extent [-].', 0.0, 10.0),
            joint_tolerance=declare(self, 'marker.joint_tolerance', 1e-4,
                                    'Joint change below which the camera counts as still and '
                                    'the marker pose is reused [rad].', 0.0, 1.0),
            max_pose_age=declare(self, 'marker.max_pose_age', 0.0,
                                 'Re-detect the marker after this long even when still '
                                 '(0: never) [s].', 0.0, 3600.0),
            refine_edges=declare(self, 'marker.refine_edges', True,
                                 'Take the corners from lines fitted to the outer edges.'),
            detect_max_width=declare(self, 'marker.detect_max_width', 640,
                                     'Wider images are downscaled for detection (0: never) '
                                     '[px].', 0, 8192))
        spot = SpotConfig(
            threshold_mode=declare(self, 'spot.threshold_mode', 'fixed',
                                   'Binary threshold for the candidates.',
                                   choices=THRESHOLD_MODES),
            threshold=declare(self, 'spot.threshold', 220.0,
                              "Grey level of the 'fixed' threshold [0-255].", 0.0, 255.0),
            min_threshold=declare(self, 'spot.min_threshold', 100.0,
                                  'Floor of the Otsu threshold [0-255].', 0.0, 255.0),
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
            max_jump=declare(self, 'spot.max_jump', 0.02,
                             'Largest move from the last spot to count as the same spot [m].',
                             0.0, 1.0),
            expected_max_age=declare(self, 'spot.expected_max_age', 2.0,
                                     'How long the last spot predicts the next [s].',
                                     0.0, 3600.0),
            saturation_level=declare(self, 'spot.saturation_level', 250.0,
                                     'Grey level counted as saturated [0-255].', 0.0, 255.0),
            refine_margin=declare(self, 'spot.refine_margin', 4,
                                  'Pixels around the region for the half-level measure [px].',
                                  1, 100),
            edge_band=declare(self, 'spot.edge_band', 2,
                              'Band around the contour measured fractionally (0: off) [px].',
                              0, 20))
        self.observer = SpotObserver(marker, spot)
        self.features_in_optics = declare(
            self, 'features_in_optics_frame', True,
            'Compute the Eq 10 features in the optics frame from /joint_states and the rig '
            'kinematics (else, or without joint states, in the world frame).')
        self.joint_state_timeout = declare(
            self, 'joint_state_timeout', 1.0,
            'Joint states older than this are not used (0: any age) [s].', 0.0, 3600.0)
        rig_file = declare(self, 'rig_file', '',
                           "Rig geometry YAML (empty: helio_optics' config/rig.yaml).")
        lens = LensParameters(
            focal_length=declare(self, 'lens.focal_length', LensParameters.focal_length,
                                 'Lens focal length f [m] (optics frame, Eq 1).', 0.01, 1.0),
            refractive_index=declare(self, 'lens.refractive_index',
                                     LensParameters.refractive_index,
                                     'Lens refractive index [-].', 1.01, 3.0),
            thickness=declare(self, 'lens.thickness', LensParameters.thickness,
                              'Lens plate thickness [m].', 0.0, 0.05),
            aperture_diameter=declare(self, 'lens.aperture_diameter',
                                      LensParameters.aperture_diameter,
                                      'Lens clear aperture [m].', 0.001, 1.0))
        self.T_lens_optics = lens.T_lens_optics
        self.rig = load_rig(self, rig_file) if self.features_in_optics else None
        self.diagnostics_period = declare(self, 'diagnostics_period', 1.0,
                                          'Period of /diagnostics and the log summary [s].',
                                          0.0, 3600.0)

        self.stats = FrameStatistics()
        self.joints = JointCache()
        self.camera = None
        self._info_key = None
        self.spot_pub = self.create_publisher(SpotObservation, 'spot',
                                              QoSProfile(depth=10,
                                                         reliability=ReliabilityPolicy.RELIABLE))
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(Image, 'rgb/image_raw', self.on_image, qos_profile_sensor_data)
        self.create_subscription(CameraInfo, 'rgb/camera_info', self.on_camera_info,
                                 qos_profile_sensor_data)
        self.create_subscription(JointState, 'joint_states', self.joints.update, 50)
        if self.diagnostics_period > 0:
            self.create_timer(self.diagnostics_period, self.publish_diagnostics)
        self.get_logger().info(
            f'spot_detector: marker {marker.dictionary} id {marker.marker_id} side '
            f'{marker.side} m, threshold {spot.threshold_mode}, features in '
            f"{'optics (from /joint_states)' if self.features_in_optics else 'world'} frame")

    def on_camera_info(self, msg):
        """Keep the intrinsics; a change of intrinsics drops the cached marker pose."""
        key = (tuple(msg.k), tuple(msg.d), msg.width, msg.height)
        if key == self._info_key:
            return
        try:
            camera = camera_from_info(msg.k, msg.d, msg.width, msg.height)
        except ValueError as error:
            self.stats.bad_frame('bad camera_info')
            self.get_logger().warn(f'ignoring /rgb/camera_info: {error}',
                                   throttle_duration_sec=5.0)
            return
        if msg.distortion_model not in ('plumb_bob', 'rational_polynomial', '') and any(msg.d):
            self.get_logger().warn(f'distortion model {msg.distortion_model!r}: using its first '
                                   'five coefficients as plumb_bob', once=True)
        self.camera, self._info_key = camera, key
        self.observer.reset()

    def on_image(self, msg):
        """Process one image: observe the spot and publish the observation."""
        started = time.perf_counter()
        stamp = stamp_seconds(msg.header.stamp)
        dropped = self.stats.frame(stamp)
        if dropped:
            self.get_logger().debug(f'{dropped} frame(s) dropped before this one')
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
            joints = self.joints.positions(self.joint_state_timeout)
            T_optics_world = None
            if self.rig is not None and joints is not None:
                pose = self.rig.forward(joints)
                T_optics_world = optics_from_world(pose.T_robot_lens, self.T_lens_optics,
                                                   self.rig.parameters.T_robot_world)
            observation = self.observer.observe(image, self.camera, stamp, joints,
                                                T_optics_world, order)
        except (ImageConversionError, ValueError, cv2.error) as error:
            self.stats.bad_frame(str(error))
            self.get_logger().warn(f'image skipped: {error}', throttle_duration_sec=2.0)
            return
        out = to_message(observation, msg.header.stamp)
        self.spot_pub.publish(out)
        self.stats.result(True, observation.valid, observation.reason,
                          (time.perf_counter() - started) * 1e3)

    def publish_diagnostics(self):
        """Publish the frame counters on /diagnostics and log them."""
        values = self.stats.as_dict()
        values.update({f'marker_{k}': v for k, v in self.observer.tracker.counts.items()})
        self.diagnostics_pub.publish(diagnostics(self, 'spot_detector: frames', values,
                                                 self.get_clock().now().to_msg()))
        self.get_logger().debug(self.stats.summary())


def to_message(observation, stamp):
    """Build a SpotObservation from an Observation (world frame, features' own frame)."""
    msg = SpotObservation()
    msg.header.stamp = stamp
    msg.header.frame_id = 'world'
    msg.valid = bool(observation.valid)
    msg.reason = observation.reason
    spot = observation.spot
    msg.marker_pose_age = float(observation.marker_pose_age)
    if observation.T_world_camera is not None:
        position, rotation = observation.T_world_camera[:3, 3], observation.T_world_camera[:3, :3]
        msg.camera_pose.position = Point(x=float(position[0]), y=float(position[1]),
                                         z=float(position[2]))
        q = quaternion_from_matrix(rotation)
        msg.camera_pose.orientation.x, msg.camera_pose.orientation.y = float(q[0]), float(q[1])
        msg.camera_pose.orientation.z, msg.camera_pose.orientation.w = float(q[2]), float(q[3])
    if not observation.valid:
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
