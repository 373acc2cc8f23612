"""Streaming decoder of a raw Leptrino capture: chunks in, records out, memory bounded.

:func:`iter_leptrino_records` reads a capture as a sequence of byte chunks (any chunking) and
yields, in stream order, the records of :func:`rdm.protocol.leptrino.decode_leptrino` with one
difference of form: a run of whole frames that each carry an OK continuous-output sample comes
as one :class:`ForceRun` (numpy columns) instead of one dict per frame. The run is found by the
Rust scan ``rdm._rdm.leptrino_ok_sample_run`` and split into frames with numpy (frames without
DLE stuffing, the usual case, have a fixed 25-byte stride) or the whole-frame expression;
everything else goes through :class:`~rdm.protocol.leptrino.LeptrinoStreamParser` byte by byte.
The parser passed in ends with the same state and counters as after one ``feed`` of the whole
capture, so its ``discarded_bytes`` counts the garbage between frames.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from rdm.protocol import leptrino as lep

#: Bytes of a frame holding an OK sample without any DLE stuffing (DLE STX, 20, DLE ETX BCC).
PLAIN_FRAME_LEN = 2 + lep.FORCE_PAYLOAD_LEN + 3
#: Largest piece handed to the Rust run scan at once (a run longer than this continues in the
#: next piece), so a flood of frame starts costs a bounded copy per start.
_WINDOW = 1 << 13
_START = b"\x10\x02"
#: Most frames in one :class:`ForceRun` (adjacent runs are joined up to this).
BATCH_FRAMES = 1 << 14
#: The stuffed payload of each whole frame, plain bytes taken in runs (a pass several times
#: faster than ``leptrino._WHOLE_FRAME``'s byte-at-a-time alternation); used only on a run of
#: frames the Rust scan has already checked, so it never backtracks far.
_STUFFED_PAYLOAD = re.compile(rb"\x10\x02((?:[^\x10]+|\x10\x10)*)\x10\x03.", re.S)
#: How an OK-sample frame begins: DLE STX and its length byte (20, never stuffed).
_SAMPLE_HEAD = bytes((lep.DLE, lep.STX, lep.FORCE_PAYLOAD_LEN))


@dataclass(frozen=True)
class ForceRun:
    """Consecutive OK force samples: ``offsets[k]`` is the stream offset of frame k's DLE and
    ``payloads[k]`` its unstuffed 20-byte payload (header, 6 int16 counts, int16 temperature,
    uint8 status, pad)."""

    offsets: npt.NDArray[np.int64]
    payloads: npt.NDArray[np.uint8]

    def __len__(self) -> int:
        return len(self.offsets)

    @property
    def raw(self) -> npt.NDArray[np.int16]:
        """Raw counts (fx, fy, fz, mx, my, mz), one row per frame."""
        return np.ascontiguousarray(self.payloads[:, 4:16]).view("<i2")

    @property
    def temperature(self) -> npt.NDArray[np.int16]:
        return np.ascontiguousarray(self.payloads[:, 16:18]).view("<i2")[:, 0]

    @property
    def status(self) -> npt.NDArray[np.uint8]:
        return self.payloads[:, 18]

    @property
    def result(self) -> npt.NDArray[np.uint8]:
        return self.payloads[:, 3]

    @property
    def term_no(self) -> npt.NDArray[np.uint8]:
        return self.payloads[:, 1]

    def records(self) -> Iterator[dict[str, Any]]:
        """The run as the dicts :func:`~rdm.protocol.leptrino.decode_leptrino` yields."""
        for off, payload in zip(self.offsets.tolist(), self.payloads, strict=True):
            data = payload.tobytes()
            obj = lep.parse_response(data)
            yield {
                "offset": off,
                "kind": "force_data",
                "ok": True,
                "error": None,
                "payload": data.hex(),
                **lep._fields(obj),
            }


def _split_run(data: bytes, start: int, end: int, count: int, base: int) -> ForceRun:
    """The ``count`` frames of an OK-sample run ``data[start:end]``; ``base`` is the stream
    offset of ``data[0]``."""
    if end - start == count * PLAIN_FRAME_LEN:  # no stuffing: a fixed stride
        frames = np.frombuffer(data, np.uint8, end - start, start).reshape(count, -1)
        payloads = frames[:, 2 : 2 + lep.FORCE_PAYLOAD_LEN].copy()
        offsets = base + start + PLAIN_FRAME_LEN * np.arange(count, dtype=np.int64)
        return ForceRun(offsets, payloads)
    # the stuffed payloads in one C-level pass; offsets from the frame lengths
    parts = _STUFFED_PAYLOAD.findall(data, start, end)
    if len(parts) != count:  # cannot happen on a run the scan accepted; the plain way then
        parts = [m.group(1) for m in lep._WHOLE_FRAME.finditer(data, start, end)]
    lengths = np.fromiter(map(len, parts), np.int64, len(parts)) + 5  # DLE STX .. DLE ETX BCC
    starts = np.empty(count, np.int64)
    starts[0] = 0
    np.cumsum(lengths[:-1], out=starts[1:])
    blob = b"".join(parts).replace(b"\x10\x10", b"\x10")
    payloads = np.frombuffer(blob, np.uint8).reshape(count, lep.FORCE_PAYLOAD_LEN).copy()
    return ForceRun(starts + (base + start), payloads)


def iter_leptrino_records(
    chunks: Iterable[bytes], *, parser: lep.LeptrinoStreamParser | None = None
) -> Iterator[dict[str, Any] | ForceRun]:
    """Yield the records of a sensor -> host capture given as ``chunks``: dicts as
    :func:`~rdm.protocol.leptrino.decode_leptrino` (frames it does not take in bulk, framing
    and payload errors) and :class:`ForceRun` batches, in stream order."""
    p = parser if parser is not None else lep.LeptrinoStreamParser()
    pending: list[ForceRun] = []  # runs not yet yielded, adjacent in the stream
    held = 0
    for item in _records(chunks, p):
        if item.__class__ is ForceRun:
            pending.append(item)
            held += len(item)
            if held < BATCH_FRAMES:
                continue
        if pending:
            yield _joined(pending)
            pending, held = [], 0
        if item.__class__ is not ForceRun:
            yield item
    if pending:
        yield _joined(pending)


def _joined(runs: list[ForceRun]) -> ForceRun:
    if len(runs) == 1:
        return runs[0]
    offsets = np.concatenate([r.offsets for r in runs])
    return ForceRun(offsets, np.concatenate([r.payloads for r in runs]))


def _records(
    chunks: Iterable[bytes], p: lep.LeptrinoStreamParser
) -> Iterator[dict[str, Any] | ForceRun]:
    """:func:`iter_leptrino_records` before runs are joined: one run per scan window."""
    run_scan = lep._ok_sample_run
    base = 0  # stream offset of the chunk's first byte
    for chunk in chunks:
        data = bytes(chunk)
        n = len(data)
        i = 0
        while i < n:
            if p._state is lep._State.IDLE and data.startswith(_SAMPLE_HEAD, i):
                end, count, _, _ = run_scan(data[i : i + _WINDOW])
                if count:
                    # the parser's state and counters as after feeding the run
                    p.feed_ok_samples(data[i : i + end])
                    yield _split_run(data, i, i + end, count, base)
                    i += end
                    continue
            # up to the next frame start (at least one byte) through the byte parser
            nxt = data.find(_START, i + 1)
            stop = n if nxt < 0 else nxt
            yield from lep.decode_leptrino(data[i:stop], parser=p)
            i = stop
        base += n
