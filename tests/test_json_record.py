"""The MCAP writer's flat JSON records (``McapWriter.add_record``, the text encoded in Rust
straight into the chunk) against ``json.dumps``, read back with the ``mcap`` package's reader;
and the logger, which writes what the Rust encoder declines with ``json.dumps``."""

from __future__ import annotations

import io
import json
import math
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from rdm.sim.mcap_log import McapLogger
from rdm.sim.mcap_writer import McapWriter


def _plain(v: Any) -> Any:
    """A record value as the plain values ``json.dumps`` takes (NaN and infinities None)."""
    if isinstance(v, np.ndarray):
        return [_plain(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (float, np.floating)):
        return float(v) if math.isfinite(v) else None
    if isinstance(v, np.integer):
        return int(v)
    return v


def logged_text(values: dict) -> str:
    """The text ``McapLogger.log_json`` writes for ``values`` on a known channel (the Rust
    encoder's, or ``json.dumps``'s for what it declines), read back with the ``mcap`` reader."""
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "x.mcap"
        with McapLogger(path) as log:
            log.log_json("/r", 0.0, {"first": 0.0})
            log.log_json("/r", 1.0, values)
        with open(path, "rb") as f:
            msgs = [m.data.decode() for _, _, m in make_reader(f).iter_messages()]
    assert len(msgs) == 2
    return msgs[1]


def reference(values: dict) -> str:
    return json.dumps(_plain(dict(values)), separators=(",", ":"))


def encode_record(values: Any) -> str | None:
    """The text ``McapWriter.add_record`` writes for ``values`` (read back from the file with
    the ``mcap`` reader), or None when it declines."""
    out = io.BytesIO()
    w = McapWriter(out, chunk_size=1 << 20)
    w.start()
    cid = w.register_channel("/r", "json", w.register_schema("r", "jsonschema", b"{}"))
    taken = w.add_record(cid, 5, 0, values)
    w.finish()
    msgs = [m for _, _, m in make_reader(io.BytesIO(out.getvalue())).iter_messages()]
    if not taken:
        assert msgs == []
        return None
    (m,) = msgs
    assert (m.channel_id, m.log_time, m.publish_time, m.sequence) == (cid, 5, 5, 0)
    return m.data.decode()


SPECIALS = np.array(
    [
        0.0,
        -0.0,
        np.nan,
        -np.nan,
        np.inf,
        -np.inf,
        5e-324,
        -5e-324,
        2.2250738585072014e-308,
        np.finfo(float).max,
        1e16,
        1e15,
        9999999999999998.0,
        1e-4,
        9.999999999999999e-05,
        1e-5,
        0.1,
        1 / 3,
        123456789012345678.0,
        1.0,
        -1.0,
        0.5,
        2.5e-7,
        1e22,
        1e21,
    ]
)


def test_random_bit_patterns_match_json_dumps() -> None:
    rng = np.random.default_rng(7)
    bits = rng.integers(0, 2**64, size=200_000, dtype=np.uint64)
    values = bits.view(np.float64)
    # Every exponent, plus values in the fixed-notation range that physics logs hold.
    scaled = rng.standard_normal(50_000) * 10.0 ** rng.integers(-8, 18, size=50_000)
    for arr in (values, scaled, SPECIALS):
        record = {"a": arr}
        assert encode_record(record) == reference(record)


def test_strided_array_and_scalars() -> None:
    arr = np.arange(24, dtype=float).reshape(4, 6) / 7.0
    record = {
        "time": 0.123,
        "col": arr[:, 2],  # not contiguous
        "flag": True,
        "np_flag": np.bool_(False),
        "count": 3,
        "np_count": np.int64(-12),
        "np_float": np.float64(-0.0),
        "nan": float("nan"),
        "none": None,
        "state": 'perched \u00e9"x\\',
        "floats": [1.5, float("inf"), -2e-9],
        "empty": [],
    }
    assert logged_text(record) == reference(record)


@pytest.mark.parametrize(
    "record",
    [
        {"nested": {"a": 1.0}},
        {"matrix": np.eye(2)},
        {"ints": np.arange(3)},
        {"mixed": [1.0, 2]},
        {3: 1.0},
        {'q"uote': 1.0},
        {"obj": object()},
        {"big": 2**63},  # beyond i64
        {"s": "\ud800"},  # a lone surrogate
        [("a", 1.0)],  # not a dict
    ],
)
def test_outside_the_flat_form_is_declined(record: dict) -> None:
    assert encode_record(record) is None


@settings(max_examples=300, deadline=None)
@given(
    st.dictionaries(
        st.from_regex(r"[a-z_]{1,8}", fullmatch=True),
        st.one_of(
            st.floats(allow_nan=True, allow_infinity=True),
            st.integers(-(2**70), 2**70),
            st.booleans(),
            st.none(),
            st.text(max_size=6),
            st.lists(st.floats(), max_size=5),
            st.lists(st.floats(width=64), max_size=5).map(lambda x: np.array(x, dtype=float)),
        ),
        max_size=6,
    )
)
def test_hypothesis_records_match_json_dumps(record: dict) -> None:
    text = encode_record(record)
    assert text is None or text == reference(record)
    assert logged_text(record) == reference(record)


def test_edge_values() -> None:
    record = {
        "specials": np.array([0.0, -0.0, np.nan, np.inf, -np.inf, 5e-324, 1e16, 1e-5, 0.1]),
        "s": 'perched \u00e9"x\\\u0000\U0001f600',
        "big": 2**63 - 1,
        "neg": -(2**63),
        "f64": np.float64(-0.0),
        "b": True,
        "none": None,
        "list": [float("nan"), -0.0, 1e300],
    }
    assert encode_record(record) == reference(record)
    assert encode_record({}) == "{}"


def _random_value(rng: np.random.Generator) -> Any:
    bits = rng.integers(0, 2**64, size=4, dtype=np.uint64).view(np.float64)
    choices = [
        lambda: float(bits[0]),
        lambda: float(rng.standard_normal() * 10.0 ** rng.integers(-8, 18)),
        lambda: np.float64(bits[1]),
        lambda: bool(rng.integers(2)),
        lambda: np.bool_(rng.integers(2)),
        lambda: int(rng.integers(-(2**62), 2**62)),
        lambda: 2**70 + int(rng.integers(100)),
        lambda: np.int64(rng.integers(-1000, 1000)),
        lambda: None,
        lambda: "".join(rng.choice(list('ab "\\\n\t\x01\x7f\u00e9\u2603\U0001f600'), 5)),
        lambda: bits.copy(),
        lambda: np.arange(12, dtype=float).reshape(3, 4)[:, 1] * bits[2],  # strided
        lambda: bits.reshape(2, 2),
        lambda: bits.astype(np.float32),
        lambda: bits.astype(">f8"),
        lambda: np.array([True, False]),
        lambda: [float(b) for b in bits],
        lambda: [np.float64(b) for b in bits],
        lambda: [1.0, 2],
        lambda: [],
        lambda: {"nested": 1.0},
        lambda: (1.0, 2.0),
    ]
    return choices[int(rng.integers(len(choices)))]()


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_random_records_are_json_dumps_text_or_declined(tmp_path) -> None:
    rng = np.random.default_rng(11)
    records = []
    for _ in range(1500):
        keys = rng.choice(["t", "base_position", "a/b.c:d+e-f g", 'q"uote', "\u00e9", "x"], 4)
        record = {str(k): _random_value(rng) for k in keys}
        if rng.integers(10) == 0:
            record[3] = 1.0  # a non-str key
        records.append(record)
    out = io.BytesIO()
    w = McapWriter(out, chunk_size=4096)
    w.start()
    cid = w.register_channel("/r", "json", w.register_schema("r", "jsonschema", b"{}"))
    taken = [r for r in records if w.add_record(cid, 0, 0, r)]
    w.finish()
    got = [m.data.decode() for _, _, m in make_reader(io.BytesIO(out.getvalue())).iter_messages()]
    assert 40 < len(taken) < len(records) - 100  # both kinds, many times
    assert got == [reference(r) for r in taken]
    # the logger writes every record, the declined ones by json.dumps
    logged = [r for r in records if all(type(k) is str for k in r)]
    with McapLogger(tmp_path / "x.mcap") as log:
        for r in logged:
            log.log_json("/r", 0.0, r)
    with open(tmp_path / "x.mcap", "rb") as f:
        got = [m.data.decode() for _, _, m in make_reader(f).iter_messages()]
    assert got == [reference(r) for r in logged]


def test_logger_writes_json_dumps_text(tmp_path) -> None:
    rng = np.random.default_rng(1)
    records = [
        {"t": i * 0.01, "v": rng.standard_normal(5), "ok": bool(i % 2), "n": i, "s": "x"}
        for i in range(20)
    ]
    records[5]["v"][2] = np.nan
    path = tmp_path / "a.mcap"
    with McapLogger(path) as log:
        for r in records:
            log.log_json("/rec", r["t"], r)
    with open(path, "rb") as f:
        got = [m.data for _, _, m in make_reader(f).iter_messages()]
    assert got == [reference(r).encode() for r in records]
