"""UART transport: spec strings, loop://, and a pty pair with pyserial on both ends."""

from __future__ import annotations

import time

import pytest
import serial

from rdm.link.serial import (
    DEFAULT_BAUD,
    SerialSpec,
    SerialSpecError,
    open_pty_pair,
    open_serial,
    parse_serial_spec,
)


@pytest.mark.parametrize(
    ("spec", "expected"),
    [
        ("serial:/dev/ttyUSB0@921600", SerialSpec("device", "/dev/ttyUSB0", 921600)),
        ("serial:/dev/flight_controller", SerialSpec("device", "/dev/flight_controller", 921600)),
        ("/dev/ttyACM1@115200", SerialSpec("device", "/dev/ttyACM1", 115200)),
        ("loop://", SerialSpec("url", "loop://", 921600)),
        ("socket://127.0.0.1:5000", SerialSpec("url", "socket://127.0.0.1:5000", 921600)),
        (" pty ", SerialSpec("pty", "", 921600)),
    ],
)
def test_parse_specs(spec, expected):
    assert parse_serial_spec(spec) == expected


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("", "empty"),
        ("serial:", "no device path"),
        ("serial:@9600", "no device path"),
        ("serial:/dev/ttyUSB0@fast", "not a positive integer"),
        ("serial:/dev/ttyUSB0@0", "not a positive integer"),
        ("ttyUSB0", "unrecognised"),
        ("can:vcan0", "unrecognised"),
    ],
)
def test_malformed_specs_are_clear_errors(spec, message):
    with pytest.raises(SerialSpecError, match=message):
        open_serial(spec)


def test_unknown_url_scheme_is_a_spec_error():
    with pytest.raises(SerialSpecError, match="nosuch"):
        open_serial("nosuch://x")


def test_missing_device_raises_serial_exception():
    with pytest.raises(serial.SerialException):
        open_serial("serial:/dev/does-not-exist-rdm@921600")


def test_loop_url_echoes_and_reads_do_not_block():
    with open_serial("loop://") as link:
        assert link.read_available() == b""
        assert link.write(bytes(range(256))) == 256
        assert link.read_available() == bytes(range(256))
        assert link.read_available() == b""
        assert link.port.baudrate == DEFAULT_BAUD


def _collect(link, n: int, timeout: float = 2.0) -> bytes:
    data = b""
    deadline = time.monotonic() + timeout
    while len(data) < n and time.monotonic() < deadline:
        data += link.read_available()
    return data


def test_pty_pair_carries_every_byte_value_both_ways():
    device, pc = open_pty_pair()
    try:
        # raw 8-bit line: 0xFF, 0x00, CR, LF, XON/XOFF and ^C pass untouched
        payload = bytes(range(256)) * 8
        assert device.read_available() == b""
        for src, dst in ((device, pc), (pc, device)):
            for i in range(0, len(payload), 512):
                src.write(payload[i : i + 512])
                assert _collect(dst, 512) == payload[i : i + 512]
        assert device.port.baudrate == 921600
        assert device.port.bytesize == 8 and device.port.parity == "N"
        assert device.port.stopbits == 1 and not device.port.rtscts
        assert isinstance(pc.port, serial.Serial)
    finally:
        device.close()
    assert not device.port.is_open and not pc.port.is_open


def test_open_serial_pty_exposes_the_peer():
    link = open_serial("pty")
    try:
        assert link.peer is not None
        link.peer.write(b"\xff\xfe\x00\x00\xff\x00\x00\xff")
        assert _collect(link, 8) == bytes.fromhex("fffe0000ff0000ff")
    finally:
        link.close()
