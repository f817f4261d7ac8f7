"""
Counters of a camera node's frames: received, published, malformed, invalid, dropped.

Dropped frames are the ones that never reached the callback (the sensor-data QoS keeps only
the newest few): they are estimated from gaps in the header stamps, against the median
frame period seen so far. `InputFreshness` tells whether the input stream stopped (on the
node clock and on wall time, so a stopped /clock is seen too). Pure Python, no rclpy: the
nodes publish `as_dict()` and `health()` as diagnostics and log them.
"""

from collections import Counter, deque
import statistics

from helio_optics.node_kit.diagnostics import ERROR, OK, WARN
from helio_optics.node_kit.parameters import declare


class FrameStatistics:
    """Count what happened to each incoming frame."""

    def __init__(self, period_window=50):
        self.received = 0
        self.published = 0
        self.malformed = 0
        self.invalid = 0
        self.dropped = 0
        self.late = 0
        self.reasons = Counter()
        self.processing_ms = deque(maxlen=200)
        self._periods = deque(maxlen=period_window)
        self._last_stamp = None
        self._reported_malformed = 0

    def frame(self, stamp):
        """Register a received frame with its header stamp [s]; return frames dropped before."""
        self.received += 1
        dropped = 0
        if self._last_stamp is not None:
            gap = stamp - self._last_stamp
            if gap > 0:
                if len(self._periods) >= 5:
                    period = statistics.median(self._periods)
                    if period > 0 and gap > 1.5 * period:
                        dropped = int(round(gap / period)) - 1
                        gap = period  # keep the period estimate clean
                self._periods.append(gap)
        self._last_stamp = stamp
        self.dropped += dropped
        return dropped

    def result(self, published, valid=True, reason='', milliseconds=None):
        """Register the outcome of a frame that was processed."""
        self.published += int(published)
        if not valid:
            self.invalid += 1
            self.reasons[_category(reason)] += 1
        if milliseconds is not None:
            self.processing_ms.append(milliseconds)

    def late_frame(self):
        """Register a frame skipped because it was too far behind the node clock."""
        self.late += 1

    def bad_frame(self, reason):
        """Register a frame that could not be used at all (logged with `reason`)."""
        self.malformed += 1
        self.reasons[_category(reason)] += 1

    def as_dict(self):
        """Return the counters (and processing times [ms]) as a flat dict of numbers/text."""
        times = sorted(self.processing_ms)
        values = {
            'frames_received': self.received, 'frames_published': self.published,
            'frames_malformed': self.malformed, 'frames_invalid': self.invalid,
            'frames_dropped_estimated': self.dropped,
            'frames_skipped_late': self.late,
            'processing_ms_median': times[len(times) // 2] if times else 0.0,
            'processing_ms_max': times[-1] if times else 0.0,
        }
        for reason, count in sorted(self.reasons.items()):
            values['reason: ' + reason] = count
        return values

    def health(self, stale='', warning=''):
        """
        Return (level, message) for /diagnostics (DiagnosticStatus OK, WARN or ERROR).

        ERROR when the input is `stale` (its reason); WARN when frames were malformed since
        the last call, or for `warning`; OK otherwise.
        """
        malformed = self.malformed - self._reported_malformed
        self._reported_malformed = self.malformed
        if stale:
            return ERROR, stale
        if malformed:
            return WARN, f'{malformed} malformed frame(s) since the last report'
        if warning:
            return WARN, warning
        return OK, ''

    def summary(self):
        """Return a one-line summary for the log."""
        values = self.as_dict()
        return ', '.join(f'{k} {v:.2f}' if isinstance(v, float) else f'{k} {v}'
                         for k, v in values.items())


def _category(reason):
    """Group reasons by their stem (numbers and details after ':' or '(' dropped)."""
    for separator in (':', '('):
        reason = reason.split(separator)[0]
    return reason.strip() or 'unknown'


class InputFreshness:
    """
    Tell whether a node's input stream is alive, on the node clock and on wall time.

    The node clock is simulated time under `use_sim_time`: it stops when /clock stops, so
    the wall clock (monotonic) is watched too. Before the first input only the wall time
    since the start counts (the node clock may not have started). Times in seconds.
    """

    def __init__(self, topic, timeout, wall_timeout, wall_now):
        if not timeout > 0 or not wall_timeout > 0:
            raise ValueError(f'input timeouts must be > 0 s, got {timeout} and {wall_timeout}')
        self.topic = topic
        self.timeout = float(timeout)
        self.wall_timeout = float(wall_timeout)
        self._started_wall = float(wall_now)
        self._last_node = None
        self._last_wall = None

    @classmethod
    def declared(cls, node, topic, wall_now):
        """Return one for `topic` with the node's `input_timeout` and `input_wall_timeout`."""
        return cls(topic,
                   declare(node, 'input_timeout', 2.0,
                           'Diagnostics ERROR when no image arrived for this long on the node '
                           'clock [s].', 0.01, 3600.0),
                   declare(node, 'input_wall_timeout', 5.0,
                           'Diagnostics ERROR when no image arrived for this long on the wall '
                           'clock (a stopped /clock) [s].', 0.01, 3600.0),
                   wall_now)

    def seen(self, node_now, wall_now):
        """Register an input arriving at node time `node_now` and wall time `wall_now`."""
        self._last_node, self._last_wall = float(node_now), float(wall_now)

    def ages(self, node_now, wall_now):
        """Return (node-clock age, wall age) of the newest input [s] (node age NaN if none)."""
        if self._last_wall is None:
            return float('nan'), float(wall_now) - self._started_wall
        return max(float(node_now) - self._last_node, 0.0), float(wall_now) - self._last_wall

    def stale(self, node_now, wall_now):
        """Return why the input is stale, in one line, or an empty string while it is fresh."""
        node_age, wall_age = self.ages(node_now, wall_now)
        if self._last_wall is None:
            if wall_age > self.wall_timeout:
                return f'no {self.topic} since the start {wall_age:.1f} s ago (wall time)'
            return ''
        if node_age > self.timeout or wall_age > self.wall_timeout:
            return (f'input stale: no {self.topic} for {node_age:.1f} s of node time '
                    f'({wall_age:.1f} s of wall time; limits {self.timeout:g} s, '
                    f'{self.wall_timeout:g} s)')
        return ''
