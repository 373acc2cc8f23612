"""Memoised decode / encode of Neuron frames for the lockstep simulation.

On the simulated bus the same few payloads repeat thousands of times (a PWM broadcast is read
by every Neuron; goals and servo states change slowly), and building a validated frame
dataclass costs far more than a dictionary look-up. These helpers run the real codec the first
time a payload (or field tuple) is seen and return the same result afterwards:

* :func:`decode_frame_cached` = :func:`rdm.protocol.neuron.decode_frame` for valid frames
  (frames are frozen dataclasses, so sharing one instance is safe); invalid frames are not
  cached and raise exactly as the codec does;
* the ``encode_*_cached`` functions return ``(can_id, payload)`` exactly as
  ``Frame(...).can_id, Frame(...).encode()`` does, including its range checks on a miss.

Each cache is bounded (cleared when full), so memory stays flat over long runs.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

from .base import NeuronFrame
from .codec import decode_frame
from .ids import Direction
from .pwm import pack_pwm
from .servo import ServoState, ServoTargetAngles, ServoTargetCurrents

#: Entries per cache before it is cleared.
CACHE_LIMIT = 4096

_decoded: dict[tuple[int, bytes, Direction | None], NeuronFrame] = {}
_states: dict[tuple, tuple[int, bytes]] = {}
_pwm: dict[tuple[int, ...], list[tuple[int, bytes]]] = {}
_words: dict[tuple, tuple[int, bytes]] = {}


def _remember(cache: dict, key: object, value: object) -> None:
    if len(cache) >= CACHE_LIMIT:
        cache.clear()
    cache[key] = value


def decode_frame_cached(
    can_id: int, data: bytes, direction: Direction | None = None
) -> NeuronFrame:
    """:func:`decode_frame` with memoisation of valid frames (``data`` must be ``bytes``)."""
    key = (can_id, data, direction)
    frame = _decoded.get(key)
    if frame is None:
        frame = _decode_servo_state(can_id, data) if direction is _N2S else None
        if frame is None:
            frame = decode_frame(can_id, data, direction)
        _remember(_decoded, key, frame)
    return frame


_N2S = Direction.NEURON_TO_SPINAL


def _decode_servo_state(can_id: int, data: bytes) -> NeuronFrame | None:
    """The only Neuron->Spinal reading of a SERVO id (message = servo index 0..3, slave
    1..14, DLC 8) is a ServoState: decode it directly (the codec would also try the
    Spinal->Neuron target frames sharing ids 0 and 1 and drop them for their direction).
    None when it does not apply or fails: the codec then gives its own answer or error."""
    if not (0x200 <= can_id <= 0x23F and len(data) == 8 and 1 <= (can_id & 0xF) <= 14):
        return None
    angle, temperature, status, current, servo_error = _SERVO_STATE.unpack(data)
    if status & ~0b111:
        return None  # reserved bits: the codec reports it
    # Every field is in range by construction (slave 1..14 and index 0..3 from the id test,
    # the rest from the struct codes), so ServoState's own checks could not fail: build the
    # frozen instance without re-running them (same fields, same equality and hash).
    frame = _new_servo_state(ServoState)
    frame.__dict__.update(
        slave=can_id & 0xF,
        index=(can_id >> 4) & 0xF,
        angle=angle,
        temperature=temperature,
        force_servo_off=bool(status & 1),
        moving=bool(status & 2),
        goal_reported=bool(status & 4),
        current=current,
        servo_error=servo_error,
    )
    return frame


_SERVO_STATE = struct.Struct("<hBBhBx")
_new_servo_state = object.__new__


def encode_servo_state_cached(
    slave: int,
    index: int,
    angle: int,
    temperature: int,
    moving: bool,
    goal_reported: bool,
    current: int,
    servo_error: int,
    force_servo_off: bool = False,
) -> tuple[int, bytes]:
    """``(can_id, payload)`` of a :class:`ServoState` with these fields."""
    key = (slave, index, angle, temperature, moving, goal_reported, current, servo_error,
           force_servo_off)  # fmt: skip
    out = _states.get(key)
    if out is None:
        frame = ServoState(
            slave=slave,
            index=index,
            angle=angle,
            temperature=temperature,
            force_servo_off=force_servo_off,
            moving=moving,
            goal_reported=goal_reported,
            current=current,
            servo_error=servo_error,
        )
        out = (frame.can_id, frame.encode())
        _remember(_states, key, out)
    return out


def encode_pwm_cached(values: Sequence[int]) -> list[tuple[int, bytes]]:
    """``(can_id, payload)`` of every frame :func:`pack_pwm` makes for ``values``."""
    key = tuple(values)
    out = _pwm.get(key)
    if out is None:
        out = [(f.can_id, f.encode()) for f in pack_pwm(list(key))]
        _remember(_pwm, key, out)
    return out


def encode_servo_words_cached(
    current: bool, slave: int, values: tuple[int, ...], flags: tuple[bool, ...]
) -> tuple[int, bytes]:
    """``(can_id, payload)`` of a :class:`ServoTargetCurrents` (``current``) or
    :class:`ServoTargetAngles` frame."""
    key = (current, slave, values, flags)
    out = _words.get(key)
    if out is None:
        cls = ServoTargetCurrents if current else ServoTargetAngles
        frame = cls(slave, values, flags)
        out = (frame.can_id, frame.encode())
        _remember(_words, key, out)
    return out
