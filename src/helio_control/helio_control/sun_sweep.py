"""
Which lens poses the sun-estimation sweep visits (paper Sec. V-B), and why.

The paper sweeps the lens yaw with the lens level over a fixed point. A level lens yawed
about its own centre casts the same spot at every yaw, so such a sweep adds no geometry: two
suns that cast the same spot from one level pose cast the same spots from all of them, and
about 7% of single level-lens images have such a twin 0.2-2.3 deg away. This sweep changes
the geometry: the lens is focused near points of the panel with its axis tilted off the sun
by several angles in several directions, so every pose sees the sun from another side.

Each pose must show the RGB camera the whole ArUco marker (the spot detector maps the spot
through the marker's pose, Eqs 7-9) and the spot (where the ray through the lens centre
meets the panel), with a margin; poses are checked with the rig's kinematics and the
camera model before the arm moves.

Before any estimate, the spot must first be found: the ephemeris gives the sun's elevation
at the site, but the robot's heading (so the sun's azimuth in the robot frame) is unknown.
``acquisition_poses`` aims the lens as if the sun stood at each of a ring of azimuths; the
pose whose guess is right casts the spot where the camera looks.

Poses are searched over a grid of points of the panel around the marker (``view_points``), lens
distances, tilts off the sun in four directions and both solutions of the wrist (the
second turns the cameras to the other side of the lens): with the camera fixed beside the
lens, only some of them show the marker and the spot for a given sun.

No rclpy. API: ``view_points``, ``in_view`` (``in_view_many``: many camera poses at once),
``candidate_poses``, ``acquisition_poses``, ``sweep_poses``, ``spot_separation`` (how far
apart a set of poses casts the spots of two suns).
"""

import math

from helio_control.lens_moves import focus_point
from helio_optics.geometry import angles_from_direction, direction_from_angles
from helio_optics.geometry import invert_transform, transform_points, unit
from helio_optics.rig_kinematics import UnreachableError
from helio_perception.ground_plane import marker_object_points
import numpy as np
from scipy.optimize import least_squares


def marker_corners(marker_side):
    """Return the four corners (4, 3) of the marker's black square, world frame [m]."""
    return marker_object_points(marker_side)


def in_view(camera, T_world_camera, points, margin=30.0):
    """Return whether the world `points` project into the image with `margin` [px]."""
    points = np.atleast_2d(np.asarray(points, dtype=float))
    seen, _ = in_view_many(camera, np.asarray(T_world_camera, dtype=float)[None], points, margin)
    return bool(seen[0])


def in_view_many(camera, T_world_cameras, points, margin=30.0, tolerance=0.0):
    """
    Return per camera pose whether its world points project into the image, and the pixels.

    `T_world_cameras` (M, 4, 4) are the camera poses, `points` (M, K, 3) or (K, 3) (the
    same for every pose) world points [m]. A pose sees its points when all lie in front of
    the camera and project at least `margin` [px] inside the image (less `tolerance` [px]).
    Returns (seen (M,), pixels (M, K, 2)); the pixels of a point behind the camera mean
    nothing (its pose is not seen).
    """
    T_world_cameras = np.asarray(T_world_cameras, dtype=float).reshape(-1, 4, 4)
    count = len(T_world_cameras)
    rotations, origins = T_world_cameras[:, :3, :3], T_world_cameras[:, :3, 3]
    # R^T (p - t) of every point, as rows: (p - t)^T R
    local = (np.asarray(points, dtype=float) - origins[:, None, :]) @ rotations
    in_front = np.all(local[..., 2] > 0.0, axis=1)
    depth = np.where(local[..., 2] > 0.0, local[..., 2], 1.0)[..., None]
    pixels = camera.project((local / depth).reshape(-1, 3)).reshape(count, -1, 2)
    limit = np.array([camera.width, camera.height]) - margin
    inside = np.all((pixels >= margin - tolerance) & (pixels <= limit + tolerance),
                    axis=(1, 2))
    return in_front & inside, pixels


def sun_ray(elevation, azimuth_robot):
    """Return the unit sun ray s0 (the way light travels) in the robot frame."""
    return -direction_from_angles(0.5 * math.pi - elevation, azimuth_robot)


def sun_angles(ray):
    """Return (elevation, azimuth) [rad] of the sun ray `ray`: the inverse of `sun_ray`."""
    polar, azimuth = angles_from_direction(-np.asarray(ray, dtype=float))
    return 0.5 * math.pi - float(polar), float(azimuth)


def in_lens_shadow(points_world, T_world_lens, sun_world, shadow_radius):
    """
    Return per point whether the sunward ray from it meets the lens disk (its shadow).

    The lens blocks the direct sun over its aperture (`shadow_radius` with a margin for the
    mount): a marker in that shadow is lit by the sky alone and loses its contrast.
    """
    points = np.atleast_2d(np.asarray(points_world, dtype=float))
    centre, axis = T_world_lens[:3, 3], T_world_lens[:3, 2]
    towards_sun = -np.asarray(sun_world, dtype=float)
    along = float(towards_sun @ axis)
    if abs(along) < 1e-9:
        return np.zeros(len(points), bool)
    distance = ((centre - points) @ axis) / along
    crossing = points + distance[:, None] * towards_sun
    return (distance > 0.0) & (np.linalg.norm(crossing - centre, axis=1) <= shadow_radius)


def sees_marker_and_spot(rig, x, sun, camera, T_robot_world, marker_side, margin,
                         shadow_radius=0.022, min_marker_pixels=40.0,
                         max_view_angle=math.radians(65.0), need_marker=True):
    """
    Return whether joints x show the camera the marker and the spot's centre ray.

    The whole marker must lie in the image (`margin` [px]), span at least
    `min_marker_pixels` on each side, be seen no more obliquely than `max_view_angle` from
    the panel's normal, and stand outside the lens shadow; the point where the ray through
    the lens centre meets the panel must lie in the image too. Without `need_marker` (the
    spot detector maps the spot through the kinematic camera pose once the rig is
    calibrated) only the spot is checked.
    """
    T_robot_world = np.asarray(T_robot_world, dtype=float)
    T_world_robot = invert_transform(T_robot_world)
    pose = rig.forward(x)
    T_world_rgb = T_world_robot @ pose.T_robot_rgb
    spot, _ = focus_point(rig, x, sun, T_robot_world)
    corners = marker_corners(marker_side)
    if spot is None or not in_view(camera, T_world_rgb, [spot], margin):
        return False
    if not need_marker:
        return True
    if not in_view(camera, T_world_rgb, corners, margin):
        return False
    to_camera = T_world_rgb[:3, 3] / np.linalg.norm(T_world_rgb[:3, 3])   # marker at origin
    if math.acos(max(-1.0, min(1.0, float(to_camera[2])))) > max_view_angle:
        return False
    pixels = camera.project(transform_points(invert_transform(T_world_rgb), corners))
    sides = np.linalg.norm(pixels - np.roll(pixels, 1, axis=0), axis=1)
    if sides.min() < min_marker_pixels:
        return False
    sun_world = T_world_robot[:3, :3] @ np.asarray(sun, dtype=float)
    edges = np.concatenate([corners, 0.5 * (corners + np.roll(corners, 1, axis=0)),
                            [[0.0, 0.0, 0.0]]])
    return not np.any(in_lens_shadow(edges, T_world_robot @ pose.T_robot_lens, sun_world,
                                     shadow_radius))


def tilted_axis(sun, tilt, turn):
    """
    Return the lens axis tilted by `tilt` off -`sun`, towards the direction `turn` [rad].

    `turn` 0 tilts towards the horizon (lower elevation), pi/2 sideways, pi upwards.
    """
    axis = -np.asarray(sun, dtype=float) / np.linalg.norm(sun)
    sideways = np.cross([0.0, 0.0, 1.0], axis)
    if np.linalg.norm(sideways) < 1e-9:            # a sun at the zenith
        sideways = np.array([0.0, 1.0, 0.0])
    sideways /= np.linalg.norm(sideways)
    down = np.cross(sideways, axis)                  # towards the horizon, perpendicular
    return (math.cos(tilt) * axis
            + math.sin(tilt) * (math.cos(turn) * down + math.sin(turn) * sideways))


def view_points(panel_extent=(-0.04, 0.16, -0.04, 0.16), spacing=0.02,
                marker_clearance=0.05, edge_margin=0.015):
    """
    Return panel points (x, y) to aim near, world frame [m]: a grid over the panel.

    `panel_extent` is (x_min, x_max, y_min, y_max) of the wood around the marker; points
    keep `edge_margin` from its edges (the spot and the view stay on the wood) and
    `marker_clearance` from the marker's centre (the spot must not land on the marker).
    """
    x_min, x_max, y_min, y_max = (float(v) for v in panel_extent)
    if not (x_min < x_max and y_min < y_max and spacing > 0.0):
        raise ValueError(f'panel_extent {panel_extent} and spacing {spacing} describe no grid')
    xs = np.arange(x_min + edge_margin, x_max - edge_margin + 1e-9, spacing)
    ys = np.arange(y_min + edge_margin, y_max - edge_margin + 1e-9, spacing)
    return [(float(x), float(y)) for x in xs for y in ys if math.hypot(x, y) >= marker_clearance]


def candidate_poses(rig, T_robot_world, sun, camera, marker_side, points,
                    distances=(0.082,), tilts=(0.0,), turns=(0.0, 90.0, 180.0, 270.0),
                    offsets=(0.0,), margin=30.0, need_marker=True):
    """
    Yield (joints, (point, distance, tilt, turn, offset)) that show the marker and the spot.

    The lens centre is `distance` up the ray `sun` from each panel `point`; its axis is
    tilted by `tilt` [deg] off the sun towards `turn` [deg] (every turn when tilted), and
    the wrist takes either of its two solutions, yawed by `offset` [deg] about the vertical.
    """
    T_robot_world = np.asarray(T_robot_world, dtype=float)
    sun = np.asarray(sun, dtype=float) / np.linalg.norm(sun)
    for point in points:
        target = transform_points(T_robot_world, [point[0], point[1], 0.0])
        for distance in distances:
            centre = target - distance * sun
            heading = math.atan2(centre[1], centre[0])
            for tilt in tilts:
                for turn in (turns if tilt > 0.0 else (0.0,)):
                    axis = tilted_axis(sun, math.radians(tilt), math.radians(turn))
                    for flip in (0.0, math.pi):
                        yaw, pitch = rig.yaw_pitch_for_axis(axis, heading + flip)
                        for offset in offsets:
                            try:
                                x = rig.inverse(centre, yaw + math.radians(offset), pitch)
                            except UnreachableError:
                                continue
                            if sees_marker_and_spot(rig, x, sun, camera, T_robot_world,
                                                    marker_side, margin,
                                                    need_marker=need_marker):
                                yield x, (tuple(point), distance, tilt, turn, offset)


def acquisition_poses(rig, T_robot_world, elevation, camera, marker_side, points,
                      azimuth_step=math.radians(30.0), distances=(0.082, 0.06, 0.11),
                      tilts=(0.0, 15.0, 30.0), margin=30.0, need_marker=True):
    """
    Return [(azimuth guess [rad], joints)] to look for the spot with an unknown heading.

    For each guessed azimuth (a ring of `azimuth_step`), the first candidate pose (aligned
    with the guess and focused first, then closer, farther and tilted) from which the camera
    would see the marker and the spot were the guess right. A guess with no such pose is
    left out.
    """
    found = []
    for azimuth in np.arange(0.0, 2.0 * math.pi - 1e-9, azimuth_step):
        sun = sun_ray(elevation, azimuth)
        first = next(candidate_poses(rig, T_robot_world, sun, camera, marker_side, points,
                                     distances, tilts, margin=margin,
                                     need_marker=need_marker), None)
        if first is not None:
            found.append((float(azimuth), first[0]))
    return found


def sweep_poses(rig, T_robot_world, sun, camera, marker_side, points, count=6,
                tilts=(0.0, 5.0, 10.0), distances=(0.076, 0.082, 0.088), margin=30.0,
                need_marker=True):
    """
    Return up to `count` joint vectors for the sweep around the sun estimate `sun`.

    Candidates (``candidate_poses``) at `distances` [m], `tilts` [deg] in four directions
    about the sun and both wrist solutions; the chosen ones are spread over tilts,
    directions and points. The defaults keep the spot compact, near the focus and within
    10 deg of the sun: there the lens model's outermost contour matches the bright region
    the spot detector measures within about 0.1-0.2 mm (measured in the simulated world:
    at a 3 cm retreat the model's centre is 1 mm off, at 20 deg of tilt 0.4 mm).
    """
    candidates = list(candidate_poses(rig, T_robot_world, sun, camera, marker_side, points,
                                      tuple(distances), tuple(tilts), margin=margin,
                                      need_marker=need_marker))
    groups = {}
    for x, (_, _, tilt, turn, _) in candidates:
        groups.setdefault((tilt, turn), []).append(x)
    queues = [spread(poses) for _, poses in sorted(groups.items())]
    chosen = []
    while len(chosen) < count and any(queues):
        for queue in queues:
            if queue and len(chosen) < count:
                chosen.append(queue.pop(0))
    return chosen


def chief_ray_sun(lens_centre, spot_centre):
    """
    Return the ray (unit) from the lens centre `lens_centre` to `spot_centre` (3,) [m].

    A thin lens does not deviate the ray through its centre, but the spot's middle is not
    where that ray lands: a low sun casts the rim's cone on the ground as an ellipse whose
    centre lies off the cone's axis (8 deg of ray at a 31 deg sun with the lens 3 cm out of
    focus). A start for `coarse_sun`, not a sun.
    """
    ray = np.asarray(spot_centre, dtype=float) - np.asarray(lens_centre, dtype=float)
    length = float(np.linalg.norm(ray))
    if not (math.isfinite(length) and length > 0.0):
        raise ValueError('no chief ray: the spot centre is not finite or lies at the lens')
    return ray / length


def coarse_sun(spot_model, T_robot_lens, spot_centres, plane_point, plane_normal,
               tolerance=1e-3):
    """
    Return the sun ray (unit, robot frame) that casts one still pose's spot where it was seen.

    The acquisition's coarse sun (Sec. V-B): the lens model (`spot_model`, a
    ``helio_optics.spot.SpotModel``) at the pose `T_robot_lens` is solved for the sun's
    elevation and azimuth that put its spot centre on the median of `spot_centres` (N, 3)
    [m, robot frame] on the plane, from the chief ray (`chief_ray_sun`). Two equations in
    two unknowns: one pose may have a twin sun a degree or two away, and the model's centre
    errs by millimetres where the lens faces far off the sun, so this only chooses the
    sweep's poses; the estimator's fit on the sweep decides. ValueError when no sun puts
    the spot within `tolerance` [m] of where it was seen.
    """
    seen = np.median(np.atleast_2d(np.asarray(spot_centres, dtype=float)), axis=0)
    pose = np.asarray(T_robot_lens, dtype=float)[None]
    chief = chief_ray_sun(pose[0, :3, 3], seen)
    if chief[2] >= 0.0:
        raise ValueError('the spot lies above the lens: no sun casts it')

    def miss(p):
        centre = spot_model.centres(sun_ray(*p), pose, plane_point, plane_normal)[0]
        return 1e3 * (centre - seen) if np.all(np.isfinite(centre)) else np.full(3, 1e3)
    # from the chief ray, else from the lens axis (the lens faces the guessed sun) and
    # between them: where the rim's rays are lost (no spot by the model) no step can start
    fit = None
    for start in (chief, unit(chief - pose[0, :3, 2]), -pose[0, :3, 2]):
        if start[2] >= 0.0:
            continue
        angles = np.array(sun_angles(start))
        if not np.all(np.abs(miss(angles)) < 1e3):
            continue
        fit = least_squares(miss, angles, bounds=([1e-3, -np.inf], [0.5 * math.pi, np.inf]),
                            x_scale=0.1)
        if np.linalg.norm(fit.fun) * 1e-3 <= tolerance:
            break
    if fit is None:
        raise ValueError('no sun casts the spot where it was seen: the lens model casts no '
                         'spot from this pose for the suns tried')
    if not np.linalg.norm(fit.fun) * 1e-3 <= tolerance:
        raise ValueError(f'no sun casts the spot where it was seen: the lens model misses it '
                         f'by {np.linalg.norm(fit.fun):.1f} mm at best')
    return sun_ray(*fit.x)


def spread(poses):
    """Return the poses reordered so that any prefix is spread over the list."""
    order, remaining = [], list(range(len(poses)))
    while remaining:
        picks = np.linspace(0, len(remaining) - 1, min(len(remaining), 3)).round()
        for index in sorted({int(p) for p in picks}, reverse=True):
            order.append(remaining.pop(index))
    return [poses[i] for i in order]


def spot_separation(spot_model, rig, poses, sun_a, sun_b, T_robot_world):
    """
    Return, per pose, the distance [m] between the spot centres two suns would cast.

    A sweep separates the two suns when some pose casts their spots much farther apart
    than the spot detector's noise.
    """
    T_robot_world = np.asarray(T_robot_world, dtype=float)
    T = np.array([rig.forward(x).T_robot_lens for x in poses])
    plane = (T_robot_world[:3, 3], T_robot_world[:3, 2])
    a = spot_model.centres(sun_a, T, *plane)
    b = spot_model.centres(sun_b, T, *plane)
    return np.linalg.norm(a - b, axis=1)
