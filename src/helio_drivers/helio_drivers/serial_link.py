"""
What both pyserial clients share: errors, opening a port, the link state, reconnect backoff.

No rclpy here: the nodes use these to keep the link state and to decide when to retry.
"""

import math
import os
import termios
import threading
import time

import serial


IMPOSSIBLE_REPLIES_MAX = 5      # replies no device can send, in a row, before a query fails


class DeviceError(RuntimeError):
    """A device command failed; the message says which and why."""


# What pyserial raises when a port fails under it (unplugged, pty closed).
PORT_FAILURES = (serial.SerialException, OSError, termios.error)


class LinkError(DeviceError):
    """The serial port is not open, could not be opened, or failed (unplugged)."""


class DeviceTimeoutError(DeviceError):
    """No valid reply arrived within the timeout, after every retry."""


class PortBusyError(LinkError):
    """The port exists but another process holds it (e.g. a second driver for the device)."""


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
        if 'exclusively lock' in str(error):
            holders = port_holders(port)
            raise PortBusyError(
                f'{port} is in use by '
                + (', '.join(holders) if holders else 'another process')
                + ': another program (a second driver?) holds this device') from error
        raise LinkError(f'cannot open {port}: {error}') from error


def port_holders(port):
    """
    Describe the processes holding `port`'s lock ('pid N (command line)'), from /proc.

    The exclusive open takes a flock on the device: /proc/locks names its owner by the
    device's inode. Without such an entry, every process with the device open is named.
    """
    try:
        status = os.stat(port)
        target = os.path.realpath(port)
    except OSError:
        return []
    inode = f'{os.major(status.st_dev):02x}:{os.minor(status.st_dev):02x}:{status.st_ino}'
    pids = []
    try:
        with open('/proc/locks') as stream:
            for line in stream:
                fields = line.split()
                if len(fields) > 5 and fields[1] == 'FLOCK' and fields[5] == inode:
                    pids.append(int(fields[4]))
    except (OSError, ValueError):
        pass
    if not pids:
        for pid in (int(p) for p in os.listdir('/proc') if p.isdigit()):
            try:
                fds = os.listdir(f'/proc/{pid}/fd')
                if any(os.path.realpath(f'/proc/{pid}/fd/{fd}') == target for fd in fds):
                    pids.append(pid)
            except OSError:
                continue        # gone meanwhile, or not ours to look at
    return [_process(pid) for pid in sorted(set(pids))]


def _process(pid):
    try:
        with open(f'/proc/{pid}/cmdline', 'rb') as stream:
            command = stream.read().replace(b'\0', b' ').decode(errors='replace').strip()
    except OSError:
        command = ''
    return f'pid {pid} ({command[:120]})' if command else f'pid {pid}'


AUTO_PORT = 'auto'


def parse_usb_id(text):
    """Return (vid, pid or None) of 'vvvv:pppp' or 'vvvv' (hexadecimal USB ids)."""
    try:
        parts = [int(part, 16) for part in str(text).split(':')]
    except ValueError:
        parts = []
    if len(parts) not in (1, 2) or not all(0 <= part <= 0xFFFF for part in parts):
        raise ValueError(f'USB id {text!r} is not "vvvv:pppp" or "vvvv" (hexadecimal)')
    return parts[0], (parts[1] if len(parts) == 2 else None)


def _describe(port):
    ids = f'{port.vid:04x}:{port.pid:04x}' if port.vid is not None else 'no USB id'
    text = f'{port.device} ({ids}'
    if port.description and port.description != 'n/a':
        text += f', {port.description}'
    return text + ')'


def _interface(port):
    """Return the USB interface number ending a port's location ('1-1.2:1.0' -> 0)."""
    location = port.location or ''
    try:
        return int(location.rsplit('.', 1)[1]) if ':' in location else 0
    except (IndexError, ValueError):
        return 0


def find_port(usb_ids, what, ports=None):
    """
    Return the device path of the one serial port whose USB id is among `usb_ids`.

    `usb_ids` are 'vvvv:pppp' or 'vvvv' strings; `ports` defaults to pyserial's
    ``serial.tools.list_ports.comports()``. A device with several ports (one serial
    number) gives its first interface. LinkError lists what was found when no port matches
    and the candidates when several devices do.
    """
    wanted = [parse_usb_id(usb_id) for usb_id in usb_ids]
    if ports is None:
        from serial.tools import list_ports
        ports = list_ports.comports()
    ports = sorted(ports, key=lambda p: p.device)
    matches = [p for p in ports if p.vid is not None and any(
        p.vid == vid and (pid is None or p.pid == pid) for vid, pid in wanted)]
    if not matches:
        found = ', '.join(_describe(p) for p in ports) or 'no serial ports at all'
        raise LinkError(f'port auto: no serial port with a USB id of {what} '
                        f'({", ".join(usb_ids)}); found: {found}')
    devices = {}
    for port in matches:
        devices.setdefault(port.serial_number or port.device, []).append(port)
    if len(devices) > 1:
        raise LinkError(f'port auto: {len(devices)} devices look like {what}: '
                        + ', '.join(_describe(p) for p in matches)
                        + '; set the parameter "port" to the one to use')
    return min(next(iter(devices.values())), key=_interface).device


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
        self.drained_bytes = 0      # late input dropped after a timeout or a retry
        # a request left without a valid reply this long in all (its attempts and the waits
        # for late replies together) fails at once as silent: DeviceTimeoutError (0: no such
        # limit, only the attempts' timeouts) [s]
        self.silence_timeout = 0.0
        self.impossible_replies = 0     # well-formed replies no such device can send (noise)

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

    def checked(self, ask, what, possible, describe):
        """
        Return `ask()`'s value, asking again while it is one the device cannot send.

        Line noise can pass as a reply: always on a line without checksums (the Maestro's),
        rarely through a checksum (the Dobot's: one random frame in 256 passes it). Such a
        value (`possible(value)` false) is dropped, counted in ``impossible_replies`` and
        asked for again, up to IMPOSSIBLE_REPLIES_MAX times in all (a line that garbles one
        reply in seven fails a query once in 10^4), then ``DeviceError`` naming the last one
        (`describe(value)`): the device answers, it is not silent.
        """
        attempts = max(self.retries + 1, IMPOSSIBLE_REPLIES_MAX)
        for attempt in range(attempts):
            value = ask()
            if possible(value):
                return value
            self.impossible_replies += 1
            if attempt < attempts - 1:
                self.retried += 1
        raise DeviceError(f'{what}: {attempts} impossible replies in a row from {self.port} '
                          f'(the last {describe(value)}; line noise?)')

    def silent_at(self, started):
        """Return when a request begun at `started` [monotonic s] counts as silent (or inf)."""
        return started + self.silence_timeout if self.silence_timeout > 0.0 else math.inf

    def silence_message(self, what, attempts):
        """Return the DeviceTimeoutError text of a request cut short by `silence_timeout`."""
        return (f'{what}: no valid reply from {self.port} within the silence limit of '
                f'{self.silence_timeout:.3f} s ({attempts} attempts of {self.timeout:.3f} s)')

    def _drain_late_replies(self, until=math.inf):
        """
        Read and drop input until the line has been quiet for one reply timeout.

        Called (lock held) after a request timed out or was retried: the device may still
        answer an attempt, and that late reply must never be read as the answer to the next
        request. Bounded by (retries + 2) reply timeouts and by `until` [monotonic s].
        """
        port = self._serial
        deadline = min(time.monotonic() + (self.retries + 2) * self.timeout, until)
        quiet_since = time.monotonic()
        while True:
            now = time.monotonic()
            if now - quiet_since >= self.timeout or now >= deadline:
                break
            port.timeout = min(self.timeout - (now - quiet_since), deadline - now, 0.05)
            data = port.read(max(1, port.in_waiting))
            if data:
                self.drained_bytes += len(data)
                quiet_since = time.monotonic()
        port.reset_input_buffer()

    def _close_locked(self):
        if self._serial is not None:
            try:
                self._serial.close()
            except PORT_FAILURES:
                pass
            self._serial = None
