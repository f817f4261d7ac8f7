"""
The marker under the lens' shadow and in strong sun, on the simulated world's frames (issue 35).

The lens casts a shadow some 4 cm wide around the focus; when the focus is beside the marker
the shadow lies across it. cv2.aruco's adaptive threshold then marks the shadow's edge as
well, the black border joins the shaded wood, and no quad is left: before issue 35 the
marker was found in none of these frames. The world's marker is printed as a laser printer
prints (ink 5 %, paper 85 % reflectance), so in full sun its black is darker than its white
in the shadow only by a factor of about 2 (1.2 under a deep blue sky): that is what the
detector's global shadow levels rely on.

The frames: the focus put 3-5 cm from the marker's centre, outside its paper sheet, with the
lens 6-16 cm above the panel, in the world's sun. Kept are the frames whose shadow, as the
world casts it, covers part of the marker's black outline and not all of it, with the whole
marker in view, at whatever angle (the detector refuses views more than 60 deg off the
marker's normal on purpose; such frames count as misses). The truth is the world's camera
pose; "the marker's pose" is the marker in the camera frame (its position and rotation). A
wrong pose is one more than 1 mm or 1 deg off: a shadow edge taken for a marker edge put the
pose 2-8 mm and 1-4 deg off in this experiment, while four corners seen without any shadow
leave up to about 0.9 deg of rotation in a few frames (docs/measurements/2026-11-28-session-44.md).
"""

from dataclasses import replace
import math

from helio_drivers.sim.cameras import RgbSettings
from helio_drivers.sim.world import SimSettings, SimWorld
from helio_optics.geometry import invert_transform, transform_points
from helio_perception.ground_plane import MarkerConfig, MarkerDetector
from helio_perception.spot_detection import to_gray
import numpy as np
import pytest

SHEET_HALF = 0.026      # the marker's black square (20 mm) plus its 6 mm quiet zone [m]


def outline(side, per_edge=16):
    """Return points (4 per_edge, 3) along the marker's black square outline, world [m]."""
    h = side / 2
    corners = np.array([[-h, h], [h, h], [h, -h], [-h, -h]])
    t = (np.arange(per_edge) + 0.5) / per_edge
    points = [a + t[:, None] * (b - a) for a, b in zip(corners, np.roll(corners, -1, axis=0))]
    return np.column_stack([np.concatenate(points), np.zeros(4 * per_edge)])


def shaded_marker_frames(settings, count, seed):
    """
    Yield (image, T_world_camera, camera) of `count` frames with the shadow across the marker.

    The world's truth decides which frames qualify: its flux field's shadow test at the
    marker's outline, its camera pose and camera model.
    """
    world = SimWorld(settings)
    rng = np.random.default_rng(seed)
    camera = world.rgb.camera
    edge = outline(settings.marker_side)
    T_robot_world = world.T_robot_world
    found = 0
    for _ in range(40 * count):
        if found == count:
            return
        while True:
            target = np.array([*rng.uniform(-0.05, 0.05, 2), 0.0, 1.0])
            if np.max(np.abs(target[:2])) > SHEET_HALF + 0.003:   # the focus off the paper
                break
        ray = T_robot_world[:3, :3] @ world.sun_ray_world()
        lens = world.rig.lens_pose_for_target((T_robot_world @ target)[:3], ray,
                                              rng.uniform(0.06, 0.16))
        if lens.x is None:
            continue
        world.set_joints(lens.x)
        world.step()
        shaded = np.mean(world.flux_field.in_shadow(edge[:, 0], edge[:, 1]))
        T_world_camera = world.camera_poses()[0]
        pixels = camera.project(transform_points(invert_transform(T_world_camera), edge))
        inside = np.all((pixels > 5) & (pixels < np.array([camera.width, camera.height]) - 5))
        if 0.05 <= shaded <= 0.95 and inside:
            found += 1
            yield world.rgb_image(), T_world_camera, camera
    raise AssertionError(f'only {found} of {count} frames with the shadow across the marker')


def marker_pose_error(T_world_camera, truth):
    """Return (position [mm], rotation [deg]) of the marker in the camera frame off its truth."""
    estimate, true = invert_transform(T_world_camera), invert_transform(truth)
    position = 1e3 * float(np.linalg.norm(estimate[:3, 3] - true[:3, 3]))
    cosine = (np.trace(estimate[:3, :3].T @ true[:3, :3]) - 1.0) / 2.0
    return position, math.degrees(math.acos(float(np.clip(cosine, -1.0, 1.0))))


def detect_all(frames, detector):
    """Return (poses found, errors [(mm, deg)], reasons of the misses)."""
    errors, reasons = [], []
    for image, truth, camera in frames:
        result = detector.detect(to_gray(image), camera)
        if result.pose is None:
            reasons.append(result.reason)
        else:
            errors.append(marker_pose_error(result.pose.T_world_camera, truth))
    return len(errors), errors, reasons


# (name, exposure: sunlit white paper's share of full scale, sky light / direct sun)
LIGHTS = [('webcam_exposure', 0.55, 0.12),
          ('strong_sun', 0.95, 0.08)]     # paper near full scale, a deep blue sky's deep shadow


@pytest.mark.parametrize('name, exposure, sky', LIGHTS, ids=[light[0] for light in LIGHTS])
def test_the_marker_is_found_under_the_lens_shadow(name, exposure, sky):
    settings = SimSettings(rgb=replace(RgbSettings(), exposure=exposure, diffuse_fraction=sky))
    frames = list(shaded_marker_frames(settings, 100, seed=35))
    found, errors, reasons = detect_all(frames, MarkerDetector())
    within = sum(mm <= 0.3 and deg <= 0.3 for mm, deg in errors)
    worst = max(errors, key=lambda error: error[0] / 0.3 + error[1] / 0.3)
    print(f'\n{name}: {len(frames)} frames, found {found}, within 0.3 mm and 0.3 deg {within}, '
          f'worst {worst[0]:.3f} mm {worst[1]:.3f} deg; misses: {sorted(set(reasons))}')
    assert within >= 0.9 * len(frames)
    assert all(mm <= 1.0 and deg <= 1.0 for mm, deg in errors), errors    # no wrong pose
    # the frames are the hard ones: the adaptive threshold alone finds few of them
    adaptive_only, _, _ = detect_all(frames, MarkerDetector(MarkerConfig(shadow_levels=())))
    print(f'without the shadow levels: found {adaptive_only}')
    assert adaptive_only <= 0.5 * len(frames)
