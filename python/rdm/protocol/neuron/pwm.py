"""Motor PWM broadcast frames (fact sheet sec. 2.4 "Motor PWM", sec. 3.6).

Six 10-bit values per 8-byte frame, packed LSB-first as one bit stream: value k occupies bits
``10*(k%3) + 32*(k//3)`` .. +9 of the little-endian payload (bits 30-31 and 62-63 stay 0).
A value is ``pulse_us - 1000`` in 0..1000. Frame 0 (message 0) carries slaves 1..6, frame 1
(message 1) slaves 7..12; Spinal puts the i-th Neuron (sorted by slave id) into slot i, so the
mapping is only consistent when slave ids run 1..N contiguously.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

from .base import NeuronFrame, check_dlc, check_int
from .errors import NeuronFrameError
from .ids import BROADCAST_ID, Device, Direction

PWM_VALUES_PER_FRAME = 6
PWM_MAX_MOTORS = 12
#: Spinal sends 0..1000 (pulse 1000..2000 us); the 10-bit field could hold up to 1023.
PWM_VALUE_MAX = 1000
#: Neuron watchdog value: after 100 ms without any frame the Neuron outputs v = 0 (1000 us).
PWM_STOP_VALUE = 0


def _bit_offset(slot: int) -> int:
    return 10 * (slot % 3) + 32 * (slot // 3)


@dataclass(frozen=True)
class PwmFrame(NeuronFrame):
    """One MOTOR broadcast frame: ``frame_index`` 0 (slaves 1-6) or 1 (slaves 7-12)."""

    frame_index: int
    values: tuple[int, ...]

    KIND: ClassVar[str] = "pwm"
    DIRECTION: ClassVar[Direction] = Direction.SPINAL_TO_NEURON
    DEVICE: ClassVar[int] = Device.MOTOR

    def __post_init__(self) -> None:
        check_int("frame_index", self.frame_index, 0, 1)
        if not isinstance(self.values, tuple) or len(self.values) != PWM_VALUES_PER_FRAME:
            raise NeuronFrameError(
                "range", f"values must be a tuple of 6 ints, got {self.values!r}"
            )
        for slot, value in enumerate(self.values):
            check_int(f"values[{slot}]", value, 0, PWM_VALUE_MAX)

    def _message_id(self) -> int:
        return self.frame_index

    def _slave_field(self) -> int:
        return BROADCAST_ID

    def encode(self) -> bytes:
        word = 0
        for slot, value in enumerate(self.values):
            word |= value << _bit_offset(slot)
        return word.to_bytes(8, "little")

    @classmethod
    def decode_payload(cls, frame_index: int, data: bytes) -> PwmFrame:
        check_dlc(cls.KIND, data, (8,))
        word = int.from_bytes(data, "little")
        if word & ((0b11 << 30) | (0b11 << 62)):
            raise NeuronFrameError("reserved_bits", "pwm: bits 30-31/62-63 must be zero")
        values = tuple((word >> _bit_offset(slot)) & 0x3FF for slot in range(6))
        return cls(frame_index, values)

    def pulse_us(self) -> tuple[int, ...]:
        """Pulse widths the Neurons output (v + 1000 us)."""
        return tuple(v + 1000 for v in self.values)


def duty_to_pwm_value(duty: float) -> int:
    """Spinal's ``(uint16_t)(duty * 2000 - 1000)``: duty 0.5 (idle, 1000 us) .. 1.0 (2000 us).

    The C cast truncates toward zero; duty outside [0.5, 1.0] or non-finite is rejected.
    """
    if not isinstance(duty, (int, float)) or not math.isfinite(duty) or not 0.5 <= duty <= 1.0:
        raise NeuronFrameError("range", f"duty={duty!r} not a finite value in 0.5..1.0")
    return int(duty * 2000.0 - 1000.0)


def pack_pwm(values: Sequence[int]) -> list[PwmFrame]:
    """Spinal's broadcast for N motors: motor i goes to slot i; a second frame when N > 6.

    Unused slots of the last frame are 0 (the Neuron stop value).
    """
    n = len(values)
    if not 1 <= n <= PWM_MAX_MOTORS:
        raise NeuronFrameError("range", f"motor count {n} not in 1..{PWM_MAX_MOTORS}")
    padded = [*values, *([PWM_STOP_VALUE] * (PWM_MAX_MOTORS - n))]
    frames = [PwmFrame(0, tuple(padded[:6]))]
    if n > PWM_VALUES_PER_FRAME:
        frames.append(PwmFrame(1, tuple(padded[6:])))
    return frames


def pwm_for_slave(frame: PwmFrame, slave: int) -> int | None:
    """What the Neuron with ``slave`` id reads from ``frame``, or None if the frame is not its.

    Slave s <= 6 reads slot s-1 (0-based) of frame 0; 7 <= s <= 12 reads slot s-7 of frame 1;
    slaves 13, 14 never receive a PWM value.
    """
    check_int("slave", slave, 1, 14)
    if slave <= 6:
        return frame.values[slave - 1] if frame.frame_index == 0 else None
    if slave <= 12:
        return frame.values[slave - 7] if frame.frame_index == 1 else None
    return None
