"""Servo frames (fact sheet sec. 2.4): Spinal's target angle / target current words and the
Neuron's per-servo state report."""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import ClassVar

from .base import NeuronFrame, check_bool, check_dlc, check_int
from .errors import NeuronFrameError
from .ids import MAX_SERVO_NUM, Device, Direction, ServoMessage, check_slave

#: 15-bit two's complement (sign bit = bit 14) carried in bits 14..0 of each word.
WORD_VALUE_MIN = -(1 << 14)
WORD_VALUE_MAX = (1 << 14) - 1


def pack_word(value: int, flag: bool) -> int:
    """``flag << 15 | value & 0x7FFF`` for a 15-bit signed value."""
    return (int(flag) << 15) | (value & 0x7FFF)


def unpack_word(word: int) -> tuple[int, bool]:
    """Sign-extend bits 14..0 (as the Neuron does) and return (value, bit 15)."""
    value = word & 0x7FFF
    if value & 0x4000:
        value -= 0x8000
    return value, bool(word & 0x8000)


@dataclass(frozen=True)
class _ServoWords(NeuronFrame):
    slave: int
    values: tuple[int, ...]
    flags: tuple[bool, ...]

    DEVICE: ClassVar[int] = Device.SERVO
    DIRECTION: ClassVar[Direction] = Direction.SPINAL_TO_NEURON
    MESSAGE: ClassVar[int]

    def __post_init__(self) -> None:
        check_slave(self.slave)
        if not isinstance(self.values, tuple) or not isinstance(self.flags, tuple):
            raise NeuronFrameError("range", f"{self.KIND}: values and flags must be tuples")
        if not 1 <= len(self.values) <= MAX_SERVO_NUM or len(self.flags) != len(self.values):
            raise NeuronFrameError(
                "range",
                f"{self.KIND}: need 1..{MAX_SERVO_NUM} values and as many flags, got "
                f"{len(self.values)} values, {len(self.flags)} flags",
            )
        for i, (value, flag) in enumerate(zip(self.values, self.flags, strict=True)):
            check_int(f"values[{i}]", value, WORD_VALUE_MIN, WORD_VALUE_MAX)
            check_bool(f"flags[{i}]", flag)

    def encode(self) -> bytes:
        words = [pack_word(v, f) for v, f in zip(self.values, self.flags, strict=True)]
        return struct.pack(f"<{len(words)}H", *words)

    @classmethod
    def decode_payload(cls, slave: int, data: bytes) -> _ServoWords:
        check_dlc(cls.KIND, data, (2, 4, 6, 8))
        words = struct.unpack(f"<{len(data) // 2}H", data)
        pairs = [unpack_word(w) for w in words]
        return cls(slave, tuple(p[0] for p in pairs), tuple(p[1] for p in pairs))


@dataclass(frozen=True)
class ServoTargetAngles(_ServoWords):
    """S->N message 0: per servo, goal position (``values``) and goal-position ack (``flags``)."""

    KIND: ClassVar[str] = "servo_target_angle"
    MESSAGE: ClassVar[int] = ServoMessage.TARGET_ANGLE


@dataclass(frozen=True)
class ServoTargetCurrents(_ServoWords):
    """S->N message 1: per servo, goal current (``values``) and torque enable (``flags``)."""

    KIND: ClassVar[str] = "servo_target_current"
    MESSAGE: ClassVar[int] = ServoMessage.TARGET_CURRENT


STATUS_FORCE_SERVO_OFF = 1 << 0
STATUS_MOVING = 1 << 1
STATUS_GOAL_REPORTED = 1 << 2


@dataclass(frozen=True)
class ServoState(NeuronFrame):
    """N->S, message id = servo ``index`` 0..3, DLC 8.

    ``angle`` is the present position, or the Neuron's goal when ``goal_reported`` (status
    bit 2) is set (goal-sync handshake). Byte 7 is struct padding: written 0, ignored on decode.
    """

    slave: int
    index: int
    angle: int
    temperature: int
    force_servo_off: bool
    moving: bool
    goal_reported: bool
    current: int
    servo_error: int

    KIND: ClassVar[str] = "servo_state"
    DIRECTION: ClassVar[Direction] = Direction.NEURON_TO_SPINAL
    DEVICE: ClassVar[int] = Device.SERVO

    def __post_init__(self) -> None:
        check_slave(self.slave)
        check_int("index", self.index, 0, MAX_SERVO_NUM - 1)
        check_int("angle", self.angle, -0x8000, 0x7FFF)
        check_int("temperature", self.temperature, 0, 0xFF)
        for name in ("force_servo_off", "moving", "goal_reported"):
            check_bool(name, getattr(self, name))
        check_int("current", self.current, -0x8000, 0x7FFF)
        check_int("servo_error", self.servo_error, 0, 0xFF)

    def _message_id(self) -> int:
        return self.index

    @property
    def status(self) -> int:
        return (
            STATUS_FORCE_SERVO_OFF * self.force_servo_off
            | STATUS_MOVING * self.moving
            | STATUS_GOAL_REPORTED * self.goal_reported
        )

    def encode(self) -> bytes:
        return struct.pack(
            "<hBBhBx", self.angle, self.temperature, self.status, self.current, self.servo_error
        )

    @classmethod
    def decode_payload(cls, slave: int, index: int, data: bytes) -> ServoState:
        check_dlc(cls.KIND, data, (8,))
        angle, temperature, status, current, servo_error = struct.unpack("<hBBhBx", data)
        if status & ~0b111:
            raise NeuronFrameError(
                "reserved_bits", f"servo_state: status 0x{status:02X} has bits other than 0..2"
            )
        return cls(
            slave,
            index,
            angle,
            temperature,
            bool(status & STATUS_FORCE_SERVO_OFF),
            bool(status & STATUS_MOVING),
            bool(status & STATUS_GOAL_REPORTED),
            current,
            servo_error,
        )
