"""
The waits of the painter's procedures on its streams, without rclpy (issue 32).

A procedure waits for the next message of a stream: the thermal statistics (the heating
loop), the light spot (the sun's return), an RGB frame taken from some time on (the
camera's check of a dot). The node's subscription callbacks offer each message to the
stream's ``Waits``; a wait takes what it is offered while it is registered (``waiting``).

- ``ThermalWaits`` also keeps the stamp of the last live thermal frame (a frozen one, a
  flat-field correction's repeat, is no fresh reading) and wakes every wait with None: a
  cancel or a device fault, for which the heating loop must check at once, not at the next
  frame (a world holding for a silent driver sends none).
- ``Waits.offer`` with a stamp gives a message only to the waits registered for messages
  stamped from their `since` on (an RGB frame taken after the lens retreated).
- ``CameraModel`` is the RGB camera's model of its latest camera_info, built again only
  when the calibration in it changes (the message comes 30 times a second).
"""

from contextlib import contextmanager


class Waits:
    """The waits registered on one stream; each takes the messages offered while there."""

    def __init__(self):
        """Start with no wait."""
        self._takers = []           # (since [s] or None, take(message))

    def __bool__(self):
        """Tell whether a wait is registered (a stream is decoded only then)."""
        return bool(self._takers)

    def offer(self, message, stamp=None):
        """Give `message` (stamped `stamp` [s]) to every wait for it."""
        for since, take in list(self._takers):
            if since is None or (stamp is not None and stamp >= since):
                take(message)

    @contextmanager
    def waiting(self, take, since=None):
        """Register `take` for the stream's messages (those stamped from `since` [s] on)."""
        entry = (since, take)
        self._takers.append(entry)
        try:
            yield
        finally:
            self._takers.remove(entry)


class ThermalWaits(Waits):
    """The waits on the thermal statistics, and the stamp of the last live frame."""

    def __init__(self):
        """Start with no wait and no live frame."""
        super().__init__()
        self.live_stamp = None      # the stamp [s] of the last frame not frozen

    def take(self, stats, stamp):
        """Take the statistics `stats` of a frame stamped `stamp` [s]; offer them."""
        if not stats.frozen:
            self.live_stamp = stamp
        self.offer(stats)

    def wake(self):
        """Wake every wait with None: the heating loop checks and retreats at once."""
        self.offer(None)


class CameraModel:
    """The camera model of the latest camera_info, built by `build` when it changes."""

    def __init__(self, build):
        """Build models with `build(info)` (ValueError: no model, e.g. K = 0)."""
        self.build = build
        self.model = None
        self._key = None

    def take(self, info):
        """Take a camera_info; build the model again when its calibration changed."""
        key = (tuple(info.k), tuple(info.d), info.width, info.height)
        if key != self._key:
            try:
                self.model = self.build(info)
            except ValueError:
                self.model = None
            self._key = key
