"""``joint_lags`` against signals whose lag is known independently: a pure delay, and the
steady-state lag of a first-order system behind a ramp (= its time constant), simulated with
scipy's ``lsim``."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from rdm.scenarios.servo_lag import joint_lags

PLAN_T = np.linspace(0.0, 4.0, 21)
PLAN_Q = np.column_stack([0.3 * (1 - np.cos(np.pi * PLAN_T / 4.0)), 0.0 * PLAN_T])


@pytest.mark.parametrize("delay", [0.037, 0.0, -0.021])
def test_a_pure_delay_is_recovered(delay: float) -> None:
    t = np.arange(0.5, 3.5, 0.01)
    q = np.column_stack([np.interp(t - delay, PLAN_T, PLAN_Q[:, j]) for j in range(2)])
    lags = joint_lags(t, q, PLAN_T, PLAN_Q)
    assert abs(lags[0] - delay) <= 0.001
    assert np.isnan(lags[1])  # that joint's plan does not move


def test_a_first_order_servo_trails_a_ramp_by_its_time_constant() -> None:
    tau = 0.033
    plan_t = np.array([0.0, 1.0, 3.0])
    plan_q = np.array([[0.0], [0.0], [0.4]])
    t = np.arange(0.0, 3.0, 0.001)
    ramp = np.interp(t, plan_t, plan_q[:, 0])
    _, y, _ = signal.lsim(([1.0], [tau, 1.0]), ramp, t)
    win = (t > 1.5) & (t < 2.9)  # steady state of the ramp
    lags = joint_lags(t[win], y[win, None], plan_t, plan_q)
    assert abs(lags[0] - tau) <= 0.001


def test_bad_shapes_are_refused() -> None:
    with pytest.raises(ValueError):
        joint_lags(np.zeros(3), np.zeros((4, 2)), PLAN_T, PLAN_Q)
    with pytest.raises(ValueError):
        joint_lags(np.zeros(3), np.zeros((3, 2)), PLAN_T, PLAN_Q, max_lag_s=0.0)


def test_the_scenarios_lead_is_configurable_per_block():
    """``common.servo_lead`` sets the lead every scenario configuration takes; outside it
    the identified ``SIM_SERVO_LEAD_S``; out-of-range values are refused."""
    from rdm.scenarios import common, perching
    from rdm.scenarios.stack import SIM_SERVO_LEAD_S

    assert perching.onboard_config().servo_lead_s == SIM_SERVO_LEAD_S
    with common.servo_lead(0.0):
        assert perching.onboard_config().servo_lead_s == 0.0
        assert common.sim_stack_options(0, "inproc").onboard.servo_lead_s == 0.0
    assert common.sim_stack_options(0, "inproc").onboard.servo_lead_s == SIM_SERVO_LEAD_S
    for bad in (-0.01, 1.5, float("nan")):
        with pytest.raises(ValueError, match="servo_lead_s"), common.servo_lead(bad):
            pass
