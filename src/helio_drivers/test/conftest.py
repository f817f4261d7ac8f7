"""Shared fixtures: a manual clock for emulators and a raw serial exchange helper."""

import time

import pytest
import serial


class ManualClock:
    """A clock that moves only when told (simulated time) [s]."""

    def __init__(self, start=100.0):
        self.now = start

    def __call__(self):
        return self.now

    def advance(self, seconds):
        self.now += seconds


@pytest.fixture
def manual_clock():
    return ManualClock()


def open_port(path, timeout=0.5):
    """Open an emulator's pty as the drivers do (pyserial, 115200 8N1)."""
    return serial.Serial(path, 115200, timeout=timeout)


def read_exactly(port, count, timeout=1.0):
    """Read `count` bytes or fewer when `timeout` [s] passes."""
    deadline = time.monotonic() + timeout
    data = b''
    while len(data) < count and time.monotonic() < deadline:
        data += port.read(count - len(data))
    return data
