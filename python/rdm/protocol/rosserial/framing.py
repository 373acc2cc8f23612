"""rosserial v2 frames: the encoder (``encode_frame``, in Rust) and a sans-IO,
resynchronising parser over the Rust scan (fact sheet sec. 1.2).

Frame: ``FF FE len_lo len_hi len_chk topic_lo topic_hi payload[len] msg_chk``.

The parser takes bytes plus the current time and returns events in stream order:
:class:`Frame` (both checksums good), :class:`BadFrame` (never delivered, counted per reason)
and :class:`SkippedBytes` (bytes outside any frame). Reasons: ``version`` (0xFF not followed by
0xFE), ``length_checksum``, ``oversize`` (length above the receiver's buffer), ``message_checksum``
and ``timeout`` (frame not complete within ``frame_timeout`` of its first 0xFF; checked, like the
firmware, when ``feed``/``poll`` is called, not per byte).

With ``rescan=True`` (default) the parser restarts the sync search at the byte after a rejected
frame's 0xFF, so a valid frame hidden behind garbage or a truncated frame is still found. With
``rescan=False`` it discards what it consumed, as the Spinal client state machine does.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import Any

from rdm._rdm import RosserialFrameError as FrameError
from rdm._rdm import rosserial_frame as encode_frame
from rdm._rdm import rosserial_scan as _scan
from rdm.protocol.rosserial.constants import FRAME_OVERHEAD

BAD_FRAME_REASONS = ("version", "length_checksum", "oversize", "message_checksum", "timeout")

__all__ = [
    "BAD_FRAME_REASONS",
    "BadFrame",
    "Frame",
    "FrameError",
    "FrameParser",
    "ParseEvent",
    "SkippedBytes",
    "encode_frame",
]


@dataclass(frozen=True)
class Frame:
    """A frame whose two checksums passed."""

    topic_id: int
    payload: bytes
    offset: int  # stream offset of its 0xFF

    @property
    def size(self) -> int:
        return len(self.payload) + FRAME_OVERHEAD


@dataclass(frozen=True)
class BadFrame:
    """A rejected frame candidate starting at ``offset``; ``data`` holds the bytes examined."""

    reason: str
    offset: int
    data: bytes


@dataclass(frozen=True)
class SkippedBytes:
    """Bytes outside any frame candidate (line noise, a capture starting mid-frame)."""

    offset: int
    data: bytes


ParseEvent = Frame | BadFrame | SkippedBytes


def _new_frame(topic_id: int, payload: bytes, offset: int) -> Frame:
    """``Frame(topic_id, payload, offset)`` without the frozen-dataclass ``__init__`` (which
    sets each field through ``object.__setattr__``); the parser makes one per good frame."""
    frame = object.__new__(Frame)
    fields = frame.__dict__
    fields["topic_id"] = topic_id
    fields["payload"] = payload
    fields["offset"] = offset
    return frame


class FrameParser:
    """Incremental frame parser; feed it bytes in any chunking.

    ``max_payload``: largest accepted length field, an ``int >= 0`` (512 on the Spinal
    client, 1022 on the rosserial_server side; :class:`FrameError` otherwise).
    ``frame_timeout``: None (no timeout) or the allowed time between a frame's 0xFF and its
    last byte, in the units of ``now``.
    """

    def __init__(
        self, max_payload: int, frame_timeout: float | None = None, rescan: bool = True
    ) -> None:
        _scan(bytearray(), 0, 0, max_payload, rescan)  # FrameError for a bad max_payload
        self.max_payload = max_payload
        self.frame_timeout = frame_timeout
        self.rescan = rescan
        self.counts: Counter[str] = Counter()
        self._buf = bytearray()
        self._base = 0  # stream offset of _buf[0]
        self._started: float | None = None  # time the current candidate's 0xFF was seen

    @property
    def in_frame(self) -> bool:
        """True while a frame candidate is partially received."""
        return self._started is not None

    @property
    def pending(self) -> tuple[int, bytes]:
        """Stream offset and bytes of the incomplete frame candidate (``b""`` if none)."""
        return self._base, bytes(self._buf)

    @property
    def bad_frames(self) -> int:
        return sum(self.counts[r] for r in BAD_FRAME_REASONS)

    def reset(self) -> None:
        """Forget buffered bytes (counters are kept)."""
        self._base += len(self._buf)
        self._buf.clear()
        self._started = None

    def poll(self, now: float = 0.0) -> list[ParseEvent]:
        """Apply the frame timeout at time ``now`` without new bytes."""
        return self.feed(b"", now)

    def feed(self, data: bytes, now: float = 0.0) -> list[ParseEvent]:
        """Consume ``data`` received at ``now``; return the events it completes."""
        return self._feed(data, now, False)

    def _feed(self, data: bytes, now: float, raw: bool) -> list[Any]:
        """:meth:`feed`; with ``raw`` good frames come as ``(topic_id, payload, offset)``
        tuples (the sessions' hot path, which builds a :class:`Frame` only when needed)."""
        started = self._started
        buf = self._buf
        if not data and started is None and not buf:
            return []  # idle: nothing buffered, no timer running, nothing new
        # The scan runs in Rust (rdm_core::firmware::rosserial_frame); the frame timer, the
        # buffer, the counters and the event objects stay here, in stream order.
        events: list[Any] = []
        counts = self.counts
        base = self._base
        pos = 0
        timeout = self.frame_timeout
        if started is not None and timeout is not None and now - started > timeout:
            pos = 1 if self.rescan else len(buf)
            events.append(BadFrame("timeout", base, bytes(buf)))
            counts["timeout"] += 1
            started = None
        buf += data
        items, pos, frames, clean, broke, reset = _scan(
            buf, pos, base, self.max_payload, self.rescan
        )
        if clean and not events:
            if frames:
                counts["frames"] += frames
            events = items if raw else [_new_frame(*item) for item in items]
        else:
            for item in items:
                kind = item[0]
                if kind.__class__ is not str:
                    events.append(item if raw else _new_frame(*item))
                    counts["frames"] += 1
                elif kind == "skip":
                    events.append(SkippedBytes(item[1], item[2]))
                    counts["skipped_bytes"] += len(item[2])
                else:
                    events.append(BadFrame(kind, item[1], item[2]))
                    counts[kind] += 1
        if broke:  # an incomplete candidate: its timer runs from its first 0xFF
            if reset or started is None:
                started = now
        elif reset:
            started = None
        del buf[:pos]
        self._base = base + pos
        self._started = started
        return events
