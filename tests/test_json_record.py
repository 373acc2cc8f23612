"""The fast JSON record writer against ``json.dumps`` (the logger's general path)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from rdm.sim.json_record import encode_record
from rdm.sim.mcap_log import McapLogger, _jsonable


def reference(values: dict) -> str:
    return json.dumps(_jsonable(dict(values)), separators=(",", ":"))


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
    assert encode_record(record) == reference(record)


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
    ],
)
def test_outside_the_fast_path_returns_none(record: dict) -> None:
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
    assert encode_record(record) == reference(record)


def test_logger_writes_the_same_bytes_as_the_general_path(tmp_path) -> None:
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
