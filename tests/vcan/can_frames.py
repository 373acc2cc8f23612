"""Independent encoding of Linux ``struct can_frame`` / ``struct canfd_frame`` (linux/can.h).

Used to check python-can against the kernel's own byte layout with a plain stdlib
``AF_CAN`` socket, without going through python-can's packing code.
"""

from __future__ import annotations

import socket
import struct

CAN_EFF_FLAG = 0x80000000  # extended 29-bit identifier
CAN_RTR_FLAG = 0x40000000  # remote transmission request
CAN_ERR_FLAG = 0x20000000  # error frame
CAN_EFF_MASK = 0x1FFFFFFF
CAN_SFF_MASK = 0x000007FF
CAN_MTU = 16  # sizeof(struct can_frame)
CANFD_MTU = 72  # sizeof(struct canfd_frame)
CANFD_BRS = 0x01
CANFD_FDF = 0x04
# struct can_frame: canid_t can_id; __u8 len; __u8 __pad, __res0, len8_dlc; __u8 data[8]
CAN_FRAME = struct.Struct("=IB3x8s")
# struct canfd_frame: canid_t can_id; __u8 len, flags, __res0, __res1; __u8 data[64]
CANFD_FRAME = struct.Struct("=IBB2x64s")


def raw_socket(channel: str, fd: bool = False, timeout: float = 2.0) -> socket.socket:
    """A stdlib CAN_RAW socket bound to ``channel`` (optionally accepting CAN FD frames)."""
    sock = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    if fd:
        sock.setsockopt(socket.SOL_CAN_RAW, socket.CAN_RAW_FD_FRAMES, 1)
    sock.bind((channel,))
    sock.settimeout(timeout)
    return sock


def decode(frame: bytes) -> tuple[int, bool, bool, bytes, bool]:
    """(identifier, extended, remote, payload, fd) of one raw frame read from a CAN_RAW socket."""
    if len(frame) == CANFD_MTU:
        can_id, length, _flags, data = CANFD_FRAME.unpack(frame)
        fd = True
    elif len(frame) == CAN_MTU:
        can_id, length, data = CAN_FRAME.unpack(frame)
        fd = False
    else:
        raise ValueError(f"frame of {len(frame)} bytes is neither CAN_MTU nor CANFD_MTU")
    extended = bool(can_id & CAN_EFF_FLAG)
    identifier = can_id & (CAN_EFF_MASK if extended else CAN_SFF_MASK)
    return identifier, extended, bool(can_id & CAN_RTR_FLAG), data[:length], fd


def encode(
    identifier: int, payload: bytes, extended: bool = False, length: int | None = None
) -> bytes:
    """A classic ``struct can_frame``; ``length`` overrides the len field (to forge bad frames)."""
    can_id = identifier | (CAN_EFF_FLAG if extended else 0)
    return CAN_FRAME.pack(can_id, len(payload) if length is None else length, payload)
