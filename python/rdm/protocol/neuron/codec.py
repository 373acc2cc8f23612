"""Classify and decode raw Neuron CAN frames, with counting.

Several request and response frames share one CAN id (fact sheet sec. 2.2): only the direction
and the DLC tell them apart. :func:`decode_candidates` returns every valid interpretation;
:func:`decode_frame` demands exactly one (pass ``direction`` to resolve the rest).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from .base import NeuronFrame
from .errors import NeuronFrameError
from .ids import BROADCAST_ID, MAX_SERVO_NUM, CanId, Device, Direction, InitializerMessage
from .imu import ImuFrame
from .initializer import (
    BOARD_CONFIG_CLASSES,
    EnumRequest,
    EnumResponse,
    InitialConfig0,
    InitialConfig1,
    InitialConfig2,
    InitialConfig3,
    InitialConfigRequest,
)
from .pwm import PwmFrame
from .servo import ServoState, ServoTargetAngles, ServoTargetCurrents


def _need_slave(cid: CanId) -> None:
    if not 1 <= cid.slave <= 14:
        raise NeuronFrameError(
            "unknown_id", f"id 0x{cid.value:03X}: slave field {cid.slave} is not a Neuron id 1..14"
        )


def _unknown(can_id: int) -> NeuronFrameError:
    return NeuronFrameError(
        "unknown_id",
        f"id 0x{can_id:03X} (device {can_id >> 8}, message {(can_id >> 4) & 15}, "
        f"slave {can_id & 15}) is not a Neuron frame",
    )


def _attempts(cid: CanId, data: bytes) -> list[Callable[[], NeuronFrame]]:
    """Every decoder that could apply to this id; each raises on mismatch."""
    dev, msg, slave = cid.device, cid.message, cid.slave
    can_id = (dev << 8) | (msg << 4) | slave
    if dev == Device.MOTOR:
        if msg in (0, 1) and slave == BROADCAST_ID:
            return [lambda: PwmFrame.decode_payload(msg, data)]
        raise _unknown(can_id)
    if dev == Device.IMU:
        if msg > 2:
            raise _unknown(can_id)
        _need_slave(cid)
        return [lambda: ImuFrame.decode_payload(slave, msg, data)]
    if dev == Device.SERVO:
        if msg >= MAX_SERVO_NUM:
            raise _unknown(can_id)
        _need_slave(cid)
        out: list[Callable[[], NeuronFrame]] = [lambda: ServoState.decode_payload(slave, msg, data)]
        if msg == 0:
            out.append(lambda: ServoTargetAngles.decode_payload(slave, data))
        elif msg == 1:
            out.append(lambda: ServoTargetCurrents.decode_payload(slave, data))
        return out
    if dev == Device.INITIALIZER:
        if msg == InitializerMessage.ENUM:
            if slave == BROADCAST_ID:
                return [lambda: EnumRequest.decode_payload(data)]
            _need_slave(cid)
            return [lambda: EnumResponse.decode_payload(slave, data)]
        _need_slave(cid)
        if msg == InitializerMessage.CONFIG_0:
            return [
                lambda: InitialConfigRequest.decode_payload(slave, data),
                lambda: InitialConfig0.decode_payload(slave, data),
            ]
        if msg == InitializerMessage.CONFIG_1:
            out = [lambda: InitialConfig1.decode_payload(slave, data)]
            if data and data[0] in BOARD_CONFIG_CLASSES:
                board = BOARD_CONFIG_CLASSES[data[0]]
                out.append(lambda: board.decode_payload(slave, data))
            elif not data or len(data) != 8:
                raise NeuronFrameError(
                    "range",
                    f"id 0x{cid.value:03X}: board-config sub-command "
                    f"{data[0] if data else None!r} unknown and DLC {len(data)} != 8",
                )
            return out
        if msg == InitializerMessage.CONFIG_2:
            return [lambda: InitialConfig2.decode_payload(slave, data)]
        if msg == InitializerMessage.CONFIG_3:
            return [lambda: InitialConfig3.decode_payload(slave, data)]
        raise _unknown(can_id)
    raise _unknown(can_id)


def decode_candidates(
    can_id: int, data: bytes | bytearray, direction: Direction | None = None
) -> list[NeuronFrame]:
    """All valid interpretations of one frame (optionally only those sent in ``direction``).

    Raises :class:`NeuronFrameError` with the most telling reason when none is valid.
    """
    data = bytes(data)
    if len(data) > 8:
        raise NeuronFrameError("dlc", f"DLC {len(data)} > 8: Neuron frames are classic CAN")
    cid = CanId.split(can_id)
    found: list[NeuronFrame] = []
    errors: list[NeuronFrameError] = []
    for attempt in _attempts(cid, data):
        try:
            frame = attempt()
        except NeuronFrameError as exc:
            errors.append(exc)
            continue
        if direction is None or direction == frame.DIRECTION:
            found.append(frame)
        else:
            errors.append(
                NeuronFrameError(
                    "direction",
                    f"{frame.KIND} is sent {frame.DIRECTION.value}, not {direction.value}",
                )
            )
    if found:
        return found
    # The most telling complaint first: a field error of a candidate whose DLC fitted, then
    # a DLC mismatch, and a direction mismatch last.
    errors.sort(key=lambda e: {"dlc": 1, "direction": 2}.get(e.reason, 0))
    raise errors[0]


def decode_frame(
    can_id: int, data: bytes | bytearray, direction: Direction | None = None
) -> NeuronFrame:
    """Decode one frame to its typed dataclass; ambiguous frames need ``direction``."""
    found = decode_candidates(can_id, data, direction)
    if len(found) > 1:
        kinds = ", ".join(f.KIND for f in found)
        raise NeuronFrameError(
            "ambiguous", f"id 0x{can_id:03X} DLC {len(data)} is one of: {kinds}; pass direction"
        )
    return found[0]


def encode_frame(frame: NeuronFrame) -> tuple[int, bytes]:
    """``(can_id, payload)`` of a frame dataclass."""
    return frame.can_id, frame.encode()


@dataclass
class DecodeResult:
    """Outcome of :meth:`NeuronDecoder.feed`: ``frame`` or ``error``; ``alternatives`` lists
    the other valid interpretations when the frame was ambiguous."""

    can_id: int
    data: bytes
    frame: NeuronFrame | None = None
    error: NeuronFrameError | None = None
    alternatives: tuple[NeuronFrame, ...] = ()

    @property
    def ok(self) -> bool:
        return self.frame is not None


@dataclass
class NeuronDecoder:
    """Stateful, counting decoder for a stream of frames (a bus capture or live bus).

    Ambiguities are resolved by ``direction`` if given, else by the servo counts learned from
    INITIAL_CONFIG_0 (a target frame has DLC 2*servo_num, a servo index is below servo_num),
    else in favour of the
    Neuron->Spinal reading (which is then flagged through ``alternatives``).
    """

    direction: Direction | None = None
    counts: Counter = field(default_factory=Counter)
    errors: Counter = field(default_factory=Counter)
    ambiguous: int = 0
    servo_num: dict[int, int] = field(default_factory=dict)

    def feed(
        self, can_id: int, data: bytes | bytearray, *, extended: bool = False, remote: bool = False
    ) -> DecodeResult:
        data = bytes(data)
        try:
            if extended:
                raise NeuronFrameError("not_standard_id", f"extended id 0x{can_id:X}")
            if remote:
                raise NeuronFrameError("remote", "remote frames are rejected by every board")
            found = decode_candidates(can_id, data, self.direction)
        except NeuronFrameError as exc:
            self.errors[exc.reason] += 1
            return DecodeResult(can_id, data, error=exc)
        if len(found) > 1:
            found = self._resolve(found)
        frame, rest = found[0], tuple(found[1:])
        if rest:
            self.ambiguous += 1
        if isinstance(frame, InitialConfig0):
            self.servo_num[frame.slave] = frame.servo_num
        self.counts[frame.KIND] += 1
        return DecodeResult(can_id, data, frame=frame, alternatives=rest)

    def _resolve(self, found: list[NeuronFrame]) -> list[NeuronFrame]:
        def plausible(f: NeuronFrame) -> bool:
            n = self.servo_num.get(f.slave)  # type: ignore[attr-defined]
            if n is None:
                return True
            if isinstance(f, (ServoTargetAngles, ServoTargetCurrents)):
                return n == len(f.values)
            if isinstance(f, (ServoState, InitialConfig1, InitialConfig2, InitialConfig3)):
                return f.index < n
            return True

        kept = [f for f in found if plausible(f)] or found
        kept.sort(key=lambda f: f.DIRECTION != Direction.NEURON_TO_SPINAL)
        return kept

    @property
    def total_errors(self) -> int:
        return sum(self.errors.values())
