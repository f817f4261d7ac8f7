"""
Pololu Maestro client over pyserial (compact protocol) with timeouts and bounded retries.

Set commands have no reply. Queries flush the input first (the compact protocol has no
framing, so a late reply must never be read as the next one), then wait up to ``timeout``
for the expected number of bytes, retrying up to ``retries`` more times before raising
``DeviceTimeoutError``. A failing port raises ``LinkError`` and closes the port.
"""

import time

from helio_drivers import maestro_protocol as proto
from helio_drivers.serial_link import (
    DeviceTimeoutError, LinkError, PORT_FAILURES, SerialClient)
import serial


class MaestroClient(SerialClient):
    """A Maestro on a serial port (thread-safe: one exchange at a time)."""

    def __init__(self, port, baudrate=115200, timeout=0.1, retries=2):
        """Configure; nothing is opened until connect()."""
        super().__init__(port, baudrate, timeout, retries)

    def _exchange(self, data, reply_length, what):
        with self._lock:
            if self._serial is None:
                raise LinkError(f'{what}: port {self.port} is not open')
            try:
                if reply_length == 0:
                    self._serial.write(data)
                    return b''
                for attempt in range(self.retries + 1):
                    if attempt:
                        self.retried += 1
                    self._serial.reset_input_buffer()
                    try:
                        self._serial.write(data)
                    except serial.SerialTimeoutException:
                        continue        # a slow link, not a lost one: retry
                    reply = self._read(reply_length, time.monotonic() + self.timeout)
                    if len(reply) == reply_length:
                        return reply
                    # Replies carry no channel number: one that comes after its timeout
                    # would be read as the answer to the next query (possibly another
                    # channel's), so it is waited out here and discarded.
                    self._drain_late_replies()
            except PORT_FAILURES as error:
                self._close_locked()
                raise LinkError(f'{what}: link to {self.port} lost: {error}') from error
        raise DeviceTimeoutError(f'{what}: no {reply_length}-byte reply from {self.port} '
                                 f'within {self.timeout:.3f} s after {self.retries + 1} attempts')

    def _read(self, count, deadline):
        reply = b''
        while len(reply) < count:
            remaining = deadline - time.monotonic()
            if remaining <= 0.0:
                break
            self._serial.timeout = min(remaining, 0.05)
            reply += self._serial.read(count - len(reply))
        return reply

    def set_target(self, channel, quarter_us):
        """Set a channel's target pulse [quarter-us] (0 = off)."""
        self._exchange(proto.set_target(channel, quarter_us), 0, f'set target ch {channel}')

    def set_speed(self, channel, units):
        """Set a channel's speed limit (protocol units, 0 = unlimited)."""
        self._exchange(proto.set_speed(channel, units), 0, f'set speed ch {channel}')

    def set_acceleration(self, channel, units):
        """Set a channel's acceleration limit (protocol units, 0 = unlimited)."""
        self._exchange(proto.set_acceleration(channel, units), 0,
                       f'set acceleration ch {channel}')

    def get_position(self, channel):
        """Return a channel's current pulse [quarter-us]."""
        return proto.decode_u16(self._exchange(proto.get_position(channel), 2,
                                               f'get position ch {channel}'))

    def moving(self):
        """Whether any servo is still moving towards its target."""
        return self._exchange(proto.get_moving_state(), 1, 'get moving state') != b'\x00'

    def get_errors(self):
        """Return and clear the error bits."""
        return proto.decode_u16(self._exchange(proto.get_errors(), 2, 'get errors'))
