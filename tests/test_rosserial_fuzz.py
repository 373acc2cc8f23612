"""Random and corrupted byte streams never crash the parser, never yield a bad frame, and are
counted (hypothesis, thousands of examples)."""

from __future__ import annotations

import json
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rdm.protocol.rosserial.client import ClientSession
from rdm.protocol.rosserial.events import FrameRejected, MessageReceived
from rdm.protocol.rosserial.framing import BadFrame, Frame, FrameParser, SkippedBytes
from rdm.protocol.rosserial.server import ServerSession

SPINAL = Path(__file__).resolve().parents[1] / "firmware_protocol" / "spinal"
GOLDEN = json.loads((SPINAL / "golden_frames.json").read_text())
GOOD = [bytes.fromhex(v["hex"]) for v in GOLDEN["topics"]]
FUZZ = settings(max_examples=3000, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def checksums_pass(raw: bytes) -> bool:
    """Independent check of a delivered frame's bytes (sec. 1.2 acceptance rule)."""
    n = raw[2] | raw[3] << 8
    return (
        raw[0] == 0xFF
        and raw[1] == 0xFE
        and len(raw) == n + 8
        and (raw[2] + raw[3] + raw[4]) % 256 == 255
        and sum(raw[5:]) % 256 == 255
    )


def run_parser(stream: bytes, cuts: list[int], max_payload: int, rescan: bool):
    parser = FrameParser(max_payload, frame_timeout=20, rescan=rescan)
    events = []
    pos = 0
    for t, cut in enumerate([*sorted(c % (len(stream) + 1) for c in cuts), len(stream)]):
        events += parser.feed(stream[pos:cut], now=t * 7)
        pos = max(pos, cut)
    return parser, events


def check_invariants(stream: bytes, parser: FrameParser, events: list) -> None:
    for e in events:
        if isinstance(e, Frame):
            raw = stream[e.offset : e.offset + e.size]
            assert checksums_pass(raw)
            assert raw[7:-1] == e.payload
            assert len(e.payload) <= parser.max_payload
    rejected = [e for e in events if isinstance(e, BadFrame)]
    assert parser.bad_frames == len(rejected)
    for reason in ("version", "length_checksum", "oversize", "message_checksum", "timeout"):
        assert parser.counts[reason] == sum(e.reason == reason for e in rejected)
    assert parser.counts["frames"] == sum(isinstance(e, Frame) for e in events)
    assert parser.counts["skipped_bytes"] == sum(
        len(e.data) for e in events if isinstance(e, SkippedBytes)
    )


@FUZZ
@given(
    st.binary(max_size=600),
    st.lists(st.integers(0, 10_000), max_size=6),
    st.sampled_from([64, 512, 1022]),
    st.booleans(),
)
def test_random_bytes(stream, cuts, max_payload, rescan):
    parser, events = run_parser(stream, cuts, max_payload, rescan)
    check_invariants(stream, parser, events)


@st.composite
def corrupted_streams(draw):
    frames = draw(st.lists(st.sampled_from(GOOD), min_size=1, max_size=6))
    stream = bytearray(b"".join(frames))
    for _ in range(draw(st.integers(0, 8))):
        kind = draw(st.sampled_from(["flip", "drop", "insert", "ff"]))
        i = draw(st.integers(0, len(stream)))
        if kind == "flip" and i < len(stream):
            stream[i] ^= 1 << draw(st.integers(0, 7))
        elif kind == "drop" and i < len(stream):
            del stream[i : i + draw(st.integers(1, 12))]
        elif kind == "insert":
            stream[i:i] = draw(st.binary(min_size=1, max_size=12))
        else:
            stream[i:i] = b"\xff\xfe"
    return frames, bytes(stream)


@FUZZ
@given(corrupted_streams(), st.lists(st.integers(0, 10_000), max_size=4), st.booleans())
def test_corrupted_valid_streams(sample, cuts, rescan):
    _frames, stream = sample
    parser, events = run_parser(stream, cuts, 1022, rescan)
    check_invariants(stream, parser, events)


@settings(max_examples=500, deadline=None)
@given(st.lists(st.sampled_from(GOOD), min_size=1, max_size=5), st.binary(max_size=40))
def test_garbage_prefix_never_hides_a_frame_when_rescanning(frames, garbage):
    stream = garbage + b"".join(frames)
    events = FrameParser(1022).feed(stream)
    payloads = [e.payload for e in events if isinstance(e, Frame)]
    expected = [f[7:-1] for f in frames]
    # every original frame is found, in order, at the end (spurious ones may precede)
    assert payloads[len(payloads) - len(expected) :] == expected


@settings(max_examples=1500, deadline=None)
@given(st.binary(max_size=400), st.integers(0, 50_000))
def test_sessions_survive_random_input(stream, now_ms):
    client = ClientSession.from_layout()
    server = ServerSession()
    server.start(0.0)
    for ev in client.spin(stream, now_ms):
        if isinstance(ev, MessageReceived):
            assert ev.topic_id >= 100
    server_events = server.feed(stream, now_ms / 1000)
    assert sum(isinstance(e, FrameRejected) for e in server_events) == server.parser.bad_frames
    client.take_output()
    server.take_output()
