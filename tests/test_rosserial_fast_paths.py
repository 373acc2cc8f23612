"""The rosserial codec and framing against independent oracles (docs/rosserial.md): message
bytes and values against rosbags' ROS1 serializer (firmware_protocol/spinal/tools/
rosbags_oracle.py, typestore built from the ``.msg`` texts), frames against the rosserial v2
layout written out here with ``struct``, and firmware_protocol/spinal/golden_frames.json.
The generated whole-message layouts are checked to be the path that runs, so a wrong
generated layout shows up against rosbags rather than being hidden by a fallback.
"""

from __future__ import annotations

import json
import math
import random
import struct
import sys
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from random_ros_messages import random_message

from rdm.protocol.rosserial import codec as rc
from rdm.protocol.rosserial import spinal_registry
from rdm.protocol.rosserial.client import ClientSession
from rdm.protocol.rosserial.codec import RosDuration, RosTime
from rdm.protocol.rosserial.events import MessageReceived
from rdm.protocol.rosserial.framing import (
    Frame,
    FrameParser,
    SkippedBytes,
    encode_frame,
)
from rdm.protocol.rosserial.registry import spinal_msgs_dir
from rdm.protocol.rosserial.server import ServerSession

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "firmware_protocol/spinal/tools"))
import rosbags_oracle as oracle

REG = spinal_registry()
TS = oracle.make_typestore()
GOLDEN = json.loads((spinal_msgs_dir() / "golden_frames.json").read_text())
# std_msgs/Header has a ROS1 ``seq`` the rosbags ROS1 store adds differently; not a link type
TYPES = [n for n in REG.message_names if n != "std_msgs/Header"]


def _message(codec: Any, rng: random.Random) -> Any:
    return random_message(codec, rng, REG, lambda r: r.choice([0, 1, 4, r.randint(0, 12)]))


def _stamps(value: Any, wrap: int) -> Any:
    """``value`` with each ``{"sec", "nsec"}`` second taken modulo 2**32, less ``wrap`` when
    it reaches ``wrap``: rosbags' ROS1 store holds a time's uint32 seconds as an int32."""
    if isinstance(value, dict):
        if value.keys() == {"sec", "nsec"}:
            sec = value["sec"] % 2**32
            return {"sec": sec - 2**32 if sec >= wrap else sec, "nsec": value["nsec"]}
        return {k: _stamps(v, wrap) for k, v in value.items()}
    if isinstance(value, list):
        return [_stamps(v, wrap) for v in value]
    return value


def _rosbags(name: str, msg: Any) -> bytes:
    """rosbags' ROS1 bytes of ``msg``."""
    fields = _stamps(rc.message_to_dict(msg), 2**31)
    return oracle.serialize(TS, oracle.rosbags_name(name), fields)


def _text(value: Any) -> str:
    """Values as text, so NaN equals NaN and -0.0 differs from 0.0; seconds as uint32."""
    return repr(_stamps(value, 2**32))


def _frame(topic: int, payload: bytes) -> bytes:
    """A rosserial v2 frame written out from the protocol (``struct``): 0xFF 0xFE, the
    little-endian length, its checksum, the topic id, the payload, the message checksum."""
    n = len(payload)
    length_chk = 255 - ((n & 0xFF) + (n >> 8)) % 256
    message_chk = 255 - ((topic & 0xFF) + (topic >> 8) + sum(payload)) % 256
    return struct.pack("<BBHBH", 0xFF, 0xFE, n, length_chk, topic) + payload + bytes([message_chk])


def test_the_generated_layouts_take_every_link_type():
    """Catches a layout generator that sends a link type down the variable-size path when a
    single struct packs it, or inlines a nested array it cannot (the Rust frame builders
    rely on the signatures)."""
    for name in (
        "spinal/ServoStates",
        "spinal/RollPitchYawTerms",
        "spinal/FourAxisCommand",
        "spinal/ServoControlCmd",
        "spinal/Pwms",
        "spinal/PMatrixPseudoInverseWithInertia",
        "rosserial_msgs/TopicInfo",
    ):
        assert REG.msg(name).fixed_size is None, name
    for name in ("spinal/Imu", "spinal/ServoState", "spinal/RollPitchYawTerm"):
        assert REG.msg(name).fixed_size == REG.msg(name).layout.size, name
    assert REG.msg("spinal/ServoStates").layout.signature() == (
        ("fixed", (("stamp", "t", None),), "II"),
        ("nested", "servos", "BhBhB", ("index", "angle", "temp", "load", "error")),
    )


def test_golden_topic_frames_decode_and_re_encode_identically():
    """Catches a field order or struct code wrong in a generated layout (the golden bytes
    come from rosbags)."""
    checked = 0
    for vec in GOLDEN["topics"] + GOLDEN["reserved"] + GOLDEN["handshake"]["client_reply"]:
        raw = bytes.fromhex(vec["hex"])
        if not REG.has_msg(vec["type"]) or len(raw) < 8:
            continue
        codec, payload = REG.msg(vec["type"]), raw[7:-1]
        msg = codec.decode(payload)
        assert rc.message_to_dict(msg) == json.loads(json.dumps(vec["fields"]))
        assert codec.encode(msg) == payload
        assert encode_frame(vec["topic_id"], codec.encode(msg)) == raw
        checked += 1
    assert checked >= 40


def test_random_messages_equal_rosbags_both_ways():
    """Random edge values (extremes, -0.0, inf, empty and long arrays) of every type: the
    bytes are rosbags' bytes and decode back to rosbags' values, through ``encode``,
    ``encode_into``, the generated ``layout.pack``, ``decode`` and ``decode_from`` at an offset.
    Catches e.g. a ``<h`` written for a ``uint16`` or an array count packed as ``B``."""
    rng = random.Random(11)
    for name in TYPES:
        codec = REG.msg(name)
        rb_name = oracle.rosbags_name(name)
        for _ in range(25):
            msg = _message(codec, rng)
            data = codec.encode(msg)
            assert data == _rosbags(name, msg), name
            assert codec.layout.pack(msg) == data, name  # the generated layout took it as it is
            out = bytearray(b"\x01")
            codec.encode_into(msg, out)
            assert bytes(out) == b"\x01" + data
            got = codec.decode(data)
            assert type(got) is codec.cls
            want = _text(oracle.deserialize(TS, rb_name, data))
            assert _text(rc.message_to_dict(got)) == want, name
            at, end = codec.decode_from(b"\x00\x00" + data + b"\x07", 2)
            assert end == 2 + len(data) and at == got
            assert codec.encode(rc.message_to_dict(msg)) == data  # dict input


def test_bad_values_raise_or_give_rosbags_bytes():
    """Each field set to a bad value: encode raises, or the value is representable and the
    bytes are rosbags' bytes. Catches a generated layout that wraps an out-of-range integer
    or drops array elements instead of refusing."""
    rng = random.Random(5)
    raised = judged = 0
    for name in TYPES:
        codec = REG.msg(name)
        for f in codec.spec.fields:
            for bad in (None, "abc", math.nan, 1e300, -1, 2**70, [math.nan], [2**40] * 3, [], [[]]):
                msg = _message(codec, rng)
                setattr(msg, f.name, bad)
                try:
                    data = codec.encode(msg)
                except (ValueError, TypeError, OverflowError):
                    raised += 1
                    continue
                try:
                    want = _rosbags(name, msg)
                except Exception:  # rosbags refuses a value struct takes (int to float32)
                    continue
                assert data == want, (name, f.name, bad)
                judged += 1
        if codec.spec.fields:
            msg = _message(codec, rng)
            delattr(msg, codec.spec.fields[-1].name)
            with pytest.raises(rc.EncodeError, match="missing field"):
                codec.encode(msg)
    assert raised > 1000 and judged > 150


@pytest.mark.parametrize(
    "name, field, value, error",
    [
        ("spinal/Imu", "quaternion", [0.0, 0.0, 1.0], r"Imu\.quaternion: needs exactly 4"),
        ("spinal/Imu", "stamp", (-1, 0), r"Imu\.stamp: bad time value"),
        ("spinal/Imu", "stamp", RosDuration(-1, 0), r"Imu\.stamp: bad time value"),
        ("spinal/Imu", "gyro", "abc", r"Imu\.gyro: element does not fit float32"),
        ("spinal/RollPitchYawTerm", "roll_p", 40000, r"roll_p: 40000 does not fit int16"),
    ],
)
def test_encode_errors_name_the_field_and_the_rule(name, field, value, error):
    """Catches a generated layout whose refusal reaches the caller as a bare ``struct``
    error instead of the per-field message naming the field."""
    codec = REG.msg(name)
    with pytest.raises(rc.EncodeError, match=error):
        codec.encode(codec.cls(**{field: value}))


@pytest.mark.parametrize(
    "name, value, error",
    [
        ("rosserial_msgs/Log", {"level": 1, "msg": 5}, r"Log\.msg: expected str or bytes"),
        ("rosserial_msgs/Log", {"level": 300, "msg": ""}, r"Log\.level: 300 does not fit uint8"),
        ("spinal/GetBoardInfoResponse", {"boards": [{}]}, r"BoardInfo: missing field 'slave_id'"),
        ("spinal/PwmInfo", {"motor_info": [{"polynominal": [0.0] * 4}]}, r"MotorInfo: missing"),
        ("spinal/ESCTelemetryArray", {"stamp": (1, -1)}, r"ESCTelemetryArray\.stamp: bad time"),
    ],
)
def test_encode_errors_of_strings_and_nested_messages(name, value, error):
    """Dict input to the types with strings and nested messages: the refused field is named
    (catches a nested refusal that escapes as a bare AttributeError or struct error)."""
    codec = REG.msg(name)
    full = {**rc.message_to_dict(codec.new()), **value}
    with pytest.raises(rc.EncodeError, match=error):
        codec.encode(full)


@pytest.mark.parametrize(
    "name, hex_payload, error",
    [
        # stamp 8 + acc 12 bytes: gyro starts at offset 20
        ("spinal/Imu", "00" * 20, r"^spinal/Imu\.gyro: needs 12 bytes at offset 20, only 0 left$"),
        # level 1 byte, then the string length 5 at offset 1, its bytes from offset 5
        ("rosserial_msgs/Log", "0305000000616263", r"Log\.msg: needs 5 bytes at offset 5,"),
        # stamp 8 bytes, count 2 at offset 8, elements from offset 12
        (
            "spinal/ServoStates",
            "01000000020000000200000001",
            r"ServoStates\.servos: count 2 exceeds the remaining bytes at offset 12$",
        ),
        # one BoardInfo (5 bytes of fields from offset 4), its servos count at offset 9
        (
            "spinal/GetBoardInfoResponse",
            "01000000010203040005000000",
            r"^spinal/BoardInfo\.servos: count 5 exceeds the remaining bytes at offset 13$",
        ),
        ("spinal/Pwms", "01000000010000", r"^spinal/Pwms: 1 trailing bytes at offset 6$"),
    ],
)
def test_decode_errors_name_the_field_and_the_offset(name, hex_payload, error):
    """Offsets counted from the ``.msg`` layout by hand: catches an error that names the
    start of the message or of the segment instead of the field that does not fit."""
    with pytest.raises(rc.DecodeError, match=error):
        REG.msg(name).decode(bytes.fromhex(hex_payload))


def test_corrupt_payloads_decode_as_rosbags_or_raise():
    """Cut, extended and byte-flipped payloads: a payload rosbags reads in full decodes to
    rosbags' values; one it cannot read, or reads with bytes left over, raises DecodeError
    (bytes that are not UTF-8 inside a string are left out: rosbags refuses them).
    Catches a decoder that ignores trailing bytes or reads past a short buffer."""
    rng = random.Random(3)
    decoded = refused = 0
    for name in TYPES:
        codec = REG.msg(name)
        rb_name = oracle.rosbags_name(name)
        data = codec.encode(_message(codec, rng))
        variants = [data[:k] for k in range(len(data))] + [data + b"\x00", data + b"\xff" * 9]
        for _ in range(10):
            junk = bytearray(data)
            if junk:
                junk[rng.randrange(len(junk))] = rng.randrange(256)
            variants.append(bytes(junk))
        variants.append(b"\xff\xff\xff\x7f" + data)  # huge array count
        for raw in variants:
            try:
                ref = TS.deserialize_ros1(raw, rb_name)
                whole = len(TS.serialize_ros1(ref, rb_name)) == len(raw)
            except Exception as exc:
                if "utf-8" in str(exc):  # ASSUMPTION: strings decode leniently, rosbags strictly
                    continue
                whole = False
            if whole:
                got = rc.message_to_dict(codec.decode(raw))
                assert _text(got) == _text(oracle.from_rosbags(TS, ref)), (name, raw.hex())
                decoded += 1
            else:
                with pytest.raises(rc.DecodeError):
                    codec.decode(raw)
                refused += 1
    assert decoded > 100 and refused > 500


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.integers(0, 255),
            st.integers(-(2**15), 2**15 - 1),
            st.integers(0, 255),
            st.integers(-(2**15), 2**15 - 1),
            st.integers(0, 255),
        ),
        max_size=20,
    ),
    st.tuples(st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1)),
)
def test_hypothesis_servo_states(servos, stamp):
    """Catches a nested-array layout that packs the element fields out of ``.msg`` order."""
    codec, item = REG.msg("spinal/ServoStates"), REG.msg("spinal/ServoState")
    msg = codec.new(
        stamp=RosTime(*stamp),
        servos=[item.new(index=s[0], angle=s[1], temp=s[2], load=s[3], error=s[4]) for s in servos],
    )
    data = codec.encode(msg)
    want = struct.pack("<III", stamp[0], stamp[1], len(servos)) + b"".join(
        struct.pack("<BhBhB", *s) for s in servos
    )  # the .msg layout written out
    assert data == want
    assert codec.decode(data) == msg


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(width=32, allow_nan=False), max_size=9),
    st.lists(st.floats(width=32, allow_nan=False), min_size=3, max_size=3),
)
def test_hypothesis_four_axis_command(thrust, angles):
    """Catches a fixed array followed by a variable one packed with the wrong count."""
    codec = REG.msg("spinal/FourAxisCommand")
    msg = codec.new(angles=angles, base_thrust=thrust)
    data = codec.encode(msg)
    assert data == struct.pack(f"<3fI{len(thrust)}f", *angles, len(thrust), *thrust)
    assert _text(rc.message_to_dict(codec.decode(data))) == _text(
        oracle.deserialize(TS, "spinal/msg/FourAxisCommand", data)
    )


def test_encode_frame_is_the_protocols_frame():
    """Catches the topic id's high byte left out of the checksum or the length checksum
    computed over the low byte only, for each payload type taken."""
    rng = random.Random(2)
    for _ in range(3000):
        topic = rng.choice([0, 7, 10, 100, 150, 255, 256, 65535, rng.randrange(65536)])
        payload = rng.randbytes(rng.choice([0, 1, 60, 300, 1022, 65535]))
        want = _frame(topic, payload)
        assert encode_frame(topic, payload) == want
        if len(payload) < 400:
            assert encode_frame(topic, bytearray(payload)) == want
            assert encode_frame(topic, memoryview(payload)) == want


def _clean_stream(rng: random.Random, max_payload: int) -> tuple[bytes, list[Frame], int]:
    """Frames that fit ``max_payload`` between noise without 0xFF: the stream, the frames
    it holds at their offsets, and the number of noise bytes."""
    stream, frames, noise = bytearray(), [], 0
    for _ in range(rng.randint(1, 30)):
        gap = bytes(rng.randrange(255) for _ in range(rng.choice([0, 0, 1, 7])))
        stream += gap
        noise += len(gap)
        topic = rng.choice([10, 100, 153, 7, 256, 65535])
        payload = rng.randbytes(rng.randint(0, min(max_payload, 80)))
        frames.append(Frame(topic, payload, len(stream)))
        stream += _frame(topic, payload)
    return bytes(stream), frames, noise


def _corrupt_stream(rng: random.Random) -> bytes:
    parts = []
    for _ in range(rng.randint(1, 30)):
        kind = rng.random()
        frame = bytearray(_frame(rng.choice([10, 100, 153, 7]), rng.randbytes(rng.randint(0, 80))))
        if kind < 0.1:
            frame[rng.randrange(len(frame))] ^= 1 << rng.randrange(8)  # any bit flipped
        elif kind < 0.15:
            frame = frame[: rng.randrange(len(frame))]  # truncated
        elif kind < 0.2:
            frame = bytearray(rng.randbytes(rng.randint(1, 20)))  # line noise
        elif kind < 0.23:
            frame = bytearray(b"\xff\xff\xfe" + bytes(frame[2:]))  # v1 sync
        elif kind < 0.26:
            frame = bytearray(b"\xff\xfe\x00\x04\xfb")  # oversize header (1024)
        parts.append(bytes(frame))
    return b"".join(parts)


def _feed_in_chunks(parser: FrameParser, data: bytes, rng: random.Random) -> list[Any]:
    """All of ``data`` fed in random chunks (empty ones too) at random times."""
    events, i, now = [], 0, 0
    while i < len(data):
        step = rng.choice([0, 0, 1, 3, 17, 64, 400])
        now += rng.choice([0, 1, 5, 25])
        events += parser.feed(data[i : i + step], now)
        i += step
    return events


MAX_PAYLOADS = [512, 40, 0]


@pytest.mark.parametrize("rescan", [True, False])
@pytest.mark.parametrize("max_payload", MAX_PAYLOADS)
def test_parser_finds_every_frame_of_a_clean_stream(max_payload, rescan):
    """Frames between noise bytes, fed in random chunks: exactly the frames written, at
    their offsets, and every noise byte counted as skipped. Catches an off-by-one in the
    offset carried across chunks or a frame lost at a chunk boundary."""
    rng = random.Random(max_payload * 2 + rescan)
    for _ in range(80):
        data, frames, noise = _clean_stream(rng, max_payload)
        parser = FrameParser(max_payload, None, rescan=rescan)
        events = _feed_in_chunks(parser, data, rng)
        assert [e for e in events if isinstance(e, Frame)] == frames
        assert all(isinstance(e, (Frame, SkippedBytes)) for e in events)
        assert sum(len(e.data) for e in events if isinstance(e, SkippedBytes)) == noise
        assert parser.counts["frames"] == len(frames)


@pytest.mark.parametrize("rescan", [True, False])
@pytest.mark.parametrize("max_payload", MAX_PAYLOADS)
def test_parser_events_on_a_corrupt_stream_are_the_streams_bytes(max_payload, rescan):
    """Bit flips, cuts, noise, v1 sync bytes and oversize headers, with frame timeouts:
    each frame found is the protocol's frame of its topic and payload at its offset, each
    bad candidate and skipped run the bytes there, and the pending candidate the stream's
    tail. Catches an event reporting the offset of the chunk instead of the stream."""
    rng = random.Random(max_payload * 3 + rescan)
    found = 0
    for _ in range(60):
        data = _corrupt_stream(rng)
        parser = FrameParser(max_payload, rng.choice([None, 20, 0.5]), rescan=rescan)
        events = _feed_in_chunks(parser, data, rng)
        for e in events:
            if isinstance(e, Frame):
                assert data[e.offset : e.offset + len(e.payload) + 8] == _frame(
                    e.topic_id, e.payload
                )
                found += 1
            else:
                assert data[e.offset : e.offset + len(e.data)] == e.data
        offset, pending = parser.pending
        assert data[offset:] == pending
    assert found > 300 or max_payload < 80


def test_session_publications_are_rosbags_bytes_in_protocol_frames():
    """After the handshake, each device publication leaves the client as the frame of its
    topic id around rosbags' bytes and reaches the server as rosbags' values. Catches a
    session that frames a publication under the wrong topic id."""
    rng = random.Random(9)
    client, server = ClientSession.from_layout(registry=REG), ServerSession(REG)
    server.start(0.0)
    to_dev = server.take_output()
    for ms in range(50):  # the handshake
        client.spin(to_dev, ms)
        server.feed(client.take_output(), ms / 1000.0)
        to_dev = server.take_output()
    assert client.configured and server.active
    received = 0
    for ms in range(50, 550):
        client.spin(to_dev, ms)
        topic = rng.choice(["imu", "servo/states", "motor_pwms", "battery_voltage_status"])
        pub = client.publisher(topic)
        msg = _message(REG.msg(pub.type), rng)
        client.take_output()
        client.publish(topic, msg)
        out = client.take_output()
        assert out == _frame(pub.topic_id, _rosbags(pub.type, msg)), topic
        events = [e for e in server.feed(out, ms / 1000.0) if isinstance(e, MessageReceived)]
        assert [(e.topic, e.topic_id) for e in events] == [(topic, pub.topic_id)]
        assert _text(rc.message_to_dict(events[0].message)) == _text(
            oracle.deserialize(TS, oracle.rosbags_name(pub.type), out[7:-1])
        )
        to_dev = server.take_output()
        received += 1
    assert received == 500
