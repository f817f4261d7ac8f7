"""
Counters of a camera node's frames: received, published, malformed, invalid, dropped.

Dropped frames are the ones that never reached the callback (the sensor-data QoS keeps only
the newest few): they are estimated from gaps in the header stamps, against the median
frame period seen so far. Pure Python, no rclpy: the nodes publish `as_dict()` as
diagnostics and log it.
"""

from collections import Counter, deque
import statistics


class FrameStatistics:
    """Count what happened to each incoming frame."""

    def __init__(self, period_window=50):
        self.received = 0
        self.published = 0
        self.malformed = 0
        self.invalid = 0
        self.dropped = 0
        self.reasons = Counter()
        self.processing_ms = deque(maxlen=200)
        self._periods = deque(maxlen=period_window)
        self._last_stamp = None

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
            'processing_ms_median': times[len(times) // 2] if times else 0.0,
            'processing_ms_max': times[-1] if times else 0.0,
        }
        for reason, count in sorted(self.reasons.items()):
            values['reason: ' + reason] = count
        return values

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
