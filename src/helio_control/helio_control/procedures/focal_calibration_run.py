"""
The focal calibration procedure (paper Sec. V-A): where the lens makes its smallest spot.

The lens aligned with the estimated sun over a panel point, d_lp swept, the spot area A_c
from the spot detector at each, fit (``helio_optics.focal_calibration``); applied, the
heating distance is published and saved and the lens model's focal length scaled so its own
focus falls where the sweep found it (``scaled_lens``).
"""

import math

from helio_control import sun_sweep
from helio_control.procedures.lens_rig_port import GoalFailed
from helio_control.procedures.sun_sweep_run import valid_spot
from helio_msgs.action import CalibrateFocus
from helio_optics.focal_calibration import calibrate_focus as fit_focal_sweep
from helio_optics.geometry import transform_points
from helio_optics.node_kit.conversions import point_to_array
from helio_optics.spot import spot_area_at
import numpy as np

# the sweep's distances this close to the heating distance [m], where its minimum should
# be, must all show the marker and the spot from the chosen panel point
NEAR_HEATING = 0.004
# the panel point is chosen on about this many distances of the sweep [-] (all of them
# would mean a visibility test per millimetre per point)
PROBES = 12
# and must show the marker and the spot on at least this share of them [-]
MIN_SEEN_SHARE = 0.6
# more distances than this in one sweep are refused as a mistake [-]
MAX_DISTANCES = 1000


def sweep_distances(port, request):
    """Return the d_lp [m] of a CalibrateFocus request (0 fields: the settings')."""
    d_min_default, d_max_default, step_default = port.settings.focus_sweep
    d_min = request.d_min or d_min_default
    d_max = request.d_max or d_max_default
    step = request.step or step_default
    target = point_to_array(request.target)
    if not all(math.isfinite(v) for v in (d_min, d_max, step, *target)):
        raise GoalFailed(f'bad sweep: every number must be finite: d_min {d_min}, d_max '
                         f'{d_max}, step {step} m, target {target.tolist()}')
    if not (0.0 < d_min < d_max and step > 0.0 and (d_max - d_min) / step < MAX_DISTANCES):
        raise GoalFailed(f'bad sweep: d_min {d_min}, d_max {d_max}, step {step} m')
    return np.round(np.arange(d_min, d_max + 0.5 * step, step), 6), target


async def calibrate_focus(port, request, result):
    """Run a CalibrateFocus goal: the spot area over d_lp, its minimum; use it if `apply`."""
    distances, target = sweep_distances(port, request)
    sun = port.sun_ray()
    camera = await port.camera()
    T_robot_world = port.rig.parameters.T_robot_world
    if not np.any(target):
        target = focus_target(port, sun, camera, distances)
    feedback = CalibrateFocus.Feedback(total=len(distances))
    areas = []
    for index, d_lp in enumerate(distances):
        lens = port.rig.lens_pose_for_target(transform_points(T_robot_world, target), sun,
                                             float(d_lp))
        if lens.x is None:
            raise GoalFailed(f'd_lp {d_lp * 100:.1f} cm over {target[:2].tolist()} is '
                             f'unreachable: {lens.reason}')
        await port.move(lens.x)
        seen = await port.observe(port.settings.observe_frames, valid_spot)
        area = float(np.median([m.area for m in seen])) if seen else math.nan
        areas.append(area)
        feedback.index, feedback.d_lp, feedback.area = index, float(d_lp), area
        port.feedback(feedback)
    result.d_lp = [float(d) for d in distances]
    result.areas = [float(a) for a in areas]
    measured = np.isfinite(areas)
    try:
        fit = fit_focal_sweep(distances[measured], np.asarray(areas)[measured])
    except ValueError as error:
        raise GoalFailed(f'focal calibration: {error} ({np.count_nonzero(measured)} of '
                         f'{len(distances)} distances gave a spot)') from None
    result.heating_distance = fit.best_d_lp
    result.sample_best_d_lp = fit.sample_best_d_lp
    result.min_area = fit.min_area
    result.fit_rms_relative = fit.fit.rms_relative
    if request.apply:
        samples = int(np.count_nonzero(measured))
        port.use_focus(fit.best_d_lp, fit.min_area, fit.fit.rms_relative, samples)
        result.saved_to = port.save('focus.yaml', {
            'heating_distance': float(fit.best_d_lp),
            'min_area': float(fit.min_area),
            'fit_rms_relative': float(fit.fit.rms_relative),
            'samples': samples})
    result.message = (f'smallest spot at d_lp {fit.best_d_lp * 100:.2f} cm (fit), '
                      f'{fit.sample_best_d_lp * 100:.1f} cm (samples), '
                      f'{fit.min_area * 1e6:.2f} mm^2; fit rms '
                      f'{fit.fit.rms_relative * 100:.1f} %'
                      + ('' if request.apply else ' (not applied)'))


def focus_target(port, sun, camera, distances):
    """
    Return the panel point from which most of the sweep shows the marker and the spot.

    The distances within ``NEAR_HEATING`` of the heating distance (where the minimum should
    be) must all be seen; at least ``MIN_SEEN_SHARE`` of the whole sweep.
    """
    settings = port.settings
    T_robot_world = port.rig.parameters.T_robot_world
    best, best_count = None, -1
    probe = distances[::max(1, len(distances) // PROBES)]
    near = [d for d in distances if abs(d - port.heating_distance) <= NEAR_HEATING]
    for point in settings.view_points:
        target = np.array([point[0], point[1], 0.0])

        def seen(d_lp):
            x = port.rig.lens_pose_for_target(transform_points(T_robot_world, target), sun,
                                              float(d_lp)).x
            return x is not None and sun_sweep.sees_marker_and_spot(
                port.rig, x, sun, camera, T_robot_world, settings.marker_side,
                settings.view_margin, need_marker=not port.world_calibrated)
        if not all(seen(d) for d in near):
            continue
        count = sum(seen(d) for d in probe)
        if count > best_count:
            best, best_count = target, count
    if best is None or best_count < MIN_SEEN_SHARE * len(probe):
        raise GoalFailed('no panel point shows the marker and the spot over most of the '
                         'sweep for this sun; give the goal a target')
    return best


def model_best_distance(lens, around, half_width=0.01, samples=41):
    """Return the d_lp [m] of the lens model's smallest spot within `half_width` of `around`."""
    distances = np.linspace(around - half_width, around + half_width, samples)
    areas = [spot_area_at(lens, d) for d in distances]
    return float(distances[int(np.argmin(areas))])


def scaled_lens(lens, heating_distance, believed_heating_distance):
    """
    Return the lens model with its focal length scaled so its focus lies at heating_distance.

    The model's smallest spot is looked for near `believed_heating_distance` [m] (the one
    used so far); the focal length scales by the measured over the model's distance.
    """
    model_best = model_best_distance(lens, believed_heating_distance)
    scale = heating_distance / model_best if model_best > 0 else 1.0
    return type(lens)(**{**lens.__dict__, 'focal_length': lens.focal_length * scale})
