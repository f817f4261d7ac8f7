"""
The one port through which the lens planner's procedures talk to the rig (issue 32).

``LensRigPort`` names everything a procedure may ask of the rig and the graph: move to
joints, observe spot (or marker) observations, the sun ray, the present joints, the camera
model, the sun estimator, keep and save a calibration, publish feedback. The lens planner
node implements it per goal (``lens_planner_node``); a test implements it with a model of
the rig whose truth the test knows. The models it holds (``rig``, ``lens``, ...) are the
planner's beliefs: a calibration changes them through the port.

A procedure ends with a ``GoalFailed`` (its message is the goal's result message) or a
``GoalCanceled``; the port raises either from any of its awaitables.
"""

import abc
from dataclasses import dataclass


class GoalFailed(Exception):
    """A procedure cannot go on; the message is the goal's result message."""


class GoalCanceled(Exception):
    """The goal was canceled while it ran."""


@dataclass(frozen=True)
class LensPlannerSettings:
    """
    The lens planner's parameters the procedures use (``config/lens_planner.yaml``).

    Their defaults, ranges and descriptions are declared once, in
    ``lens_planner_parameters.declare_settings``.
    """

    retreat_offset: float        # the retreat (and travel) d_lp beyond the heating d_lp [m]
    safe_margin: float           # sideways moves this far or farther from the heating d_lp [m]
    same_point: float            # a focus shift below this goes straight along the ray [m]
    marker_side: float           # the ArUco marker's black square [m]
    view_margin: float           # marker and spot this far inside the image [px]
    observe_frames: int          # spot observations per pose [-]
    view_points: tuple           # panel points the calibrations aim near, world (x, y) [m]
    world_poses: int             # poses of the robot-world calibration [-]
    world_distance: float        # lens height over the panel while the marker is seen [m]
    rig_poses: int               # marker views of the rig calibration [-]
    rig_spot_poses: int          # sweep poses of its lens-centre fit [-]
    rig_spot_tilts: tuple        # their lens tilts off the sun [deg]
    rig_max_residual: tuple      # rms bounds: camera chain [m], [rad]; spots [m]
    sweep_count: int             # poses of the sun sweep [-]
    sweep_tilts: tuple           # its lens tilts off the sun [deg]
    sweep_distances: tuple       # its lens-panel distances [m]
    acquire_step: float          # azimuth step of the spot search [deg]
    focus_sweep: tuple           # d_min, d_max, step of the focal sweep [m]


class LensRigPort(abc.ABC):
    """
    What the lens planner's procedures ask of the rig and the graph, one goal at a time.

    Attributes a port holds (read by the procedures; changed only through ``use_*``):
    ``settings`` (``LensPlannerSettings``), ``rig`` (``helio_optics.rig_kinematics.Rig``,
    the believed build and T_robot_world), ``nominal_rig`` (the rig file's parameters: a
    calibration's priors), ``lens`` (``LensParameters``), ``spot_model`` (``SpotModel`` of
    that lens), ``targeting`` (``FocusTargeting`` of rig and lens), ``site`` (for the
    ephemeris), ``heating_distance`` [m] and ``world_calibrated`` (T_robot_world measured:
    the spot detector needs no marker in view).
    """

    # ---- the rig ---------------------------------------------------------------------------

    @abc.abstractmethod
    async def move(self, x):
        """Move arm and wrist to the five joints `x` together; return the joints reached."""

    @abc.abstractmethod
    async def observe(self, count, accept):
        """
        Return up to `count` spot observations (helio_msgs/SpotObservation) imaged from now.

        Only those `accept` (a predicate of an observation) takes count; after a settle time
        and at most a timeout, fewer come back when fewer came.
        """

    @abc.abstractmethod
    def joints_at(self, seconds):
        """Return the reported joints at image time `seconds` (a ``JointLookup``)."""

    @abc.abstractmethod
    def present_joints(self):
        """Return the present joints (5,); raise ``GoalFailed`` when they are unknown."""

    @abc.abstractmethod
    async def camera(self):
        """Return the RGB camera model (``PinholeCamera``); ``GoalFailed`` when none came."""

    @abc.abstractmethod
    def now(self):
        """Return the time on the node clock [s] (the images' and joints' clock)."""

    # ---- the sun ---------------------------------------------------------------------------

    @abc.abstractmethod
    def sun_ray(self):
        """Return the estimated sun ray s0, robot frame (3,); ``GoalFailed`` when none."""

    @abc.abstractmethod
    def has_sun(self):
        """Return whether a trustworthy sun estimate is known."""

    @abc.abstractmethod
    async def estimate_sun(self, method, since, rig_calibration=None):
        """
        Return estimate_sun's response (EstimateSun.Response) on the spots since `since`.

        With `rig_calibration`, wait (at most the server timeout) for a response whose lens
        poses came from that rig calibration; ``GoalFailed`` when none did.
        """

    # ---- keeping what was measured ---------------------------------------------------------

    @abc.abstractmethod
    def use_sun(self, estimate):
        """Use `estimate` (helio_msgs/SunEstimate) as the sun from now on."""

    @abc.abstractmethod
    def use_world(self, world_in_robot, world_yaw):
        """Use and publish a measured T_robot_world (marker position [m] and yaw [rad])."""

    @abc.abstractmethod
    def use_rig(self, flat, identity):
        """Use and publish a rig calibration (``rig_calibration.build_terms``) named identity."""

    @abc.abstractmethod
    def use_rig_parameters(self, parameters):
        """Plan with these rig parameters for now (not published, not saved)."""

    @abc.abstractmethod
    def use_focus(self, heating_distance, min_area, fit_rms_relative, samples):
        """Use and publish a measured heating distance [m] (the lens model scaled to it)."""

    @abc.abstractmethod
    def save(self, name, tree, notes=None):
        """Save a calibration (a YAML tree) under `name`; return the path written."""

    # ---- the goal --------------------------------------------------------------------------

    @abc.abstractmethod
    def feedback(self, message):
        """Publish the goal's feedback message."""

    @abc.abstractmethod
    def log(self, text, warning=False):
        """Log a line of the procedure (a warning when `warning`)."""

    @abc.abstractmethod
    async def in_background(self, function):
        """Return function() computed off the node's thread (a long fit)."""

    # ---- the focus lease (the painter's heartbeat) ----------------------------------------

    @abc.abstractmethod
    async def wait_for_inputs(self):
        """Just after the start, wait a while for the sun estimate and the joint states."""

    @abc.abstractmethod
    def client_alive(self):
        """Return whether the client a focus is held for is heard (before the moves)."""

    @abc.abstractmethod
    def placed(self, at_heating, alive):
        """Say the lens was placed, at the heating distance or not, for a client alive or not."""
