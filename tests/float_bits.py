"""Bit-level float comparison shared by the fast-path tests (NaN equal to NaN, -0.0 not 0.0)."""

from __future__ import annotations

import numpy as np


def same_bits(x, y) -> bool:
    """Same shape and the same values, NaN where NaN, and the same sign bits (so 0.0 != -0.0)."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    return (
        x.shape == y.shape
        and np.array_equal(x, y, equal_nan=True)
        and np.array_equal(np.signbit(x), np.signbit(y))
    )
