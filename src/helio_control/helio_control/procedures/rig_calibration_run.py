"""
The rig calibration procedure (issue 28): the build measured, not taken from its drawing.

Marker views from over the marker fit the camera chain (the Dobot's joint zeros, the
servos' neutral and travel, the camera mount: ``rig_calibration.fit_camera_chain``); a sun
sweep with that chain gives still spots that fit the lens centre
(``rig_calibration.fit_lens_centre``, Eq 18 offsets from the sweep's middle); applied, the
rig as built is published, saved and the sun estimated again from the same spots.
"""

from dataclasses import replace
import math

from helio_control import rig_calibration
from helio_control.procedures.lens_rig_port import GoalFailed
from helio_control.procedures.sun_sweep_run import sweep, utc
from helio_control.procedures.world_calibration_run import marker_views
from helio_msgs.action import CalibrateRig
from helio_optics.ephemeris import angle_offsets, sun_position
from helio_optics.geometry import transform_points
from helio_optics.node_kit.conversions import point_to_array
from helio_optics.rig_kinematics import Rig
import numpy as np

# the marker views aim over the marker and over the panel points this close to it [m]
VIEW_RADIUS = 0.08
# the views are taken at the robot-world calibration's height and this much higher [m]:
# two depths of the marker in the camera chain's fit
SECOND_HEIGHT = 0.03
# fewer marker views than this (planned) leave the camera chain's terms unobserved
MIN_VIEW_POSES = 12
# at least this many marker views and still spots are needed for a fit
MIN_VIEWS, MIN_SPOTS = 3, 4


async def calibrate_rig(port, request, result):
    """Run a CalibrateRig goal: fit the camera chain and lens centre; use and save if apply."""
    settings = port.settings
    started = port.now()
    camera = await port.camera()
    feedback = CalibrateRig.Feedback()
    # the rig file is the prior; T_robot_world the best one known (a saved calibration)
    world = (port.rig.parameters.world_in_robot, port.rig.parameters.world_yaw)
    belief = Rig(replace(port.nominal_rig, world_in_robot=world[0], world_yaw=world[1]))
    # over the marker and the panel points near it, the focus spread out (the lens at
    # least the robot-world calibration's height over the panel)
    points = [(0.0, 0.0)] + [p for p in settings.view_points if math.hypot(*p) <= VIEW_RADIUS]
    poses = rig_calibration.marker_view_poses(
        belief, camera, settings.marker_side, points, request.poses or settings.rig_poses,
        distances=(settings.world_distance, settings.world_distance + SECOND_HEIGHT),
        margin=settings.view_margin)
    if len(poses) < MIN_VIEW_POSES:
        raise GoalFailed(f'only {len(poses)} poses show the whole marker to the camera '
                         f'according to the rig file ({MIN_VIEW_POSES} needed): check '
                         'world_in_robot in the rig file and the panel_extent parameter')
    feedback.total = len(poses)
    joints, world_rgb, indices = await marker_views(port, poses, feedback)
    feedback.phase = 'fitting the camera chain'
    port.feedback(feedback)
    try:
        if len(joints) < MIN_VIEWS:
            raise ValueError(f'{len(joints)} marker views: at least {MIN_VIEWS} are needed')
        joints, world_rgb = rig_calibration.mean_views(joints, world_rgb, indices)
        chain = await port.in_background(lambda: rig_calibration.fit_camera_chain(
            port.nominal_rig, joints, world_rgb, world_guess=world))
    except ValueError as error:
        raise GoalFailed(f'rig calibration failed: {error}') from None
    result.views_used = chain.used
    result.residual_position, result.residual_angle = (chain.residual_position,
                                                       chain.residual_angle)
    max_position, max_angle, max_spot = settings.rig_max_residual
    if chain.residual_position > max_position or chain.residual_angle > max_angle:
        raise GoalFailed(
            f'rig calibration refused: the marker views miss the camera chain by '
            f'{chain.residual_position * 1000:.2f} mm and '
            f'{math.degrees(chain.residual_angle):.2f} deg rms (bounds '
            f'{max_position * 1000:.2f} mm, {math.degrees(max_angle):.2f} deg): the '
            'marker moved, or the build is off beyond what the model holds')
    before = port.rig.parameters
    port.use_rig_parameters(chain.parameters)      # the sweep plans with the chain
    try:
        feedback.phase = 'spot sweep'
        sweep_run = await sweep(port, feedback, '', settings.rig_spot_poses,
                                settings.rig_spot_tilts)
        if len(sweep_run.spots) < MIN_SPOTS:
            raise GoalFailed(f'rig calibration failed: {len(sweep_run.spots)} still spots in '
                             f'the sweep, {MIN_SPOTS} needed (clouds? the marker out of view?)')
        feedback.phase = 'fitting the lens centre'
        port.feedback(feedback)
        lens = await fit_lens_centre(port, chain.parameters, sweep_run)
    except BaseException:
        port.use_rig_parameters(before)
        raise
    result.spots_used = lens.used
    result.spot_residual = lens.residual_position
    if lens.residual_position > max_spot:
        port.use_rig_parameters(before)
        raise GoalFailed(f'rig calibration refused: the spots miss the lens-centre fit by '
                         f'{lens.residual_position * 1000:.2f} mm rms (bound '
                         f'{max_spot * 1000:.2f} mm)')
    estimates = chain.estimates + lens.estimates
    result.names = [e.name for e in estimates]
    result.values = [e.value for e in estimates]
    result.rig_file = [e.prior for e in estimates]
    result.sigmas = [e.std for e in estimates]
    unobserved = {**chain.unobserved, **lens.unobserved}
    result.unobserved = [f'{name}: {why}' for name, why in sorted(unobserved.items())]
    flat = rig_calibration.build_terms(lens.parameters)
    if request.apply:
        identity = f'{port.now():.3f}'
        port.use_rig(flat, identity)
        result.saved_to = port.save('rig_build.yaml', {'rig': flat,
                                                       'calibration_id': identity}, {
            'residual_position_m': chain.residual_position,
            'residual_angle_rad': chain.residual_angle,
            'spot_residual_m': lens.residual_position,
            'views_used': chain.used, 'spots_used': lens.used,
            'unobserved': result.unobserved})
        # the sun again, from the same spots with the calibrated rig, once the estimator
        # has it (its response names the rig calibration its lens poses came from)
        response = await port.estimate_sun('', sweep_run.start, rig_calibration=identity)
        if response.success:
            port.use_sun(response.estimate)
        result.estimate = response.estimate
    else:
        port.use_rig_parameters(before)
    result.rig_time = port.now() - started
    result.message = (
        f'rig calibrated from {chain.used} marker views and {lens.used} spots in '
        f'{result.rig_time:.0f} s: camera chain rms {chain.residual_position * 1000:.2f} '
        f'mm, {math.degrees(chain.residual_angle):.2f} deg; spots rms '
        f'{lens.residual_position * 1000:.2f} mm; {len(unobserved)} terms not observed'
        + ('' if request.apply else ' (not applied)'))
    port.log(result.message + '\n  ' + '\n  '.join(chain.table() + lens.table()))


async def fit_lens_centre(port, parameters, sweep_run):
    """Fit the lens centre to a sweep's still spots (Eq 18 offsets from its middle)."""
    times = [spot[0] for spot in sweep_run.spots]
    middle = 0.5 * (min(times) + max(times))
    anchor = sun_position(port.site, utc(middle))
    offsets = [angle_offsets(anchor, sun_position(port.site, utc(t))) for t in times]
    guess = point_to_array(sweep_run.response.estimate.direction)
    if not (np.all(np.isfinite(guess)) and guess[2] < 0.0):
        raise GoalFailed('rig calibration failed: the sweep gave no sun to start from: '
                         f'{sweep_run.response.message}')
    spot_model_of_lens = port.spot_model

    def spot_model(rays, T_robot_lens, T_robot_world):
        count = len(rays)
        centres = spot_model_of_lens.centres(
            rays, T_robot_lens, np.repeat(T_robot_world[None, :3, 3], count, axis=0),
            np.repeat(T_robot_world[None, :3, 2], count, axis=0))
        return transform_points(np.linalg.inv(T_robot_world), centres)[:, :2]

    def fit():
        return rig_calibration.fit_lens_centre(
            parameters, [spot[1] for spot in sweep_run.spots],
            [spot[2] for spot in sweep_run.spots], guess, offsets, spot_model=spot_model)

    try:
        return await port.in_background(fit)
    except ValueError as error:
        raise GoalFailed(f'rig calibration failed: {error}') from None
