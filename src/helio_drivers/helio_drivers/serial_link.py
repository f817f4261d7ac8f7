"""
What both pyserial clients share: errors, opening a port, the link state, reconnect backoff.

No rclpy here: the nodes use these to keep the link state and to decide when to retry.
"""

import termios
import threading

import serial


class DeviceError(RuntimeError):
    """A device command failed; the message says which and why."""


# What pyserial raises when a port fails under it (unplugged, pty closed).
PORT_FAILURES = (serial.SerialException, OSError, termios.error)


class LinkError(DeviceError):
    """The serial port is not open, could not be opened, or failed (unplugged)."""


class DeviceTimeoutError(DeviceError):
    """No valid reply arrived within the timeout, after every retry."""


def open_serial(port, baudrate, reply_timeout):
    """
    Open `port` 8N1 with a short read timeout (the clients loop to their own deadline).

    Writes time out after max(1 s, 10 reply timeouts): a pty under load can be slow to
    report room to write, and a slow write is retried, not taken for an unplugged port.
    """
    if not port:
        raise LinkError('no serial port configured (parameter "port" is empty)')
    try:
        return serial.Serial(port, baudrate=baudrate, timeout=0.01,
                             write_timeout=max(1.0, 10.0 * reply_timeout), exclusive=True)
    except PORT_FAILURES + (ValueError,) as error:
        raise LinkError(f'cannot open {port}: {error}') from error


class ReconnectBackoff:
    """Exponential backoff between reconnect attempts: initial, x2 each failure, capped."""

    def __init__(self, initial_s=0.2, maximum_s=5.0):
        """Delays in seconds; initial must be positive and not above maximum."""
        if not 0.0 < initial_s <= maximum_s:
            raise ValueError(f'backoff needs 0 < initial ({initial_s}) <= maximum ({maximum_s})')
        self.initial_s = initial_s
        self.maximum_s = maximum_s
        self.attempts = 0
        self.next_attempt_at = 0.0

    def due(self, now):
        """Whether an attempt should be made at time `now` [s]."""
        return now >= self.next_attempt_at

    def failed(self, now):
        """Record a failed attempt at `now`; return the delay until the next one [s]."""
        delay = min(self.initial_s * 2.0 ** self.attempts, self.maximum_s)
        self.attempts += 1
        self.next_attempt_at = now + delay
        return delay

    def succeeded(self):
        """Reset after a successful connection."""
        self.attempts = 0
        self.next_attempt_at = 0.0


class SerialClient:
    """
    The link half of a device client: port settings, connect/close, one exchange at a time.

    Subclasses add the device's requests; they hold `self._lock` around each exchange and
    override `_on_open()` to reset per-link state (e.g. a frame reader).
    """

    def __init__(self, port, baudrate, timeout, retries):
        """Configure; nothing is opened until connect()."""
        if timeout <= 0.0:
            raise ValueError(f'timeout must be positive, got {timeout}')
        if retries < 0:
            raise ValueError(f'retries must be >= 0, got {retries}')
        self.port = port
        self.baudrate = baudrate
        self.timeout = timeout
        self.retries = retries
        self._serial = None
        self._lock = threading.Lock()
        self.retried = 0            # requests sent again after a bad or missing reply

    @property
    def connected(self):
        """Whether the port is open (no failure seen since)."""
        return self._serial is not None

    def connect(self):
        """Open the port; LinkError if it cannot be opened."""
        with self._lock:
            self._close_locked()
            self._serial = open_serial(self.port, self.baudrate, self.timeout)
            self._on_open()

    def close(self):
        """Close the port (idempotent)."""
        with self._lock:
            self._close_locked()

    def _on_open(self):
        """Reset per-link state after the port opened (called with the lock held)."""

    def _close_locked(self):
        if self._serial is not None:
            try:
                self._serial.close()
            except PORT_FAILURES:
                pass
            self._serial = None
