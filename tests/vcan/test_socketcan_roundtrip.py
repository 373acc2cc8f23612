"""Frames sent through python-can reach other sockets on vcan0 unchanged (real kernel SocketCAN)."""

from __future__ import annotations

import can
import pytest
from can_frames import decode, encode, raw_socket

CLASSIC_FRAMES = [
    can.Message(arbitration_id=0x123, data=bytes(range(1, 9)), is_extended_id=False),
    can.Message(arbitration_id=0x7FF, data=b"", is_extended_id=False),
    can.Message(arbitration_id=0x000, data=b"\xff", is_extended_id=False),
    can.Message(arbitration_id=0x1ABCDE0F, data=b"\xde\xad\xbe\xef", is_extended_id=True),
    can.Message(arbitration_id=0x1FFFFFFF, data=bytes(8), is_extended_id=True),
    can.Message(arbitration_id=0x456, dlc=4, is_remote_frame=True, is_extended_id=False),
]


def _same_frame(sent: can.Message, got: can.Message) -> None:
    assert got.arbitration_id == sent.arbitration_id
    assert got.is_extended_id == sent.is_extended_id
    assert got.is_remote_frame == sent.is_remote_frame
    assert got.dlc == sent.dlc
    assert bytes(got.data) == bytes(sent.data)
    assert got.is_fd == sent.is_fd


def test_classic_frames_reach_a_second_bus_identically(vcan_bus, recv_all, vcan_channel):
    sender, receiver = vcan_bus(), vcan_bus()
    for msg in CLASSIC_FRAMES:
        sender.send(msg)
    got = recv_all(receiver, window=5.0, limit=len(CLASSIC_FRAMES))
    assert len(got) == len(CLASSIC_FRAMES)
    for sent, received in zip(CLASSIC_FRAMES, got, strict=True):
        _same_frame(sent, received)
        assert received.channel == vcan_channel
    # Nothing else arrives: each frame is delivered once.
    assert receiver.recv(timeout=0.2) is None


def test_kernel_bytes_match_the_linux_frame_layout(vcan_bus, vcan_channel):
    """A stdlib AF_CAN socket sees python-can's frames as struct can_frame with the same fields."""
    sender = vcan_bus()
    with raw_socket(vcan_channel) as sock:
        for msg in CLASSIC_FRAMES:
            sender.send(msg)
        for sent in CLASSIC_FRAMES:
            identifier, extended, remote, payload, fd = decode(sock.recv(128))
            assert identifier == sent.arbitration_id
            assert extended == sent.is_extended_id
            assert remote == sent.is_remote_frame
            assert fd is False
            if not remote:
                assert payload == bytes(sent.data)


def test_frames_from_a_stdlib_socket_reach_python_can(vcan_bus, recv_all, vcan_channel):
    receiver = vcan_bus()
    with raw_socket(vcan_channel) as sock:
        sock.send(encode(0x321, b"\x10\x20\x30"))
        sock.send(encode(0x0ABCDEF0, b"\x01", extended=True))
    got = recv_all(receiver, window=5.0, limit=2)
    assert [(m.arbitration_id, m.is_extended_id, bytes(m.data)) for m in got] == [
        (0x321, False, b"\x10\x20\x30"),
        (0x0ABCDEF0, True, b"\x01"),
    ]


@pytest.mark.parametrize("length", [12, 64])
def test_can_fd_frames_roundtrip(vcan_bus, recv_all, vcan_channel, length):
    sender, receiver = vcan_bus(fd=True), vcan_bus(fd=True)
    payload = bytes((7 * i + 3) % 256 for i in range(length))
    sent = can.Message(
        arbitration_id=0x18DAF110,
        data=payload,
        is_fd=True,
        bitrate_switch=True,
        is_extended_id=True,
    )
    with raw_socket(vcan_channel, fd=True) as sock:
        sender.send(sent)
        identifier, extended, _, raw_payload, fd = decode(sock.recv(128))
    assert (identifier, extended, raw_payload, fd) == (0x18DAF110, True, payload, True)
    [got] = recv_all(receiver, window=5.0, limit=1)
    _same_frame(sent, got)
    assert got.bitrate_switch


def test_own_frames_echo_only_when_asked(vcan_bus, recv_all):
    quiet = vcan_bus(receive_own_messages=False)
    echoing = vcan_bus(receive_own_messages=True)
    quiet.send(can.Message(arbitration_id=0x10, data=b"\x01", is_extended_id=False))
    echoing.send(can.Message(arbitration_id=0x20, data=b"\x02", is_extended_id=False))
    # quiet sees only the other bus's frame; echoing sees both.
    assert [m.arbitration_id for m in recv_all(quiet, window=5.0, limit=1)] == [0x20]
    assert [m.arbitration_id for m in recv_all(echoing, window=5.0, limit=2)] == [0x10, 0x20]
    assert quiet.recv(timeout=0.2) is None
    assert echoing.recv(timeout=0.2) is None


def test_locally_sent_frames_are_flagged_as_not_received(vcan_bus, recv_all):
    """The kernel marks frames that originate on this host (MSG_DONTROUTE), and python-can turns
    that into is_rx=False, for every local socket: on vcan all traffic is local. Node code must
    not rely on is_rx to tell its own frames from a peer's there (use receive_own_messages)."""
    sender, receiver = vcan_bus(), vcan_bus()
    sender.send(can.Message(arbitration_id=0x30, data=b"\x03", is_extended_id=False))
    [got] = recv_all(receiver, window=5.0, limit=1)
    assert got.arbitration_id == 0x30
    assert got.is_rx is False
