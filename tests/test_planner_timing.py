"""``rdm.planner.timing``: the profiles against their closed forms, checked by finite
differences of the samples."""

from __future__ import annotations

import numpy as np
import pytest

from rdm.planner import timing


def test_ruckig_profile_against_finite_differences_of_a_straight_line():
    """One straight segment of 0.6 rad: duration and peak speed against the analytic
    jerk-limited rest-to-rest profile (v_max reached, a_max reached)."""
    line = np.outer(np.linspace(0.0, 1.0, 5), [0.6, -0.3, 0, 0, 0, 0])
    t, q = timing.time_parameterise(line, 0.15, 0.15, 0.5, sample_s=0.001)
    v, a, j = 0.15, 0.15, 0.5
    # time to reach v: a/j (jerk) + (v/a - a/j) (constant a) + a/j; cruise covers the rest
    t_acc = v / a + a / j
    expected = 2 * t_acc + (0.6 - v * t_acc) / v
    assert t[-1] == pytest.approx(expected, rel=1e-3)
    speed = np.abs(np.diff(q[:, 0]) / np.diff(t))
    assert speed.max() == pytest.approx(v, rel=1e-3)


def test_cosine_profile_over_a_duration():
    """A polyline with a corner: samples every 25 ms on it, the last sample the end state,
    at rest at both ends, peak speed pi/2 * L / T (the cosine's), the start not repeated."""
    poly = np.array([[0.0] * 6, [0.2, 0.1, 0, 0, 0, 0], [0.2, 0.5, 0, 0, 0, 0]])
    t, q = timing.over_duration(poly, 2.0)
    assert t[0] == pytest.approx(timing.SAMPLE_S) and t[-1] == 2.0
    assert np.allclose(np.diff(t), timing.SAMPLE_S)
    assert np.array_equal(q[-1], poly[-1])
    length = 0.2 + 0.4  # largest joint change per segment
    s = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(np.vstack([poly[:1], q]), axis=0)).max(1))])
    speed = np.diff(s) / np.diff(np.r_[0.0, t])
    assert speed.max() == pytest.approx(np.pi / 2 * length / 2.0, rel=2e-3)
    assert speed[0] < 0.02 * speed.max() and speed[-1] < 0.02 * speed.max()
    # on the polyline: the first segment keeps q2 = q1 / 2, the second q1 = 0.2
    first = q[:, 0] < 0.2 - 1e-12
    assert np.allclose(q[first, 1], q[first, 0] / 2)
    assert np.allclose(q[~first, 0], 0.2)


def test_bad_input_is_a_one_line_error():
    with pytest.raises(ValueError, match="duration: must be > 0 s"):
        timing.over_duration(np.zeros((2, 6)), 0.0)
    with pytest.raises(ValueError, match="q: expected a non-empty"):
        timing.time_parameterise(np.full((2, 6), np.nan), 0.1, 0.1, 0.1)
