"""
Pololu Maestro client over pyserial (compact protocol) with timeouts and bounded retries.

Set commands have no reply. Queries flush the input first (the compact protocol has no
framing, so a late reply must never be read as the next one), then wait up to ``timeout``
for the expected number of bytes, retrying up to ``retries`` more times before raising
``DeviceTimeoutError``; a reply no Maestro can send (a position outside every channel
range, a moving state other than 0 or 1, an unused error bit) is asked for again (up to
``serial_link.IMPOSSIBLE_REPLIES_MAX`` times, ``SerialClient.checked``). A failing port
raises ``LinkError`` and closes the port.
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
                silent_at = self.silent_at(time.monotonic())
                attempts = 0
                for attempt in range(self.retries + 1):
                    if time.monotonic() >= silent_at:
                        break
                    if attempt:
                        self.retried += 1
                    attempts += 1
                    self._serial.reset_input_buffer()
                    try:
                        self._serial.write(data)
                    except serial.SerialTimeoutException:
                        continue        # a slow link, not a lost one: retry
                    reply = self._read(reply_length, min(time.monotonic() + self.timeout,
                                                         silent_at))
                    if len(reply) == reply_length:
                        return reply
                    # Replies carry no channel number: one that comes after its timeout
                    # would be read as the answer to the next query (possibly another
                    # channel's), so it is waited out here and discarded.
                    self._drain_late_replies(until=silent_at)
                if time.monotonic() >= silent_at:
                    raise DeviceTimeoutError(self.silence_message(what, attempts))
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

    def _checked_query(self, data, reply_length, what, decode, possible, describe):
        """Return a query's decoded reply; impossible ones asked again (``checked``)."""
        return self.checked(lambda: decode(self._exchange(data, reply_length, what)), what,
                            possible, describe)

    def get_position(self, channel):
        """Return a channel's current pulse [quarter-us] (0 or within PULSE_RANGE_US)."""
        return self._checked_query(proto.get_position(channel), 2, f'get position ch {channel}',
                                   proto.decode_u16, proto.possible_position,
                                   lambda value: f'{value / 4.0:.2f} us')

    def moving(self):
        """Whether any servo is still moving towards its target (the reply is 0 or 1)."""
        return self._checked_query(proto.get_moving_state(), 1, 'get moving state',
                                   lambda reply: reply[0], lambda value: value in (0, 1),
                                   lambda value: f'0x{value:02X}') == 1

    def get_errors(self):
        """Return and clear the error bits (bits 9-15 are not used by any Maestro)."""
        return self._checked_query(proto.get_errors(), 2, 'get errors', proto.decode_u16,
                                   lambda value: value < 1 << len(proto.ERROR_BITS),
                                   lambda value: f'0x{value:04X}')
