"""The onboard node's input check (``rdm.nodes.onboard_operator._vector``, its common case in
``_rdm.finite_float_vector``) against numpy's reading of the rule, on lists, tuples and other
values of every kind: ``np.asarray(value, dtype=float)`` of n values, all finite, else None;
the same None or the same float64 array (values and bits)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rdm import _rdm
from rdm.nodes.onboard_operator import _vector


class FloatSub(float):
    """A float subclass: not the exact-float case, numpy converts it."""


def _cases(rng: np.random.Generator) -> list[tuple[object, int]]:
    specials = [math.nan, math.inf, -math.inf, -0.0, 0.0, 5e-324, 1.7976931348623157e308]
    out: list[tuple[object, int]] = []
    for _ in range(3000):
        n = int(rng.integers(0, 20))
        values: list[object] = [float(v) for v in rng.normal(0.0, 10.0 ** rng.integers(-5, 6), n)]
        kind = rng.random()
        if kind < 0.15 and values:
            values[int(rng.integers(0, n))] = specials[int(rng.integers(0, len(specials)))]
        elif kind < 0.25 and values:
            values[int(rng.integers(0, n))] = int(rng.integers(-3, 3))
        elif kind < 0.3 and values:
            values[int(rng.integers(0, n))] = np.float64(1.5)
        elif kind < 0.35 and values:
            values[int(rng.integers(0, n))] = FloatSub(2.5)
        elif kind < 0.38 and values:
            values[int(rng.integers(0, n))] = True
        container = list if rng.random() < 0.5 else tuple
        asked = n if rng.random() < 0.8 else int(rng.integers(0, 20))
        out.append((container(values), asked))
    out += [
        (np.array([1.0, 2.0, 3.0]), 3),
        (np.array([1, 2, 3]), 3),
        ("abc", 3),
        (None, 3),
        ([[1.0], [2.0], [3.0]], 3),
        ((1.0, 2.0), 2),
        ([], 0),
        ([1.0] * 17, 17),  # beyond the Rust call's 16 slots: numpy
        ([1.0] * 16, 16),
    ]
    return out


def _numpy(value: object, n: int) -> np.ndarray | None:
    """The rule as numpy states it: n float64 values, all finite, else None."""
    try:
        v = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        return None
    return v if v.shape == (n,) and bool(np.isfinite(v).all()) else None


def _same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def test_vector_is_numpys_reading_on_random_values():
    rng = np.random.default_rng(1616)
    cases = _cases(rng)
    rust_taken = 0
    for value, n in cases:
        got, want = _vector(value, n), _numpy(value, n)
        assert _same(got, want), (value, n, got, want)
        rust_taken += _rdm.finite_float_vector(value, n) is not None
    assert rust_taken > 1000  # the Rust call decided many of them


@pytest.mark.parametrize(
    ("value", "n", "expected"),
    [
        ([1.0, 2.0, 3.0], 3, "array"),
        ((1.0, 2.0, 3.0), 3, "array"),
        ([1.0, math.nan, 3.0], 3, False),
        ((math.inf,), 1, False),
        ([1.0, 2.0], 3, None),  # wrong length: numpy decides
        ([1.0, 2, 3.0], 3, None),  # an int
        ([1.0, np.float64(2.0), 3.0], 3, None),  # a float subclass
        (np.zeros(3), 3, None),  # not a list or tuple
    ],
)
def test_finite_float_vector_states_its_three_answers(value, n, expected):
    got = _rdm.finite_float_vector(value, n)
    if expected == "array":
        assert isinstance(got, np.ndarray) and got.dtype == np.float64
        assert got.tolist() == list(value)
    else:
        assert got is expected


@pytest.mark.parametrize(
    "value",
    [
        (0.1, -2.5, 3e-9),
        [0.0, -0.0, 1e300],
        (0.1, float("nan"), 0.0),
        (float("inf"), 0.0, 0.0),
        (1, 2, 3),  # ints
        (0.1, 0.2),
        (0.1, 0.2, 0.3, 0.4),
        [[0.1], [0.2], [0.3]],
        ("0.5", 1.0, 2.0),
        ("x", 1.0, 2.0),
        None,
        np.array([0.1, -2.5, 3e-9]),
        np.array([0.0, -0.0, np.nan]),
        np.array([0.0, -np.inf, 1.0]),
        np.array([1.0, 2.0, 3.0, 4.0])[::2][:3],  # a strided view, length 2
        np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])[::2],  # a strided view, length 3
        np.array([[0.1, 0.2, 0.3]]),
        np.array([1, 2, 3]),
        np.array([0.1, 0.2, 0.3], dtype=np.float32),
    ],
)
def test_vector_of_fixed_values_is_numpys_reading(value):
    got, want = _vector(value, 3), _numpy(value, 3)
    assert (got is None) == (want is None), (got, want)
    if want is not None:
        assert _same(got, want)
        # a float64 vector stays a view of the caller's memory, as numpy reads it (a script
        # that later writes its setpoint in place moves the target too)
        assert np.shares_memory(got, value) == np.shares_memory(want, value)
