"""Leptrino counts <-> wrench (``rdm.protocol.leptrino``) against the rules written out with
numpy: ``(raw - offset) * rated / 10000`` per axis with a non-zero tare, the JSK node's
truncation toward zero to mN and uN m (negative values included), the int16 range closed at
both ends, and the ``value`` reason of every refusal. Catches a tare added instead of
subtracted, an offset not passed on, an open range edge."""

from __future__ import annotations

import struct
from fractions import Fraction

import numpy as np
import pytest

from rdm.protocol.leptrino import (
    MODELS,
    RAW_AT_RATED,
    ForceData,
    LeptrinoError,
    LeptrinoStreamParser,
    cfs_node_wrench,
    decode_leptrino,
    encode_response,
    from_wrench,
    parse_response,
    to_wrench,
)

FOOT = "CFS034CA301U"
RATED = np.array(MODELS[FOOT].rated)
RAW = (1234, -2345, 9876, -321, 45, -7000)
TARE = (100.5, -200.0, 300.0, -40.0, 5.0, 60.0)


def test_counts_to_wrench_subtract_the_tare_on_every_axis() -> None:
    expected = (np.array(RAW) - np.array(TARE)) * RATED / RAW_AT_RATED
    np.testing.assert_allclose(to_wrench(RAW, FOOT, TARE), expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ForceData(RAW).wrench(FOOT, TARE), expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ForceData(RAW).wrench(FOOT), np.array(RAW) * RATED / 1e4)


def test_the_jsk_node_truncates_toward_zero_to_millinewtons_and_micronewton_metres() -> None:
    """Exact rationals (``fractions``) as the oracle: -2145 counts x 150 N / 10000 is exactly
    -32.175 N, which float arithmetic in another order would truncate to -32.174."""
    scale = [1000] * 3 + [1_000_000] * 3
    expected = [
        int((Fraction(r) - Fraction(o)) * Fraction(k) / RAW_AT_RATED * s) / s
        for r, o, k, s in zip(RAW, TARE, MODELS[FOOT].rated, scale, strict=True)
    ]
    got = cfs_node_wrench(RAW, FOOT, TARE)
    assert got == pytest.approx(expected, rel=0, abs=1e-12)
    assert got[1] == -32.175  # toward zero, and not one mN short of it


def test_wrench_to_counts_covers_the_whole_int16_range_and_no_more() -> None:
    low = RATED * -0x8000 / RAW_AT_RATED
    high = RATED * 0x7FFF / RAW_AT_RATED
    assert from_wrench(tuple(low), FOOT) == (-0x8000,) * 6
    assert from_wrench(tuple(high), FOOT) == (0x7FFF,) * 6
    for axis in range(6):
        for edge, step in ((low, -1), (high, +1)):
            w = edge.copy()
            w[axis] += step * RATED[axis] / RAW_AT_RATED  # one count beyond
            with pytest.raises(LeptrinoError, match=f"axis {axis}") as err:
                from_wrench(tuple(w), FOOT)
            assert err.value.reason == "value"


@pytest.mark.parametrize(
    "call",
    [
        lambda: to_wrench(RAW[:5], FOOT),
        lambda: to_wrench(RAW, FOOT, TARE[:5]),
        lambda: to_wrench(RAW, "nosuch"),
        lambda: from_wrench((0.0,) * 5, FOOT),
        lambda: from_wrench((0.0, 0.0, float("nan"), 0.0, 0.0, 0.0), FOOT),
    ],
)
def test_every_refusal_is_a_value_error_with_its_reason(call) -> None:
    with pytest.raises(LeptrinoError) as err:
        call()
    assert err.value.reason == "value" and str(err.value).startswith("value: ")


def _framed(payload: bytes) -> bytes:
    """DLE STX, the payload with each DLE doubled, DLE ETX, then the BCC: the XOR of the
    payload and ETX (the Leptrino manual's frame, written out here)."""
    bcc = 0x03
    for b in payload:
        bcc ^= b
    return b"\x10\x02" + payload.replace(b"\x10", b"\x10\x10") + b"\x10\x03" + bytes([bcc])


@pytest.mark.parametrize(
    ("cmd", "body", "expected"),
    [
        (0x2B, struct.pack("<6f", 150, 150, 300, 4, 4, 4), "RatedValues"),
        (0x32, struct.pack("<6hhBx", *RAW, 25, 0), "ForceData"),
        (0xB6, bytes([3, 0, 0, 0]), "DigitalFilter"),
        (0x33, b"", "Ack"),
    ],
)
def test_a_response_keeps_its_result_and_sensor_number(cmd, body, expected) -> None:
    """Header bytes ``len, term_no, command, result`` (written out): a parsed response keeps
    the sensor's result code and sensor number, which name the sensor that answered."""
    payload = bytes([4 + len(body), 7, cmd, 3]) + body
    resp = parse_response(payload)
    assert type(resp).__name__ == expected
    assert (resp.result, resp.term_no) == (3, 7)
    assert encode_response(resp) == _framed(payload)


def test_each_damaged_frame_is_counted() -> None:
    """Two frames with a wrong BCC and one with a bad escape: the counters say 2 and 1."""
    good = _framed(bytes([4, 0, 0x32, 0]))
    bad_bcc = good[:-1] + bytes([good[-1] ^ 0xFF])
    bad_escape = b"\x10\x02\x04\x00\x10\x41"
    parser = LeptrinoStreamParser()
    events = parser.feed(bad_bcc + bad_bcc + bad_escape + good)
    assert parser.errors == {"bcc": 2, "escape": 1}
    assert [e.error is None for e in events] == [False, False, False, True]
    records = list(decode_leptrino(bad_bcc + bad_bcc + good))
    assert [r["ok"] for r in records] == [False, False, True]
