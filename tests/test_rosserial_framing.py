"""rosserial v2 framing: the fact sheet's frames byte for byte, checksums, limits, resync."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from rdm.protocol.rosserial.framing import (
    BadFrame,
    Frame,
    FrameError,
    FrameParser,
    SkippedBytes,
    encode_frame,
)
from rdm.protocol.rosserial.registry import spinal_registry

SPINAL = Path(__file__).resolve().parents[1] / "firmware_protocol" / "spinal"
sys.path.insert(0, str(SPINAL / "tools"))
import rosbags_oracle as oracle  # noqa: E402

GOLDEN = json.loads((SPINAL / "golden_frames.json").read_text())
REG = spinal_registry()


def frames(events):
    return [e for e in events if isinstance(e, Frame)]


def bad(events):
    return [e for e in events if isinstance(e, BadFrame)]


def test_fact_sheet_example_frames_byte_for_byte():
    # literal hex of jsk-wire-protocols.md sec. 1.2
    examples = {e["name"]: bytes.fromhex(e["hex"]) for e in GOLDEN["fact_sheet_examples"]}
    assert encode_frame(0, b"") == examples["server topic request"]
    time = REG.msg("std_msgs/Time")
    assert encode_frame(10, time.encode(time.new())) == examples["client time request"]
    cmd = REG.msg("spinal/FourAxisCommand")
    payload = cmd.encode(cmd.new(angles=[0.0, 0.0, 0.0], base_thrust=[5.0] * 4))
    name = "FourAxisCommand angles {0,0,0}, base_thrust {5,5,5,5} on id 108"
    assert encode_frame(108, payload) == examples[name]
    assert examples["server topic request"].hex(" ") == "ff fe 00 00 ff 00 00 ff"


@given(st.integers(0, 0xFFFF), st.binary(max_size=300))
def test_checksums_match_the_independent_formula(topic_id, payload):
    raw = encode_frame(topic_id, payload)
    assert raw == oracle.frame(topic_id, payload)
    n = len(payload)
    assert (n % 256 + n // 256 + raw[4]) % 256 == 255  # the receiver's length test
    assert (topic_id % 256 + topic_id // 256 + sum(payload) + raw[-1]) % 256 == 255


def test_a_topic_id_above_255_is_in_the_checksum_byte_for_byte():
    """Topic 0x0123, payload 01, written out by hand: length 01 00, its checksum
    255 - 1 = fe, the message checksum 255 - (0x23 + 0x01 + 0x01) = da. The same frame with
    the topic's high byte changed (0x02) fails the checksum."""
    frame = bytes.fromhex("fffe 0100 fe 2301 01 da")
    assert encode_frame(0x0123, b"\x01") == frame
    parser = FrameParser(512, rescan=False)
    assert [(f.topic_id, f.payload) for f in frames(parser.feed(frame))] == [(0x0123, b"\x01")]
    wrong_high = bytes.fromhex("fffe 0100 fe 2302 01 da")
    events = FrameParser(512, rescan=False).feed(wrong_high)
    assert not frames(events) and bad(events)[0].reason == "message_checksum"


def test_encode_frame_limits():
    """Each refusal is a FrameError (a ValueError) naming the argument and the rule."""
    assert issubclass(FrameError, ValueError)
    for topic, payload, text in (
        (70000, b"", "topic_id 70000 outside 0..65535"),
        (-1, b"", "topic_id -1 outside 0..65535"),
        (2**70, b"", "outside 0..65535"),
        (150.0, b"ab", "topic_id 150.0 is not an integer"),
        (True, b"ab", "topic_id True is not an integer"),
        (1, bytes(70000), "payload of 70000 bytes does not fit the uint16 length field"),
        (1, bytearray(65536), "payload of 65536 bytes does not fit"),
        (1, [1, 2, 3], "payload of type list is not bytes, bytearray or memoryview"),
        (1, "ab", "payload of type str is not bytes"),
    ):
        with pytest.raises(FrameError, match=text):
            encode_frame(topic, payload)


def test_max_payload_must_be_a_non_negative_int():
    """Catches a limit the scan would read differently from the caller (a float, a bool,
    a negative number): refused when the parser is made."""
    for odd in (512.0, -1, True, None, "512"):
        with pytest.raises(FrameError, match=r"max_payload .* is not an integer >= 0"):
            FrameParser(odd)  # type: ignore[arg-type]
    frame = encode_frame(150, bytes(600))
    assert frames(FrameParser(2**80).feed(frame))  # any int above the uint16 range: no limit


@pytest.mark.parametrize("vec", GOLDEN["bad_frames"], ids=lambda v: v["reason"] + ":" + v["name"])
def test_golden_bad_frames_are_rejected_for_the_listed_reason(vec):
    parser = FrameParser(512, rescan=False)  # the Spinal client's receive limits
    events = parser.feed(bytes.fromhex(vec["hex"]))
    assert not frames(events)
    assert bad(events)[0].reason == vec["reason"]
    assert bad(events)[0].offset == 0
    assert parser.counts[vec["reason"]] >= 1


def test_golden_good_frames_in_any_chunking():
    stream = b"".join(bytes.fromhex(v["hex"]) for v in GOLDEN["topics"])
    expected = [(v["topic_id"], bytes.fromhex(v["hex"])[7:-1]) for v in GOLDEN["topics"]]
    for chunk in (1, 2, 7, 64, 1000, len(stream)):
        parser = FrameParser(512)
        got = []
        for i in range(0, len(stream), chunk):
            got += [(f.topic_id, f.payload) for f in frames(parser.feed(stream[i : i + chunk]))]
        assert got == expected
        assert parser.bad_frames == 0


def test_garbage_then_valid_frame_resyncs_and_reports_offsets():
    good = bytes.fromhex(GOLDEN["topics"][3]["hex"])
    garbage = bytes([0x00, 0x41, 0xFF, 0x13, 0xFF, 0xFE, 0x05, 0x00, 0x00, 0x99])
    parser = FrameParser(512)
    events = parser.feed(garbage + good)
    assert [f.offset for f in frames(events)] == [len(garbage)]
    assert frames(events)[0].payload == good[7:-1]
    assert [(b.reason, b.offset) for b in bad(events)] == [("version", 2), ("length_checksum", 4)]
    skipped = sum(len(e.data) for e in events if isinstance(e, SkippedBytes))
    assert skipped == 2 + 1 + 5  # 00 41, 13, then FE 05 00 00 99 after the bad header's FF


def test_truncated_frame_followed_by_valid_frame():
    good = next(bytes.fromhex(v["hex"]) for v in GOLDEN["topics"] if len(v["hex"]) > 80)
    # a frame cut after 10 bytes swallows the next frame as its body; rescanning finds it
    parser = FrameParser(1022)
    events = parser.feed(good[:10] + good)
    assert [f.offset for f in frames(events)] == [10]
    assert [b.reason for b in bad(events)] == ["message_checksum"]
    # the firmware-like mode (no rescan) loses the second frame, as Spinal would
    firmware = FrameParser(1022, rescan=False)
    assert not frames(firmware.feed(good[:10] + good))


def test_oversize_is_rejected_before_buffering():
    parser = FrameParser(512)
    header = bytes([0xFF, 0xFE, 0x01, 0x02, 255 - 3, 100, 0])  # 513 = 0x0201
    events = parser.feed(header)
    assert [b.reason for b in bad(events)] == ["oversize"]
    exact = encode_frame(100, bytes(512))
    assert len(frames(parser.feed(exact))) == 1


def test_frame_timeout_20ms():
    good = bytes.fromhex(GOLDEN["topics"][0]["hex"])
    on_time = FrameParser(512, frame_timeout=20)
    assert not on_time.feed(good[:6], now=1000)
    assert len(frames(on_time.feed(good[6:], now=1020))) == 1
    late = FrameParser(512, frame_timeout=20)
    assert not late.feed(good[:6], now=1000)
    events = late.feed(good[6:], now=1021)
    assert not frames(events)
    assert bad(events)[0].reason == "timeout" and bad(events)[0].offset == 0
    assert late.counts["timeout"] == 1
    # poll() applies the timeout without new bytes, then a fresh frame is accepted
    idle = FrameParser(512, frame_timeout=20)
    idle.feed(good[:3], now=0)
    assert [b.reason for b in bad(idle.poll(now=25))] == ["timeout"]
    assert len(frames(idle.feed(good, now=30))) == 1
