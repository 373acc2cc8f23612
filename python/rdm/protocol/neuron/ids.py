"""CAN identifier layout of the Spinal <-> Neuron link (fact sheet sec. 2.2, 2.3).

``StdId = device << 8 | message << 4 | slave``: 3 device bits, 4 message bits, 4 slave bits.
There are no separate priority bits; a lower id wins arbitration, so MOTOR (device 0) frames
have the highest priority on the bus.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from .errors import NeuronFrameError

MASTER_ID = 0
BROADCAST_ID = 15
#: Valid Neuron slave ids read from flash (0 and > 14 are rewritten to 1 by the Neuron).
NEURON_SLAVE_IDS = range(1, 15)
#: A Neuron drives at most this many Dynamixel servos (``MAX_SERVO_NUM``).
MAX_SERVO_NUM = 4
MAX_STD_ID = 0x7FF


class Device(enum.IntEnum):
    """Device field (id bits 10..8)."""

    MOTOR = 0
    IMU = 1
    SERVO = 2
    CANFD_TEST = 6
    INITIALIZER = 7


class Direction(enum.Enum):
    """Who transmits a frame. Request and response frames can share one CAN id."""

    SPINAL_TO_NEURON = "spinal_to_neuron"
    NEURON_TO_SPINAL = "neuron_to_spinal"


class ImuMessage(enum.IntEnum):
    GYRO = 0
    ACC = 1
    MAG = 2


class ServoMessage(enum.IntEnum):
    """Spinal->Neuron meaning; Neuron->Spinal message id 0..3 is the servo index."""

    TARGET_ANGLE = 0
    TARGET_CURRENT = 1
    RECEIVE_SERVO_CONFIG_UNUSED = 15


class InitializerMessage(enum.IntEnum):
    """Message ids of device INITIALIZER (7)."""

    ENUM = 0  # ENUM_REQUEST (S->N, slave 15) / ENUM_RESPONSE (N->S)
    CONFIG_0 = 1  # INITIAL_CONFIG_REQUEST (S->N, DLC 0) / INITIAL_CONFIG_0 (N->S, DLC 5)
    CONFIG_1 = 2  # BOARD_CONFIG_REQUEST (S->N) / INITIAL_CONFIG_1 (N->S)
    CONFIG_2 = 3
    CONFIG_3 = 4


@dataclass(frozen=True)
class CanId:
    """A decomposed 11-bit Neuron CAN id."""

    device: int
    message: int
    slave: int

    def __post_init__(self) -> None:
        for name, value, top in (
            ("device", self.device, 7),
            ("message", self.message, 15),
            ("slave", self.slave, 15),
        ):
            if not isinstance(value, int) or not 0 <= value <= top:
                raise NeuronFrameError("range", f"id field {name}={value!r} not in 0..{top}")

    @property
    def value(self) -> int:
        """The 11-bit standard identifier."""
        return make_id(self.device, self.message, self.slave)

    @classmethod
    def split(cls, can_id: int) -> CanId:
        """Split an 11-bit identifier into device, message and slave fields."""
        if not isinstance(can_id, int) or not 0 <= can_id <= MAX_STD_ID:
            raise NeuronFrameError(
                "not_standard_id", f"CAN id {can_id!r} is not an 11-bit standard id"
            )
        return cls((can_id >> 8) & 0x7, (can_id >> 4) & 0xF, can_id & 0xF)

    def __repr__(self) -> str:
        return (
            f"CanId(0x{self.value:03X}: device={self.device}, message={self.message}, "
            f"slave={self.slave})"
        )


def make_id(device: int, message: int, slave: int) -> int:
    """``device << 8 | message << 4 | slave`` with range checks."""
    for name, value, top in (("device", device, 7), ("message", message, 15), ("slave", slave, 15)):
        if not isinstance(value, int) or not 0 <= value <= top:
            raise NeuronFrameError("range", f"id field {name}={value!r} not in 0..{top}")
    return (device << 8) | (message << 4) | slave


def check_slave(slave: int) -> None:
    """A Neuron's own slave id must be 1..14."""
    if not isinstance(slave, int) or isinstance(slave, bool) or slave not in NEURON_SLAVE_IDS:
        raise NeuronFrameError("range", f"slave={slave!r} not a Neuron slave id 1..14")
