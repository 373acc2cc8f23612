"""How far the true joints trail the planned joint path: the time shift that best explains
each joint's motion as the plan delayed (least squares over a grid of shifts).

Used to identify the feed-forward lead of the joint servo goals
(:attr:`rdm.nodes.onboard_config.OnboardConfig.servo_lead_s`; docs/scenarios.md) and to
report, per run, what is left of the lag once the lead is applied.
"""

from __future__ import annotations

import numpy as np


def joint_lags(
    t: np.ndarray,
    q_true: np.ndarray,
    plan_times: np.ndarray,
    plan_q: np.ndarray,
    max_lag_s: float = 0.15,
    step_s: float = 0.001,
    min_motion: float = 0.01,
) -> np.ndarray:
    """Per joint, the shift ``L`` [s] in ``[-max_lag_s, max_lag_s]`` (grid ``step_s``)
    minimising ``sum (q_plan(t - L) - q_true(t))^2`` over the samples ``t``; positive = the
    joint trails the plan. The plan is linear between its samples and held outside them (as
    the onboard node interpolates it). NaN for joints whose plan moves less than
    ``min_motion`` [rad] over the window (no lag to see)."""
    t = np.asarray(t, dtype=float)
    q_true = np.asarray(q_true, dtype=float)
    plan_times = np.asarray(plan_times, dtype=float)
    plan_q = np.asarray(plan_q, dtype=float)
    if q_true.ndim != 2 or q_true.shape[0] != t.size or plan_q.shape[1] != q_true.shape[1]:
        raise ValueError("joint_lags: t (n,), q_true (n, J) and plan_q (m, J) required")
    if not (max_lag_s > 0 and step_s > 0):
        raise ValueError("joint_lags: max_lag_s and step_s must be > 0")
    shifts = np.arange(-round(max_lag_s / step_s), round(max_lag_s / step_s) + 1) * step_s
    out = np.full(q_true.shape[1], np.nan)
    for j in range(q_true.shape[1]):
        planned = np.interp(t, plan_times, plan_q[:, j])
        if np.ptp(planned) < min_motion:
            continue
        cost = [
            float(np.sum((np.interp(t - s, plan_times, plan_q[:, j]) - q_true[:, j]) ** 2))
            for s in shifts
        ]
        out[j] = shifts[int(np.argmin(cost))]
    return out
