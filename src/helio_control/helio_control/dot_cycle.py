"""
Algorithm 1 of the paper for one dot, as decisions (Sec. IV-B, Algorithm 1 lines 6-13).

Thermal readings and time in; heat, retreat or next dot out.

The paper's loop, per target point p_i*:

- lines 6-9: hold the lens at the heating distance d_lp while N_p < N_p* (the dot's target,
  30 in the paper: a dot about 2 mm wide);
- lines 10-13: retreat by delta d_lp and wait while N_p > 0 (the previous dot's afterglow
  must not count in the next dot's N_p);
- line 14: the next dot (and the Eq 18 update of the sun estimate).

``DotCycle`` holds that state for one dot. Whoever moves the lens (the painter node, the
demo, a calibration experiment) tells it when heating started and feeds it each thermal
reading; it answers with a ``Decision``. It never sleeps and never reads a clock: the time of
each reading is given, so the same code runs against simulated time, wall time or a test.
It does not import rclpy.

Beyond the paper (its Fig. 15d: a cloud, N_p reached but no char): while heating, a loss of
sun is told by the thermal image itself. The wood under a steady focus only warms, so N_p
falling back from its peak by ``cloud_n_p_drop`` pixels, or T_max falling from its peak by
``cloud_t_drop`` K while below the camera's cap, means the sun went (a cloud); so does the
RGB camera seeing no spot for ``cloud_dark_time`` (when the caller says whether it sees
one). The cycle then answers CLOUD: retreat, wait for the sun, and heat the same dot again
from the start with its full target (``restart``): a dot heated through a cloud is reheated,
not counted.

Beyond the paper (issue 29), for dots wider than N_p can ask for: the thermal image's hot
area stops growing long before the char does (the simulated world's N_p levels off near 45
after 90 s while the char still spreads), so a wide dot is heated to N_p* and then *held*
there: ``hold`` seconds counted only between readings at or above N_p* (a cloud or a
frozen camera does not count as holding), at most ``max_heating + hold`` in all.
"""

from dataclasses import dataclass
import enum
import math


class Decision(enum.Enum):
    """What to do after a reading."""

    HEAT = 'heat'          # keep the lens at the heating distance
    RETREAT = 'retreat'    # move the lens to the retreat distance (heating is over)
    CLOUD = 'cloud'        # the sun went while heating: retreat, wait for it, heat again
    WAIT = 'wait'          # stay retreated, the dot is still hot
    NEXT = 'next'          # this dot is finished: go to the next one


class Phase(enum.Enum):
    """Where the cycle stands."""

    APPROACH = 'approach'  # moving to the dot; no reading counts yet
    HEATING = 'heating'
    COOLING = 'cooling'
    DONE = 'done'


@dataclass(frozen=True)
class CycleSettings:
    """Termination rules of one dot (paper Sec. IV-B defaults)."""

    n_p_target: int = 30          # N_p* that ends the heating [-]
    max_heating: float = 90.0     # longest heating before giving the dot up [s]
    max_cooling: float = 60.0     # longest wait for N_p to reach 0 after the retreat [s]
    wait_for_zero: bool = True    # the paper's rule: next dot only once N_p is 0
    cloud_n_p_drop: int = 3       # N_p this far under its peak while heating: sun lost [-]
    cloud_t_drop: float = 5.0     # T_max this far under its peak (below the cap): sun lost [K]
    cloud_dark_time: float = 1.0  # no spot in the RGB camera this long: sun lost [s]
    hold: float = 0.0             # after N_p* is reached, heat on this long at N_p >= N_p* [s]

    def __post_init__(self):
        """Reject settings that cannot end a dot."""
        if self.n_p_target < 1:
            raise ValueError(f'n_p_target must be >= 1, got {self.n_p_target}')
        if not (self.max_heating > 0.0 and self.max_cooling > 0.0):
            raise ValueError(f'max_heating and max_cooling must be > 0 s, got '
                             f'{self.max_heating} and {self.max_cooling}')
        if self.cloud_n_p_drop < 1 or not (self.cloud_t_drop > 0.0
                                           and self.cloud_dark_time > 0.0):
            raise ValueError('cloud_n_p_drop must be >= 1, cloud_t_drop and cloud_dark_time '
                             '> 0')
        if not (math.isfinite(self.hold) and self.hold >= 0.0):
            raise ValueError(f'hold must be a finite time >= 0 s, got {self.hold}')


class DotCycle:
    """
    Algorithm 1 for one dot; see the module docstring.

    After ``start_heating(t)`` every ``update(t, n_p)`` returns HEAT until N_p reaches the
    target and has been held there for ``hold`` (then RETREAT once), or until
    ``max_heating`` (plus ``hold``) has passed (RETREAT with ``outcome`` 'max_heating').
    After the retreat it returns WAIT while N_p > 0 and NEXT once N_p is 0 (or at once
    without ``wait_for_zero``, or after ``max_cooling`` with ``cooling_timed_out`` set).
    The durations of both phases are kept for the cycle model.
    """

    def __init__(self, settings=None):
        """Start in the approach phase."""
        self.settings = settings or CycleSettings()
        self.phase = Phase.APPROACH
        self.heating_started = math.nan
        self.retreated = math.nan
        self.finished = math.nan
        self.outcome = ''             # 'charred' or 'max_heating' once heating ended
        self.cooling_timed_out = False
        self.peak_n_p = 0
        self.peak_t_max = -math.inf
        self.dark_since = math.nan
        self.clouds = 0               # heatings of this dot broken off by a loss of sun
        self.cloud_reason = ''
        self.reached = math.nan       # when N_p first reached the target [s]
        self.held = 0.0               # time held at N_p >= target since [s]
        self._at_target_since = math.nan   # the last reading's time when it was at target

    @property
    def heating_time(self):
        """Return how long the lens heated [s] (nan before the retreat)."""
        return self.retreated - self.heating_started

    @property
    def cooling_time(self):
        """Return how long the retreated lens waited for N_p to drop [s] (nan before)."""
        return self.finished - self.retreated

    def start_heating(self, now):
        """Start the heating: the lens reached the heating distance at `now` [s]."""
        if self.phase is not Phase.APPROACH:
            raise RuntimeError(f'start_heating in phase {self.phase.value}')
        self.phase = Phase.HEATING
        self.heating_started = float(now)

    def restart(self):
        """Go back to the approach of the same dot (after a cloud); the clouds are counted."""
        clouds, reason = self.clouds, self.cloud_reason
        self.__init__(self.settings)
        self.clouds, self.cloud_reason = clouds, reason

    def update(self, now, n_p, t_max=None, cap=None, sun_seen=None):
        """
        Take the reading N_p (and T_max [degC]) at `now` [s]; return the Decision.

        `cap` is the camera's read-out cap (T_max at it cannot fall as the wood cools
        unseen); `sun_seen` whether the RGB camera sees the spot now (None: unknown).
        """
        settings = self.settings
        if self.phase is Phase.APPROACH:
            raise RuntimeError('a reading before start_heating')
        if self.phase is Phase.DONE:
            return Decision.NEXT
        if self.phase is Phase.HEATING:
            lost = self._sun_lost(now, n_p, t_max, cap, sun_seen)
            if lost:
                self.clouds += 1
                self.cloud_reason = lost
                return Decision.CLOUD
            self.peak_n_p = max(self.peak_n_p, int(n_p))
            if t_max is not None:
                self.peak_t_max = max(self.peak_t_max, float(t_max))
            if n_p >= settings.n_p_target:
                if math.isnan(self.reached):
                    self.reached = float(now)
                elif not math.isnan(self._at_target_since):
                    self.held += float(now) - self._at_target_since
                self._at_target_since = float(now)
                if self.held >= settings.hold:
                    return self._retreat(now, 'charred')
            else:
                self._at_target_since = math.nan
            return self._heat_or_give_up(now)
        if not settings.wait_for_zero or n_p <= 0:
            return self._finish(now)
        if now - self.retreated > settings.max_cooling:
            self.cooling_timed_out = True
            return self._finish(now)
        return Decision.WAIT

    def update_unread(self, now):
        """
        Take a frame at `now` [s] that has no reading of the dot; return the Decision.

        E.g. the window rule's frame whose camera pose is unknown: only the time limit
        applies (HEAT, or RETREAT with outcome 'max_heating' past ``max_heating``).
        """
        if self.phase is not Phase.HEATING:
            raise RuntimeError(f'update_unread in phase {self.phase.value}')
        self._at_target_since = math.nan      # no reading: the hold does not go on blind
        return self._heat_or_give_up(now)

    def _heat_or_give_up(self, now):
        settings = self.settings
        if now - self.heating_started > settings.max_heating + settings.hold:
            return self._retreat(now, 'max_heating')
        return Decision.HEAT

    def _sun_lost(self, now, n_p, t_max, cap, sun_seen):
        """Return why the sun seems gone ('' while it shines), see the module docstring."""
        settings = self.settings
        if self.peak_n_p >= settings.cloud_n_p_drop and \
                n_p <= self.peak_n_p - settings.cloud_n_p_drop:
            return f'N_p fell from {self.peak_n_p} to {int(n_p)} while heating'
        below_cap = cap is None or t_max is None or t_max < cap - 0.05
        if t_max is not None and below_cap and \
                t_max <= self.peak_t_max - settings.cloud_t_drop:
            return f'T_max fell from {self.peak_t_max:.1f} to {t_max:.1f} degC while heating'
        if sun_seen is False:
            if math.isnan(self.dark_since):
                self.dark_since = float(now)
            if now - self.dark_since >= settings.cloud_dark_time:
                return f'no light spot seen for {now - self.dark_since:.1f} s'
        elif sun_seen:
            self.dark_since = math.nan
        return ''

    def _retreat(self, now, outcome):
        self.phase = Phase.COOLING
        self.retreated = float(now)
        self.outcome = outcome
        return Decision.RETREAT

    def _finish(self, now):
        self.phase = Phase.DONE
        self.finished = float(now)
        return Decision.NEXT
