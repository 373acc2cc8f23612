"""Leptrino F/T sensor protocol: framing, BCC, golden frames, stream robustness, conversion."""

from __future__ import annotations

import json
import math
from functools import reduce
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rdm.protocol import leptrino as lp

VECTORS = json.loads(
    (Path(__file__).resolve().parents[1] / "firmware_protocol/leptrino/vectors.json").read_text()
)["vectors"]
HOST = [v for v in VECTORS if v["role"] == "host"]
SENSOR = [v for v in VECTORS if v["role"] == "sensor"]


def _independent_frame(payload: bytes) -> bytes:
    """DLE STX, payload with 0x10 doubled, DLE ETX, XOR(payload, ETX) unstuffed."""
    body = b"".join(b"\x10\x10" if b == 0x10 else bytes([b]) for b in payload)
    check = reduce(lambda a, b: a ^ b, payload, 0x03)
    return b"\x10\x02" + body + b"\x10\x03" + bytes([check])


@pytest.mark.parametrize("v", VECTORS, ids=[v["name"] for v in VECTORS])
def test_golden_frame_roundtrip(v):
    payload, wire = bytes.fromhex(v["payload"]), bytes.fromhex(v["frame"])
    assert lp.frame(payload) == wire
    events = lp.LeptrinoStreamParser().feed(wire)
    assert [(e.offset, e.payload, e.error) for e in events] == [(0, payload, None)]
    (decoded,) = lp.decode_leptrino(wire, from_sensor=v["role"] == "sensor")
    assert decoded["ok"] and decoded["kind"] == v["kind"] and decoded["offset"] == 0
    for key, value in v["fields"].items():
        assert decoded[key] == value, key
    if v["role"] == "host":
        assert lp.parse_command(payload).encode() == wire
    else:
        assert lp.encode_response(lp.parse_response(payload)) == wire


def test_command_helpers_match_golden_frames():
    by_name = {v["name"]: bytes.fromhex(v["frame"]) for v in HOST}
    assert lp.get_product_info() == by_name["get_product_info"]
    assert lp.get_rated_values() == by_name["get_rated_values"]
    assert lp.start_continuous_output() == by_name["start_continuous"]
    assert lp.stop_continuous_output() == by_name["stop_continuous"]
    assert lp.get_digital_filter() == by_name["get_digital_filter"]
    assert lp.set_digital_filter(16) == by_name["set_digital_filter"]


def test_bcc_equal_to_dle_is_sent_raw():
    v = next(v for v in VECTORS if v["name"] == "force_data_bcc_is_dle")
    wire = bytes.fromhex(v["frame"])
    assert wire[-3:] == b"\x10\x03\x10"
    assert lp.bcc(bytes.fromhex(v["payload"])) == 0x10


@settings(max_examples=1000, deadline=None)
@given(st.binary(min_size=1, max_size=lp.MAX_PAYLOAD))
def test_stuffing_roundtrip_and_bcc(payload):
    wire = lp.frame(payload)
    assert wire == _independent_frame(payload)
    events = lp.LeptrinoStreamParser().feed(wire)
    assert [e.payload for e in events] == [payload]


def _check_events_against_input(data: bytes, parser: lp.LeptrinoStreamParser, events):
    ok = [e for e in events if e.error is None]
    for e in ok:
        # a delivered frame is exactly a well-formed frame (correct BCC) present in the input
        wire = _independent_frame(e.payload)
        assert data[e.offset : e.offset + len(wire)] == wire
    assert parser.frames == len(ok)
    assert parser.total_errors == len(events) - len(ok)


@settings(max_examples=3000, deadline=None)
@given(st.binary(max_size=400))
def test_random_streams_never_crash_nor_deliver_bad_frames(data):
    parser = lp.LeptrinoStreamParser()
    events = parser.feed(data)
    _check_events_against_input(data, parser, events)
    list(lp.decode_leptrino(data))  # typed decoding of whatever came out never raises


@settings(max_examples=1000, deadline=None)
@given(st.binary(max_size=60), st.binary(min_size=1, max_size=40), st.data())
def test_resync_after_garbage_and_corruption(garbage, payload, data):
    wire = lp.frame(payload)
    stream = bytearray(garbage + wire * 3)
    flips = data.draw(st.lists(st.integers(0, len(garbage) - 1), max_size=3)) if garbage else []
    for i in flips:
        stream[i] ^= 0xFF
    parser = lp.LeptrinoStreamParser()
    events = parser.feed(bytes(stream))
    _check_events_against_input(bytes(stream), parser, events)
    good = [e.payload for e in events if e.error is None]
    # at most one copy is swallowed by the garbage; the last two are always recovered
    assert good[-2:] == [payload, payload]


@settings(max_examples=300, deadline=None)
@given(st.lists(st.binary(min_size=1, max_size=30), min_size=1, max_size=5), st.data())
def test_corrupting_a_frame_byte_is_detected(payloads, data):
    stream = bytearray(b"".join(lp.frame(p) for p in payloads))
    i = data.draw(st.integers(0, len(stream) - 1))
    stream[i] ^= data.draw(st.integers(1, 255))
    parser = lp.LeptrinoStreamParser()
    events = parser.feed(bytes(stream))
    _check_events_against_input(bytes(stream), parser, events)
    assert len([e for e in events if e.error is None]) < len(payloads) or parser.total_errors


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300), st.integers(1, 17))
def test_chunking_does_not_change_events(data, chunk):
    whole = lp.LeptrinoStreamParser().feed(data)
    parser = lp.LeptrinoStreamParser()
    pieces = []
    for i in range(0, len(data), chunk):
        pieces += parser.feed(data[i : i + chunk])
    assert [(e.offset, e.payload, str(e.error)) for e in pieces] == [
        (e.offset, e.payload, str(e.error)) for e in whole
    ]


def test_overflow_and_bad_escape_are_counted():
    parser = lp.LeptrinoStreamParser()
    events = parser.feed(b"\x10\x02" + b"\x00" * 300 + b"\x10\x03\x00")
    assert parser.errors["overflow"] == 1 and parser.frames == 0 and len(events) == 1
    events = parser.feed(b"\x10\x02\x01\x10\x55" + lp.frame(b"\x04\x00\x33\x00"))
    assert parser.errors["escape"] == 1 and parser.frames == 1
    assert events[-1].payload == b"\x04\x00\x33\x00"


def test_decode_stream_with_garbage_offsets_kinds_and_counts():
    parts, expected = [], []
    at = 0
    for v in SENSOR:
        junk = b"\xaa\x55"
        wire = bytes.fromhex(v["frame"])
        parts += [junk, wire]
        expected.append((at + len(junk), v["kind"]))
        at += len(junk) + len(wire)
    bad = bytearray(lp.frame(bytes([4, 0, 0x33, 0])))
    bad[-1] ^= 1  # BCC error
    broken_len = lp.frame(bytes([5, 0, 0x33, 0]))  # length byte lies
    unknown = lp.frame(bytes([4, 0, 0x99, 0]))
    parts += [bytes(bad), broken_len, unknown]
    parser = lp.LeptrinoStreamParser()
    out = list(lp.decode_leptrino(b"".join(parts), parser=parser))
    assert [(d["offset"], d["kind"]) for d in out[: len(SENSOR)]] == expected
    tail = out[len(SENSOR) :]
    assert [d["ok"] for d in tail] == [False, False, False]
    assert [d["error"].split(":")[0] for d in tail] == ["bcc", "length", "command"]
    assert parser.errors == {"bcc": 1, "length": 1, "command": 1}


PAPER_RATED = {
    # paper: foot CFS034CA301U +-150 N xy, +-300 N z, +-4.0 N m
    "CFS034CA301U": (150, 150, 300, 4.0, 4.0, 4.0),
    # paper: end effector CFS018CA201 +-100 N xy, +-200 N z, +-1.0 N m
    "CFS018CA201U": (100, 100, 200, 1.0, 1.0, 1.0),
}


@pytest.mark.parametrize("model", sorted(PAPER_RATED))
def test_full_scale_raw_converts_to_rated(model):
    rated = PAPER_RATED[model]
    assert lp.to_wrench([10000] * 6, model) == pytest.approx(rated, rel=1e-15)
    assert lp.to_wrench([-10000] * 6, model) == pytest.approx([-r for r in rated], rel=1e-15)
    assert lp.cfs_node_wrench([10000] * 6, model) == pytest.approx(rated, rel=1e-15)
    sample = lp.ForceData((10000, -10000, 5000, 0, 2500, -10000))
    expect = (rated[0], -rated[1], rated[2] / 2, 0.0, rated[4] / 4, -rated[5])
    assert sample.wrench(model) == pytest.approx(expect, rel=1e-15)
    assert lp.from_wrench(rated, model) == (10000,) * 6


def test_offset_and_cfs_node_truncation():
    # (1 - 0.5) * 150 N * 1000 / 10000 = 7.5 mN -> the node truncates to 7 mN
    got = lp.cfs_node_wrench([1, 1, 3, 1, 1, 1], "CFS034CA301U", offset=[0.5, 0, 0, 0, 0, 0])
    assert got == pytest.approx((0.007, 0.015, 0.09, 0.0004, 0.0004, 0.0004), abs=1e-15)
    exact = lp.to_wrench([1, 1, 3, 1, 1, 1], "CFS034CA301U", offset=[0.5, 0, 0, 0, 0, 0])
    assert exact[0] == pytest.approx(0.0075)
    with pytest.raises(lp.LeptrinoError, match="saturates"):
        lp.from_wrench([400.0, 0, 0, 0, 0, 0], "CFS018CA201U")
    with pytest.raises(lp.LeptrinoError, match="unknown sensor model"):
        lp.to_wrench([0] * 6, "CFS999")
    with pytest.raises(lp.LeptrinoError, match="finite"):
        lp.from_wrench([math.nan] * 6, "CFS018CA201U")


def test_sensor_mirror_answers_host_commands():
    """A sensor-side mirror: parse host commands, reply with frames the host parser accepts."""
    host_tx = lp.get_rated_values() + lp.start_continuous_output()
    sensor_rx = lp.LeptrinoStreamParser()
    replies = b""
    for event in sensor_rx.feed(host_tx):
        command = lp.parse_command(event.payload).command
        if command == lp.Command.GET_LIMIT:
            replies += lp.encode_response(lp.RatedValues(lp.END_EFFECTOR_SENSOR.rated))
        elif command == lp.Command.DATA_START:
            raw = lp.from_wrench((1.0, -2.0, 20.0, 0.1, 0.0, -0.05), lp.END_EFFECTOR_SENSOR)
            replies += lp.encode_response(lp.ForceData(raw, temperature=300))
    out = list(lp.decode_leptrino(replies))
    assert [d["kind"] for d in out] == ["rated_values", "force_data"]
    assert out[0]["limits"] == [100.0, 100.0, 200.0, 1.0, 1.0, 1.0]
    assert lp.to_wrench(out[1]["raw"], "CFS018CA201U") == pytest.approx(
        (1.0, -2.0, 20.0, 0.1, 0.0, -0.05), abs=1e-12
    )


def test_encoder_rejects_bad_values():
    with pytest.raises(lp.LeptrinoError, match="length"):
        lp.frame(b"")
    with pytest.raises(lp.LeptrinoError, match="force data out of range"):
        lp.encode_response(lp.ForceData((40000, 0, 0, 0, 0, 0)))
    with pytest.raises(lp.LeptrinoError, match="digital_filter"):
        lp.CommandFrame(lp.Command.GET_INF, digital_filter=1)
    with pytest.raises(lp.LeptrinoError, match="longer than 16"):
        lp.encode_response(lp.ProductInfo("X" * 17, "", "", ""))
