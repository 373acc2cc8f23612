"""The hover LQI state model of eqs. (21)-(26) built in numpy (JSK state order), the test-side
reference the Rust synthesis and the flight-envelope poles are checked against with scipy."""

from __future__ import annotations

import numpy as np


def hover_state_model(
    mass: float, inertia: np.ndarray, allocation_bar: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(A, B): states (z, dz, roll, droll, pitch, dpitch, yaw, dyaw, 4 integrals), inputs the
    rotor thrusts (one column of ``allocation_bar`` each: rows force z, moment x, y, z)."""
    a = np.zeros((12, 12))
    for i in range(4):
        a[2 * i, 2 * i + 1] = 1.0
        a[8 + i, 2 * i] = -1.0
    b = np.zeros((12, allocation_bar.shape[1]))
    b[1] = allocation_bar[0] / mass
    b[3], b[5], b[7] = np.linalg.solve(inertia, allocation_bar[1:4])
    return a, b
