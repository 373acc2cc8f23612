"""Receive filters given to python-can are installed in the kernel (CAN_RAW_FILTER)."""

from __future__ import annotations

import can
import pytest
from can_frames import CAN_EFF_FLAG, CAN_EFF_MASK, CAN_RTR_FLAG, CAN_SFF_MASK, decode

# (identifier, extended) pairs that exercise both sides of every filter below.
TRAFFIC = [
    (0x0FF, False),
    (0x100, False),
    (0x105, False),
    (0x10F, False),
    (0x110, False),
    (0x105, True),
    (0x1234567, True),
    (0x1234500, True),
    (0x7FF, False),
]


def _kernel_rule(identifier: int, extended: bool, filters: list[dict]) -> bool:
    """The rule of linux/net/can/af_can.c, written out from its documentation:
    a frame passes when (frame_can_id & can_mask) == (filter_can_id & can_mask) for some filter,
    where frame_can_id carries CAN_EFF_FLAG for extended frames and python-can adds
    CAN_EFF_FLAG (and, for extended filters, to the id) to the mask when "extended" is given."""
    frame_id = identifier | (CAN_EFF_FLAG if extended else 0)
    for flt in filters:
        can_id, can_mask = flt["can_id"], flt["can_mask"]
        if "extended" in flt:
            can_mask |= CAN_EFF_FLAG
            if flt["extended"]:
                can_id |= CAN_EFF_FLAG
        if (frame_id & can_mask) == (can_id & can_mask):
            return True
    return False


def _send_traffic(bus: can.BusABC) -> None:
    for identifier, extended in TRAFFIC:
        bus.send(can.Message(arbitration_id=identifier, is_extended_id=extended, data=b"\x5a"))


def _socket_ids(bus: can.BusABC, expected: int) -> list[tuple[int, bool]]:
    """Read ``expected`` frames straight from the bus's kernel socket, bypassing python-can's
    software filtering (whatever arrives here was let through by the kernel), then check that
    no further frame follows."""
    got = []
    bus.socket.settimeout(5.0)
    for _ in range(expected):
        identifier, extended, _, _, _ = decode(bus.socket.recv(128))
        got.append((identifier, extended))
    bus.socket.settimeout(0.2)
    with pytest.raises(TimeoutError):
        bus.socket.recv(128)
    return got


def test_standard_id_range_filter_is_applied_by_the_kernel(vcan_bus):
    filters = [{"can_id": 0x100, "can_mask": 0x7F0, "extended": False}]
    sender, receiver = vcan_bus(), vcan_bus(can_filters=filters)
    expected = [(i, e) for i, e in TRAFFIC if _kernel_rule(i, e, filters)]
    assert expected == [(0x100, False), (0x105, False), (0x10F, False)]
    _send_traffic(sender)
    assert _socket_ids(receiver, len(expected)) == expected


def test_extended_exact_and_standard_filters_combine(vcan_bus):
    filters = [
        {"can_id": 0x1234567, "can_mask": CAN_EFF_MASK, "extended": True},
        {"can_id": 0x7FF, "can_mask": CAN_SFF_MASK, "extended": False},
    ]
    sender, receiver = vcan_bus(), vcan_bus(can_filters=filters)
    expected = [(i, e) for i, e in TRAFFIC if _kernel_rule(i, e, filters)]
    assert expected == [(0x1234567, True), (0x7FF, False)]
    _send_traffic(sender)
    assert _socket_ids(receiver, len(expected)) == expected


def test_filter_without_extended_key_matches_both_id_kinds(vcan_bus):
    # No "extended" key: the EFF bit is not in the mask, so 0x105 matches as standard and extended.
    filters = [{"can_id": 0x105, "can_mask": CAN_SFF_MASK}]
    sender, receiver = vcan_bus(), vcan_bus(can_filters=filters)
    expected = [(i, e) for i, e in TRAFFIC if _kernel_rule(i, e, filters)]
    assert expected == [(0x105, False), (0x105, True)]
    _send_traffic(sender)
    assert _socket_ids(receiver, len(expected)) == expected


def test_filters_can_be_replaced_at_run_time(vcan_bus):
    sender, receiver = vcan_bus(), vcan_bus(can_filters=[{"can_id": 0x0FF, "can_mask": 0x7FF}])
    new = [{"can_id": 0x110, "can_mask": 0x7FF, "extended": False}]
    receiver.set_filters(new)
    _send_traffic(sender)
    assert _socket_ids(receiver, 1) == [(0x110, False)]
    # None removes all filters: everything passes again.
    receiver.set_filters(None)
    _send_traffic(sender)
    assert _socket_ids(receiver, len(TRAFFIC)) == TRAFFIC


def test_rtr_flag_is_part_of_the_match(vcan_bus):
    # Mask includes CAN_RTR_FLAG with the flag clear in the id: remote frames are rejected.
    filters = [{"can_id": 0x200, "can_mask": CAN_SFF_MASK | CAN_RTR_FLAG | CAN_EFF_FLAG}]
    sender, receiver = vcan_bus(), vcan_bus(can_filters=filters)
    remote = can.Message(arbitration_id=0x200, is_remote_frame=True, dlc=2, is_extended_id=False)
    sender.send(remote)
    sender.send(can.Message(arbitration_id=0x200, data=b"\x01\x02", is_extended_id=False))
    assert _socket_ids(receiver, 1) == [(0x200, False)]
