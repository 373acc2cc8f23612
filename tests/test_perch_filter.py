"""The 1 Hz foot-wrench IIR filter (Sec. VII-B) against scipy.signal."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from rdm.control.perch import PerchError, WrenchFilter


@pytest.mark.parametrize(("cutoff", "rate"), [(1.0, 40.0), (1.0, 100.0), (2.5, 40.0)])
def test_coefficients_equal_scipy_first_order_butterworth(cutoff: float, rate: float) -> None:
    b, a = signal.butter(1, cutoff, fs=rate)
    b0, b1, a1 = WrenchFilter(cutoff, rate).coefficients()
    assert np.allclose([b0, b1], b, rtol=1e-13, atol=0)
    assert np.allclose([1.0, a1], a, rtol=1e-13, atol=1e-15)


def test_minus_3db_point_is_the_cutoff() -> None:
    b0, b1, a1 = WrenchFilter(1.0, 40.0).coefficients()
    _, h = signal.freqz([b0, b1], [1.0, a1], worN=[1.0], fs=40.0)
    assert abs(20 * np.log10(abs(h[0])) - 20 * np.log10(np.sqrt(0.5))) < 1e-9
    _, h_dc = signal.freqz([b0, b1], [1.0, a1], worN=[0.0], fs=40.0)
    assert abs(abs(h_dc[0]) - 1.0) < 1e-12


def test_output_equals_lfilter_started_in_steady_state() -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(size=(500, 6)) * [5, 5, 20, 0.5, 0.5, 1] + [0, 0, 15, 0, 0, 0]
    f = WrenchFilter(1.0, 40.0)
    ours = np.array([f.update(row) for row in x])
    b0, b1, a1 = f.coefficients()
    b, a = np.array([b0, b1]), np.array([1.0, a1])
    zi = signal.lfilter_zi(b, a)
    ref = np.column_stack([signal.lfilter(b, a, x[:, k], zi=zi * x[0, k])[0] for k in range(6)])
    assert np.max(np.abs(ours - ref)) < 1e-11


def test_non_finite_sample_is_refused_and_state_kept() -> None:
    f = WrenchFilter(1.0, 40.0)
    f.update(np.ones(6))
    y1 = f.update(np.full(6, 2.0))
    assert f.update(np.array([np.nan, 0, 0, 0, 0, 0])) is None
    y2 = f.update(np.full(6, 2.0))
    b0, b1, a1 = f.coefficients()
    assert np.allclose(y2, b0 * 2 + b1 * 2 - a1 * y1)


def test_cutoff_above_nyquist_is_refused() -> None:
    with pytest.raises(PerchError, match="cutoff_hz"):
        WrenchFilter(25.0, 40.0)
