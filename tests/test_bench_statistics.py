"""rdm.bench.statistics against numpy.percentile (an independent implementation)."""

from __future__ import annotations

import numpy as np
import pytest

from rdm.bench.statistics import percentile_sorted, percentiles, summarize_ns


@pytest.mark.parametrize("n", [1, 2, 3, 10, 999, 1000, 100_001])
def test_percentiles_match_numpy_linear(n: int) -> None:
    rng = np.random.default_rng(n)
    # Heavy-tailed like real latencies, with ties.
    x = np.round(rng.lognormal(0.0, 1.5, n) * 1000.0)
    qs = (0.0, 1.0, 25.0, 50.0, 90.0, 99.0, 99.9, 99.99, 100.0)
    ours = percentiles(x, qs)
    np.testing.assert_allclose(ours, np.percentile(x, qs), rtol=1e-12, atol=0.0)


def test_summary_matches_numpy() -> None:
    rng = np.random.default_rng(3)
    ns = rng.integers(200, 5_000_000, 54_321)
    s = summarize_ns(ns)
    us = ns / 1000.0
    assert s.n == ns.size
    for field, q in (("median_us", 50), ("p99_us", 99), ("p999_us", 99.9)):
        assert getattr(s, field) == pytest.approx(np.percentile(us, q), rel=1e-12)
    assert s.max_us == us.max()
    assert s.min_us == us.min()
    assert s.mean_us == pytest.approx(us.mean(), rel=1e-12)


def test_bad_samples_are_rejected() -> None:
    with pytest.raises(ValueError, match="no samples"):
        summarize_ns([])
    with pytest.raises(ValueError, match="finite"):
        summarize_ns([1.0, np.nan])
    with pytest.raises(ValueError, match="finite"):
        summarize_ns([5, -1])
    with pytest.raises(ValueError, match="q"):
        percentile_sorted(np.arange(3.0), 101.0)
    with pytest.raises(ValueError, match="empty"):
        percentile_sorted(np.array([]), 50.0)
