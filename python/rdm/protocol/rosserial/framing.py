"""rosserial v2 frames: encoder and a sans-IO, resynchronising parser (fact sheet sec. 1.2).

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

import struct
from collections import Counter
from dataclasses import dataclass
from typing import Any

from rdm._rdm import rosserial_frame as _native_frame
from rdm._rdm import rosserial_scan as _native_scan
from rdm.protocol.rosserial.checksums import byte_sum
from rdm.protocol.rosserial.constants import FRAME_OVERHEAD, PROTOCOL_VERSION, SYNC

BAD_FRAME_REASONS = ("version", "length_checksum", "oversize", "message_checksum", "timeout")


class FrameError(ValueError):
    """A frame that cannot be built (topic id or payload length out of range)."""


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


_HEADER = struct.Struct("<BBHBH")  # FF FE len(u16) len_chk topic(u16)


_HEADERS: dict[tuple[int, int], bytes] = {}  # (topic id, length) -> header bytes already built
_HEADERS_MAX = 4096


def encode_frame(topic_id: int, payload: bytes) -> bytes:
    """Build one v2 frame."""
    if payload.__class__ is bytes:
        frame = _native_frame(topic_id, payload)  # one Rust call; None where it declines
        if frame is not None:
            return frame
        header = _HEADERS.get((topic_id, len(payload)))
        if header is not None:  # this topic id and length passed the checks below before
            chk = 255 - (((topic_id & 0xFF) + (topic_id >> 8) + byte_sum(payload)) % 256)
            return b"".join((header, payload, _CHECKSUM_BYTE[chk]))
    if not 0 <= topic_id <= 0xFFFF:
        raise FrameError(f"topic_id {topic_id} outside 0..65535")
    n = len(payload)
    if n > 0xFFFF:
        raise FrameError(f"payload of {n} bytes does not fit the uint16 length field")
    if payload.__class__ is not bytes:
        payload = bytes(payload)  # a bytearray, a list of ints ...
    # checksums as in checksums.py, inlined: this runs for every frame either end sends
    length_chk = 255 - (((n & 0xFF) + (n >> 8)) % 256)
    message_chk = 255 - (((topic_id & 0xFF) + (topic_id >> 8) + byte_sum(payload)) % 256)
    header = _HEADER.pack(SYNC, PROTOCOL_VERSION, n, length_chk, topic_id)
    if len(_HEADERS) >= _HEADERS_MAX:
        _HEADERS.clear()
    _HEADERS[(topic_id, n)] = header
    return b"".join((header, payload, _CHECKSUM_BYTE[message_chk]))


_CHECKSUM_BYTE = [bytes((i,)) for i in range(256)]


class FrameParser:
    """Incremental frame parser; feed it bytes in any chunking.

    ``max_payload``: largest accepted length field (512 on the Spinal client, 1022 on the
    rosserial_server side). ``frame_timeout``: None (no timeout) or the allowed time between a
    frame's 0xFF and its last byte, in the units of ``now``.
    """

    def __init__(
        self, max_payload: int, frame_timeout: float | None = None, rescan: bool = True
    ) -> None:
        self.max_payload = max_payload
        self.frame_timeout = frame_timeout
        self.rescan = rescan
        self.counts: Counter[str] = Counter()
        self.native = True  # the Rust scan; False: the Python loop
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
        max_payload = self.max_payload
        if not (self.native and max_payload.__class__ is int and max_payload >= 0):
            return self._feed_python(data, now, raw)
        # The scan runs in Rust (rdm_core::firmware::rosserial_frame); the frame timer, the
        # buffer, the counters and the event objects stay here, in the reference's order.
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
        items, pos, frames, clean, broke, reset = _native_scan(
            buf, pos, base, max_payload, self.rescan
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

    def _feed_python(self, data: bytes, now: float, raw: bool) -> list[Any]:
        """:meth:`_feed` without the Rust scanner: a ``max_payload`` that is not a
        non-negative int, or :attr:`native` set False."""
        started = self._started
        buf = self._buf
        # Sync, version, length and its checksum, size limit, message checksum, classified
        # as the Rust scan (rosserial_frame::next_candidate) does; the attributes in locals.
        events: list[ParseEvent] = []
        counts = self.counts
        base = self._base
        pos = 0
        if (
            started is not None
            and self.frame_timeout is not None
            and now - started > self.frame_timeout
        ):
            used = 1 if self.rescan else len(buf)
            events.append(BadFrame("timeout", base, bytes(buf)))
            counts["timeout"] += 1
            pos = used
            started = None
        buf += data
        end = len(buf)
        max_payload = self.max_payload
        while pos < end:
            if buf[pos] != 0xFF:  # SYNC
                nxt = buf.find(0xFF, pos)
                stop = end if nxt < 0 else nxt
                events.append(SkippedBytes(base + pos, bytes(buf[pos:stop])))
                counts["skipped_bytes"] += stop - pos
                pos = stop
                continue
            if started is None:
                started = now
            if end - pos < 2:
                break
            reason = ""
            used = 0
            if buf[pos + 1] != 0xFE:  # PROTOCOL_VERSION
                reason, used = "version", 2
            elif end - pos < 7:
                break
            else:
                lo, hi = buf[pos + 2], buf[pos + 3]
                n = lo | (hi << 8)
                if (lo + hi + buf[pos + 4]) % 256 != 255:
                    reason, used = "length_checksum", 5
                elif n > max_payload:
                    reason, used = "oversize", 5
                elif end - pos < n + 8:  # FRAME_OVERHEAD
                    break
                else:
                    used = n + 8
                    payload = bytes(buf[pos + 7 : pos + 7 + n])
                    lo, hi = buf[pos + 5], buf[pos + 6]  # topic id
                    if (lo + hi + byte_sum(payload) + buf[pos + 7 + n]) % 256 == 255:
                        if raw:
                            events.append((lo | (hi << 8), payload, base + pos))
                        else:
                            events.append(_new_frame(lo | (hi << 8), payload, base + pos))
                        counts["frames"] += 1
                    else:
                        reason = "message_checksum"
            if reason:
                events.append(BadFrame(reason, base + pos, bytes(buf[pos : pos + used])))
                counts[reason] += 1
                if self.rescan:
                    used = 1
            pos += used
            started = None
        del buf[:pos]
        self._base = base + pos
        self._started = started
        return events
