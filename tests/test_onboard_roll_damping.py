"""The deployed onboard configuration's roll loop (docs/onboard.md "Configuration files",
docs/flying.md "The hover's roll loop"): the shipped ``rdm.toml``'s LQI weights give the
straight posture's roll loop a least damping above 0.3 with the 10 ms ESC lag and Spinal's
gyro IIR, computed independently: scipy's LQR on MuJoCo's inertia and rotor allocation, then
the eigenvalues of a linear roll loop on MuJoCo's I_xx. Table V's roll weights (damping about
0.07, the 12 Hz ring) fail the same check."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from lqi_reference import hover_state_model
from test_flight_envelope import MujocoRobot

from rdm.nodes.onboard_config_file import EXAMPLE_FILE, load_onboard_file
from rdm.scenarios import hil_mission

#: Table V's W1 (JSK order), typed from the paper: the weights a revert would bring back.
TABLE_V_W1 = np.array([20, 30, 90, 12.8, 600, 80, 100, 50, 20, 0.15, 1, 0.5], dtype=float)
#: Rotor (ESC + motor) lag, s (``StackOptions.esc_tau``).
ESC_TAU_S = 0.010
#: Spinal's gyro IIR ``p -= p/12; p += x`` at 1 kHz as a first-order lag: a pole of 11/12 per
#: 1 ms sample, time constant -1 ms / ln(11/12) = 11.5 ms.
GYRO_TAU_S = -1e-3 / np.log(11.0 / 12.0)
#: Least damping ratio the roll loop must keep.
MIN_DAMPING = 0.3


@pytest.fixture(scope="module")
def straight() -> tuple[float, np.ndarray, np.ndarray]:
    """(mass, inertia about the CoG, allocation rows fz, mx, my, mz) of the levelled straight
    posture, from MuJoCo alone."""
    mj = MujocoRobot()
    mj.levelled(np.zeros(6))
    wrench, mass = mj.rotor_wrenches()
    return mass, mj.inertia(), wrench[2:6]


def roll_loop_damping(
    straight: tuple[float, np.ndarray, np.ndarray], q_weights: np.ndarray, r_weights: np.ndarray
) -> float:
    """Least damping ratio of the roll loop: phi' = w, I_xx w' = T, T' = (u - T)/tau_esc,
    w_f' = (w - w_f)/tau_gyro, xi' = -phi, u = the LQR's roll torque on (phi, w_f, xi)."""
    mass, inertia, qbar = straight
    a, b = hover_state_model(mass, inertia, qbar)
    r = np.diag(r_weights)
    p = scipy.linalg.solve_continuous_are(a, b, np.diag(q_weights), r)
    k = -np.linalg.solve(r, b.T @ p)
    k_phi, k_w, k_xi = qbar[1] @ k[:, 2], qbar[1] @ k[:, 3], qbar[1] @ k[:, 9]
    ixx = inertia[0, 0]
    te, tf = ESC_TAU_S, GYRO_TAU_S
    f = np.array(
        [
            [0.0, 1.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 1.0 / ixx, 0.0, 0.0],
            [k_phi / te, 0.0, -1.0 / te, k_w / te, k_xi / te],
            [0.0, 1.0 / tf, 0.0, -1.0 / tf, 0.0],
            [-1.0, 0.0, 0.0, 0.0, 0.0],
        ]
    )
    ev = np.linalg.eigvals(f)
    assert ev.real.max() < 0.0
    return float(min(-e.real / abs(e) for e in ev))


def _weights(config) -> tuple[np.ndarray, np.ndarray]:
    q = config.lqi_q_weights
    r = config.lqi_r_weights
    assert q is not None, "the shipped rdm.toml must set lqi_q_weights"
    return np.array(q, dtype=float), np.ones(4) if r is None else np.array(r, dtype=float)


def test_shipped_config_damps_the_roll_loop(straight) -> None:
    q, r = _weights(load_onboard_file(EXAMPLE_FILE).config)
    assert roll_loop_damping(straight, q, r) > MIN_DAMPING  # 0.41


def test_table_v_roll_weights_fail_the_check(straight) -> None:
    """The check can fail: Table V's roll weights on the shipped file's others ring."""
    q, r = _weights(load_onboard_file(EXAMPLE_FILE).config)
    q[2:4] = TABLE_V_W1[2:4]
    assert roll_loop_damping(straight, q, r) < 0.1  # 0.07


def test_hil_mission_flies_the_shipped_weights(tmp_path) -> None:
    """The process-level mission's configuration file loads and carries the same weights."""
    path = tmp_path / "onboard.toml"
    path.write_text(hil_mission.ONBOARD_TOML)
    shipped = load_onboard_file(EXAMPLE_FILE).config
    assert load_onboard_file(path).config.lqi_q_weights == shipped.lqi_q_weights
