"""
Spot and marker on frames as a webcam delivers them (issue 15).

The frames come from `helio_optics.ground_render`'s webcam pipeline (light blurred in linear
units, shot and read noise, the sRGB tone curve): a blurred black edge's grey midpoint is
not where the edge is, a saturated paper sheet is as bright as the spot, and so on. Every
truth (camera pose, spot ellipse) is the scene's, never the detector's.
"""

import cv2
from helio_optics.geometry import invert_transform, transform_points
from helio_optics.ground_render import GroundEllipse
from helio_perception.ground_plane import GroundMapping, MarkerConfig, MarkerDetector
from helio_perception.ground_plane import marker_object_points, refine_corners_from_edges
from helio_perception.spot_detection import (
    QUALITY_BLURRED, QUALITY_CUT_BY_BORDER, QUALITY_FULL, QUALITY_OCCLUDED, to_gray)
from helio_perception.spot_observer import SpotObserver
from helio_perception.synthetic_scene import SyntheticScene
import numpy as np
import pytest


def tilted(scene, height=(0.10, 0.20), tilt_deg=(15.0, 45.0)):
    """Return a pose drawer: `height` [m] above the panel, axis tilted `tilt_deg` [deg]."""
    return lambda rng: scene.tilted_pose(rng, rng.uniform(*height),
                                         np.radians(rng.uniform(*tilt_deg)))


def medium_spot_view(scene, rng):
    """Return (pose, [spot]): a tilted view of a 3-5 mm spot and the marker."""
    return scene.random_view(rng, pose=tilted(scene), spot_options={'semi_major': (0.003, 0.005)})


def pixel_of(scene, T_world_camera, point):
    """Return the pixel (2,) of a ground point (x, y)."""
    return scene.camera.project(transform_points(invert_transform(T_world_camera),
                                                 [[point[0], point[1], 0.0]]))[0]


def spot_radius_pixels(scene, T_world_camera, spot):
    """Return the spot's smaller semi-axis as seen in the image, about its centre [px]."""
    centre = pixel_of(scene, T_world_camera, spot.center)
    b = min(spot.semi_axes)
    around = [pixel_of(scene, T_world_camera, (spot.center[0] + b * np.cos(t),
                                               spot.center[1] + b * np.sin(t)))
              for t in np.linspace(0, 2 * np.pi, 12, endpoint=False)]
    return float(np.min(np.linalg.norm(np.array(around) - centre, axis=1)))


@pytest.mark.parametrize('width, height', [(640, 480), (1280, 720)])
def test_spot_world_position_over_tilted_camera_poses(width, height):
    """Done when: median <= 0.15 mm, p95 <= 0.4 mm (camera 10-20 cm up, tilted 15-45 deg)."""
    scene = SyntheticScene(width, height, horizontal_fov=np.radians(70.0))
    rng = np.random.default_rng(15)
    errors, camera_errors = [], []
    for _ in range(24):
        pose, (spot,) = scene.random_view(rng, pose=tilted(scene),
                                          spot_options={'semi_major': (0.001, 0.006)})
        frame = scene.render(pose, [spot], rng=rng, vignetting=0.2)
        observation = SpotObserver().observe(frame.image, scene.camera, 0.0)
        assert observation.valid, observation.reason
        errors.append(np.linalg.norm(observation.spot.center[:2] - spot.center))
        camera_errors.append(np.linalg.norm(observation.T_world_camera[:3, 3] - pose[:3, 3]))
    errors = np.array(errors) * 1e3
    print(f'{width}x{height}: spot world position error [mm] median {np.median(errors):.3f}, '
          f'p95 {np.percentile(errors, 95):.3f}, max {errors.max():.3f}; camera position '
          f'[mm] median {1e3 * np.median(camera_errors):.3f}')
    assert np.median(errors) <= 0.15
    assert np.percentile(errors, 95) <= 0.4


def test_the_marker_pose_is_unbiased_on_srgb_frames():
    """Finding 1: the edge half level in sRGB grey levels put the camera ~2 mm too far."""
    scene = SyntheticScene(640, 480, horizontal_fov=np.radians(70.0))
    rng = np.random.default_rng(16)
    detector = MarkerDetector()
    distances = []
    for _ in range(10):
        pose, _ = scene.random_view(rng, pose=tilted(scene))
        frame = scene.render(pose, rng=rng, blur_sigma=1.2)
        result = detector.detect(to_gray(frame.image), scene.camera)
        assert result.pose is not None, result.reason
        # signed: how much farther from the marker the camera is put than it is
        distances.append(np.linalg.norm(result.pose.T_world_camera[:3, 3])
                         - np.linalg.norm(pose[:3, 3]))
    distances = np.array(distances) * 1e3
    print('camera distance error [mm]:', np.round(distances, 3))
    assert abs(np.mean(distances)) < 0.15 and np.max(np.abs(distances)) < 0.5


def test_an_unsaturated_spot_is_found_and_measured():
    """Finding 8: a spot peaking at grey ~200 was 'no spot' under the fixed 220 threshold."""
    scene = SyntheticScene(640, 480, horizontal_fov=np.radians(70.0))
    rng = np.random.default_rng(18)
    for _ in range(5):
        pose, (spot,) = scene.random_view(rng, pose=tilted(scene),
                                          spot_options={'value': 0.35})
        frame = scene.render(pose, [spot], rng=rng)
        u, v = np.rint(pixel_of(scene, pose, spot.center)).astype(int)
        peak = int(cv2.GaussianBlur(to_gray(frame.image), (5, 5), 0)[v - 2:v + 3,
                                                                     u - 2:u + 3].max())
        assert 150 < peak < 220, peak   # the scene is what the test means: unsaturated
        observation = SpotObserver().observe(frame.image, scene.camera, 0.0)
        assert observation.valid, observation.reason
        assert np.linalg.norm(observation.spot.center[:2] - spot.center) < 2e-4
        assert observation.spot.area == pytest.approx(spot.area, rel=0.04)
        assert not observation.spot.saturated


def test_a_marker_sheet_with_wide_margins_is_never_the_spot():
    """Finding 2: a paper margin of 14-22 mm under bright exposure was reported as the spot."""
    # exposure 0.95: the paper at sRGB 250, above the fixed threshold but not clipped
    rng = np.random.default_rng(19)
    for margins in [(0.006, 0.022, 0.006, 0.006), (0.014, 0.006, 0.006, 0.018),
                    (0.006, 0.006, 0.02, 0.006), (0.006, 0.016, 0.006, 0.022)]:
        scene = SyntheticScene(640, 480, horizontal_fov=np.radians(70.0),
                               sheet_margins=margins)
        for _ in range(4):   # 16 frames without a spot
            pose, _ = scene.random_view(rng, pose=tilted(scene))
            frame = scene.render(pose, rng=rng, exposure=0.95)
            observation = SpotObserver().observe(frame.image, scene.camera, 0.0)
            assert not observation.valid and observation.reason.startswith('no spot'), \
                (margins, observation.reason)
        for _ in range(3):   # 12 frames with one, clear of the sheet
            pose, (spot,) = scene.random_view(
                rng, pose=tilted(scene), spot_options={'centre': (0.055, 0.075),
                                                       'semi_major': (0.002, 0.004)})
            frame = scene.render(pose, [spot], rng=rng, exposure=0.95)
            observation = SpotObserver().observe(frame.image, scene.camera, 0.0)
            assert observation.valid, (margins, observation.reason)
            assert np.linalg.norm(observation.spot.center[:2] - spot.center) < 3e-4


def test_an_over_exposed_marker_is_refused_with_its_reason():
    """A clipped white paper moves the edges outwards (0.4 px at 1.4x): refused, not biased."""
    scene = SyntheticScene(640, 480, horizontal_fov=np.radians(70.0))
    rng = np.random.default_rng(26)
    pose, (spot,) = scene.random_view(rng, pose=tilted(scene))
    observation = SpotObserver().observe(scene.render(pose, [spot], rng=rng,
                                                      exposure=1.4).image, scene.camera, 0.0)
    assert not observation.valid and 'over-exposed' in observation.reason
    assert SpotObserver().observe(scene.render(pose, [spot], rng=rng).image, scene.camera,
                                  0.0).valid


def test_a_spot_cut_by_the_image_border_is_flagged():
    """Finding 3: a spot 55 % in view was measured as if whole (3 mm off)."""
    scene = SyntheticScene(640, 480, horizontal_fov=np.radians(70.0))
    rng = np.random.default_rng(20)
    flagged = 0
    while flagged < 4:
        pose, (spot,) = medium_spot_view(scene, rng)
        radius = spot_radius_pixels(scene, pose, spot)
        # move the spot along the ground until its image centre is 0.1 radius inside the
        # right border: about 55 % of it in view
        centre = pixel_of(scene, pose, spot.center)
        target = np.array([scene.camera.width - 1 - 0.1 * radius, centre[1]])
        ground = GroundMapping(scene.camera, pose).pixels_to_ground([target])[0]
        cut = GroundEllipse(tuple(ground[:2]), spot.semi_axes, spot.angle, spot.value)
        if not scene.sees(pose, scene.marker_outline()):
            continue
        frame = scene.render(pose, [cut], rng=rng)
        observation = SpotObserver().observe(frame.image, scene.camera, 0.0)
        assert not observation.valid, 'a cut spot was published as good'
        if observation.spot.measured:
            assert observation.quality == QUALITY_CUT_BY_BORDER, observation.reason
            assert 'border' in observation.reason
        else:
            assert observation.reason.startswith('no spot'), observation.reason
        flagged += 1


def occluding_bar(scene, pose, spot, covered, rng):
    """Return a dark bar's polygon [px] whose straight edge hides `covered` of the spot."""
    centre = pixel_of(scene, pose, spot.center)
    radius = spot_radius_pixels(scene, pose, spot)
    angle = rng.uniform(0, 2 * np.pi)
    normal = np.array([np.cos(angle), np.sin(angle)])
    along = np.array([-normal[1], normal[0]])
    # a disk's segment of area fraction f has its chord at d = r cos(theta / 2) from the
    # centre, theta - sin(theta) = 2 pi f
    theta = 2.0
    for _ in range(50):
        theta -= (theta - np.sin(theta) - 2 * np.pi * covered) / (1 - np.cos(theta))
    edge = centre + normal * radius * np.cos(theta / 2)
    return np.array([edge - 2.5 * radius * along, edge + 2.5 * radius * along,
                     edge + 2.5 * radius * along + 3 * radius * normal,
                     edge - 2.5 * radius * along + 3 * radius * normal]), centre, radius


def test_a_partly_occluded_spot_is_flagged():
    """Finding 4: a spot 36 % hidden by an object passed the shape gates (1.65 mm off)."""
    scene = SyntheticScene(640, 480, horizontal_fov=np.radians(70.0))
    rng = np.random.default_rng(21)
    tested = 0
    while tested < 5:
        pose, (spot,) = medium_spot_view(scene, rng)
        bar, _, _ = occluding_bar(scene, pose, spot, 0.36, rng)
        corners = scene.camera.project(transform_points(invert_transform(pose),
                                                        scene.marker_outline()))
        if cv2.pointPolygonTest(bar.astype(np.float32), tuple(corners.mean(axis=0)),
                                True) > -80:
            continue   # keep the object off the marker
        frame = scene.render(pose, [spot], rng=rng, occluder=(bar, 0.02))
        observation = SpotObserver().observe(frame.image, scene.camera, 0.0)
        assert not observation.valid, 'an occluded spot was published as good'
        if observation.spot.measured:
            assert observation.quality == QUALITY_OCCLUDED, observation.reason
        tested += 1


@pytest.mark.parametrize('width, height', [(640, 480), (1280, 720)])
def test_motion_blur_is_flagged_and_a_sharp_frame_is_not(width, height):
    """Finding 5: 11 px of motion blur gave a plausible pose 8.7 mm off, published as good."""
    scene = SyntheticScene(width, height, horizontal_fov=np.radians(70.0))
    rng = np.random.default_rng(22)
    flagged = 0
    for length in (7.0, 11.0):
        pose, (spot,) = scene.random_view(rng, pose=tilted(scene))
        sharp = scene.render(pose, [spot], rng=rng)
        observation = SpotObserver().observe(sharp.image, scene.camera, 0.0)
        assert observation.valid and observation.quality == QUALITY_FULL, observation.reason
        assert observation.edge_width < 3.5
        moving = scene.render(pose, [spot], rng=rng, motion_blur=(length, rng.uniform(0, 3)))
        observation = SpotObserver().observe(moving.image, scene.camera, 0.0)
        assert not observation.valid, 'a motion-blurred frame was published as good'
        if observation.T_world_camera is not None:   # else refused: marker not found
            assert observation.quality == QUALITY_BLURRED, observation.reason
            assert observation.edge_width > 4.5 and 'blur' in observation.reason
            flagged += 1
    assert flagged >= 1   # the marker was found in a blurred frame and the flag was seen


def test_a_blurred_pose_is_not_kept_for_the_next_frames():
    scene = SyntheticScene(640, 480, horizontal_fov=np.radians(70.0))
    rng = np.random.default_rng(23)
    joints = np.zeros(5)
    for _ in range(10):   # a view whose blurred marker is still found
        pose, (spot,) = scene.random_view(rng, pose=tilted(scene))
        moving = scene.render(pose, [spot], rng=rng, motion_blur=(6.0, rng.uniform(0, 3)))
        observer = SpotObserver()
        first = observer.observe(moving.image, scene.camera, 0.0, joints)
        if first.T_world_camera is not None:
            break
    assert first.quality == QUALITY_BLURRED, first.reason
    assert observer.observe(moving.image, scene.camera, 0.1, joints).quality == QUALITY_BLURRED
    # the joints are still, but the blurred pose was never cached: detected again
    sharp = scene.render(pose, [spot], rng=rng).image
    observation = observer.observe(sharp, scene.camera, 0.2, joints)
    assert observation.marker_search != 'cache' and observation.valid, observation.reason
    assert observation.marker_pose_age == 0.0


def test_a_fainter_reflection_near_the_spot_is_told_apart_from_the_first_frame():
    """Finding 6: a second reflection within the jump radius made every frame ambiguous."""
    scene = SyntheticScene(640, 480, horizontal_fov=np.radians(70.0))
    rng = np.random.default_rng(24)
    pose, (spot,) = scene.random_view(rng, pose=tilted(scene),
                                      spot_options={'semi_major': (0.003, 0.0035)})
    direction = rng.uniform(0, 2 * np.pi)
    ghost = GroundEllipse((spot.center[0] + 0.012 * np.cos(direction),
                           spot.center[1] + 0.012 * np.sin(direction)), (0.0011, 0.001),
                          value=3.0)
    assert scene.sees(pose, np.array([[*ghost.center, 0.0]]), margin=20)
    observer = SpotObserver()
    for stamp in (0.0, 0.2, 0.4):
        frame = scene.render(pose, [spot, ghost], rng=rng)
        observation = observer.observe(frame.image, scene.camera, stamp)
        assert observation.valid, observation.reason
        assert np.linalg.norm(observation.spot.center[:2] - spot.center) < 2e-4


def test_two_equal_spots_within_the_jump_radius_follow_the_last_spot():
    scene = SyntheticScene(640, 480, horizontal_fov=np.radians(70.0))
    rng = np.random.default_rng(25)
    pose, (spot,) = scene.random_view(rng, pose=tilted(scene),
                                      spot_options={'semi_major': (0.003, 0.0035)})
    twin = GroundEllipse((spot.center[0] + 0.011, spot.center[1] - 0.004), spot.semi_axes,
                         spot.angle, spot.value)
    assert scene.sees(pose, np.array([[*twin.center, 0.0]]), margin=20)
    both = scene.render(pose, [spot, twin], rng=rng).image
    observer = SpotObserver()
    first = observer.observe(both, scene.camera, 0.0)
    assert not first.valid and first.reason.startswith('ambiguous')   # nothing to go by
    alone = scene.render(pose, [spot], rng=rng).image
    assert observer.observe(alone, scene.camera, 0.2).valid
    moved = GroundEllipse((spot.center[0] + 0.001, spot.center[1]), spot.semi_axes,
                          spot.angle, spot.value)
    observation = observer.observe(scene.render(pose, [moved, twin], rng=rng).image,
                                   scene.camera, 0.4)
    assert observation.valid, observation.reason   # both within 20 mm; one far nearer
    assert np.linalg.norm(observation.spot.center[:2] - moved.center) < 2e-4


def test_a_1280x720_frame_is_searched_at_full_resolution_when_downscaled_fails():
    """Finding 7: 1280x720 frames were only searched downscaled to 640 px."""
    side = 0.012
    scene = SyntheticScene(1280, 720, horizontal_fov=np.radians(70.0), marker_side=side)
    detector = MarkerDetector(MarkerConfig(side=side))
    aruco = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50),
                                    cv2.aruco.DetectorParameters())
    rng = np.random.default_rng(1)
    lost_downscaled = 0
    for _ in range(8):
        pose = scene.tilted_pose(rng, 0.2, np.radians(rng.uniform(15, 40)), target=(0, 0, 0))
        gray = to_gray(scene.render(pose, rng=rng).image)
        half = cv2.resize(gray, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)
        if aruco.detectMarkers(half)[1] is not None or aruco.detectMarkers(gray)[1] is None:
            continue
        lost_downscaled += 1
        result = detector.detect(gray, scene.camera)
        assert result.pose is not None, result.reason
        assert np.linalg.norm(result.pose.T_world_camera[:3, 3] - pose[:3, 3]) < 1e-3
    assert lost_downscaled >= 1   # the case the test is about happened


def test_corners_several_pixels_off_are_refined_from_a_downscaled_detection():
    """Finding 7: corners 6.5 px off (from a downscaled image) made the marker rejected."""
    scene = SyntheticScene(1280, 720, horizontal_fov=np.radians(70.0))
    rng = np.random.default_rng(27)
    pose = scene.tilted_pose(rng, 0.15, np.radians(30.0), target=(0.0, 0.0, 0.0))
    gray = to_gray(scene.render(pose, rng=rng).image)
    truth = scene.camera.project(transform_points(invert_transform(pose),
                                                  marker_object_points(scene.marker_side)))
    off = truth + rng.uniform(-1, 1, (4, 2)) * 4.6   # up to 6.5 px
    assert refine_corners_from_edges(gray, off, scene.camera).contrast == 0.0
    # (one fine pass cannot reach so far: the old code dropped the marker)
    fit = MarkerDetector().refine(gray, off, scene.camera, scale=0.5)
    assert fit.contrast > 0.3 and fit.edge_width < 3.5 and fit.clipped_fraction == 0.0
    assert np.max(np.linalg.norm(fit.corners - truth, axis=1)) < 0.1
