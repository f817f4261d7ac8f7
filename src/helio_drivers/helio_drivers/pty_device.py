"""
A serial device emulated on a pseudo-terminal, with link fault injection.

The emulator holds the master side of a pty (os.openpty) and a reader thread; the driver
opens the slave side through a stable symlink (``port_path``) exactly as it would open
/dev/ttyUSB0. ``disconnect()`` closes the pty and removes the link (the driver's reads fail
as on a USB unplug); ``reconnect()`` makes a new pty behind the same link path. Subclasses
implement ``handle_input(data) -> list of reply bytes``.

Faults are injected on replies (what the driver sees), as on a real noisy or hung link:
dropped replies (no reply), corrupted last byte (a bad checksum), truncated replies
(partial frames), garbage before a reply, delayed replies and randomly dropped bytes; and on
the device itself: ``mute`` (acts, never answers) and ``deaf`` (hung: ignores everything).
"""

from dataclasses import dataclass
import os
import random
import select
import tempfile
import threading
import time
import tty


@dataclass
class LinkFaults:
    """Faults applied to the next replies; counters count down as replies are sent."""

    drop_replies: int = 0         # swallow this many whole replies (the driver times out)
    corrupt_replies: int = 0      # flip bits of the last byte (checksum) of this many replies
    truncate_replies: int = 0     # send only the first half of this many replies
    garbage_replies: int = 0      # put random bytes before this many replies
    garbage_rate: float = 0.0     # probability that random bytes come before any reply [-]
    reply_delay_s: float = 0.0    # delay every reply by this long [s]
    byte_drop_rate: float = 0.0   # probability that any reply byte is lost [-]
    mute: bool = False            # never answer (input still acted on) until cleared
    deaf: bool = False            # ignore all input and answer nothing (a hung device)


class PtyDevice:
    """Base of the emulators: pty + symlink + reader thread + fault injection."""

    def __init__(self, port_path=None, seed=0, name='device', line_baudrate=None):
        """
        Create the pty now; `port_path` is the symlink (a temporary path if None).

        A pty moves bytes instantly; with `line_baudrate` [bit/s] each reply is held back
        by its transmission time on a real 8N1 line (10 bits per byte).
        """
        self.name = name
        self.line_baudrate = line_baudrate
        self._owned_dir = None
        if port_path is None:
            self._owned_dir = tempfile.mkdtemp(prefix=f'helio_{name}_')
            port_path = os.path.join(self._owned_dir, name)
        self.port_path = str(port_path)
        self.faults = LinkFaults()
        self._random = random.Random(seed)
        self._io_lock = threading.Lock()
        self._master = None
        self._slave = None
        self._stop = threading.Event()
        self._wake_read, self._wake_write = os.pipe()
        self.bytes_received = 0
        self.bytes_ignored = 0
        self.replies_sent = 0
        self._open_pty()
        self._thread = threading.Thread(target=self._run, name=f'{name}-emulator', daemon=True)
        self._thread.start()

    # ---- link -------------------------------------------------------------------------------

    @property
    def connected(self):
        """Whether the pty exists (the device is 'plugged in')."""
        return self._master is not None

    @property
    def device_name(self):
        """Return the slave device (/dev/pts/N) behind port_path, None when unplugged."""
        return os.ttyname(self._slave) if self._slave is not None else None

    def _open_pty(self):
        master, slave = os.openpty()
        tty.setraw(slave)           # no echo, no CR/LF translation, no signals: 8-bit clean
        tty.setraw(master)
        os.set_blocking(master, False)
        temporary = self.port_path + '.new'
        os.makedirs(os.path.dirname(os.path.abspath(self.port_path)), exist_ok=True)
        if os.path.lexists(temporary):
            os.unlink(temporary)
        os.symlink(os.ttyname(slave), temporary)
        os.replace(temporary, self.port_path)
        with self._io_lock:
            self._master, self._slave = master, slave
        self._wake()

    def disconnect(self):
        """Unplug: remove the link and close the pty; the driver's I/O fails."""
        with self._io_lock:
            master, slave = self._master, self._slave
            self._master = self._slave = None
        if os.path.lexists(self.port_path):
            os.unlink(self.port_path)
        for fd in (master, slave):
            if fd is not None:
                os.close(fd)
        self._wake()

    def reconnect(self):
        """Plug back in: a new pty behind the same port_path."""
        if self.connected:
            return
        self._open_pty()

    def close(self):
        """Stop the reader thread, close the pty and remove the link."""
        self._stop.set()
        self._wake()
        self._thread.join(timeout=2.0)
        self.disconnect()
        os.close(self._wake_read)
        os.close(self._wake_write)
        if self._owned_dir is not None:
            try:
                os.rmdir(self._owned_dir)
            except OSError:
                pass

    def __enter__(self):
        """Use as a context manager that closes the emulator."""
        return self

    def __exit__(self, *exc_info):
        """Close on leaving the with-block."""
        self.close()

    def inject(self, **faults):
        """Set fields of LinkFaults, e.g. drop_replies=1; unknown names raise."""
        for key, value in faults.items():
            if not hasattr(self.faults, key):
                raise AttributeError(f'no link fault named {key!r}')
            setattr(self.faults, key, value)

    def clear_faults(self):
        """Remove all injected faults."""
        self.faults = LinkFaults()

    # ---- reader thread ----------------------------------------------------------------------

    def _wake(self):
        try:
            os.write(self._wake_write, b'x')
        except OSError:
            pass

    def _run(self):
        while not self._stop.is_set():
            master = self._master
            watch = [self._wake_read] + ([master] if master is not None else [])
            try:
                readable, _, _ = select.select(watch, [], [], 0.5)
            except (OSError, ValueError):
                continue        # the master was closed by disconnect() meanwhile
            if self._wake_read in readable:
                os.read(self._wake_read, 1024)
            if master is None or master not in readable:
                continue
            try:
                data = os.read(master, 4096)
            except (BlockingIOError, InterruptedError):
                continue
            except OSError:
                continue        # closed by disconnect() meanwhile
            if not data:
                continue
            if self.faults.deaf:
                self.bytes_ignored += len(data)
                continue
            self.bytes_received += len(data)
            for reply in self.handle_input(data):
                self._send(master, reply)

    def _send(self, master, reply):
        faults = self.faults
        if faults.mute:
            return
        if faults.drop_replies > 0:
            faults.drop_replies -= 1
            return
        reply = bytearray(reply)
        if faults.corrupt_replies > 0 and reply:
            faults.corrupt_replies -= 1
            reply[-1] ^= 0x5A
        if faults.truncate_replies > 0:
            faults.truncate_replies -= 1
            reply = reply[:len(reply) // 2]
        if faults.garbage_replies > 0 or (
                faults.garbage_rate > 0.0 and self._random.random() < faults.garbage_rate):
            faults.garbage_replies = max(0, faults.garbage_replies - 1)
            reply = bytearray(self._random.randrange(256) for _ in range(7)) + reply
        if faults.byte_drop_rate > 0.0:
            reply = bytearray(b for b in reply if self._random.random() >= faults.byte_drop_rate)
        delay = faults.reply_delay_s
        if self.line_baudrate:
            delay += 10.0 * len(reply) / self.line_baudrate
        if delay > 0.0 and self._stop.wait(delay):
            return
        deadline = time.monotonic() + 1.0
        with self._io_lock:
            if self._master != master:
                return          # unplugged while the reply was pending
            view = memoryview(bytes(reply))
            while view:
                try:
                    written = os.write(master, view)
                except BlockingIOError:
                    # nobody drains the other side: give up after a second, as bytes
                    # sent to a closed port are lost
                    if time.monotonic() > deadline or self._stop.is_set():
                        return
                    select.select([], [master], [], 0.05)
                    continue
                except OSError:
                    return
                view = view[written:]
        self.replies_sent += 1

    def handle_input(self, data):
        """Parse received bytes, act on them and return the replies (override)."""
        raise NotImplementedError
