"""
The lens planner's parameters its procedures use, declared on the node (issue 32).

``declare_settings`` declares them (``node_kit.parameters.declare``: default, range and
description, as in ``config/lens_planner.yaml``) and returns the procedures'
``LensPlannerSettings``; the node declares its own wiring parameters itself.
``code_defaults`` gives the same without a node, at the defaults (for tests and tools).
"""

import math
from types import SimpleNamespace

from helio_control import sun_sweep
from helio_control.lens_moves import HEATING_DISTANCE, RETREAT_OFFSET
from helio_control.procedures.lens_rig_port import LensPlannerSettings
from helio_optics.node_kit.parameters import declare


def declare_heating_distance(node):
    """Declare heating_distance [m] (until a focal calibration says otherwise)."""
    return declare(
        node, 'heating_distance', HEATING_DISTANCE,
        'd_lp at which a dot is heated until the focal calibration (calibration/focus) says '
        'otherwise (paper: 8.2 cm); FocusLens goals ask for it as HEATING [m].', 0.02, 0.3)


def declare_settings(node):
    """Declare the procedures' parameters on `node`; return them as LensPlannerSettings."""
    retreat_offset = declare(
        node, 'retreat_offset', RETREAT_OFFSET,
        "The retreat distance lies this far beyond the heating distance (the paper's delta "
        'd_lp, 3 cm, Sec. IV-B): the lens retreats there after a dot (FocusLens RETREAT) and '
        'travels there between points, so the focus never sweeps the wood; it follows a '
        'focal calibration [m].', 0.005, 0.2)
    safe_margin = declare(
        node, 'safe_margin', 0.015,
        'The focus moves sideways only this far or farther from the heating distance '
        '(where the retreat distance is out of reach, such a distance is taken) [m].',
        0.002, 0.1)
    same_point = declare(node, 'same_point', 0.001,
                         'Moves that shift the focus less than this on the panel go '
                         'straight along the sun ray [m].', 0.0, 0.05)
    marker_side = declare(node, 'marker_side', 0.04,
                          "Side of the ArUco marker's black square [m].", 0.001, 1.0)
    view_margin = declare(node, 'view_margin', 30.0,
                          'Marker and spot must lie this far inside the image '
                          '[px].', 0.0, 500.0)
    observe_frames = declare(node, 'observe_frames', 4,
                             'Spot observations collected per pose [-].', 1, 100)
    view_points = sun_sweep.view_points(
        declare(node, 'panel_extent', [-0.04, 0.16, -0.04, 0.16],
                'The wood panel around the marker: x_min, x_max, y_min, y_max, world '
                'frame [m]; the calibrations aim at points of it.'),
        declare(node, 'view_spacing', 0.02,
                'Spacing of the grid of panel points the calibrations aim near [m].',
                0.002, 0.1),
        declare(node, 'marker_clearance', 0.05,
                "Aim no closer than this to the marker's centre (the spot must miss the "
                'marker) [m].', 0.0, 0.5))
    world_poses = declare(node, 'world_calibration.poses', 8,
                          'Arm poses of the robot-world calibration [-].', 3, 100)
    world_distance = declare(node, 'world_calibration.distance', 0.11,
                             'Lens height over the panel while the marker is '
                             'observed (the focus spread out) [m].', 0.05, 0.4)
    rig_poses = declare(node, 'rig_calibration.poses', 48,
                        'Marker views of the rig calibration [-].', 12, 400)
    rig_spot_poses = declare(node, 'rig_calibration.spot_poses', 16,
                             'Sweep poses whose spots fit the lens centre [-].', 4, 200)
    rig_spot_tilts = declare(
        node, 'rig_calibration.spot_tilts_deg', [0.0, 5.0, 10.0],
        "Tilts of the lens axis off the sun in the rig calibration's sweep (0, 8, 16 "
        'placed dots 0.7 mm worse than these in the simulated 3D-printed build: the lens '
        "model's spot drifts from the detector's with the tilt) [deg].")
    rig_max_residual = (
        declare(node, 'rig_calibration.max_residual_position', 0.001,
                'Refuse a rig calibration whose marker views miss the camera chain by '
                'more than this, rms [m].', 1e-5, 0.05),
        declare(node, 'rig_calibration.max_residual_angle', math.radians(0.5),
                'The same for the camera orientation, rms [rad].', 1e-5, 0.5),
        declare(node, 'rig_calibration.max_spot_residual', 0.0005,
                'Refuse it when the spots miss the lens-centre fit by more than this, rms '
                '[m].', 1e-5, 0.05))
    sweep_count = declare(node, 'sweep.poses', 6, 'Poses of the sun sweep [-].', 2, 100)
    sweep_tilts = declare(node, 'sweep.tilts_deg', [0.0, 5.0, 10.0],
                          'Tilts of the lens axis off the sun in the sweep [deg].')
    sweep_distances = declare(
        node, 'sweep.distances', [0.076, 0.082, 0.088],
        'Lens-panel distances of the sweep, near the focus where the spot model holds '
        '[m].')
    acquire_step = declare(node, 'sweep.acquire_azimuth_step_deg', 30.0,
                           'Azimuth step of the search for the spot [deg].', 1.0, 180.0)
    focus_sweep = (declare(node, 'focal_calibration.d_min', 0.064,
                           'First d_lp of the focal sweep (paper 6.4 cm) [m].', 0.02, 0.3),
                   declare(node, 'focal_calibration.d_max', 0.098,
                           'Last d_lp of the focal sweep (paper 9.8 cm) [m].', 0.02, 0.3),
                   declare(node, 'focal_calibration.step', 0.001,
                           'Step of the focal sweep (paper 0.1 cm) [m].', 1e-4, 0.05))
    return LensPlannerSettings(
        retreat_offset=retreat_offset, safe_margin=safe_margin, same_point=same_point,
        marker_side=marker_side, view_margin=view_margin, observe_frames=observe_frames,
        view_points=tuple(view_points), world_poses=world_poses,
        world_distance=world_distance, rig_poses=rig_poses, rig_spot_poses=rig_spot_poses,
        rig_spot_tilts=tuple(rig_spot_tilts), rig_max_residual=rig_max_residual,
        sweep_count=sweep_count, sweep_tilts=tuple(sweep_tilts),
        sweep_distances=tuple(sweep_distances), acquire_step=acquire_step,
        focus_sweep=focus_sweep)


class _CodeDefaults:
    """A stand-in for a node that takes every parameter at its declared default."""

    def declare_parameter(self, name, value, descriptor=None):
        """Return the parameter at its default."""
        return SimpleNamespace(value=value)


def code_defaults(declare_them):
    """Return what `declare_them(node)` returns with every parameter at its default."""
    return declare_them(_CodeDefaults())
