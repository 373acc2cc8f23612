"""Neuron CAN frames (``rdm.protocol.neuron``): the counting stream decoder, and the
candump ``.log`` / Vector ``.asc`` log readers that feed it from files.

``neuron_can`` input: records ``flags id_lo id_hi data[n]`` where ``flags`` bits 0-3 are
``n`` (0..15: more than 8 exercises the DLC rule), bit 4 marks an extended id, bit 5 a
remote frame, bits 6-7 the decoder's direction (none, Spinal->Neuron, Neuron->Spinal,
none). Checks: an accepted frame has an 11-bit standard id, at most 8 bytes and re-encodes
to its id and bytes (byte 7 of a servo state is padding: written 0, ignored on decode);
every field is finite; the memoised decoder gives what the decoder gives; the decoder's
counters add up to the frames fed.

``candump_log`` / ``candump_asc`` input: the text of a log file. Checks: every output row
is valid JSON (``json.dumps(allow_nan=False)``) with finite numbers; a ``.log`` gives one
row per non-blank line, and an accepted row carries the id and bytes written on its line
(read here with a plain split, not the reader's pattern).
"""

from __future__ import annotations

import atexit
import json
import os
import shutil
import tempfile
from collections.abc import Iterable
from functools import cache
from pathlib import Path
from typing import Any

from fuzz_targets.base import NotCanonical, Target, WrongCount, all_finite
from rdm.protocol.neuron import (
    Direction,
    NeuronDecoder,
    NeuronFrameError,
    decode_candump,
    decode_frame,
    decode_frame_cached,
    encode_frame,
)
from rdm.protocol.neuron.servo import ServoState
from rdm.protocol.rosserial.registry import spinal_msgs_dir

VECTORS = spinal_msgs_dir().parent / "neuron" / "vectors.json"
DIRECTIONS = (None, Direction.SPINAL_TO_NEURON, Direction.NEURON_TO_SPINAL, None)


@cache
def _vectors() -> list[tuple[int, bytes, str]]:
    rows = json.loads(Path(VECTORS).read_text())["vectors"]
    return [(int(v["id"], 16), bytes.fromhex(v["data"]), v["direction"]) for v in rows]


def records(data: bytes) -> Iterable[tuple[int, bytes, bool, bool, Direction | None]]:
    """The frames an input stands for: ``(can_id, payload, extended, remote, direction)``."""
    pos = 0
    while pos + 3 <= len(data):
        flags = data[pos]
        n = flags & 0x0F
        can_id = data[pos + 1] | data[pos + 2] << 8
        yield (can_id, data[pos + 3 : pos + 3 + n], bool(flags & 0x10), bool(flags & 0x20),
               DIRECTIONS[flags >> 6])  # fmt: skip
        pos += 3 + n


def record(can_id: int, payload: bytes, direction: str | None = None) -> bytes:
    """The input record of one frame (the inverse of :func:`records`)."""
    d = {None: 0, "spinal_to_neuron": 1, "neuron_to_spinal": 2}[direction]
    return bytes([len(payload) | d << 6, can_id & 0xFF, can_id >> 8]) + payload


def _outcome(call: Any, *args: Any) -> Any:
    try:
        return call(*args)
    except NeuronFrameError as exc:
        return ("error", exc.reason)


def check_frames(data: bytes) -> None:
    """Feed every record to a :class:`NeuronDecoder` per direction."""
    decoders: dict[Direction | None, NeuronDecoder] = {}
    fed = 0
    for can_id, payload, extended, remote, direction in records(data):
        decoder = decoders.setdefault(direction, NeuronDecoder(direction=direction))
        res = decoder.feed(can_id, payload, extended=extended, remote=remote)
        fed += 1
        if not (extended or remote):
            plain = _outcome(decode_frame, can_id, payload, direction)
            if res.ok and plain != res.frame and plain != ("error", "ambiguous"):
                raise WrongCount(f"decoder gave {res.frame}, decode_frame {plain}")
            cached = _outcome(decode_frame_cached, can_id, payload, direction)
            if cached != plain:
                raise NotCanonical(f"0x{can_id:03X} {payload.hex()}: cached {cached} != {plain}")
        if not res.ok:
            continue
        for frame in (res.frame, *res.alternatives):
            if extended or remote or can_id > 0x7FF or len(payload) > 8:
                raise NotCanonical(f"accepted a frame that is no classic standard frame: {frame}")
            all_finite(frame.as_dict(), frame.KIND)
            got_id, got = encode_frame(frame)
            want = payload
            if isinstance(frame, ServoState):
                got, want = got[:7], payload[:7]
            if (got_id, got) != (can_id, want):
                raise NotCanonical(f"0x{can_id:03X} {payload.hex()} re-encodes as "
                                   f"0x{got_id:03X} {got.hex()} ({frame.KIND})")  # fmt: skip
    total = sum(sum(d.counts.values()) + sum(d.errors.values()) for d in decoders.values())
    if total != fed:
        raise WrongCount(f"{fed} frames fed, decoders counted {total}")


def frame_seeds() -> Iterable[bytes]:
    """Each golden frame alone (with and without its direction), then all of them."""
    vectors = _vectors()
    for can_id, payload, direction in vectors:
        yield record(can_id, payload)
        yield record(can_id, payload, direction)
    yield b"".join(record(i, p, d) for i, p, d in vectors)


# -- log files ---------------------------------------------------------------------------
_SCRATCH = Path(os.environ.get("RDM_FUZZ_SCRATCH") or tempfile.gettempdir())


@cache
def _scratch() -> Path:
    """A folder of this process for the files the log readers open (tmpfs when there is
    one: ``/dev/shm``)."""
    base = Path("/dev/shm") if Path("/dev/shm").is_dir() else _SCRATCH
    folder = Path(tempfile.mkdtemp(prefix="rdm-fuzz-", dir=base))
    atexit.register(shutil.rmtree, folder, True)
    return folder


def _rows(text: bytes, suffix: str) -> tuple[list[dict[str, Any]], NeuronDecoder]:
    path = _scratch() / f"input{suffix}"
    path.write_bytes(text)
    decoder = NeuronDecoder()
    return list(decode_candump(path, decoder=decoder)), decoder


def _check_rows(rows: list[dict[str, Any]], decoder: NeuronDecoder) -> None:
    for row in rows:
        json.dumps(row, allow_nan=False)  # ValueError: a NaN or infinity in the output
        all_finite(row, f"line {row.get('line')}")
    counted = sum(decoder.counts.values()) + sum(decoder.errors.values())
    if counted != len(rows):
        raise WrongCount(f"{len(rows)} rows, decoder counted {counted}")


def _line_frame(line: str) -> tuple[int, bytes]:
    """``(id, data)`` of a ``candump -L`` line, read with a plain split."""
    frame = line.split()[2]
    can_id, data = frame.split("#", 1)
    return int(can_id, 16), bytes.fromhex(data)


def check_log(data: bytes) -> None:
    """Read ``data`` as a ``candump -L`` file."""
    rows, decoder = _rows(data, ".log")
    _check_rows(rows, decoder)
    # the reader's lines: a text file in universal-newline mode (\n, \r\n and \r end one)
    text = data.decode("utf-8", "replace").replace("\r\n", "\n").replace("\r", "\n")
    lines = text.split("\n")
    nonblank = [k + 1 for k, line in enumerate(lines) if line.strip()]
    if [r["line"] for r in rows] != nonblank:
        raise WrongCount(f"rows for lines {[r['line'] for r in rows][:8]}, lines {nonblank[:8]}")
    for row in rows:
        if row["ok"]:
            can_id, payload = _line_frame(lines[row["line"] - 1])
            if (row["id"], row["data"]) != (can_id, payload.hex()):
                raise NotCanonical(f"line {row['line']}: row {row['id']:X}#{row['data']}")


def check_asc(data: bytes) -> None:
    """Read ``data`` as a Vector ASCII file."""
    rows, decoder = _rows(data, ".asc")
    _check_rows(rows, decoder)


def log_seeds() -> Iterable[bytes]:
    """The golden frames as ``candump -L`` lines, one file each and one of all."""
    lines = []
    for k, (can_id, payload, direction) in enumerate(_vectors()):
        end = " R" if direction == "neuron_to_spinal" else " T"
        line = f"(1700000000.{k:06d}) can0 {can_id:03X}#{payload.hex().upper()}{end}\n"
        lines.append(line)
        yield line.encode()
    yield "".join(lines).encode()
    yield b"(1700000000.000000) can0 12345678#00\n(1.5) can0 7FF#R\n(2) vcan0 123##1AB\n"


_ASC_HEAD = (
    "date Thu Jan 1 00:00:00.000 1970\nbase hex  timestamps absolute\n"
    "internal events logged\nBegin Triggerblock Thu Jan 1 00:00:00.000 1970\n"
    " 0.000000 Start of measurement\n"
)


def asc_seeds() -> Iterable[bytes]:
    """The golden frames as Vector ASCII (python-can's ``ASCWriter`` layout): each alone,
    all of them, an error frame and a remote frame."""
    lines = []
    for k, (can_id, payload, direction) in enumerate(_vectors()):
        rx = "Rx" if direction == "neuron_to_spinal" else "Tx"
        data = " ".join(f"{b:02X}" for b in payload)
        lines.append(f" {k / 1000:.6f} 1  {can_id:X}{' ' * 14}{rx}   d {len(payload)} {data}\n")
    tail = "End TriggerBlock\n"
    for line in lines:
        yield (_ASC_HEAD + line + tail).encode()
    yield (_ASC_HEAD + "".join(lines) + tail).encode()
    yield (_ASC_HEAD + " 0.002000 1  ErrorFrame\n 0.003000 1  105  Rx   r\n" + tail).encode()


TARGETS = [
    Target("neuron_can", check_frames, frame_seeds,
           about="rdm.protocol.neuron.NeuronDecoder.feed, decode_frame, decode_frame_cached"),
    Target("candump_log", check_log, log_seeds,
           about="rdm.protocol.neuron.decode_candump, candump -L .log text"),
    Target("candump_asc", check_asc, asc_seeds,
           about="rdm.protocol.neuron.decode_candump, Vector .asc text (python-can ASCReader)"),
]  # fmt: skip
