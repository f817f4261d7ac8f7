"""
One RGB frame in, one light-spot observation out: marker pose (cached), spot, Eq 10 features.

This is the whole of spot_detector's logic without ROS: `SpotObserver.observe` takes the
image, the camera, the image stamp, the joint positions (for the pose cache) and optionally
T_optics_world (for features in the optics frame, Eq 9), and returns an `Observation` that the
node turns into a helio_msgs/SpotObservation.
"""

from dataclasses import dataclass, field

from helio_optics.geometry import invert_transform, transform_points
from helio_perception.ground_plane import (
    GroundMapping, marker_object_points, MarkerConfig, MarkerDetector, MarkerPoseTracker)
from helio_perception.spot_detection import (
    position_features, QUALITY_BLURRED, QUALITY_NONE, SpotConfig, SpotDetector, SpotFeatures,
    SpotResult, to_gray)
import numpy as np


@dataclass
class Observation:
    """The outcome for one frame (see SpotObservation.msg)."""

    valid: bool
    reason: str
    spot: SpotResult
    features: SpotFeatures = None
    quality: int = QUALITY_NONE
    quality_reason: str = ''
    edge_width: float = float('nan')   # the marker's outer edges, 10-90 % rise [px]
    T_world_camera: np.ndarray = None
    marker_pose_age: float = float('nan')
    marker_search: str = ''
    pose_source: str = ''                  # 'marker', 'kinematics' or '' (no pose)
    stats: dict = field(default_factory=dict)


def optics_from_world(T_robot_lens, T_lens_optics, T_robot_world):
    """Return T_optics_world = (T_robot_lens T_lens_optics)^-1 T_robot_world (Eq 9's chain)."""
    return invert_transform(T_robot_lens @ T_lens_optics) @ T_robot_world


def marker_out_of_view(camera, T_world_camera, side, margin):
    """
    Tell whether the marker, grown by `margin` of its sides all round, is wholly out of view.

    The marker is a square of `side` [m] centred on the world origin (z = 0), the camera at
    `T_world_camera`; a negative margin: never out of view. Conservative: the grown square's
    corners, projected through the pinhole without distortion, must all lie beyond one and
    the same image edge; a corner behind or nearly in the camera's plane keeps the marker
    "maybe in view".
    """
    if margin < 0.0:
        return False
    corners = marker_object_points(side * (1.0 + 2.0 * margin))
    in_camera = transform_points(invert_transform(np.asarray(T_world_camera, dtype=float)),
                                 corners)
    if np.any(in_camera[:, 2] <= 1e-3):
        return False
    pixels = in_camera[:, :2] / in_camera[:, 2:3] @ camera.matrix[:2, :2].T \
        + camera.matrix[:2, 2]
    u, v = pixels[:, 0], pixels[:, 1]
    return bool(np.all(u < -0.5) or np.all(u > camera.width - 0.5)
                or np.all(v < -0.5) or np.all(v > camera.height - 0.5))


class SpotObserver:
    """Marker pose tracking plus spot detection, with the ground mapping cached per pose."""

    def __init__(self, marker_config=None, spot_config=None):
        self.marker_config = marker_config or MarkerConfig()
        self.tracker = MarkerPoseTracker(MarkerDetector(self.marker_config))
        self.detector = SpotDetector(spot_config or SpotConfig())
        self._mapping = None
        self._mapping_key = None

    def reset(self):
        """Forget the marker pose and the last spot (e.g. new camera intrinsics)."""
        self.tracker.forget()
        self.detector.last_center = None
        self._mapping = self._mapping_key = None

    def observe(self, image, camera, stamp, joints=None, T_optics_world=None,
                channel_order='rgb', T_world_camera_kinematic=None):
        """
        Return the Observation of one image (uint8 mono, rgb/bgr or rgba/bgra).

        `stamp` [s] of the image; `joints` the joint positions when it was taken (None if
        unknown: the marker is then searched near its last corners every frame).
        `T_world_camera_kinematic`, when given, is the camera pose from the joints' forward
        kinematics and the robot-world calibration: used when the marker is not in view, and
        the marker is not searched for where that pose puts it wholly out of view
        (`marker_out_of_view`, ``MarkerConfig.out_of_view_margin``).
        """
        gray = to_gray(image, channel_order)
        if gray.shape != (camera.height, camera.width):
            raise ValueError(f'image is {gray.shape[1]}x{gray.shape[0]} but the camera info '
                             f'says {camera.width}x{camera.height}')
        if T_world_camera_kinematic is not None and marker_out_of_view(
                camera, T_world_camera_kinematic, self.marker_config.side,
                self.marker_config.out_of_view_margin):
            self.tracker.counts['out_of_view'] += 1
            return self._observe_with(gray, camera, stamp, T_world_camera_kinematic,
                                      T_optics_world, 'out_of_view')
        marker = self.tracker.update(gray, camera, stamp, joints)
        if marker.pose is None:
            if T_world_camera_kinematic is None:
                return Observation(valid=False, reason=marker.reason, spot=SpotResult(),
                                   marker_search=marker.searched)
            return self._observe_with(gray, camera, stamp, T_world_camera_kinematic,
                                      T_optics_world, marker.searched)
        pose = marker.pose
        key = (id(pose), id(camera))
        if key != self._mapping_key:
            self._mapping = GroundMapping(camera, pose.T_world_camera)
            self._mapping_key = key
        spot = self.detector.detect(gray, self._mapping, self.marker_config.side, stamp)
        if spot.measured and pose.edge_width > self.marker_config.max_edge_width:
            spot.degrade(QUALITY_BLURRED, f"the marker's edges rise over "
                         f'{pose.edge_width:.1f} px (> {self.marker_config.max_edge_width:g}'
                         ' px: motion blur or defocus)')
        observation = Observation(valid=spot.valid, reason=spot.reason, spot=spot,
                                  T_world_camera=pose.T_world_camera,
                                  marker_pose_age=max(0.0, stamp - pose.stamp),
                                  marker_search=marker.searched, quality=spot.quality,
                                  quality_reason=spot.quality_reason,
                                  edge_width=pose.edge_width, pose_source='marker')
        if spot.measured:
            frame = 'optics' if T_optics_world is not None else 'world'
            observation.features = position_features(spot, T_optics_world, frame)
        return observation

    def _observe_with(self, gray, camera, stamp, T_world_camera, T_optics_world, searched):
        """Detect the spot through a camera pose given from outside (no marker in view)."""
        spot = self.detector.detect(gray, GroundMapping(camera, T_world_camera),
                                    self.marker_config.side, stamp)
        observation = Observation(valid=spot.valid, reason=spot.reason, spot=spot,
                                  T_world_camera=np.asarray(T_world_camera, dtype=float),
                                  marker_search=searched, quality=spot.quality,
                                  quality_reason=spot.quality_reason,
                                  pose_source='kinematics')
        if spot.measured:
            frame = 'optics' if T_optics_world is not None else 'world'
            observation.features = position_features(spot, T_optics_world, frame)
        return observation
