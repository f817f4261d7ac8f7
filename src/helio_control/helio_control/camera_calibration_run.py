"""
The camera calibration procedure of ``helio calibrate camera`` (issue 29, item 5).

Plan at most 25 views of the printed ChArUco board (``camera_views``), visit each, take
frames only once the camera is still, find the board's corners, fit the camera
(``helio_perception.camera_calibration``) and write the camera_info file into the calibration
directory (``camera_info/rgb.yaml``), where ``usb_cam``'s ``camera_info_url`` and
``spot_detector``'s ``camera_info_file`` read it.

The procedure does not know ROS: it is given ``move(x)`` (bring the rig to joints x, return
when the drivers report it there) and ``grab()`` (return the next frame the camera takes,
RGB or grey uint8). ``helio_control.camera_calibration_graph`` gives it the running graph's
driver actions and camera topic; the tests give it the simulated world itself.

Still frames: a frame counts only when the board's corners stand within
``still_tolerance`` [px] of where the frame before put them (a servo settles after the
driver reports it arrived; a frame taken while the arm still moves smears the corners);
``frames`` such frames are averaged per view (the sensor noise of the corners falls by the
square root). Each frame's corners go through ``evenly_lit`` first: the lens' shadow and
its concentrated light fall on the board, and a corner they cross is left out.
"""

from dataclasses import dataclass, field
import datetime
import os

from helio_control.camera_views import plan_camera_views, view_candidates
from helio_optics.node_kit.deployment import calibration_dir_or_default, RGB_CAMERA_INFO_FILE
from helio_perception.camera_calibration import (BoardNotSeen, BoardView, calibrate,
                                                 detect_board, evenly_lit, write_camera_info)
import numpy as np


@dataclass
class Collected:
    """The views found, one per pose visited that showed the board, and what went wrong."""

    views: list = field(default_factory=list)     # BoardViews (averaged still frames)
    poses: list = field(default_factory=list)     # index of each view's pose in the plan
    missed: list = field(default_factory=list)    # (pose index, reason)
    uneven: int = 0                               # corners left out for uneven light
    frames: int = 0                               # frames grabbed in all


def corner_shift(a, b):
    """Return the largest image distance [px] of the corners two BoardViews share (inf: none)."""
    common, ia, ib = np.intersect1d(a.ids, b.ids, return_indices=True)
    if not len(common):
        return float('inf')
    return float(np.max(np.linalg.norm(a.image_points[ia] - b.image_points[ib], axis=1)))


def average_views(views):
    """Return one BoardView of the corners all `views` share, their image points averaged."""
    ids = views[0].ids
    for view in views[1:]:
        ids = np.intersect1d(ids, view.ids)
    points = np.mean([view.image_points[np.searchsorted(view.ids, ids)] for view in views],
                     axis=0)
    first = views[0]
    return BoardView(ids=ids, image_points=points,
                     object_points=first.object_points[np.searchsorted(first.ids, ids)])


def still_view(grab, spec, frames=2, still_tolerance=0.25, max_frames=8):
    """
    Return (BoardView averaged over `frames` still frames, uneven corners, frames grabbed).

    Frames are grabbed until `frames` consecutive ones agree within `still_tolerance` [px]
    (at most `max_frames`); raises BoardNotSeen with the last reason otherwise.
    """
    run, reason, uneven = [], 'no frame', 0
    for grabbed in range(1, max_frames + 1):
        image = grab()
        try:
            view = detect_board(image, spec)
        except BoardNotSeen as error:
            run, reason = [], str(error)
            continue
        view, left_out = evenly_lit(view, image, spec)
        if run and corner_shift(run[-1], view) > still_tolerance:
            run, reason = [], f'the corners moved between frames (more than {still_tolerance} px)'
        run.append(view)
        uneven += left_out
        if len(run) >= frames:
            return average_views(run[-frames:]), uneven, grabbed
    raise BoardNotSeen(f'{reason} in {max_frames} frames')


def collect(plan, move, grab, spec, frames=2, still_tolerance=0.25, max_frames=8,
            progress=lambda index, total, note: None):
    """
    Visit the CameraViews `plan` with `move`, take a still view of the board at each.

    `progress(index, total, note)` is told of each pose. Returns Collected.
    """
    collected = Collected()
    for index, planned in enumerate(plan):
        progress(index, len(plan), 'moving')
        move(planned.x)
        try:
            view, uneven, grabbed = still_view(grab, spec, frames, still_tolerance, max_frames)
        except BoardNotSeen as error:
            collected.missed.append((index, str(error)))
            collected.frames += max_frames
            progress(index, len(plan), f'no view: {error}')
            continue
        collected.views.append(view)
        collected.poses.append(index)
        collected.uneven += uneven
        collected.frames += grabbed
        progress(index, len(plan), f'{len(view)} corners')
    return collected


def plan_views(rig, camera, spec, centre, yaw, count=25, **limits):
    """Return the planned CameraViews (``camera_views``); ValueError when too few are found."""
    plan = plan_camera_views(view_candidates(rig, camera, spec, centre, yaw, **limits), camera,
                             count)
    if len(plan) < 6:
        raise ValueError(f'only {len(plan)} poses show the board at ({centre[0]:.3f}, '
                         f'{centre[1]:.3f}) m to the camera according to the rig file (6 '
                         'needed): is the board where --board-centre says, within reach?')
    return plan


@dataclass
class CameraCalibrationRun:
    """What ``calibrate_camera`` did: the fit, the views and the file written."""

    calibration: object              # CameraCalibration
    collected: Collected
    planned: int
    path: str = ''                   # the camera_info file ('' when not written)


def calibrate_camera(plan, move, grab, spec, size, guess=None, frames=2, still_tolerance=0.25,
                     max_frames=8, progress=lambda index, total, note: None):
    """
    Collect views along `plan` and fit the camera of images `size` (width, height) [px].

    `guess`: the nominal PinholeCamera the fit starts from (None: OpenCV's own start).
    Returns CameraCalibrationRun; ValueError when the fit has too few views.
    """
    collected = collect(plan, move, grab, spec, frames, still_tolerance, max_frames, progress)
    progress(len(plan), len(plan), f'fitting {len(collected.views)} views')
    try:
        calibration = calibrate(collected.views, size, guess)
    except ValueError as error:
        missed = '; '.join(f'pose {i}: {why}' for i, why in collected.missed[:5])
        raise ValueError(f'camera calibration failed: {error}'
                         + (f' (poses without a view: {missed})' if missed else '')) from None
    return CameraCalibrationRun(calibration, collected, len(plan))


def save_camera_calibration(directory, run, spec, camera_name):
    """Write the run's camera_info file into calibration `directory`; return its path."""
    path = os.path.join(calibration_dir_or_default(directory), RGB_CAMERA_INFO_FILE)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    calibration = run.calibration
    when = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds')
    comments = [
        f'camera_info of the RGB camera: written by helio calibrate camera at {when}',
        f'board: ChArUco {spec.squares[0]} x {spec.squares[1]} squares of '
        f'{spec.square * 1e3:.1f} mm, markers {spec.marker * 1e3:.1f} mm, {spec.dictionary}',
        f'{len(calibration.used)} views of {run.planned} poses, {calibration.corners} corners '
        f'({calibration.corners_refused} refused by the fit, {run.collected.uneven} for '
        f'uneven light); reprojection RMS {calibration.rms:.3f} px',
        'fitted: fx = fy (square pixels), cx, cy, k1, k2; p1 = p2 = k3 = 0 '
        '(helio_perception.camera_calibration says why)',
        'use: usb_cam camera_info_url file://<this file>, or spot_detector camera_info_file']
    return write_camera_info(path, calibration.camera, camera_name, comments)


__all__ = ['average_views', 'calibrate_camera', 'CameraCalibrationRun',
           'collect', 'corner_shift', 'plan_views', 'save_camera_calibration', 'still_view']
