"""
What the painting needs from the rig: the painter's one port, its settings and its endings.

The painting run (``painting_run``: goal, plan, resume, the dots in order) and the dot
(``dot_procedure``: Algorithm 1 lines 6-14 with the fire-safety watchdog, clouds and the
camera's check) are procedures; they talk to the rig, the lens planner, the cameras and the
clock only through a ``PainterRigPort``. The painter node implements it over ROS (its
actions, topics, timers and goal handle); a test implements it over a physical model of the
rig and runs the procedures in-process in milliseconds.

Pure Python: no rclpy, no message import. What the port hands over is duck-typed: a thermal
reading has the ``helio_msgs/ThermalStats`` fields the procedures read (``n_p``, ``t_max``,
``window_valid``, ``window_n_p``, ``window_t_max``, ``camera_cap``, ``frozen``); an action's
result has ``success`` and ``message`` (and ``estimate`` for the calibrations and the
sweep, a ``helio_msgs/SunEstimate``).
"""

import abc
from dataclasses import asdict, dataclass

COOLING_RULES = ('paper', 'window')
# Where along the sun ray a focus goal puts the lens: the lens planner owns both distances
# (issue 32; helio_msgs/FocusLens ``HEATING``, ``RETREAT``), relative to its calibrated focus.
HEAT = 'heating'         # at the heating distance, where a dot is burnt (paper 8.2 cm)
RETREAT = 'retreat'      # at the retreat distance: delta d_lp beyond it (paper 3 cm, Sec. IV-B)


class PaintFailed(Exception):
    """The painting cannot go on; the message is the goal's result message."""


class PaintCanceled(Exception):
    """The goal was canceled."""


@dataclass
class PainterSettings:
    """
    The painter's parameters as the procedures read them (``painter_parameters`` declares).

    Read live: the node sets the dynamic parameters (``max_heating``,
    ``verify_min_diameter_ratio``) when they are set. Units as the parameters': [m], [s],
    [rad]. The heating and retreat distances are not here: the lens planner owns them
    (``PainterRigPort.focus_distances``).
    """

    cooling: str
    window_radius: float
    window_separation: float
    window_travel_offset: float
    max_heating: float
    max_cooling: float
    thermal_stale: float
    thermal_stale_wall: float
    thermal_freeze_max: float
    thermal_back_timeout: float
    cloud_timeout: float
    sun_back_frames: int
    calibrate_world: str
    calibrate_rig: str
    server_timeout: float
    runs_dir: str
    device_silence: float
    goal_accept_timeout: float
    retreat_retry_time: float
    retreat_retry_period: float
    retreat_accept_timeout: float
    wrist_escape_pitch: float
    arm_escape_lift: float
    verify_dots: bool
    verify_reheats: int
    verify_timeout: float
    verify_dark_ratio: float
    verify_min_diameter_ratio: float
    verify_camera_response: str
    calibration_dir: str
    sun_max_sigma: float
    sky_min_sweep_elevation_deg: float
    sky_reach_spacing: float
    interrupt_timeout: float
    heartbeat_period: float
    site: object = None          # helio_optics.ephemeris.Site of the deployment
    rig_file: str = ''           # the rig file the node read (the dot-size calibration's)
    calibrate_dots: str = 'never'   # the dot-size test row before a painting (dot_size_run)
    dot_row: object = None       # dot_size_run.DotRowSettings of that row (None: defaults)


@dataclass
class PaintFeedback:
    """The ``paint`` action's feedback (helio_msgs/PaintPattern), field for field."""

    index: int = 0               # the dot worked on [-]
    total: int = 0               # dots of the plan [-]
    phase: str = ''
    t_max: float = 0.0           # latest T_max [degC]
    n_p: int = 0                 # latest N_p [-]
    elapsed: float = 0.0         # since the goal began [s]
    eta: float = 0.0             # estimated time to finish [s]


@dataclass
class PaintResult:
    """The ``paint`` action's result (helio_msgs/PaintPattern), field for field."""

    success: bool = False
    dots_burnt: int = 0
    dots_skipped: int = 0
    duration: float = 0.0        # [s] node clock
    message: str = ''
    dots_planned: int = 0
    dots_resumed: int = 0
    time_estimated: float = 0.0  # [s]
    cloud_wait: float = 0.0      # [s]
    run_dir: str = ''


def as_message(fields, message_type):
    """Return a `message_type` of the dataclass `fields`, each of its field's Python type."""
    blank = message_type()
    return message_type(**{name: type(getattr(blank, name))(value)
                           for name, value in asdict(fields).items()})


class GoalStops:
    """
    The running paint goal, and what asks it to end: a port's bookkeeping of its endings.

    ``cancel`` (the client's cancel) and ``stop`` (a stop signal, the emergency stop: only
    while a goal runs) ask the painting to end and `wake` its heating loop at once (it may
    wait for thermal statistics); ``requested``, ``signal`` and ``client_canceled`` answer
    the port's ``cancel_requested``, ``stop_signal`` and ``client_canceled``.
    """

    def __init__(self, wake):
        """Call `wake()` when the painting must end."""
        self.wake = wake
        self.busy = False
        self.goal = None             # the running goal's handle (``is_cancel_requested``)
        self.requested = False       # the painting must end
        self.signal = ''             # why the node stops mid-painting ('' while it does not)

    def begin(self, goal):
        """Start the goal `goal` (its handle) afresh."""
        self.busy, self.goal, self.requested, self.signal = True, goal, False, ''

    def cancel(self):
        """Take the client's cancel of the goal."""
        self.requested = True
        self.wake()

    def stop(self, why):
        """End a running painting because of `why` (a stop signal, the emergency stop)."""
        if self.busy:
            self.signal = why
            self.cancel()

    def client_canceled(self):
        """Return whether the goal's client asked for the cancel."""
        return self.goal is not None and self.goal.is_cancel_requested


class PainterRigPort(abc.ABC):
    """
    The rig as the painting procedures see it; the painter node implements it over ROS.

    Times: ``now`` is the node clock (simulated under ``use_sim_time``) [s]; ``wall_now``
    the steady wall clock [s]; ``unix_now`` the Unix time [s] (the journal's wall times).
    Awaitable methods are coroutines: they wait without blocking the node's executor.
    """

    # ---- the clock and the log ------------------------------------------------------------

    @abc.abstractmethod
    def now(self):
        """Return the node clock [s]."""

    @abc.abstractmethod
    def wall_now(self):
        """Return the steady wall clock [s]."""

    @abc.abstractmethod
    def unix_now(self):
        """Return the Unix time [s]."""

    @abc.abstractmethod
    def get_logger(self):
        """Return a logger (``info``, ``warning``, ``error``)."""

    @abc.abstractmethod
    async def pause(self, seconds):
        """Wait `seconds` of wall time."""

    @abc.abstractmethod
    def running(self):
        """Return whether the node still runs (its ROS context is up)."""

    @abc.abstractmethod
    async def wait_until(self, ready, what):
        """Wait until `ready()` holds, at most ``server_timeout`` (wall); else TimeoutError."""

    # ---- the rig and the sun --------------------------------------------------------------

    rig = None    # the rig model (helio_optics.rig_kinematics.Rig), calibrations applied

    @abc.abstractmethod
    def joints(self):
        """Return every joint's latest position, by name [rad]."""

    @abc.abstractmethod
    def sun_ray(self):
        """Return (s0 robot frame (3,), its estimate's stamp [s]) of the sun, or None."""

    @abc.abstractmethod
    def use_sun_estimate(self, estimate):
        """Take `estimate` (a SunEstimate from a calibration or the sweep) as the sun's."""

    # ---- what stops a painting ------------------------------------------------------------

    @abc.abstractmethod
    def cancel_requested(self):
        """Return whether the painting must end (a cancel, a stop signal, the stop)."""

    @abc.abstractmethod
    def client_canceled(self):
        """Return whether the goal's client asked for the cancel."""

    @abc.abstractmethod
    def stop_signal(self):
        """Return why the node stops mid-painting ('' while it does not)."""

    @abc.abstractmethod
    def emergency_engaged(self):
        """Return whether the emergency stop is engaged."""

    @abc.abstractmethod
    def device_faults(self):
        """Return [(device, why)] of the devices that fault or fell silent, faults first."""

    # ---- moves ----------------------------------------------------------------------------

    @abc.abstractmethod
    def focus_distances(self):
        """
        Return the lens planner's (heating distance, retreat distance) [m], or None.

        None until the lens planner said them (``focus/distances``); they follow its focal
        calibration. The plan checks reach at both and times the moves with them.
        """

    @abc.abstractmethod
    async def focus(self, target, at, travel_offset=0.0, urgent=False):
        """
        Focus the lens on world `target` (x, y) [m] `at` HEAT or RETREAT; return the result.

        The lens planner resolves `at` to its own distance. `travel_offset`: it travels
        there this far beyond the heating distance [m] (0: at its retreat distance).
        `urgent`: a retreat, accepted within ``retreat_accept_timeout`` or PaintFailed at
        once. PaintFailed when the goal is refused or not accepted in time.
        """

    @abc.abstractmethod
    async def escape_wrist(self, yaw, pitch):
        """Turn the wrist to (yaw, pitch) [rad] as an escape; return the result."""

    @abc.abstractmethod
    async def lift_arm(self, joints):
        """Move the arm to joints (j1, j2, j3, j4) [rad]; return the result."""

    @abc.abstractmethod
    async def calibrate_rig(self):
        """Run the lens planner's rig calibration (applied); return its result."""

    @abc.abstractmethod
    async def calibrate_world(self):
        """Run the robot-world calibration (applied); return its result."""

    @abc.abstractmethod
    async def sweep_sun(self):
        """Run the sun sweep; return its result."""

    # ---- observations ---------------------------------------------------------------------

    @abc.abstractmethod
    async def next_stats(self, stale_after=None):
        """
        Return the next thermal statistics, or None when they are stale (the watchdog).

        Stale after ``thermal_stale`` of the node clock (`stale_after` [s] if sooner) or
        ``thermal_stale_wall`` of wall time; None at once when something wakes the heating
        (a cancel, a device fault).
        """

    @abc.abstractmethod
    def live_stats_stamp(self):
        """Return the stamp [s] of the last thermal frame that was not frozen, or None."""

    @abc.abstractmethod
    async def wait_for_spots(self, back, timeout):
        """
        Offer each light spot's validity to `back` until it returns True; return True then.

        False after `timeout` [s node clock] or when the painting is canceled.
        """

    @abc.abstractmethod
    def rgb_camera(self):
        """Return the RGB camera's model (PinholeCamera), or None before its camera_info."""

    @abc.abstractmethod
    async def next_rgb_image(self, since, timeout):
        """
        Return the first RGB image stamped at or after `since` [s] as an array, or None.

        None when none came within `timeout` [s wall]; ValueError when it cannot be decoded.
        """

    # ---- outputs --------------------------------------------------------------------------

    @abc.abstractmethod
    def publish_feedback(self, feedback):
        """Publish the goal's PaintFeedback."""

    @abc.abstractmethod
    def set_window(self, target):
        """Tell the thermal monitor the N_p window's centre (world, [m]); None: no window."""
