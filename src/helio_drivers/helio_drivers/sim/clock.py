"""
Simulated time of the world (issue 6, item 7).

``SimClock`` holds the simulated time in seconds since the start of the run and the
timezone-aware date and time that start corresponds to (for the sun). It only moves when the
world steps, so the run is deterministic whatever the wall clock does. Calling the clock
returns its seconds: it is the injected clock of the device emulators (their motion follows
simulated time). ``Pacer`` keeps the simulation at a real-time factor: given the wall time
and the simulated time it says how long to wait before the next step (0 when behind), and
reports the factor achieved.
"""

import datetime
import threading


class SimClock:
    """Simulated seconds since `start` (a timezone-aware datetime); thread-safe reads."""

    def __init__(self, start, time=0.0):
        """Start at `start` (aware datetime) plus `time` seconds."""
        if not isinstance(start, datetime.datetime) or start.utcoffset() is None:
            raise ValueError(f'start must be a timezone-aware datetime, got {start!r}')
        self.start = start
        self._time = float(time)
        self._lock = threading.Lock()

    def __call__(self):
        """Return the simulated time [s] (the emulators' clock callable)."""
        with self._lock:
            return self._time

    @property
    def time(self):
        """Return the simulated seconds since the start."""
        return self()

    def advance(self, dt):
        """Move simulated time forward by `dt` > 0 seconds; return the new time."""
        if not dt > 0.0:
            raise ValueError(f'dt must be > 0 s, got {dt}')
        with self._lock:
            self._time += float(dt)
            return self._time

    def datetime(self):
        """Return the aware datetime of the present simulated instant."""
        return self.start + datetime.timedelta(seconds=self())

    def nanoseconds(self):
        """
        Return the simulated instant as ns since the Unix epoch (for /clock and stamps).

        /clock carries the absolute simulated date and time, not the seconds since the start:
        the sun estimator's Eq 18 update asks pysolar where the sun is at the node clock's
        time, which must be the simulated day, not 1 January 1970.
        """
        return int(round(self.start.timestamp() * 1e9)) + int(round(self() * 1e9))


class Pacer:
    """
    Hold a real-time factor between wall time and simulated time.

    `real_time_factor` <= 0 means as fast as possible. If the simulation falls behind by
    more than `max_lag` wall seconds it stops trying to catch up (the lag is dropped).
    """

    def __init__(self, real_time_factor=1.0, max_lag=0.5):
        """Pace at `real_time_factor` simulated seconds per wall second."""
        self.real_time_factor = float(real_time_factor)
        self.max_lag = float(max_lag)
        self._wall0 = None
        self._sim0 = 0.0
        self._first_wall = None
        self._first_sim = 0.0

    def set_real_time_factor(self, real_time_factor):
        """Pace at a new factor from the next step on (the achieved figure keeps counting)."""
        self.real_time_factor = float(real_time_factor)
        self._wall0 = None

    def delay(self, wall_now, sim_now):
        """Return the wall seconds to wait before simulating past `sim_now` (0: step now)."""
        if self._wall0 is None:
            self._wall0, self._sim0 = wall_now, sim_now
        if self._first_wall is None:
            self._first_wall, self._first_sim = wall_now, sim_now
        if self.real_time_factor <= 0.0:
            return 0.0
        due = self._wall0 + (sim_now - self._sim0) / self.real_time_factor
        if wall_now - due > self.max_lag:  # too far behind: restart the reference
            self._wall0, self._sim0 = wall_now, sim_now
            return 0.0
        return max(0.0, due - wall_now)

    def achieved(self, wall_now, sim_now):
        """Return the real-time factor achieved since the first call (sim s per wall s)."""
        if self._first_wall is None or wall_now <= self._first_wall:
            return 0.0
        return (sim_now - self._first_sim) / (wall_now - self._first_wall)


class Lockstep:
    """
    Keep a world that runs faster than real time from outrunning the graph that reads it.

    Each consumer (a `source`: the thermal monitor's ``thermal/stats``, each driver's
    ``joint_states``) stamps its outputs with the simulated instant of the input they answer
    or of the node clock they were read on. ``hold`` says to wait while the world is more
    than `lead` simulated seconds ahead of the newest stamp of any source, as a robot's real
    sensors and devices never run ahead of the software reading them. A source that has not
    answered anything newer for `timeout` wall seconds (stopped, crashed, unplugged, or
    answering the same frame again and again) is left behind until it answers again, so it
    cannot freeze the world; the world node then paces itself at real time
    (``left_behind``), as the world of a real robot whose perception stopped would go on.
    """

    def __init__(self, lead=0.2, timeout=1.0):
        """Allow `lead` [s simulated] ahead; give up on a source after `timeout` [s wall]."""
        if not (lead > 0.0 and timeout > 0.0):
            raise ValueError(f'lockstep lead and timeout must be > 0, got {lead}, {timeout}')
        self.lead, self.timeout = float(lead), float(timeout)
        self._stamps = {}            # source -> newest stamp answered [s simulated]
        self._heard = {}             # source -> wall time it was last heard [s]
        self._leads = {}             # source -> its own lead, where not `lead` [s simulated]

    def seen(self, stamp, wall_now, source='', lead=None):
        """
        Note an output of `source` answering the simulated instant `stamp` [s].

        `lead` [s simulated], if given, replaces the default lead for this source. A stamp
        of 0 or less (a node that stamped before its clock got its first /clock) says
        nothing about where the source is and is ignored.
        """
        if not stamp > 0.0:
            return
        newest = self._stamps.get(source)
        if newest is None or stamp > newest:     # progress: an answer to something new
            self._stamps[source] = stamp
            self._heard[source] = wall_now
        if lead is not None:
            if not lead > 0.0:
                raise ValueError(f'lockstep lead must be > 0, got {lead}')
            self._leads[source] = float(lead)

    def forget(self, source):
        """Stop waiting for `source` until it answers again (it said it is done)."""
        for table in (self._stamps, self._heard, self._leads):
            table.pop(source, None)

    def hold(self, sim_now, wall_now):
        """Return whether the world should wait before simulating past `sim_now` [s]."""
        return bool(self.holding(sim_now, wall_now))

    def holding(self, sim_now, wall_now):
        """Return the sources the world waits for at `sim_now` [s] (sorted)."""
        return sorted(source for source, stamp in self._stamps.items()
                      if sim_now - stamp > self._leads.get(source, self.lead)
                      and wall_now - self._heard[source] <= self.timeout)

    def left_behind(self, wall_now):
        """Return whether a source that answered before has been silent past the timeout."""
        return bool(self.silent(wall_now))

    def silent(self, wall_now):
        """Return the sources silent past the timeout (sorted)."""
        return sorted(source for source, heard in self._heard.items()
                      if wall_now - heard > self.timeout)
