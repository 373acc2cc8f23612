"""Leptrino length and range edges: the 255-byte payload limit of the receiver, the 0..255
range of every one-byte field, and the bytes after a run of samples.

Frames are written out here byte by byte from the framing rule (``DLE STX``, payload with
every 0x10 doubled, ``DLE ETX``, BCC = XOR of the payload and ETX), independently of
:func:`rdm.protocol.leptrino.frame`.
"""

from __future__ import annotations

import functools
import operator
import struct

import pytest

from rdm.protocol import leptrino as lp

DLE, STX, ETX = 0x10, 0x02, 0x03


def written_frame(payload: bytes) -> bytes:
    """The frame of ``payload`` written out from the framing rule."""
    stuffed = b"".join(b"\x10\x10" if b == DLE else bytes([b]) for b in payload)
    check = functools.reduce(operator.xor, payload, ETX)
    return bytes([DLE, STX]) + stuffed + bytes([DLE, ETX, check])


def sample_payload(raw: tuple[int, ...], temperature: int = 25, status: int = 0) -> bytes:
    """A continuous-output sample: header, 6 int16 counts, int16 temperature, status, pad."""
    body = struct.pack("<6hhBx", *raw, temperature, status)
    return bytes([4 + len(body), 0, 0x32, 0]) + body


def feed_in(parser: lp.LeptrinoStreamParser, data: bytes, chunk: int) -> list:
    events = []
    for i in range(0, len(data), chunk):
        events += parser.feed(data[i : i + chunk])
    return events


# A payload with DLE bytes inside, so the stuffing is part of every edge below.
LONGEST = bytes((i * 7 + 1) % 256 for i in range(255))
TOO_LONG = LONGEST + b"\x10"  # the 256th byte arrives stuffed (DLE DLE)
TOO_LONG_PLAIN = LONGEST + b"\x01"  # the 256th byte arrives among plain bytes


def test_written_frames_have_the_stuffing_in_them():
    assert LONGEST.count(DLE) > 0
    assert len(written_frame(LONGEST)) == 2 + len(LONGEST) + LONGEST.count(DLE) + 3


def test_frame_takes_255_payload_bytes_and_refuses_256_and_0():
    assert lp.frame(LONGEST) == written_frame(LONGEST)
    for bad in (TOO_LONG, TOO_LONG_PLAIN, b""):
        with pytest.raises(lp.LeptrinoError) as err:
            lp.frame(bad)
        assert err.value.reason == "length"


@pytest.mark.parametrize("chunk", [1, 7, 10_000])
def test_parser_delivers_a_255_byte_payload_in_any_chunking(chunk):
    parser = lp.LeptrinoStreamParser()
    events = feed_in(parser, written_frame(LONGEST), chunk)
    assert [e.payload for e in events] == [LONGEST]
    assert parser.frames == 1 and parser.total_errors == 0


@pytest.mark.parametrize("chunk", [1, 7, 10_000])
@pytest.mark.parametrize("too_long", [TOO_LONG, TOO_LONG_PLAIN], ids=["dle_last", "plain_last"])
def test_parser_drops_a_256_byte_payload_counts_it_once_and_resyncs(chunk, too_long):
    good = sample_payload((1, -2, 3, -4, 5, -6))
    data = written_frame(too_long) + written_frame(good)
    parser = lp.LeptrinoStreamParser()
    events = feed_in(parser, data, chunk)
    assert [e.payload for e in events if e.error is None] == [good]
    overflow = [e for e in events if e.error is not None and e.error.reason == "overflow"]
    assert len(overflow) == 1 and overflow[0].offset == 0
    assert parser.errors["overflow"] == 1
    assert parser.frames == 1


@pytest.mark.parametrize(
    "make",
    [
        lambda v: lp.CommandFrame(lp.Command.GET_INF, sensor_no=v).encode(),
        lambda v: lp.set_digital_filter(v),
        lambda v: lp.encode_response(lp.Ack(command=v)),
        lambda v: lp.encode_response(lp.Ack(command=0x33, result=v)),
        lambda v: lp.encode_response(lp.Ack(command=0x33, term_no=v)),
        lambda v: lp.encode_response(lp.DigitalFilter(v)),
    ],
    ids=["sensor_no", "set_df", "ack_command", "ack_result", "ack_term_no", "get_df"],
)
def test_one_byte_fields_take_0_and_255_and_refuse_the_rest_by_name(make):
    for ok in (0, 255):
        frame = make(ok)
        assert frame[:2] == bytes([DLE, STX]) and frame[-3:-1] == bytes([DLE, ETX])
        assert ok in frame[2:-3]
    for bad in (256, -1, True, 2.0, "1"):
        with pytest.raises(lp.LeptrinoError) as err:
            make(bad)
        assert err.value.reason == "value"
        assert "not in 0..255" in str(err.value)


def test_one_byte_fields_land_in_their_header_slots():
    assert lp.CommandFrame(lp.Command.GET_INF, sensor_no=255).encode() == written_frame(
        bytes([4, 255, 0x2A, 0])
    )
    assert lp.set_digital_filter(255) == written_frame(bytes([8, 0xFF, 0xA6, 0, 255, 0, 0, 0]))
    assert lp.encode_response(lp.Ack(command=0x33, result=255, term_no=254)) == written_frame(
        bytes([4, 254, 0x33, 255])
    )


@pytest.mark.parametrize("tail_cut", [1, 5, 17])
def test_the_bytes_after_a_run_of_samples_complete_in_the_next_chunk(tail_cut):
    samples = [sample_payload((i, -i, 2 * i, 0, 0, i)) for i in range(1, 6)]
    last = sample_payload((100, 200, 300, 400, 500, 600), status=3)
    run = b"".join(written_frame(p) for p in samples)
    tail = written_frame(last)
    parser = lp.LeptrinoStreamParser()
    count, newest, events = parser.feed_ok_samples(run + tail[:tail_cut])
    assert count == len(samples) and newest == samples[-1]
    assert events == []
    count, newest, events = parser.feed_ok_samples(tail[tail_cut:])
    assert (count, newest) == (0, None)
    assert [e.payload for e in events] == [last]
    assert events[0].offset == len(run)
    assert parser.frames == len(samples) + 1 and parser.total_errors == 0
