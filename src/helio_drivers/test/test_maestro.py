"""Maestro protocol bytes, calibration and the emulator over a real pty."""

import math

from conftest import open_port, read_exactly
from helio_drivers import maestro_protocol as proto
from helio_drivers.maestro_emulator import CONFIGURED_SETTINGS as CONFIGURED
from helio_drivers.maestro_emulator import MaestroEmulator
import pytest


def test_encoding_matches_the_pololu_examples():
    # Pololu's user guide: target 1500 us = 6000 quarter-us = 0x70 0x2E on channel 2
    assert proto.set_target(2, 6000) == bytes([0x84, 0x02, 0x70, 0x2E])
    assert proto.set_speed(1, 140) == bytes([0x87, 0x01, 0x0C, 0x01])
    assert proto.set_acceleration(0, 4) == bytes([0x89, 0x00, 0x04, 0x00])
    assert proto.get_position(5) == bytes([0x90, 0x05])
    assert proto.get_moving_state() == bytes([0x93])
    assert proto.get_errors() == bytes([0xA1])
    assert proto.decode_u16(bytes([0x70, 0x17])) == 0x1770
    with pytest.raises(proto.MaestroProtocolError, match='target'):
        proto.set_target(0, 1 << 14)
    with pytest.raises(proto.MaestroProtocolError, match='channel'):
        proto.get_position(200)


def test_parser_round_trips_and_flags_protocol_errors():
    commands = [proto.Command(proto.SET_TARGET, 3, 7000), proto.Command(proto.SET_SPEED, 0, 5),
                proto.Command(proto.SET_ACCELERATION, 1, 9), proto.Command(proto.GET_POSITION, 4),
                proto.Command(proto.GET_MOVING_STATE), proto.Command(proto.GET_ERRORS)]
    data = b''.join(proto.encode_command(c) for c in commands)
    parser = proto.CommandParser()
    assert sum((parser.feed(bytes([b])) for b in data), []) == commands
    assert parser.protocol_errors == 0
    # a target cut short by a new command byte, then a stray data byte
    assert parser.feed(bytes([0x84, 0x01, 0x93, 0x05])) == [proto.Command(0x93)]
    assert parser.protocol_errors == 2


def test_the_pololu_protocol_carries_the_same_commands_for_its_device_number_only():
    # issue 35: public clients address a Maestro as 0xAA, device number, command & 0x7F
    commands = [proto.Command(proto.SET_TARGET, 3, 7000), proto.Command(proto.GET_POSITION, 4),
                proto.Command(proto.GET_MOVING_STATE), proto.Command(proto.GO_HOME)]
    # Pololu's documented example: Set Target 1500 us (6000) on channel 2 of device 12
    assert proto.encode_pololu(proto.Command(proto.SET_TARGET, 2, 6000)) == bytes(
        [0xAA, 0x0C, 0x04, 0x02, 0x70, 0x2E])
    data = b''.join(proto.encode_pololu(c) for c in commands)
    parser = proto.CommandParser()
    assert sum((parser.feed(bytes([b])) for b in data), []) == commands
    # another device's commands are read and dropped; compact ones still act
    other = proto.encode_pololu(proto.Command(proto.SET_TARGET, 0, 8000), device_number=13)
    compact = proto.encode_command(proto.Command(proto.GET_ERRORS))
    assert parser.feed(other + compact) == [proto.Command(proto.GET_ERRORS)]
    # a Pololu command cut short by a compact one, and an unknown command
    assert parser.feed(bytes([0xAA, 0x0C, 0x04, 0x01, 0x93])) == [proto.Command(0x93)]
    assert parser.feed(bytes([0xAA, 0x0C, 0x55])) == []
    assert parser.protocol_errors == 2
    with pytest.raises(proto.MaestroProtocolError):
        proto.encode_pololu(commands[0], device_number=128)


def test_the_emulator_answers_a_pololu_protocol_client_of_its_device_number(maestro):
    emulator, port, clock = maestro
    pololu = proto.encode_pololu
    port.write(pololu(proto.Command(proto.SET_SPEED, 0, 0))
               + pololu(proto.Command(proto.SET_TARGET, 0, 4 * 1800)))
    clock.advance(0.1)
    reply = query(port, pololu(proto.Command(proto.GET_POSITION, 0)), 2)
    assert proto.decode_u16(reply) == 4 * 1800
    assert emulator.pulse_widths_us()[0] == pytest.approx(1800.0)
    # addressed to device 13: neither acted on nor answered
    port.write(pololu(proto.Command(proto.SET_TARGET, 0, 4 * 1200), device_number=13))
    assert query(port, pololu(proto.Command(proto.GET_POSITION, 0), device_number=13), 2) == b''
    assert emulator.pulse_widths_us()[0] == pytest.approx(1800.0)
    assert proto.decode_u16(query(port, proto.get_errors(), 2)) == 0


def test_calibration_round_trips_and_refuses_out_of_range():
    calibration = proto.ServoCalibration('lens_yaw', 0, min_pulse_us=1000.0,
                                         max_pulse_us=2000.0, direction=-1,
                                         zero_offset=0.1)
    # -1 direction: +0.2 rad from the zero offset is 0.2 * 2000/pi us below the centre
    assert calibration.pulse_us(0.3) == pytest.approx(1500.0 - 0.2 * 2000.0 / math.pi)
    for angle in (-0.5, 0.0, 0.1, 0.7):
        assert calibration.angle(calibration.pulse_us(angle)) == pytest.approx(angle)
    low, high = calibration.angle_range()
    assert calibration.pulse_us(low) == pytest.approx(2000.0)
    with pytest.raises(ValueError, match='lens_yaw'):
        calibration.pulse_us(high + 0.01)
    with pytest.raises(ValueError, match='direction'):
        proto.ServoCalibration('x', 0, direction=0)


@pytest.fixture
def maestro(manual_clock):
    calibrations = [proto.ServoCalibration('lens_yaw', 0), proto.ServoCalibration('lens_pitch', 1)]
    emulator = MaestroEmulator(clock=manual_clock, calibrations=calibrations, **CONFIGURED)
    port = open_port(emulator.port_path, timeout=0.05)
    try:
        yield emulator, port, manual_clock
    finally:
        port.close()
        emulator.close()


def query(port, data, count):
    port.reset_input_buffer()
    port.write(data)
    return read_exactly(port, count)


def test_emulated_servo_ramps_under_speed_and_acceleration(maestro):
    emulator, port, clock = maestro
    # 100 units = 2500 us/s, 10 units = 3125 us/s^2; 500 us move: ramps 0.8 s and 1000 us,
    # more than the move, so it is triangular: T = 2 sqrt(500 / 3125) = 0.8 s
    port.write(proto.set_speed(0, 100) + proto.set_acceleration(0, 10)
               + proto.set_target(0, 4 * 2000))
    assert query(port, proto.get_moving_state(), 1) == b'\x01'
    clock.advance(0.4)
    position = proto.decode_u16(query(port, proto.get_position(0), 2))
    assert position == pytest.approx(4 * 1750, abs=1)
    assert emulator.joint_positions()['lens_yaw'] == pytest.approx(
        250.0 * math.pi / 2000.0, abs=1e-6)
    clock.advance(0.41)
    assert query(port, proto.get_moving_state(), 1) == b'\x00'
    assert proto.decode_u16(query(port, proto.get_position(0), 2)) == 8000
    # the device clamps targets to the channel range (2500 us)
    port.write(proto.set_speed(1, 0) + proto.set_acceleration(1, 0) + proto.set_target(1, 12000))
    assert proto.decode_u16(query(port, proto.get_position(1), 2)) == 10000
    # the limits as the device holds them: Set Speed/Acceleration units, 0 = unlimited
    assert emulator.motion_limits()[:2] == [(2500.0, 3125.0), (math.inf, math.inf)]


def test_every_reading_of_a_ramped_move_fits_its_envelope_and_noise_does_not(maestro):
    # the independent truth: the emulator's ramp (speed and acceleration limited), read
    # every 20 ms through a move, a reversal mid-move and a hold
    emulator, port, clock = maestro
    envelope = proto.PositionEnvelope(tolerance_qus=1)
    port.write(proto.set_speed(0, 40) + proto.set_acceleration(0, 5))
    start = proto.decode_u16(query(port, proto.get_position(0), 2))
    readings = []
    for target, steps in ((4 * 2200, 40), (4 * 1200, 60), (4 * 1200, 100)):
        envelope.accepted(start) if not readings else None
        envelope.targeted(target)
        port.write(proto.set_target(0, target))
        for _ in range(steps):
            clock.advance(0.02)
            reading = proto.decode_u16(query(port, proto.get_position(0), 2))
            assert proto.possible_position(reading)
            assert envelope.consistent(reading), (target, reading)
            envelope.accepted(reading)
            readings.append(reading)
    assert max(readings) > 4 * 1600 and readings[-1] == 4 * 1200      # it moved, then held
    # held at 1200 us: noise that happens to be a possible value is not where the pulse is
    assert not envelope.consistent(4 * 1210) and not envelope.consistent(4 * 1000)
    assert envelope.consistent(4 * 1200)
    # values no Maestro sends (the 22.7 rad of issue 35's report: 15 950 us)
    assert not any(proto.possible_position(v) for v in (1, 255, 16321, 4 * 15950, 0xFFFF))
    assert all(proto.possible_position(v) for v in (0, 256, 4 * 1500, 16320))
    envelope.forget()
    assert envelope.consistent(4 * 3000) and not envelope.known()


def test_protocol_errors_are_reported_and_cleared(maestro):
    emulator, port, _ = maestro
    port.write(bytes([0x84, 0x00, 0xFF]))
    assert proto.decode_u16(query(port, proto.get_errors(), 2)) == proto.SERIAL_PROTOCOL_ERROR
    assert proto.decode_u16(query(port, proto.get_errors(), 2)) == 0


def test_maestro_fault_no_reply_and_unplug(maestro):
    emulator, port, _ = maestro
    emulator.inject(drop_replies=1)
    assert query(port, proto.get_position(0), 2) == b''
    assert len(query(port, proto.get_position(0), 2)) == 2
    emulator.disconnect()
    with pytest.raises(Exception):
        port.read(1)
    port.close()
    emulator.reconnect()
    port.open()
    assert len(query(port, proto.get_position(0), 2)) == 2
