"""
A Dobot client written here to the public protocol description connects to the emulator.

helio's own client shares ``dobot_protocol`` with the emulator, so it cannot show that the
emulator answers as the firmware does. ``PublicClient`` below is written from the Dobot
Magician Communication Protocol (frame ``AA AA len id ctrl params checksum``, little-endian)
without helio's code, and sends exactly the start-up sequence of the public pydobot clients
(pydobot 1.3.2, pydobotplus 0.1.2: queue start and clear, PTP joint, coordinate, jump and
common parameters, all queued, then the alarms and the pose), HOME without its reserved
word (pydobotplus), MOVL moves waited on through the executed index, the suction cup, the
gripper, an EIO read, a CP move of 14 parameter bytes as pydobot sends it, and a command id
outside the protocol. (pydobot and pydobotplus pin pyserial 3.4, below the workspace's 3.5,
so they are not installed here; pydobotplus 0.1.2 was run by hand against this emulator:
see the README.)
"""

import struct
import time

from helio_drivers.dobot_emulator import DobotEmulator
import pytest
import serial


class PublicClient:
    """Frames and reads replies as the protocol document describes (no helio code)."""

    def __init__(self, port, timeout=1.0):
        self.port = serial.Serial(port, 115200, timeout=timeout)

    def close(self):
        self.port.close()

    def send(self, command_id, ctrl=0, params=b''):
        """Send one command; return (id, ctrl, params) of its reply, reading as pydobotplus."""
        checksum = (256 - (command_id + ctrl + sum(params)) % 256) % 256
        frame = bytes([0xAA, 0xAA, 2 + len(params), command_id, ctrl]) + params + \
            bytes([checksum])
        self.port.reset_input_buffer()
        self.port.write(frame)
        previous = None
        for _ in range(8):                      # look for the AA AA header
            byte = self.port.read(1)
            assert byte, f'no reply to command {command_id} within the timeout'
            if byte == b'\xaa' and previous == b'\xaa':
                break
            previous = byte
        else:
            raise AssertionError(f'no header in the reply to command {command_id}')
        length = self.port.read(1)[0]
        payload = self.port.read(length + 1)
        assert len(payload) == length + 1, 'reply cut short'
        assert (sum(payload[:-1]) + payload[-1]) % 256 == 0, 'reply checksum'
        return payload[0], payload[1], payload[2:-1]

    def queued(self, command_id, params=b''):
        """Send a queued write (ctrl 3); return its queue index (u64)."""
        reply_id, ctrl, params = self.send(command_id, 0x03, params)
        assert (reply_id, ctrl, len(params)) == (command_id, 0x03, 8)
        return struct.unpack('<Q', params)[0]

    def wait_for(self, index, timeout=10.0):
        """Poll GetQueuedCmdCurrentIndex (246) until it reaches `index`."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            _, _, params = self.send(246)
            if struct.unpack('<Q', params)[0] >= index:
                return
            time.sleep(0.02)        # the polling period of a client, not synchronisation
        raise AssertionError(f'queued command {index} not executed in {timeout} s')

    def pose(self):
        """Return x, y, z, r [mm, deg], j1..j4 [deg] (GetPose, id 10)."""
        reply_id, _, params = self.send(10)
        assert reply_id == 10 and len(params) == 32
        return struct.unpack('<8f', params)

    def start_up(self):
        """Connect as pydobot does (its start-up sequence)."""
        assert self.send(240, 0x01)[:2] == (240, 0x01)              # queue start
        assert self.send(245, 0x01)[:2] == (245, 0x01)              # queue clear
        indices = [self.queued(80, struct.pack('<8f', *[200.0] * 8)),
                   self.queued(81, struct.pack('<4f', 200.0, 200.0, 200.0, 200.0)),
                   self.queued(82, struct.pack('<2f', 10.0, 200.0)),  # SetPTPJumpParams
                   self.queued(83, struct.pack('<2f', 100.0, 100.0))]
        assert indices == sorted(indices) and len(set(indices)) == 4
        _, _, alarms = self.send(20)
        if any(alarms):
            self.send(20, 0x01)                                     # clear all alarms
        return self.pose()


@pytest.fixture
def public_client():
    emulator = DobotEmulator()
    client = PublicClient(emulator.port_path)
    try:
        yield emulator, client
    finally:
        client.close()
        emulator.close()


def test_a_public_client_starts_up_homes_moves_and_reads_poses(public_client):
    emulator, client = public_client
    pose = client.start_up()
    assert pose[4:] == pytest.approx(tuple(emulator.home_joints_deg), abs=1e-4)
    target = (220.0, 30.0, 40.0, 10.0)                            # MOVL_XYZ, mm and deg
    client.wait_for(client.queued(84, struct.pack('<B4f', 2, *target)))
    assert client.pose()[:4] == pytest.approx(target, abs=1e-3)
    client.wait_for(client.queued(31))                           # HOME, no parameters
    assert client.pose()[4:] == pytest.approx(tuple(emulator.home_joints_deg), abs=1e-4)
    client.wait_for(client.queued(31, struct.pack('<I', 0)))     # HOME, reserved u32
    # end effectors and EIO, as pydobot sends them
    client.wait_for(client.queued(62, bytes([1, 1])))            # suction cup on
    assert client.send(62)[2] == bytes([1, 1])
    client.wait_for(client.queued(63, bytes([1, 0])))            # gripper open
    assert client.send(63)[2] == bytes([1, 0])
    assert client.send(131, 0x01, bytes([3, 1]))[:2] == (131, 0x01)   # EIO 3 high
    assert client.send(131, 0x00, bytes([3])) == (131, 0x00, bytes([3, 1]))
    # pydobot's CP move: mode 1 (absolute), x, y, z and one byte
    cp = client.queued(91, bytes([1]) + struct.pack('<3f', 200.0, -20.0, 60.0) + b'\x00')
    client.wait_for(cp)
    assert client.pose()[:3] == pytest.approx((200.0, -20.0, 60.0), abs=1e-3)
    _, _, alarms = client.send(20)
    assert not any(alarms), 'the start-up and the moves raised alarms'
    assert client.send(247)[2] == struct.pack('<I', emulator.queue_capacity)


def test_a_command_outside_the_protocol_is_answered_and_flagged(public_client):
    emulator, client = public_client
    assert client.send(199, 0x01, b'\x01\x02') == (199, 0x01, b'')
    _, _, alarms = client.send(20)
    assert alarms[0] & 0x02                      # COMMON_UNDEFINED_INSTRUCTION (bit 1)
    client.send(20, 0x01)
    assert not any(client.send(20)[2])
