"""Bad frames are refused with clear errors, by python-can and by the kernel, and the bus
keeps working afterwards."""

from __future__ import annotations

import errno

import can
import pytest
from can_frames import CAN_FRAME, encode, raw_socket


def test_python_can_rejects_a_dlc_above_8_for_classic_can():
    with pytest.raises(ValueError, match="DLC"):
        can.Message(arbitration_id=0x100, data=bytes(9), is_extended_id=False, check=True)


def test_kernel_rejects_a_classic_frame_with_9_data_bytes(vcan_bus, recv_all):
    sender, receiver = vcan_bus(), vcan_bus()
    bad = can.Message(arbitration_id=0x100, data=bytes(9), is_extended_id=False)
    with pytest.raises(can.CanOperationError) as info:
        sender.send(bad)
    assert info.value.error_code == errno.EINVAL
    # Nothing reached the bus, and the same bus still sends valid frames.
    assert receiver.recv(timeout=0.2) is None
    sender.send(can.Message(arbitration_id=0x101, data=bytes(8), is_extended_id=False))
    [got] = recv_all(receiver, window=2.0, limit=1)
    assert got.arbitration_id == 0x101


@pytest.mark.parametrize("length", [9, 15, 255])
def test_kernel_rejects_a_len_field_above_8(vcan_channel, length):
    """A well-sized struct can_frame whose len field says more than 8 bytes: EINVAL."""
    with raw_socket(vcan_channel) as sock, raw_socket(vcan_channel) as listener:
        with pytest.raises(OSError) as info:
            sock.send(encode(0x123, bytes(8), length=length))
        assert info.value.errno == errno.EINVAL
        sock.send(encode(0x124, bytes(8)))  # the socket is still usable
        assert len(listener.recv(128)) == CAN_FRAME.size


def test_fd_frame_on_a_classic_bus_is_refused(vcan_bus):
    classic = vcan_bus(fd=False)
    fd_msg = can.Message(arbitration_id=0x100, data=bytes(12), is_fd=True, is_extended_id=False)
    with pytest.raises(can.CanOperationError) as info:
        classic.send(fd_msg)
    assert info.value.error_code == errno.EINVAL


def test_unknown_interface_is_a_clear_error():
    with pytest.raises(OSError):
        can.Bus(interface="socketcan", channel="nosuchcan0")
