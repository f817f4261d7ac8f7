"""
The painter node's parameters, declared on the node and handed to the procedures.

``declare_painter_parameters(node)`` declares every parameter of ``painter`` (with its
descriptor: description, range, choices; ``helio_optics.node_kit.parameters``) and returns
their values as the ``PainterSettings`` the painting run and the dot procedure read. The node
keeps that object up to date: the parameters declared ``dynamic`` when they are set at run
time (``DYNAMIC``). The heating and retreat distances are not the painter's: the lens
planner owns them (issue 32; ``lens_planner_parameters``).
No rclpy import: it takes the node.
"""

import os

from helio_control.procedures.dot_size_run import CALIBRATE_DOTS, DotRowSettings
from helio_control.procedures.painter_port import COOLING_RULES, PainterSettings
from helio_optics.node_kit.deployment import declare_calibration_dir, declare_site
from helio_optics.node_kit.parameters import declare
from helio_perception.ground_plane import RESPONSES

# The parameters set at run time, by name, and the PainterSettings field each one sets.
DYNAMIC = {'max_heating': 'max_heating',
           'verify.min_diameter_ratio': 'verify_min_diameter_ratio',
           'calibrate_dots': 'calibrate_dots'}
# the range of max_heating [s]: below a second a dot is not a dot
MAX_HEATING_RANGE_S = (1.0, 3600.0)


def declare_painter_parameters(node):
    """Declare the painter's parameters on `node`; return their PainterSettings."""
    settings = PainterSettings(
        site=declare_site(node)[0],
        sky_min_sweep_elevation_deg=declare(
            node, 'sky.min_sweep_elevation_deg', 30.0,
            'Without a sun estimate, a goal is refused while the sun stands lower than this '
            'at the site (the simulated sweep estimated a 31 deg sun, not a 26.5 deg one; '
            'helio sky uses the same figure) [deg].', 0.0, 89.0),
        sky_reach_spacing=declare(
            node, 'sky.reach_spacing', 0.01,
            "Spacing of the grid over a picture goal's canvas that must have a point within "
            'reach of the sun estimate, or the goal is refused [m].', 0.001, 0.1),
        cooling=declare(
            node, 'cooling', 'paper',
            "Before the next dot: 'paper' waits until N_p is 0; 'window' "
            'counts N_p only near the dot and goes on at once.',
            choices=COOLING_RULES),
        window_radius=declare(
            node, 'window_radius', 0.004,
            'Radius of the N_p window around the dot (world) [m].',
            0.0005, 0.05),
        window_separation=declare(
            node, 'window_separation', 0.0075,
            'Window rule: dots burnt one after the other lie at least this far apart where the '
            "plan can (the last dot's hot region, about 2 mm around it, and a thermal pixel "
            "outside the next one's window); a next dot closer than this waits for N_p = 0 as "
            "the paper's rule does [m].", 0.0, 0.1),
        window_travel_offset=declare(
            node, 'window_travel_offset', 0.015,
            'Window rule: between dots the focus moves sideways this far beyond the lens '
            "planner's heating distance (FocusLens travel_offset) instead of at its retreat "
            "distance (the paper's, which the window rule does not wait at); 0: at the "
            "retreat distance. 1.5 cm puts 9 % of the heating peak's irradiance on the wood "
            '(simulated lens) [m].', 0.0, 0.2),
        max_heating=declare(
            node, 'max_heating', 90.0,
            'A dot held longer than this is given up (set at run time: '
            'from the next dot on) [s].', *MAX_HEATING_RANGE_S, dynamic=True),
        max_cooling=declare(
            node, 'max_cooling', 60.0,
            "Longest wait for N_p = 0 (paper's rule) [s].", 1.0, 3600.0),
        thermal_stale=declare(
            node, 'thermal_stale', 0.5,
            'Thermal statistics older than this (node clock) while the lens is at the heating '
            'distance: retreat, wait for them, heat the dot again [s].', 0.05, 10.0),
        thermal_stale_wall=declare(
            node, 'thermal_stale_wall', 2.0,
            'The same on the wall clock, so a stopped /clock cannot hold the lens [s].',
            0.1, 60.0),
        thermal_freeze_max=declare(
            node, 'thermal_freeze_max', 1.5,
            'Frozen thermal frames (a flat-field correction: the last frame again) are no '
            'fresh reading; heat on blind for at most this long (node clock), then treat the '
            "stream as stale [s] (a Lepton's freezes last 0.3-1 s).", 0.0, 10.0),
        thermal_back_timeout=declare(
            node, 'thermal_back_timeout', 30.0,
            'After a stale thermal stream, wait at most this long (wall clock) for it to come '
            'back before the painting stops [s].', 0.0, 3600.0),
        cloud_timeout=declare(
            node, 'cloud_timeout', 600.0,
            'Longest wait for the sun after a cloud [s].',
            1.0, 86400.0),
        sun_back_frames=declare(
            node, 'sun_back_frames', 5,
            'Valid spot observations in a row that say the sun is '
            'back [-].', 1, 100),
        calibrate_world=declare(
            node, 'calibrate_world', 'once',
            "Robot-world calibration before a painting: 'once' per "
            "node, 'always', or 'never'.",
            choices=('once', 'always', 'never')),
        calibrate_rig=declare(
            node, 'calibrate_rig', 'never',
            "Rig calibration before a painting: 'missing' (when no "
            'calibration of the rig as built has come on '
            "calibration/rig), 'always', or 'never' (the rig file "
            'and the robot-world calibration only).',
            choices=('missing', 'always', 'never')),
        server_timeout=declare(
            node, 'server_timeout', 60.0,
            'Wait at most this long for the lens planner (wall) [s].',
            0.1, 3600.0),
        runs_dir=declare(
            node, 'runs_dir', 'runs', 'Where runs are written (a relative path is taken from '
            'the working directory).'),
        device_silence=declare(
            node, 'device_silence', 1.0,
            'A driver whose joint states stopped this long (wall clock, not counting time in '
            'which the painter itself did not run) is a device fault while heating [s].',
            0.1, 60.0),
        goal_accept_timeout=declare(
            node, 'goal_accept_timeout', 5.0,
            'A focus or wrist goal not accepted within this (wall clock) fails the painting, '
            'which then retreats: a killed server stays discovered for seconds and never '
            'answers [s].', 0.1, 600.0),
        retreat_retry_time=declare(
            node, 'retreat_retry_time', 10.0,
            'A retreat that failed every way (both devices at fault) is tried again for this '
            'long (wall clock), until one way works [s].', 0.0, 600.0),
        retreat_retry_period=declare(
            node, 'retreat_retry_period', 0.2,
            'Between those tries (wall clock) [s].', 0.01, 10.0),
        retreat_accept_timeout=declare(
            node, 'retreat_accept_timeout', 0.25,
            'A retreat goal not accepted within this (wall clock) goes to the next way of '
            'taking the focus off the wood: the lens planner, then the wrist; it counts '
            'against the 0.5 s in which the focus must be off [s].', 0.05, 10.0),
        wrist_escape_pitch=declare(
            node, 'wrist_escape_pitch', 0.6,
            'If the arm cannot retreat, turn the lens pitch by this to '
            'put the focus off the wood [rad].', 0.05, 1.5),
        arm_escape_lift=declare(
            node, 'arm_escape_lift', 0.06,
            'If the wrist cannot move, lift the lens straight up by this '
            'with the arm alone (halved while a joint limit is in the '
            'way): 3 cm leaves a quarter of the peak irradiance, 6 cm '
            'about a tenth [m].', 0.005, 0.2),
        verify_dots=declare(
            node, 'verify_dots', True,
            'After each dot, with the lens retreated, the RGB camera checks that a dot of the '
            'expected size charred at the target (helio_perception.char_dots); the window '
            "rule's dots are verified only where it retreats."),
        verify_reheats=declare(
            node, 'verify_reheats', 1,
            'A dot the camera finds not charred is heated again at most this often, then '
            'counted as failed [-].', 0, 5),
        verify_timeout=declare(
            node, 'verify_timeout', 5.0,
            'Wait at most this long (wall clock) for an RGB frame after a dot, the camera '
            'subscribed to from then on; without one the dot is recorded as not verified '
            '[s].', 0.1, 60.0),
        verify_dark_ratio=declare(
            node, 'verify.dark_ratio', 0.6,
            "Char: darker than this share of the bare wood's light around the target [-].",
            0.05, 0.95),
        verify_min_diameter_ratio=declare(
            node, 'verify.min_diameter_ratio', 0.5,
            'A dot is charred when its char is at least this share of the expected '
            "diameter (the plan's dot pitch at the paper's N_p 30, scaled by the square "
            "root of the dot's N_p target over 30; set at run time: from the next look "
            'on) [-].',
            0.05, 2.0, dynamic=True),
        verify_camera_response=declare(
            node, 'verify.camera_response', 'srgb',
            "The RGB camera's tone curve, undone before char is measured.",
            choices=RESPONSES),
        calibration_dir=declare_calibration_dir(
            node, 'its dots.yaml (helio calibrate dots) is read at start and at each goal'),
        sun_max_sigma=declare(
            node, 'sun_max_sigma', 0.2,
            'A sun estimate on sun/estimate is used when the larger standard deviation of '
            'its angles is at most this (the sweep gives 0.04-0.09 deg, its acquisition '
            'about 0.3 deg); otherwise the painting sweeps first [deg].', 0.0, 90.0),
        interrupt_timeout=declare(
            node, 'interrupt_timeout', 5.0,
            'On Ctrl-C or SIGTERM, how long the running painting may take to put the focus '
            'off the wood before the node stops [s wall].', 0.0, 60.0),
        heartbeat_period=declare(
            node, 'heartbeat_period', 0.05,
            "Period of painter/heartbeat, the lens planner's focus lease, on the node clock "
            'and on the wall clock [s].', 0.01, 1.0))
    settings.calibrate_dots = declare(
        node, 'calibrate_dots', 'never',
        "The dot-size test row before a painting (issue 29): 'missing' (no dots.yaml for "
        "this rig in calibration_dir yet), 'always', or 'never' (helio calibrate dots "
        "only). With a calibration a goal's dot_radius is the burnt dot's width. Set at run "
        'time: from the next goal on.', choices=CALIBRATE_DOTS, dynamic=True)
    defaults = DotRowSettings()
    settings.dot_row = DotRowSettings(
        n_p_targets=tuple(declare(
            node, 'dot_calibration.n_p_targets', list(defaults.n_p_targets),
            'N_p targets of the test row, one group of dots each [-].')),
        per_target=declare(node, 'dot_calibration.per_target', defaults.per_target,
                           'Test dots per N_p target [-].', 1, 10),
        start=tuple(declare(
            node, 'dot_calibration.start', list(defaults.start),
            "The test row's first dot, world x and y, on the panel's margin outside the "
            'canvases painted [m].')),
        pitch=declare(node, 'dot_calibration.pitch', defaults.pitch,
                      'Spacing of the test dots along world +x [m].', 0.002, 0.05),
        holds=tuple(declare(
            node, 'dot_calibration.holds', [float(h) for h in defaults.holds],
            'Holds of the test row: per_target dots for each, held this long at the largest '
            'N_p target once reached, for dots wider than N_p can ask for (values <= 0: '
            'none) [s].')))
    settings.runs_dir = os.path.abspath(os.path.expanduser(settings.runs_dir))
    return settings
