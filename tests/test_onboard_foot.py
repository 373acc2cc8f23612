"""The foot sensor's host side (``rdm.nodes.onboard_foot.FootSensorReader``) and the Leptrino
stream it reads, against the protocol's own functions and golden frames: the wrench of the
newest sample is ``(raw - offset) * rated / 10000`` (and what ``parse_response`` +
``to_wrench`` give), non-finite and malformed samples are counted; the parser's summarised
run of OK samples (``feed_ok_samples``) is what ``feed`` and ``parse_response`` see, on
random, corrupt and golden streams (``firmware_protocol/leptrino/vectors.json``); a stream
fed whole or byte by byte gives the same events and state.
"""

from __future__ import annotations

import json
import random
from pathlib import Path

import numpy as np
import pytest
from fed_byte_link import FedByteLink

from rdm import _rdm
from rdm.nodes.onboard_foot import FootSensorReader
from rdm.protocol import leptrino as lp

VECTORS = Path(__file__).resolve().parents[1] / "firmware_protocol" / "leptrino" / "vectors.json"


def _stream(rng: random.Random) -> tuple[list[bytes], list[list[tuple[int, ...]]]]:
    """Batches of frames: mostly samples, some acks, result errors, bad BCC, junk; also the
    raw values of the good samples per batch, in order."""
    batches, goods = [], []
    for _ in range(80):
        chunk, good = b"", []
        for _ in range(rng.randint(0, 14)):
            kind = rng.random()
            raw = tuple(rng.randint(-32768, 32767) for _ in range(6))
            if kind < 0.7:
                chunk += lp.encode_response(lp.ForceData(raw, rng.randint(0, 80), 0))
                good.append(raw)
            elif kind < 0.78:
                chunk += lp.encode_response(lp.ForceData(raw, 20, 0, result=1))
            elif kind < 0.84:
                chunk += lp.encode_response(lp.Ack(lp.Command.DATA_STOP, lp.Result.OK, 0))
            elif kind < 0.9:
                f = bytearray(lp.encode_response(lp.ForceData(raw, 20, 0)))
                f[-1] ^= 0x5A  # BCC
                chunk += bytes(f)
            else:
                chunk += bytes(rng.randint(0, 255) for _ in range(rng.randint(1, 6)))
        batches.append(chunk)
        goods.append(good)
    return batches, goods


@pytest.mark.parametrize("offset", [(0.0,) * 6, (10.0, -3.0, 0.5, 1e4, -2e4, 7.0)])
def test_foot_reader_keeps_the_newest_sample(offset):
    """Batches of samples, result errors, acks, bad BCC and junk: after each poll the wrench
    is the newest good sample's (raw - offset) * rated / 10000, counters as stated."""
    batches, goods = _stream(random.Random(5))
    link = FedByteLink()
    reader = FootSensorReader(link, offset=offset)
    rated = np.array(lp.MODELS["CFS034CA301U"].rated)
    last_good = None
    samples = 0
    for k, (chunk, good) in enumerate(zip(batches, goods, strict=True)):
        link.pending = chunk
        now = 0.025 * k
        reader.poll(now)
        samples += len(good)
        assert reader.counts["samples"] == samples
        if good:
            last_good = good[-1]
            assert reader.stamp == now
        if last_good is None:
            assert reader.wrench is None
        else:
            want = (np.array(last_good, dtype=float) - np.array(offset)) * rated / 10000.0
            np.testing.assert_allclose(reader.wrench, want, rtol=1e-15, atol=0)
    assert reader.counts["samples"] > 200 and reader.counts["result_error"] > 0


def test_foot_reader_counts_a_non_finite_offset():
    reader = FootSensorReader(FedByteLink(), offset=(np.inf, 0, 0, 0, 0, 0))
    assert not reader._skip_older
    reader.link.pending = lp.encode_response(lp.ForceData((1, 2, 3, 4, 5, 6), 20, 0)) * 3
    reader.poll(0.0)
    assert reader.counts["non_finite"] == 3 and reader.wrench is None


@pytest.mark.parametrize("offset", [(0.0,) * 6, (10.0, -3.0, 0.5, 1e4, -2e4, 7.25), (1e99,) * 6])
def test_take_matches_parse_response_and_to_wrench(offset):
    reader = FootSensorReader(FedByteLink(), offset=offset)
    rated = np.array(lp.MODELS["CFS034CA301U"].rated)
    rng = random.Random(21)
    for _ in range(500):
        raw = tuple(rng.randint(-32768, 32767) for _ in range(6))
        payload = lp.encode_response(lp.ForceData(raw, rng.randint(-5, 80), 3))
        payload = lp.LeptrinoStreamParser().feed(payload)[0].payload
        reader._take(payload)
        resp = lp.parse_response(payload)
        via_protocol = np.array(lp.to_wrench(resp.raw, reader.model, reader.offset), dtype=float)
        assert reader.wrench.tobytes() == via_protocol.tobytes()
        want = (np.array(raw, dtype=float) - np.array(offset)) * rated / 10000.0
        np.testing.assert_allclose(reader.wrench, want, rtol=1e-15, atol=0)


def test_foot_reader_wrong_offset_length_takes_the_general_path():
    reader = FootSensorReader(FedByteLink(), offset=(0.0,) * 5)
    assert not reader._skip_older
    reader.link.pending = lp.encode_response(lp.ForceData((1, 2, 3, 4, 5, 6), 20, 0))
    with pytest.raises(lp.LeptrinoError):
        reader.poll(0.0)


def test_leptrino_whole_frame_path_equals_byte_at_a_time():
    """Whole frames in one chunk take the regex path; byte-at-a-time never can."""
    gen = random.Random(11)
    stream = b""
    for _ in range(300):
        r = gen.random()
        payload = bytes(gen.choice([0x10, 0x02, 0x03, gen.randrange(256)]) for _ in range(20))
        if r < 0.55:
            stream += lp.frame(payload)
        elif r < 0.65:  # bad BCC
            stream += lp.frame(payload)[:-1] + bytes([gen.randrange(256)])
        elif r < 0.72:  # empty payload
            stream += b"\x10\x02\x10\x03" + bytes([gen.choice([3, 7])])
        elif r < 0.8:  # DLE STX inside a frame, then the frame
            stream += b"\x10\x02\x01\x02\x10\x02" + lp.frame(payload)[2:]
        elif r < 0.87:  # bad escape
            stream += b"\x10\x02\x05\x10\x07" + lp.frame(payload)
        else:
            stream += bytes(gen.choice([0x10, 0x02, 0x03, gen.randrange(256)]) for _ in range(5))
    whole, single = lp.LeptrinoStreamParser(), lp.LeptrinoStreamParser()
    calls = 0
    original = lp._WHOLE_FRAME

    class Counting:
        def match(self, data, pos):
            nonlocal calls
            calls += 1
            return original.match(data, pos)

    lp._WHOLE_FRAME = Counting()
    try:
        events_whole = whole.feed(stream)
    finally:
        lp._WHOLE_FRAME = original
    events_single = [e for b in stream for e in single.feed(bytes([b]))]
    assert repr(events_whole) == repr(events_single)
    assert whole == single  # counters, position, state and buffer
    assert calls > 150 and whole.frames > 150
    assert {"bcc", "length", "restart", "escape"} <= set(whole.errors)


def _state(p: lp.LeptrinoStreamParser) -> tuple:
    return (p.frames, dict(p.errors), p.discarded_bytes, p._state, bytes(p._buf), p._start, p._pos)


def _event_key(e: lp.StreamEvent) -> tuple:
    return (e.offset, e.payload, None if e.error is None else e.error.reason)


def _random_stream(rng: random.Random, n: int = 400) -> list[bytes]:
    """Samples (some with DLE bytes to stuff), result errors, acks, bad BCC, truncated frames,
    DLE STX restarts, bad escapes, over-long payloads and junk; one piece each."""
    out: list[bytes] = []
    for _ in range(n):
        kind = rng.random()
        raw = tuple(rng.choice([16, 0x1010, -4080, rng.randint(-32768, 32767)]) for _ in range(6))
        sample = lp.encode_response(lp.ForceData(raw, rng.choice([16, 25]), rng.choice([0, 16])))
        if kind < 0.6:
            out.append(sample)
        elif kind < 0.65:
            out.append(lp.encode_response(lp.ForceData(raw, 20, 0, result=1)))
        elif kind < 0.7:
            out.append(lp.encode_response(lp.Ack(lp.Command.DATA_STOP, lp.Result.OK, 0)))
        elif kind < 0.75:
            f = bytearray(sample)
            f[-1] ^= 0x21
            out.append(bytes(f))
        elif kind < 0.8:
            out.append(sample[: rng.randint(1, len(sample) - 1)])
        elif kind < 0.84:
            out.append(sample[:8] + b"\x10\x02" + sample[2:])
        elif kind < 0.88:
            out.append(sample[:6] + b"\x10\x55" + sample[6:])
        elif kind < 0.9:
            out.append(b"\x10\x02" + bytes([7]) * 300 + b"\x10\x03\x00")
        elif kind < 0.93:
            f = bytearray(sample)
            f[4] = 0x33  # another command byte
            out.append(bytes(f))
        else:
            out.append(bytes(rng.randint(0, 255) for _ in range(rng.randint(1, 5))))
    return out


def _chunks(pieces: list[bytes], rng: random.Random) -> list[bytes]:
    """Runs of whole pieces (as a UART read delivers them), now and then cut anywhere."""
    out, i = [], 0
    while i < len(pieces):
        n = rng.randint(1, 30)
        chunk = b"".join(pieces[i : i + n])
        i += n
        if rng.random() < 0.3:
            cut = rng.randint(0, len(chunk))
            out += [chunk[:cut], chunk[cut:]]
        else:
            out.append(chunk)
    return out


@pytest.mark.parametrize("seed", range(6))
def test_feed_ok_samples_matches_feed(seed):
    rng = random.Random(seed)
    data = _random_stream(rng)
    summed, framed, bytewise = (lp.LeptrinoStreamParser() for _ in range(3))
    summarised = 0
    for chunk in _chunks(data, rng):
        count, newest, rest = summed.feed_ok_samples(chunk)
        want = framed.feed(chunk)
        # the summarised run is a prefix of OK-sample payload events, newest last
        head, tail = want[:count], want[count:]
        assert all(e.error is None and lp.is_ok_sample(e.payload) for e in head)
        assert newest == (head[-1].payload if head else None)
        assert [_event_key(e) for e in rest] == [_event_key(e) for e in tail]
        assert _state(summed) == _state(framed)
        summarised += count
    for b in b"".join(data):
        bytewise.feed(bytes([b]))
    assert _state(summed)[:3] == _state(bytewise)[:3]
    assert summarised > 20
    assert summed.errors["bcc"] > 0 and summed.errors["restart"] > 0 and summed.discarded_bytes > 0


def test_feed_ok_samples_accepts_what_parse_response_accepts():
    """Independent check of the Rust classification: every payload it summarises parses to
    an OK ForceData, and every chunk of whole OK samples is summarised in full."""
    rng = random.Random(11)
    for _ in range(300):
        raws = [tuple(rng.randint(-32768, 32767) for _ in range(6)) for _ in range(25)]
        chunk = b"".join(lp.encode_response(lp.ForceData(r, 25, 0)) for r in raws)
        end, count, last_start, payload = _rdm.leptrino_ok_sample_run(chunk)
        assert (end, count) == (len(chunk), 25)
        resp = lp.parse_response(payload)
        assert isinstance(resp, lp.ForceData) and resp.result == lp.Result.OK
        assert resp.raw == raws[-1]
        assert chunk[last_start:] == lp.encode_response(lp.ForceData(raws[-1], 25, 0))


def test_feed_ok_samples_on_golden_frames():
    vectors = json.loads(VECTORS.read_text())["vectors"]
    for v in vectors:
        frame, payload = bytes.fromhex(v["frame"]), bytes.fromhex(v["payload"])
        parser, ref = lp.LeptrinoStreamParser(), lp.LeptrinoStreamParser()
        count, newest, rest = parser.feed_ok_samples(frame + frame)
        want = ref.feed(frame + frame)
        assert [e.payload for e in want] == [payload, payload]
        if lp.is_ok_sample(payload):
            assert (count, newest, rest) == (2, payload, [])
        else:
            assert count == 0 and [_event_key(e) for e in rest] == [_event_key(e) for e in want]
        assert _state(parser) == _state(ref)
    assert any(lp.is_ok_sample(bytes.fromhex(v["payload"])) for v in vectors)


def test_feed_ok_samples_while_not_idle_takes_the_general_path():
    sample = lp.encode_response(lp.ForceData((1, 2, 3, 4, 5, 6), 25, 0))
    summed, framed = lp.LeptrinoStreamParser(), lp.LeptrinoStreamParser()
    for p in (summed, framed):
        p.feed(sample[:7])  # mid-frame
    count, newest, rest = summed.feed_ok_samples(sample[7:] + sample * 2)
    want = framed.feed(sample[7:] + sample * 2)
    assert count == 0 and newest is None
    assert [_event_key(e) for e in rest] == [_event_key(e) for e in want]
    assert _state(summed) == _state(framed)


def test_ok_sample_run_on_bad_input():
    assert _rdm.leptrino_ok_sample_run(b"") == (0, 0, 0, None)
    assert _rdm.leptrino_ok_sample_run(b"\x10") == (0, 0, 0, None)
    assert _rdm.leptrino_ok_sample_run(b"\x10\x02" + b"\x10" * 99) == (0, 0, 0, None)
    with pytest.raises(TypeError):
        _rdm.leptrino_ok_sample_run("not bytes")
