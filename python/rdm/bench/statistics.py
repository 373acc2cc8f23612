"""Latency statistics of a long run: median, p99, p99.9 and max from per-call nanoseconds.

Percentiles use linear interpolation between the closest ranks (the definition numpy calls
``method="linear"``, its default), computed here from one sort so a 100,000-sample run
costs one ``O(n log n)`` pass; ``tests/test_bench_statistics.py`` checks them against
``numpy.percentile``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike


def percentile_sorted(sorted_values: np.ndarray, q: float) -> float:
    """The ``q``-th percentile (0..100) of already sorted values, linear interpolation.

    Rank ``h = (n - 1) q / 100``; the result is ``x[floor h] + (h - floor h)(x[floor h + 1]
    - x[floor h])``. Raises ``ValueError`` on an empty array or ``q`` outside [0, 100].
    """
    n = len(sorted_values)
    if n == 0:
        raise ValueError("percentile of an empty sample")
    if not 0.0 <= q <= 100.0 or math.isnan(q):
        raise ValueError(f"percentile `q` must be in [0, 100], got {q}")
    h = (n - 1) * (q / 100.0)
    lo = math.floor(h)
    hi = min(lo + 1, n - 1)
    x_lo = float(sorted_values[lo])
    return x_lo + (h - lo) * (float(sorted_values[hi]) - x_lo)


def percentiles(values: ArrayLike, qs: tuple[float, ...]) -> list[float]:
    """Several percentiles of unsorted ``values`` (one sort)."""
    x = np.sort(np.asarray(values, dtype=np.float64).ravel())
    return [percentile_sorted(x, q) for q in qs]


@dataclass(frozen=True)
class Summary:
    """Latency figures of one measured run, in microseconds."""

    n: int
    median_us: float
    p99_us: float
    p999_us: float
    max_us: float
    mean_us: float
    min_us: float

    def to_dict(self) -> dict[str, float | int]:
        """Plain dict (JSON-ready)."""
        return asdict(self)


def summarize_ns(ns: ArrayLike) -> Summary:
    """Summary of per-call durations given in nanoseconds.

    Raises ``ValueError`` for an empty sample or a non-finite/negative duration (a broken
    timer must not turn into a plausible figure).
    """
    x = np.asarray(ns, dtype=np.float64).ravel()
    if x.size == 0:
        raise ValueError("no samples")
    if not np.all(np.isfinite(x)) or np.any(x < 0):
        raise ValueError("durations must be finite and non-negative")
    us = np.sort(x) / 1000.0
    median, p99, p999 = (percentile_sorted(us, q) for q in (50.0, 99.0, 99.9))
    return Summary(
        n=int(us.size),
        median_us=median,
        p99_us=p99,
        p999_us=p999,
        max_us=float(us[-1]),
        mean_us=float(us.mean()),
        min_us=float(us[0]),
    )
