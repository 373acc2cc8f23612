"""Leptrino F/T sensor stream (``rdm.protocol.leptrino``): the de-framer in both of its
entry points (``feed`` and the Rust-assisted ``feed_ok_samples``), and the payload
parsers of both roles (``parse_response`` for sensor replies, ``parse_command`` for host
commands), as ``decode_leptrino`` runs them.

Input: the bytes read from the port, read in pieces (:func:`base.chunks`).

Checks: every payload the de-framer delivers is found in the input as a whole frame
written by the harness's own encoder from the framing notes (DLE stuffing, BCC =
XOR ^ ETX), at the offset it reports: no frame with a bad BCC is ever accepted; both entry
points deliver the same payloads and counts; a parsed response or command re-encodes to
its frame (``encode_response`` / ``CommandFrame.encode``, canonical for every type but
the zero-padded product-info strings, and commands but their
reserved bytes); a force sample's wrench is finite (int16 counts
times the rated values); only the rated values (float32 on the wire) may be NaN.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from functools import cache
from pathlib import Path

from fuzz_targets.base import (
    BadFrameAccepted,
    NotCanonical,
    Target,
    WrongCount,
    all_finite,
    chunks,
    leptrino_frame,
)
from rdm.protocol.leptrino import (
    MODELS,
    ForceData,
    LeptrinoError,
    LeptrinoStreamParser,
    ProductInfo,
    RatedValues,
    encode_response,
    parse_command,
    parse_response,
)
from rdm.protocol.rosserial.registry import spinal_msgs_dir

VECTORS = spinal_msgs_dir().parent / "leptrino" / "vectors.json"


def _deframe(data: bytes, ok_samples: bool) -> tuple[list[tuple[int, bytes]], LeptrinoStreamParser]:
    parser = LeptrinoStreamParser()
    got: list[tuple[int, bytes]] = []
    for piece in chunks(data):
        if ok_samples:
            count, last, events = parser.feed_ok_samples(piece)
            if count:
                got.append((-count, last or b""))  # a run: its count and newest payload
        else:
            events = parser.feed(piece)
        got.extend((e.offset, e.payload) for e in events if e.payload is not None)
    return got, parser


def check(data: bytes) -> None:
    """De-frame ``data`` both ways and parse every payload in both roles."""
    plain, parser = _deframe(data, ok_samples=False)
    for offset, payload in plain:
        frame = leptrino_frame(payload)
        if data[offset : offset + len(frame)] != frame:
            raise BadFrameAccepted(f"payload {payload.hex()} at {offset} is no whole good frame")
        _check_payload(payload)
    fast, fast_parser = _deframe(data, ok_samples=True)
    # a run in the fast path stands for that many OK samples of the plain path
    expanded: list[bytes] = []
    for offset, payload in fast:
        expanded.extend([payload] * -offset if offset < 0 else [payload])
    runs_ok = [p for _, p in plain]
    if len(expanded) != len(runs_ok) or (expanded and expanded[-1] != runs_ok[-1]):
        raise WrongCount(f"feed_ok_samples delivered {len(expanded)}, feed {len(runs_ok)}")
    if (fast_parser.frames, fast_parser.errors, fast_parser.discarded_bytes) != (
        parser.frames, parser.errors, parser.discarded_bytes
    ):  # fmt: skip
        raise WrongCount(
            f"feed_ok_samples counts {fast_parser.frames} {dict(fast_parser.errors)} "
            f"{fast_parser.discarded_bytes}, feed {parser.frames} {dict(parser.errors)} "
            f"{parser.discarded_bytes}"
        )


def _check_payload(payload: bytes) -> None:
    try:
        resp = parse_response(payload)
    except LeptrinoError:
        resp = None
    if resp is not None:
        if not isinstance(resp, RatedValues):
            all_finite(resp, type(resp).__name__)
        if isinstance(resp, ForceData):
            all_finite(resp.wrench(MODELS["CFS034CA301U"]), "wrench")
        finite_limits = not isinstance(resp, RatedValues) or all(
            v == v and abs(v) != float("inf") for v in resp.limits
        )
        if finite_limits and not isinstance(resp, ProductInfo):
            again = encode_response(resp)
            # ASSUMPTION: reserved bytes are ignored (bytes 5-7 of a GET_DF answer, the
            # last byte of a sample), as the driver does; the rest must re-encode exactly.
            reserved = {8: (5, 6, 7), 20: (19,)}.get(len(payload), ()) if len(payload) > 4 else ()
            masked = bytes(0 if k in reserved else b for k, b in enumerate(payload))
            if again != leptrino_frame(masked):
                raise NotCanonical(f"response {payload.hex()} re-encodes as {again.hex()}")
    try:
        cmd = parse_command(payload)
    except LeptrinoError:
        return
    # ASSUMPTION: the reserved bytes of a command (byte 3; bytes 5-7 of SET_DF) are
    # ignored, as the sensor does; the rest must re-encode exactly.
    reserved = (3, 5, 6, 7) if len(payload) == 8 else (3,)
    masked = bytes(0 if k in reserved else b for k, b in enumerate(payload))
    if cmd.encode() != leptrino_frame(masked):
        raise NotCanonical(f"command {payload.hex()} re-encodes as {cmd.encode().hex()}")


@cache
def _vectors() -> list[bytes]:
    rows = json.loads(Path(VECTORS).read_text())["vectors"]
    return [bytes.fromhex(v["frame"]) for v in rows]


def seeds() -> Iterable[bytes]:
    """Each golden frame, all of them, and a run of samples cut by garbage."""
    frames = _vectors()
    yield from frames
    yield b"".join(frames)
    samples = [f for f in frames if len(f) > 20]
    yield b"".join(samples * 3) + b"\x10\x02\x14" + b"".join(samples)


TARGETS = [
    Target("leptrino_stream", check, seeds,
           about="rdm.protocol.leptrino: LeptrinoStreamParser.feed / feed_ok_samples, "
                 "parse_response, parse_command"),
]  # fmt: skip
