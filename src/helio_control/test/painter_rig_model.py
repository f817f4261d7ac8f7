"""
A rig for the painting procedures' tests: a PainterRigPort whose outer edge is physics.

The wood under the lens heats as a first-order system: the temperature rise dT of a dot's
hottest point follows ``dT' = (G P g(d_lp) - dT) / tau`` (P the sun's power share, 0 under
a cloud; g the lens' concentration, 1 at the heating distance and falling with the defocus
as the spot's area grows, Sec. III-B; G the rise a dot settles at in full sun). Its hot
region is a Gaussian ``dT exp(-r^2 / w^2)``, so the thermal camera's N_p (pixels above the
threshold theta, Sec. IV-B) is ``pi w^2 ln(dT / theta) / a_pixel`` and grows with the dwell.
Every dot keeps its own dT and cools on its own when the focus leaves it.

Time is simulated and jumps (nothing sleeps): the node clock and the wall clock are the same
model clock, started at a Unix instant. Thermal frames come every ``FRAME`` seconds, except
in the intervals the test takes the stream down (none then) or freezes it (the last live
frame again, ``frozen``); a focus move takes ``MOVE`` seconds in which the focus is on no
dot. The lens planner is modelled as far as the painter sees it: it owns the heating and
retreat distances (``heating_distance``, ``retreat_offset``: its shipped defaults, which a
test may change as a focal calibration would) and resolves a focus goal's HEAT or RETREAT to
them. A cancel, a device fault or the sun's return happen at times the test sets. The model
records what the tests judge by: the intervals in which the focus rested on the wood at the
heating distance (``heatings``), every thermal frame delivered, the escapes.

The procedures' coroutines await nothing but this port, whose waits return at once: ``run``
(the lens planner's fake rig's) drives one to its end with a single ``send``.
"""

from dataclasses import dataclass
import math
from types import SimpleNamespace

from fake_lens_rig import run  # noqa: F401 (the procedures' tests drive them with it)
from helio_control.lens_planner_parameters import HEATING_DISTANCE, RETREAT_OFFSET
from helio_control.procedures.painter_port import HEAT, PainterRigPort, PainterSettings
from helio_control.procedures.painter_port import RETREAT
from helio_optics.ephemeris import Site
from helio_optics.geometry import unit
from helio_optics.rig_kinematics import Rig
from helio_perception.char_dots import DotMeasure
import numpy as np
import yaml

FRAME = 1.0 / 8.7          # the Lepton's frame period [s]
MOVE = 0.8                 # a focus move [s]
SPOT_PERIOD = 0.1          # the RGB camera's spot observations [s]
START = 1.7639e9           # the model's clock at its start: a Unix instant [s]
SUN = unit(np.array([-0.3, 0.2, -1.0]))   # s0 (robot frame) that reaches the test canvas
AMBIENT = 20.0             # [degC]
CAP = 1000.0               # the thermal camera's read-out cap, out of the way [degC]


def settings(tmp_path, **overrides):
    """Return the shipped config/painter.yaml's PainterSettings, runs in `tmp_path`."""
    import helio_control
    path = f'{helio_control.__path__[0]}/../config/painter.yaml'
    with open(path) as stream:
        tree = next(iter(yaml.safe_load(stream).values()))['ros__parameters']
    flat = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            flat.update({f'{key}_{k}': v for k, v in value.items()})
        else:
            flat[key] = value
    names = set(PainterSettings.__dataclass_fields__)
    values = {k: v for k, v in flat.items() if k in names}
    values.update(runs_dir=str(tmp_path / 'runs'), calibration_dir=str(tmp_path / 'calibration'),
                  site=Site(48.137, 11.575, 520.0),
                  verify_dots=False)
    values.update(overrides)
    return PainterSettings(**values)


@dataclass
class Wood:
    """The thermal physics of the wood under the focus (module docstring)."""

    tau: float = 10.0          # time constant of a dot's rise [s]
    rise: float = 300.0        # rise G a dot settles at in full sun at the focus [K]
    threshold: float = 20.0    # theta: a pixel above AMBIENT + this counts in N_p [K]
    width: float = 0.6e-3      # w of the hot region [m]
    pixel: float = 0.25e-3     # side of a thermal pixel on the wood [m]
    depth_of_focus: float = 0.004   # defocus that halves the concentration g [m]
    char_rise: float = 20.0    # the wood chars where its rise has reached this [K]

    def concentration(self, defocus):
        """Return g, the focus' share of its peak irradiance, at a defocus [m] [-]."""
        return 1.0 / (1.0 + (defocus / self.depth_of_focus) ** 2)

    def n_p(self, rise):
        """Return N_p of a dot at rise dT [K] [-]."""
        if rise <= self.threshold:
            return 0
        return int(math.pi * self.width ** 2 * math.log(rise / self.threshold)
                   / self.pixel ** 2)

    def char_diameter(self, peak):
        """Return the diameter [m] of the char a dot whose rise peaked at `peak` [K] left."""
        if peak <= self.char_rise:
            return 0.0
        return 2.0 * self.width * math.sqrt(math.log(peak / self.char_rise))

    def rise_reaching(self, n_p):
        """Return the smallest rise dT [K] whose N_p is `n_p` [-]."""
        return self.threshold * math.exp(n_p * self.pixel ** 2 / (math.pi * self.width ** 2))


class RigModel(PainterRigPort):
    """The PainterRigPort of a modelled rig; see the module docstring."""

    def __init__(self, settings):
        """Start at START with the focus on nothing, the sun out and a converged estimate."""
        self.settings = settings
        self.heating_distance = HEATING_DISTANCE    # the lens planner's [m]
        self.retreat_offset = RETREAT_OFFSET        # the lens planner's [m]
        self.wood = Wood()
        self.rig = Rig()
        self.t = 0.0                   # model time since START [s]
        self.lens = None               # (target (x, y), d_lp) where the focus rests
        self.rise = {}                 # target -> dT of its hottest point [K]
        self.peak = {}                 # target -> the highest dT it reached [K]
        self.camera = False            # an RGB camera that measures the char (measure)
        self.clouds = []               # (begin, end) [s] of no sun
        self.stream_down = []          # (begin, end) [s] without thermal frames
        self.frozen = []               # (begin, end) [s] of frozen frames
        self.window_blind = []         # (begin, end) [s] without a thermal camera pose
        self.cancel_at = math.inf      # the client cancels the goal
        self.stop_at = math.inf        # a stop signal (Ctrl-C, SIGTERM) to the node
        self.emergency_at = math.inf   # the emergency stop engages
        self.cancel_in_heating = None  # (n, delay): a cancel `delay` [s] into heating n (1...)
        self.fault_at = math.inf       # a servo alarm from then on
        self.arm_fault = (math.inf, math.inf)   # (begin, end) [s] of a Dobot link reset
        self.sun = (SUN, START)
        self.heatings = []             # [target, since, until] of the focus on the wood
        self.frames = []               # (time, the wood's N_p of each dot) of every frame
        self.moves = []                # (time, target, d_lp, travel d_lp or 0, urgent) of each
        #                                focus, at the distances the lens planner resolved
        self.escapes = []              # (time, 'wrist' or 'arm')
        self.feedback = []
        self.windows = []
        self._live = None              # the last live frame's reading and time
        self._woken = set()            # the wake-ups already delivered
        self.log = SimpleNamespace(info=lambda text, **_: None, warning=lambda text, **_: None,
                                   error=lambda text, **_: None)

    # ---- the physics ----------------------------------------------------------------------

    def sun_out(self, t):
        """Return whether the sun shines at `t` [s]."""
        return not any(begin <= t < end for begin, end in self.clouds)

    def advance(self, seconds):
        """Let `seconds` pass: every dot's rise follows its first-order law (exactly)."""
        end = self.t + seconds
        while self.t < end:
            # the sun's power is constant up to the next cloud edge, the focus all along
            edges = [edge for cloud in self.clouds for edge in cloud if self.t < edge < end]
            dt = min(edges, default=end) - self.t
            power = 1.0 if self.sun_out(self.t) else 0.0
            for target in self.rise:
                gain = 0.0
                if self.lens is not None and self.lens[0] == target:
                    gain = self.wood.concentration(self.lens[1] - self.heating_distance)
                settled = self.wood.rise * power * gain
                self.rise[target] = settled + (self.rise[target] - settled) * math.exp(
                    -dt / self.wood.tau)
                self.peak[target] = max(self.peak.get(target, 0.0), self.rise[target])
            self.t += dt

    def true_n_p(self, target):
        """Return the N_p the wood at `target` shows now [-]."""
        return self.wood.n_p(self.rise.get(tuple(target), 0.0))

    def _place(self, target, d_lp):
        """Put the focus at `target`, `d_lp`, noting the heatings; None: off every dot."""
        if self.heatings and self.heatings[-1][2] is None:
            self.heatings[-1][2] = self.t
        self.lens = None if target is None else (tuple(float(v) for v in target), d_lp)
        if self.lens is not None:
            self.rise.setdefault(self.lens[0], 0.0)
            if abs(d_lp - self.heating_distance) < 1e-6:
                self.heatings.append([self.lens[0], self.t, None])
                if self.cancel_in_heating and self.cancel_in_heating[0] == len(self.heatings):
                    self.cancel_at = self.t + self.cancel_in_heating[1]

    def heated(self, target):
        """Return the heating intervals (since, until) of `target`."""
        return [(since, until) for where, since, until in self.heatings
                if where == tuple(target)]

    def _reading(self):
        """Return the thermal statistics of the wood now (the window's: the last set)."""
        window = self.windows[-1] if self.windows else None
        if any(begin <= self.t < end for begin, end in self.window_blind):
            window = None              # no camera pose for this image: no window reading
        near = {} if window is None else {
            target: rise for target, rise in self.rise.items()
            if math.dist(target, window) <= self.settings.window_radius}
        return SimpleNamespace(
            n_p=sum(self.wood.n_p(rise) for rise in self.rise.values()),
            t_max=AMBIENT + max(self.rise.values(), default=0.0), window_valid=bool(near),
            window_n_p=sum(self.wood.n_p(rise) for rise in near.values()),
            window_t_max=AMBIENT + max(near.values(), default=0.0), camera_cap=CAP,
            frozen=False)

    # ---- the port -------------------------------------------------------------------------

    def now(self):
        return START + self.t

    def wall_now(self):
        return self.t

    def unix_now(self):
        return START + self.t

    def get_logger(self):
        return self.log

    async def pause(self, seconds):
        self.advance(seconds)

    def running(self):
        return True

    async def wait_until(self, ready, what):
        if not ready():
            raise TimeoutError(f'{what} is not available')

    def joints(self):
        return {'dobot_j1': 0.0, 'dobot_j2': 0.6, 'dobot_j3': 0.3, 'dobot_j4': 0.0,
                'lens_yaw': 0.0, 'lens_pitch': 0.2}

    def sun_ray(self):
        return self.sun

    def use_sun_estimate(self, estimate):
        self.sun = (SUN, START)

    def cancel_requested(self):
        return self.t >= min(self.cancel_at, self.stop_at, self.emergency_at)

    def client_canceled(self):
        return self.t >= self.cancel_at

    def stop_signal(self):
        if self.emergency_engaged():
            return 'the EMERGENCY STOP'
        return 'a stop signal' if self.t >= self.stop_at else ''

    def emergency_engaged(self):
        return self.t >= self.emergency_at

    def device_faults(self):
        faults = []
        if self.arm_fault[0] <= self.t < self.arm_fault[1]:
            faults.append(('dobot', 'dobot not connected (link reset)'))
        if self.t >= self.fault_at:
            faults.append(('servo', 'servo alarm: overload'))
        return faults

    def focus_distances(self):
        return self.heating_distance, self.heating_distance + self.retreat_offset

    async def focus(self, target, at, travel_offset=0.0, urgent=False):
        heating, retreat = self.focus_distances()        # the lens planner resolves them
        d_lp = {HEAT: heating, RETREAT: retreat}[at]
        travel_d_lp = heating + travel_offset if travel_offset else 0.0
        self.moves.append((self.t, tuple(target), d_lp, travel_d_lp, urgent))
        self._place(None, 0.0)
        self.advance(MOVE)
        self._place(target, d_lp)
        return SimpleNamespace(success=True, message='')

    async def escape_wrist(self, yaw, pitch):
        self.escapes.append((self.t, 'wrist'))
        self._place(None, 0.0)
        return SimpleNamespace(success=True, message='')

    async def lift_arm(self, joints):
        self.escapes.append((self.t, 'arm'))
        self._place(None, 0.0)
        return SimpleNamespace(success=True, message='')

    async def calibrate_rig(self):
        return SimpleNamespace(success=True, message='', estimate=None)

    async def calibrate_world(self):
        return SimpleNamespace(success=True, message='')

    async def sweep_sun(self):
        return SimpleNamespace(success=True, message='', estimate=None)

    def _wake_up(self, until):
        """Return the time of a stop or fault not yet told, in (now, until], or None."""
        for name, at in (('cancel', self.cancel_at), ('stop', self.stop_at),
                         ('emergency', self.emergency_at), ('fault', self.fault_at)):
            if name not in self._woken and at <= until:
                self._woken.add(name)
                return max(at, self.t)
        return None

    async def next_stats(self, stale_after=None):
        settings = self.settings
        limit = min(settings.thermal_stale, settings.thermal_stale_wall,
                    math.inf if stale_after is None else stale_after)
        frame = (math.floor(self.t / FRAME + 1e-9) + 1) * FRAME
        for begin, end in sorted(self.stream_down):
            if begin <= frame < end:           # the first frame after the stream is back
                frame = math.ceil(end / FRAME) * FRAME if math.isfinite(end) else math.inf
        deadline = self.t + limit
        woken = self._wake_up(min(frame, deadline))
        if woken is not None:
            self.advance(woken - self.t)
            return None
        if frame > deadline:
            self.advance(deadline - self.t)
            return None
        self.advance(frame - self.t)
        self.frames.append((self.t, {t: self.wood.n_p(r) for t, r in self.rise.items()}))
        if self._live is not None and any(begin <= self.t < end for begin, end in self.frozen):
            reading = SimpleNamespace(**vars(self._live[0]))
            reading.frozen = True
            return reading
        reading = self._reading()
        self._live = (reading, self.now())
        return reading

    def live_stats_stamp(self):
        return None if self._live is None else self._live[1]

    async def wait_for_spots(self, back, timeout):
        began = self.t
        while self.t - began < timeout:
            self.advance(SPOT_PERIOD)
            if self.cancel_requested():
                return False
            if back(self.sun_out(self.t)):
                return True
        return False

    def rgb_camera(self):
        return 'camera' if self.camera else None

    async def next_rgb_image(self, since, timeout):
        self.advance(0.1)
        return np.zeros((4, 4, 3), np.uint8)

    def measure(self, image, camera, T_world_camera, target, expected, neighbours, settings):
        """Measure the char at `target` as the RGB camera would (char_dots.measure_in_image)."""
        diameter = self.wood.char_diameter(self.peak.get(tuple(target), 0.0))
        charred = diameter >= settings.min_diameter_ratio * expected
        return DotMeasure(charred, diameter, tuple(target), expected,
                          '' if charred else f'char {diameter * 1e3:.2f} mm: too small')

    def publish_feedback(self, feedback):
        self.feedback.append((self.t, feedback.phase, feedback.index, feedback.n_p))

    def set_window(self, target):
        self.windows.append(None if target is None else tuple(float(v) for v in target))
