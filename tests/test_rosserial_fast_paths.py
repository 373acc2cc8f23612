"""The rosserial fast paths: the generated whole-message codecs for fixed and variable layouts
give the bytes, values and errors of the per-field path (a registry compiled with both layouts
off) and of an independent ``struct`` packing; the frame encoder and the Rust frame builder
give the frame written out with ``struct``; the Rust frame scan and the Python loop give the
same events, each found in the stream at its offset; Adler-32 byte sums equal Python's
``sum``; bytes are also checked against firmware_protocol/spinal/golden_frames.json.
"""

from __future__ import annotations

import json
import math
import random
import struct
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from random_ros_messages import random_message

from rdm.protocol.rosserial import codec as rc
from rdm.protocol.rosserial import spinal_registry
from rdm.protocol.rosserial.checksums import byte_sum
from rdm.protocol.rosserial.client import ClientSession
from rdm.protocol.rosserial.codec import RosTime
from rdm.protocol.rosserial.framing import (
    BadFrame,
    Frame,
    FrameError,
    FrameParser,
    SkippedBytes,
    encode_frame,
)
from rdm.protocol.rosserial.registry import TypeRegistry, spinal_msgs_dir
from rdm.protocol.rosserial.server import ServerSession

FAST = spinal_registry()
GOLDEN = json.loads((spinal_msgs_dir() / "golden_frames.json").read_text())


def _plain_registry() -> TypeRegistry:
    """The Spinal registry with every codec on the per-field path (both layouts off)."""
    flat_of, var_of = rc._FlatLayout.of, rc._VarLayout.of
    rc._FlatLayout.of = classmethod(lambda cls, spec: None)  # type: ignore[method-assign]
    rc._VarLayout.of = classmethod(lambda cls, spec, resolve: None)  # type: ignore[method-assign]
    try:
        reg = TypeRegistry.from_directory(spinal_msgs_dir())
        for name in reg.message_names:
            reg.msg(name)  # compile now, while the fast layouts are off
        for name in reg.service_names:
            reg.srv(name)
    finally:
        rc._FlatLayout.of, rc._VarLayout.of = flat_of, var_of  # type: ignore[method-assign]
    return reg


PLAIN = _plain_registry()


def _message(codec: Any, rng: random.Random) -> Any:
    return random_message(codec, rng, FAST, _array_len)


def _array_len(rng: random.Random) -> int:
    return rng.choice([0, 1, 4, rng.randint(0, 12)])


def _outcome(call: Any) -> tuple[str, Any]:
    try:
        got = call()
    except Exception as exc:  # the comparison is the point
        return type(exc).__name__, str(exc)
    # repr: NaN payload values compare equal as text
    return "ok", repr(rc.message_to_dict(got)) if not isinstance(got, bytes) else got


def test_fast_layouts_cover_the_link_types_and_the_plain_registry_has_none():
    for name in (
        "spinal/ServoStates",
        "spinal/RollPitchYawTerms",
        "spinal/FourAxisCommand",
        "spinal/ServoControlCmd",
        "spinal/Pwms",
        "spinal/PMatrixPseudoInverseWithInertia",
    ):
        assert FAST.msg(name)._var is not None, name
    assert FAST.msg("spinal/Imu")._flat is not None
    for name in PLAIN.message_names:
        assert PLAIN.msg(name)._pack is None, name


def test_golden_topic_frames_decode_and_re_encode_identically():
    vectors = GOLDEN["topics"] + GOLDEN["reserved"] + GOLDEN["handshake"]["client_reply"]
    checked = 0
    for vec in vectors:
        raw = bytes.fromhex(vec["hex"])
        payload = raw[7:-1]
        if not FAST.has_msg(vec["type"]) or len(raw) < 8:
            continue
        fast, plain = FAST.msg(vec["type"]), PLAIN.msg(vec["type"])
        msg = fast.decode(payload)
        assert rc.message_to_dict(msg) == rc.message_to_dict(plain.decode(payload))
        assert rc.message_to_dict(msg) == json.loads(json.dumps(vec["fields"]))
        assert fast.encode(msg) == payload == plain.encode(msg)
        assert encode_frame(vec["topic_id"], fast.encode(msg)) == raw
        checked += 1
    assert checked >= 40


def test_random_messages_same_bytes_values_and_classes():
    rng = random.Random(11)
    for name in FAST.message_names:
        fast, plain = FAST.msg(name), PLAIN.msg(name)
        for _ in range(25):
            msg = _message(fast, rng)
            data = fast.encode(msg)
            assert data == plain.encode(msg), name
            if fast._pack is not None:  # the fast path itself took it (no silent fallback)
                assert fast._pack(msg) == data, name
            out = bytearray(b"\x01")
            fast.encode_into(msg, out)
            assert bytes(out) == b"\x01" + data
            got, want = fast.decode(data), plain.decode(data)
            assert type(got).__name__ == type(want).__name__, name
            assert rc.message_to_dict(got) == rc.message_to_dict(want), name
            assert fast.decode(fast.encode(want)) == got
            # decode_from at an offset inside a larger buffer
            at, end = fast.decode_from(b"\x00\x00" + data + b"\x07", 2)
            assert end == 2 + len(data) and at == got
            # dicts go through the per-field path on both
            as_dict = {f.name: getattr(msg, f.name) for f in fast.spec.fields}
            assert fast.encode(as_dict) == data


def test_bad_messages_same_errors_on_both_paths():
    rng = random.Random(5)
    cases = 0
    for name in FAST.message_names:
        fast, plain = FAST.msg(name), PLAIN.msg(name)
        if not fast.spec.fields:
            continue
        for f in fast.spec.fields:
            for bad in (None, "abc", math.nan, 1e300, -1, 2**70, [math.nan], [2**40] * 3, [], [[]]):
                msg = _message(fast, rng)
                setattr(msg, f.name, bad)
                assert _outcome(lambda m=msg, c=fast: c.encode(m)) == _outcome(
                    lambda m=msg, c=plain: c.encode(m)
                ), (name, f.name, bad)
                cases += 1
        msg = _message(fast, rng)
        delattr(msg, fast.spec.fields[-1].name)
        assert _outcome(lambda m=msg, c=fast: c.encode(m)) == _outcome(
            lambda m=msg, c=plain: c.encode(m)
        )
    assert cases > 500


def test_corrupt_payloads_same_values_or_errors():
    rng = random.Random(3)
    for name in FAST.message_names:
        fast, plain = FAST.msg(name), PLAIN.msg(name)
        data = fast.encode(_message(fast, rng))
        variants = [data[:k] for k in range(len(data))] + [data + b"\x00", data + b"\xff" * 9]
        for _ in range(10):
            junk = bytearray(data)
            if junk:
                junk[rng.randrange(len(junk))] = rng.randrange(256)
            variants.append(bytes(junk))
        variants.append(b"\xff\xff\xff\x7f" + data)  # huge array count
        for raw in variants:
            assert _outcome(lambda r=raw, c=fast: c.decode(r)) == _outcome(
                lambda r=raw, c=plain: c.decode(r)
            ), (name, raw.hex())


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
    fast, plain = FAST.msg("spinal/ServoStates"), PLAIN.msg("spinal/ServoStates")
    item = FAST.msg("spinal/ServoState")
    msg = fast.new(
        stamp=RosTime(*stamp),
        servos=[item.new(index=s[0], angle=s[1], temp=s[2], load=s[3], error=s[4]) for s in servos],
    )
    data = fast.encode(msg)
    want = struct.pack("<III", stamp[0], stamp[1], len(servos)) + b"".join(
        struct.pack("<BhBhB", *s) for s in servos
    )  # independent packing of the .msg layout
    assert data == want == plain.encode(msg)
    assert fast.decode(data) == msg
    assert rc.message_to_dict(plain.decode(data)) == rc.message_to_dict(msg)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(width=32, allow_nan=False), max_size=9),
    st.lists(st.floats(width=32, allow_nan=False), min_size=3, max_size=3),
)
def test_hypothesis_four_axis_command(thrust, angles):
    fast, plain = FAST.msg("spinal/FourAxisCommand"), PLAIN.msg("spinal/FourAxisCommand")
    msg = fast.new(angles=angles, base_thrust=thrust)
    data = fast.encode(msg)
    assert data == struct.pack(f"<3fI{len(thrust)}f", *angles, len(thrust), *thrust)
    assert data == plain.encode(msg)
    assert rc.message_to_dict(fast.decode(data)) == rc.message_to_dict(plain.decode(data))


def test_byte_sum_is_sum():
    rng = random.Random(1)
    for n in [0, 1, 255, 256, 257, 511, 512, 513, 1022, 1023, 5000]:
        for fill in (0xFF, None):
            data = bytes([fill] * n) if fill is not None else rng.randbytes(n)
            assert byte_sum(data) == sum(data)
            assert byte_sum(bytearray(data)) == sum(data)


def _frame(topic: int, payload: bytes) -> bytes:
    """A rosserial v2 frame written out from the protocol (``struct``): 0xFF 0xFE, the
    little-endian length, its checksum, the topic id, the payload, the message checksum."""
    n = len(payload)
    length_chk = 255 - ((n & 0xFF) + (n >> 8)) % 256
    message_chk = 255 - ((topic & 0xFF) + (topic >> 8) + sum(payload)) % 256
    return struct.pack("<BBHBH", 0xFF, 0xFE, n, length_chk, topic) + payload + bytes([message_chk])


def test_encode_frame_is_the_protocols_frame_and_names_its_errors():
    rng = random.Random(2)
    for _ in range(300):
        topic = rng.choice([0, 7, 10, 100, 150, 255, 256, 65535, rng.randrange(65536)])
        payload = rng.randbytes(rng.choice([0, 1, 60, 300, 1022]))
        assert encode_frame(topic, payload) == _frame(topic, payload)
        assert encode_frame(topic, bytearray(payload)) == _frame(topic, payload)
    assert encode_frame(150, [1, 2, 3]) == _frame(150, bytes([1, 2, 3]))
    odd: list[tuple[Any, Any]] = [(150.0, b"ab"), (150, [1, 300]), (150, ["a"]), (150, iter(b""))]
    for topic, payload in odd:  # the (topic, length) header cache is warm for 150 / 2 bytes
        with pytest.raises((TypeError, ValueError)):
            encode_frame(topic, payload)
    for topic, payload, text in (
        (-1, b"", "topic_id -1 outside 0..65535"),
        (65536, b"", "topic_id 65536 outside 0..65535"),
        (1, bytes(65536), "payload of 65536 bytes does not fit the uint16 length field"),
    ):
        with pytest.raises(FrameError, match=text):
            encode_frame(topic, payload)


def test_native_frame_is_the_protocols_frame_and_declines_the_rest():
    from rdm import _rdm

    rng = random.Random(3)
    for _ in range(3000):
        topic = rng.choice([0, 7, 10, 100, 255, 256, 65535, rng.randrange(65536)])
        payload = rng.randbytes(rng.choice([0, 1, 60, 300, 1022, 65535]))
        assert _rdm.rosserial_frame(topic, payload) == _frame(topic, payload)
    # what encode_frame converts or refuses: no frame built here
    for topic, payload in ((-1, b""), (65536, b""), (1, bytes(65536)), (150, bytearray(2)),
                           (150.0, b"ab"), (150, [1, 2])):  # fmt: skip
        assert _rdm.rosserial_frame(topic, payload) is None


def _stream(rng: random.Random) -> bytes:
    parts = []
    for _ in range(rng.randint(1, 30)):
        kind = rng.random()
        frame = bytearray(
            encode_frame(rng.choice([10, 100, 153, 7]), rng.randbytes(rng.randint(0, 80)))
        )
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


def _check_against_stream(events: list[Any], stream: bytes) -> None:
    """Every event is the stream's bytes at its offset: a frame the protocol's frame of its
    topic and payload (``_frame``), a bad candidate and skipped bytes the bytes there."""
    for e in events:
        if isinstance(e, tuple):  # the sessions' raw form (topic id, payload, offset)
            e = Frame(*e)
        if isinstance(e, Frame):
            frame = _frame(e.topic_id, e.payload)
            assert stream[e.offset : e.offset + len(frame)] == frame
        else:
            assert stream[e.offset : e.offset + len(e.data)] == e.data


@pytest.mark.parametrize("rescan", [True, False])
@pytest.mark.parametrize("max_payload", [512, 1022, 40, 0])
def test_parser_events_are_the_streams_bytes_and_the_scan_equals_the_python_loop(
    rescan, max_payload
):
    """The Rust scan and the Python loop (which takes a ``max_payload`` the scan does not)
    give events found in the stream at their offsets, in the same order and counts."""
    rng = random.Random(max_payload * 2 + rescan)
    frames = 0
    for trial in range(120):
        data = _stream(rng)
        timeout = rng.choice([None, 20, 0.5])
        scan = FrameParser(max_payload, timeout, rescan=rescan)
        assert scan.native is True  # the extension has the scanner
        loop = FrameParser(max_payload, timeout, rescan=rescan)
        loop.native = False
        stream = bytearray()
        now, i = 0, 0
        while i <= len(data):
            step = rng.choice([0, 0, 1, 3, 17, 64, 400])
            now += rng.choice([0, 1, 5, 25])
            chunk = data[i : i + step]
            stream += chunk
            got = scan.feed(chunk, now)
            assert got == loop.feed(chunk, now), trial
            _check_against_stream(got, bytes(stream))
            frames += sum(isinstance(e, Frame) for e in got)
            assert scan.pending == loop.pending and scan.in_frame == loop.in_frame
            offset, pending = scan.pending
            assert bytes(stream[offset:]) == pending  # the candidate is the stream's tail
            i += max(step, 1)
        assert scan.poll(now + 100) == loop.poll(now + 100)
        for raw in (True, False):  # the sessions' raw form too
            tail = encode_frame(150, b"ab") + b"\xff\xfe\x05"
            stream += tail
            got = scan._feed(tail, now + 101, raw)
            assert got == loop._feed(tail, now + 101, raw)
            _check_against_stream(got, bytes(stream))
        assert dict(scan.counts) == dict(loop.counts)
        assert list(scan.counts) == list(loop.counts)  # same insertion order too
    assert frames > 500 or max_payload < 80


def test_native_scanner_is_used_and_odd_max_payload_takes_the_python_loop():
    parser = FrameParser(512)
    assert parser.native  # built with the extension that has rosserial_scan
    frame = encode_frame(150, b"xyz")
    oversize = [BadFrame("oversize", 0, frame[:5]), SkippedBytes(1, frame[1:])]  # to the next 0xFF
    for odd, events, counts in (
        (512.0, [Frame(150, b"xyz", 0)], {"frames": 1}),
        (-1, oversize, None),
        (True, oversize, None),
    ):
        parser = FrameParser(odd)  # type: ignore[arg-type]
        assert parser.feed(frame + frame[:3]) == events, odd
        if counts is not None:
            assert dict(parser.counts) == counts
        else:  # 3 bytes are over a limit of -1 or True (1)
            assert dict(parser.counts) == {"oversize": 1, "skipped_bytes": len(frame) - 1}
        assert parser.pending == (len(frame), frame[:3])


def _pair(registry: TypeRegistry) -> tuple[ClientSession, ServerSession]:
    return ClientSession.from_layout(registry=registry), ServerSession(registry)


def _events(events: list[Any]) -> list[Any]:
    out = []
    for e in events:
        message = getattr(e, "message", None)
        out.append((type(e).__name__, repr(e) if message is None else rc.message_to_dict(message)))
    return out


def test_sessions_fast_and_plain_give_the_same_events_bytes_and_counters():
    """A handshake then 3 s of link traffic with corrupt bytes and silent gaps, on a fast
    pair and on a pair with per-field codecs."""
    rng_msgs = random.Random(9)
    pairs = [_pair(FAST), _pair(PLAIN)]
    logs: list[list[Any]] = [[], []]
    pc_topics = [
        "rpy/gain",
        "four_axes/command",
        "servo/target_states",
        "desire_coordinate",
        "p_matrix_pseudo_inverse_inertia",
    ]
    dev_topics = ["imu", "servo/states", "motor_pwms", "battery_voltage_status"]
    script = []
    for ms in range(3000):
        pubs = [
            (t, _message(FAST.msg(_pub_type(pairs[0][0], t)), rng_msgs))
            for t in dev_topics
            if rng_msgs.random() < 0.3
        ]
        cmds = [
            (t, _message(FAST.msg(_sub_type(pairs[0][0], t)), rng_msgs))
            for t in pc_topics
            if ms % 25 == 0
        ]
        noise = rng_msgs.randbytes(5) if rng_msgs.random() < 0.01 else b""
        script.append((pubs, cmds, noise))
    for (client, server), log in zip(pairs, logs, strict=True):
        server.start(0.0)
        to_dev = server.take_output()
        for ms, (pubs, cmds, noise) in enumerate(script):
            now = ms / 1000.0
            log.append(_events(client.spin(to_dev, ms)))
            to_dev = b""
            for topic, msg in pubs:
                log.append(client.publish(topic, msg))
            to_pc = client.take_output() + noise
            log.append(_events(server.feed(to_pc, now)))
            if server.outbound:
                for topic, msg in cmds:
                    log.append(server.publish(topic, msg))
            to_dev = server.take_output()
            log.append(to_pc + to_dev)
        log.append(
            (
                dict(client.counts),
                dict(client.parser.counts),
                dict(server.counts),
                dict(server.parser.counts),
                client.configured,
                server.active,
            )
        )
    assert logs[0] == logs[1]
    received = sum(
        1
        for item in logs[0]
        if isinstance(item, list) and item and any(k == "MessageReceived" for k, _ in item)
    )
    assert received > 300  # the traffic did flow both ways


def _pub_type(client: ClientSession, topic: str) -> str:
    return client.publisher(topic).type


def _sub_type(client: ClientSession, topic: str) -> str:
    return next(s.type for s in client.subscribers if s.name == topic)
