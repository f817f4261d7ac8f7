"""Tests of the marker pose (cv2.aruco), the pixel <-> ground mapping and the pose cache."""

from helio_optics.geometry import (
    intersect_plane, invert_transform, look_at, matrix_from_quaternion, PinholeCamera,
    transform_points, transform_vectors)
from helio_perception.ground_plane import (
    GroundMapping, MarkerConfig, MarkerDetector, MarkerPoseTracker)
from helio_perception.spot_detection import to_gray
from helio_perception.synthetic_scene import SyntheticScene
import numpy as np
import pytest

DISTORTION = np.array([-0.12, 0.03, 0.001, -0.0015, 0.0])


@pytest.fixture(scope='module')
def scene():
    return SyntheticScene(640, 480)


def rotation_angle(a, b):
    """Return the angle [rad] of the rotation between two rotation matrices."""
    return np.arccos(np.clip((np.trace(a.T @ b) - 1.0) / 2.0, -1.0, 1.0))


@pytest.mark.parametrize('distortion', [np.zeros(5), DISTORTION], ids=['plain', 'distorted'])
def test_pixels_to_ground_and_back(distortion):
    base = PinholeCamera.from_fov(640, 480, np.radians(60))
    camera = PinholeCamera(base.matrix, 640, 480, distortion)
    T_world_camera = look_at((0.08, -0.1, 0.2), (0.03, 0.02, 0.0))
    mapping = GroundMapping(camera, T_world_camera)
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(-0.02, 0.08, (50, 2)), np.zeros(50)])
    pixels = mapping.ground_to_pixels(points)
    np.testing.assert_allclose(mapping.pixels_to_ground(pixels), points, atol=1e-9)
    # second method: geometry's ray-plane intersection (Eq 6) of the camera's pixel rays
    rays = transform_vectors(T_world_camera, camera.pixel_rays(pixels))
    origins = np.broadcast_to(T_world_camera[:3, 3], rays.shape)
    expected, _ = intersect_plane(origins, rays, [0, 0, 0], [0, 0, 1])
    np.testing.assert_allclose(mapping.pixels_to_ground(pixels), expected, atol=1e-9)


def test_homography_is_eq_8():
    camera = PinholeCamera.from_fov(640, 480, np.radians(60))
    T_world_camera = look_at((0.05, 0.02, 0.25), (0.0, 0.0, 0.0))
    mapping = GroundMapping(camera, T_world_camera)
    point = np.array([0.031, -0.012, 0.0])
    projected = mapping.homography() @ np.array([point[0], point[1], 1.0])
    np.testing.assert_allclose(projected[:2] / projected[2], mapping.ground_to_pixels(point)[0])


def test_pixels_above_the_horizon_have_no_ground_point():
    camera = PinholeCamera.from_fov(640, 480, np.radians(90))
    T_world_camera = look_at((0.0, 0.0, 0.2), (1.0, 0.0, 0.15))  # looking almost level
    mapping = GroundMapping(camera, T_world_camera)
    pixels = np.array([[320.0, 0.0], [320.0, 479.0]])  # top and bottom rows
    ground = mapping.pixels_to_ground(pixels)
    rising = transform_vectors(T_world_camera, camera.pixel_rays(pixels))[:, 2] >= 0
    assert rising.tolist() in ([True, False], [False, True])  # one row sees the sky
    assert np.all(np.isnan(ground[rising])) and np.all(ground[~rising][:, 0] > 0.0)


def test_marker_pose_matches_the_rendering_pose(scene):
    detector = MarkerDetector(MarkerConfig(side=scene.marker_side))
    rng = np.random.default_rng(11)
    for _ in range(6):
        T_world_camera, _ = scene.random_view(rng)
        frame = scene.render(T_world_camera, rng=rng)
        result = detector.detect(to_gray(frame.image), scene.camera, stamp=1.5)
        assert result.pose is not None, result.reason
        pose = result.pose.T_world_camera
        assert np.linalg.norm(pose[:3, 3] - T_world_camera[:3, 3]) < 5e-4
        assert rotation_angle(pose[:3, :3], T_world_camera[:3, :3]) < np.radians(0.1)
        assert result.pose.stamp == 1.5 and result.pose.reprojection_error < 0.5


def test_missing_wrong_id_partial_and_implausible_markers_are_reported(scene):
    rng = np.random.default_rng(3)
    T_world_camera, _ = scene.random_view(rng)
    detector = MarkerDetector(MarkerConfig(side=scene.marker_side))
    plain = to_gray(scene.render(T_world_camera, with_marker=False, rng=rng).image)
    assert detector.detect(plain, scene.camera).reason == 'marker 0 not found'
    seen = to_gray(scene.render(T_world_camera, rng=rng).image)
    other = MarkerDetector(MarkerConfig(marker_id=7)).detect(seen, scene.camera)
    assert other.pose is None and other.reason == 'marker 7 not found (saw ids [0])'
    strict = MarkerDetector(MarkerConfig(max_reprojection_error=1e-6))
    implausible = strict.detect(seen, scene.camera)
    assert implausible.pose is None and 'implausible' in implausible.reason
    too_close = MarkerDetector(MarkerConfig(max_distance=0.05)).detect(seen, scene.camera)
    assert too_close.pose is None and 'outside' in too_close.reason


def ground_error_through(pose, T_world_camera, camera, points):
    """Return the largest distance [m] between ground points and their images mapped back."""
    pixels = GroundMapping(camera, T_world_camera).ground_to_pixels(points)
    return float(np.max(np.linalg.norm(
        GroundMapping(camera, pose).pixels_to_ground(pixels) - points, axis=1)))


def test_a_marker_seen_too_slanted_is_refused_and_one_within_the_limit_places_the_ground(scene):
    """
    Refuse a marker far off its normal, whose pose misplaces the ground by millimetres.

    At 80 deg and 27 cm it put the ground up to 6 mm off (the sun estimate's outliers in CI);
    within the limit the ground is placed within 0.3 mm. Truth: the ground points, mapped
    into the image through the rendering pose and back through the detected one.
    """
    detector = MarkerDetector(MarkerConfig(side=scene.marker_side))
    points = np.array([[0.05, 0.05, 0.0], [0.1, 0.1, 0.0], [0.02, -0.03, 0.0]])
    rng = np.random.default_rng(5)
    refused_for_the_angle = 0
    for angle, accepted in ((45.0, True), (55.0, True), (72.0, False), (78.0, False)):
        for azimuth in np.radians([20.0, 140.0, 260.0]):
            slant = np.radians(angle)
            eye = 0.27 * np.array([np.sin(slant) * np.cos(azimuth),
                                   np.sin(slant) * np.sin(azimuth), np.cos(slant)])
            T_world_camera = look_at(eye, (0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0))
            frame = scene.render(T_world_camera, rng=rng)
            result = detector.detect(to_gray(frame.image), scene.camera)
            if accepted:
                assert result.pose is not None, result.reason
                assert abs(np.degrees(result.pose.view_angle) - angle) < 1.0
                error = ground_error_through(result.pose.T_world_camera, T_world_camera,
                                             scene.camera, points)
                assert error < 0.3e-3, f'{angle} deg: ground {error * 1e3:.2f} mm off'
            else:     # refused; a view this slanted may also fail the outline's checks
                assert result.pose is None, f'{angle} deg: a slanted pose was accepted'
                if 'off its normal' in result.reason:
                    assert f'seen {angle:.0f} deg off' in result.reason, result.reason
                    assert '> 60 deg' in result.reason
                    refused_for_the_angle += 1
    assert refused_for_the_angle >= 3


def test_the_corners_do_not_depend_on_where_the_search_began(scene):
    """
    Find the same corners in the whole frame and in any window around the marker.

    The node searches a window around the last corners first; a replay that skips images,
    or a second node, searches elsewhere. Before the fine edge fit was iterated to its
    fixed point with a reach in half pixels, a slanted marker's corners moved by up to
    0.3 px with the window (0.1-0.4 mm of camera position at 79 deg). Truth: the same
    image searched two ways (and the tracker told to search the whole frame does so).
    """
    detector = MarkerDetector(MarkerConfig(side=scene.marker_side, max_view_angle_deg=90.0))
    rng = np.random.default_rng(11)
    worst = 0.0
    for slant, azimuth in ((50.0, 30.0), (65.0, 200.0), (75.0, 120.0)):
        eye = 0.25 * np.array([np.sin(np.radians(slant)) * np.cos(np.radians(azimuth)),
                               np.sin(np.radians(slant)) * np.sin(np.radians(azimuth)),
                               np.cos(np.radians(slant))])
        gray = to_gray(scene.render(look_at(eye, (0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0)),
                                    rng=rng).image)
        whole = detector.detect(gray, scene.camera)
        assert whole.pose is not None, whole.reason
        corners = whole.pose.corners
        low, high = corners.min(axis=0), corners.max(axis=0)
        size = float(np.max(high - low))
        for _ in range(6):
            shift = rng.uniform(-0.3, 0.3, 2) * size
            margin = rng.uniform(0.4, 1.2) * size
            x0, y0 = np.maximum(np.floor(low + shift - margin), 0).astype(int)
            x1 = int(min(high[0] + shift[0] + margin, gray.shape[1]))
            y1 = int(min(high[1] + shift[1] + margin, gray.shape[0]))
            window = detector.detect(gray, scene.camera, roi=(x0, y0, x1, y1))
            assert window.pose is not None, window.reason
            worst = max(worst, float(np.max(np.abs(window.pose.corners - corners))))
    assert worst < 0.01, f'corners {worst:.3f} px apart'
    tracker = MarkerPoseTracker(MarkerDetector(MarkerConfig(side=scene.marker_side,
                                                            roi_search=False)))
    first_pose, _ = scene.random_view(rng)
    first = to_gray(scene.render(first_pose, rng=rng).image)
    assert [tracker.update(first, scene.camera, 0.1 * i, None).searched
            for i in range(3)] == ['full'] * 3


def test_pose_cache_reuses_while_joints_are_still_and_redetects_when_they_move(scene):
    rng = np.random.default_rng(5)
    first_pose, _ = scene.random_view(rng)
    first = to_gray(scene.render(first_pose, rng=rng).image)
    tracker = MarkerPoseTracker(MarkerDetector(MarkerConfig(side=scene.marker_side)))
    joints = np.array([0.1, 0.5, 0.3, 0.0, 0.2])
    assert tracker.update(first, scene.camera, 0.0, joints).searched == 'full'
    # the joints were not known still before that image: detected once more, then reused
    assert tracker.update(first, scene.camera, 0.1, joints).searched == 'roi'
    cached = tracker.update(first, scene.camera, 0.5, joints + 1e-6)
    assert cached.searched == 'cache' and cached.pose.stamp == 0.1
    # the camera moves a little (joints change): the ROI around the last corners finds it
    moved_pose = first_pose.copy()
    moved_pose[:3, 3] += [0.004, -0.003, 0.002]
    moved = to_gray(scene.render(moved_pose, rng=rng).image)
    result = tracker.update(moved, scene.camera, 1.0, joints + 0.01)
    assert result.searched == 'roi' and result.detected_now
    assert np.linalg.norm(result.pose.T_world_camera[:3, 3] - moved_pose[:3, 3]) < 5e-4
    # without joint states the marker is searched (in the ROI) every frame
    assert tracker.update(moved, scene.camera, 1.1, None).searched == 'roi'
    assert tracker.update(moved, scene.camera, 1.2, None).searched == 'roi'
    # the marker gone: the failure is reported, and the stale pose is not used
    plain = to_gray(scene.render(moved_pose, with_marker=False, rng=rng).image)
    lost = tracker.update(plain, scene.camera, 1.3, joints + 0.02)
    assert lost.pose is None and 'not found' in lost.reason
    assert tracker.counts == {'cache': 1, 'roi': 4, 'full': 1, 'failed': 1, 'miss_cache': 0,
                              'out_of_view': 0}


def test_a_marker_out_of_view_is_searched_again_only_when_the_joints_move_or_a_period_passed(
        scene):
    """While painting the marker is out of view: a failed whole-frame search costs ~30 ms."""
    rng = np.random.default_rng(8)
    pose, _ = scene.random_view(rng)
    plain = to_gray(scene.render(pose, with_marker=False, rng=rng).image)
    seen = to_gray(scene.render(pose, rng=rng).image)
    tracker = MarkerPoseTracker(MarkerDetector(MarkerConfig(side=scene.marker_side,
                                                            miss_retry_period=1.0)))
    joints = np.array([0.1, 0.5, 0.3, 0.0, 0.2])
    assert 'not found' in tracker.update(plain, scene.camera, 0.0, joints).reason
    # searched again: the joints were not known still before that image
    assert tracker.update(plain, scene.camera, 0.2, joints).searched == 'full'
    remembered = tracker.update(plain, scene.camera, 0.4, joints)
    assert remembered.searched == 'cache' and 'not found' in remembered.reason
    assert tracker.update(plain, scene.camera, 1.1, joints).searched == 'cache'
    assert tracker.counts['failed'] == 2 and tracker.counts['miss_cache'] == 2
    # a period after the remembered miss the frame is searched again, and finds the marker
    # that has come into view (a shadow over it gone)
    found = tracker.update(seen, scene.camera, 1.2, joints)
    assert found.pose is not None and found.searched == 'full'
    # a move forgets a miss at once
    tracker.update(plain, scene.camera, 1.4, joints + 0.01)
    tracker.update(plain, scene.camera, 1.6, joints + 0.01)         # remembered from here
    moved = tracker.update(seen, scene.camera, 1.8, joints + 0.02)
    assert moved.pose is not None and moved.searched != 'cache'


def test_an_image_older_than_the_joint_states_is_not_cached(scene):
    """The joints jump before the image of the new pose arrives: no stale pose is kept."""
    rng = np.random.default_rng(12)
    old_pose, _ = scene.random_view(rng)
    new_pose = old_pose.copy()
    new_pose[:3, 3] += [0.006, 0.004, -0.003]
    old = to_gray(scene.render(old_pose, rng=rng).image)
    new = to_gray(scene.render(new_pose, rng=rng).image)
    tracker = MarkerPoseTracker(MarkerDetector(MarkerConfig(side=scene.marker_side)))
    before, after = np.zeros(5), np.full(5, 0.05)
    tracker.update(old, scene.camera, 0.0, before)
    tracker.update(old, scene.camera, 0.1, before)
    late = tracker.update(old, scene.camera, 0.2, after)  # old image, new joints
    assert late.searched == 'roi'
    result = tracker.update(new, scene.camera, 0.3, after)
    assert result.searched != 'cache'
    assert np.linalg.norm(result.pose.T_world_camera[:3, 3] - new_pose[:3, 3]) < 5e-4
    assert tracker.update(new, scene.camera, 0.4, after).searched == 'cache'


def test_pose_cache_expires_after_max_pose_age(scene):
    rng = np.random.default_rng(6)
    pose, _ = scene.random_view(rng)
    gray = to_gray(scene.render(pose, rng=rng).image)
    tracker = MarkerPoseTracker(MarkerDetector(MarkerConfig(max_pose_age=1.0)))
    joints = np.zeros(5)
    tracker.update(gray, scene.camera, 0.0, joints)
    tracker.update(gray, scene.camera, 0.0, joints)
    assert tracker.update(gray, scene.camera, 0.9, joints).searched == 'cache'
    assert tracker.update(gray, scene.camera, 1.1, joints).searched == 'roi'


def test_a_marker_leaving_the_image_is_reported_partly_visible(scene):
    camera = scene.camera
    down = matrix_from_quaternion([1.0, 0.0, 0.0, 0.0])  # optical z down, image x = world x
    tracker = MarkerPoseTracker(MarkerDetector(MarkerConfig(side=scene.marker_side)))
    height = 0.18
    side_pixels = camera.matrix[0, 0] * scene.marker_side / height

    def looking_down_with_marker_at(u):
        pose = np.eye(4)
        pose[:3, :3] = down
        pose[:3, 3] = [(camera.matrix[0, 2] - u) * height / camera.matrix[0, 0], 0.0, height]
        return to_gray(scene.render(pose, rng=np.random.default_rng(int(u))).image)

    inside = looking_down_with_marker_at(camera.width - 0.75 * side_pixels)
    assert tracker.update(inside, camera, 0.0, np.zeros(5)).pose is not None
    cut = looking_down_with_marker_at(camera.width - 0.1 * side_pixels)
    result = tracker.update(cut, camera, 0.1, np.full(5, 0.01))
    assert result.pose is None and 'partly visible' in result.reason, result.reason


def test_world_frame_is_the_marker_frame(scene):
    """A camera straight above the marker, image x along world x, sees world +y upwards."""
    T_world_camera = np.eye(4)
    T_world_camera[:3, :3] = matrix_from_quaternion([1.0, 0.0, 0.0, 0.0])  # x, -y, -z
    T_world_camera[:3, 3] = [0.0, 0.0, 0.18]
    image = scene.render(T_world_camera, rng=np.random.default_rng(9)).image
    result = MarkerDetector().detect(to_gray(image), scene.camera)
    assert result.pose is not None, result.reason
    np.testing.assert_allclose(result.pose.T_world_camera, T_world_camera, atol=3e-3)
    corner = transform_points(invert_transform(T_world_camera), [[-0.02, 0.02, 0.0]])
    np.testing.assert_allclose(result.pose.corners[0], scene.camera.project(corner)[0],
                               atol=0.1)
