"""The lost-rotor detection and the feasibility figure behind its reaction
(``rdm.nodes.onboard_rotor_loss``).

* :func:`diverging_axis`: trips only when the error is beyond the angle **and** the gyro turns
  it further beyond the rate (catches a dropped sign test: a swing back to the target is no
  fault; a dropped rate test: a slow lean is none either).
* :func:`three_rotor_hover_tilt` on the shipped robot against scipy: ``linprog`` finds no
  nonnegative thrusts of the three remaining rotors that balance roll and pitch level, and
  the smallest offset of a thrust centroid from the CoG comes from ``nnls`` over convex
  weights (not the function's segment search).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linprog, nnls

from rdm.model import Robot
from rdm.nodes.onboard_monitors import MonitorLimits
from rdm.nodes.onboard_rotor_loss import diverging_axis, three_rotor_hover_tilt

LIM = MonitorLimits()
TILT, RATE = LIM.rotor_loss_tilt_rad, LIM.rotor_loss_rate_rad_s


def test_diverging_needs_angle_rate_and_the_same_sign() -> None:
    assert diverging_axis(TILT, RATE, (-0.17, 0.0), (0.0, 0.0), (-5.0, 0.0)) == "roll"
    assert diverging_axis(TILT, RATE, (0.0, 0.2), (0.0, 0.0), (0.0, 4.0)) == "pitch"
    # swinging back towards the target
    assert diverging_axis(TILT, RATE, (-0.17, 0.0), (0.0, 0.0), (5.0, 0.0)) is None
    # a slow lean, and a fast turn inside the angle (a turn starting from the target)
    assert diverging_axis(TILT, RATE, (-0.3, 0.0), (0.0, 0.0), (-1.0, 0.0)) is None
    assert diverging_axis(TILT, RATE, (-0.004, 0.0), (0.0, 0.0), (-6.0, 0.0)) is None
    # the error counts against the target, not against level
    assert diverging_axis(TILT, RATE, (0.3, 0.0), (0.3, 0.0), (6.0, 0.0)) is None


def _robot_rotors() -> tuple[np.ndarray, np.ndarray, float]:
    """Rotor positions, CoG (world, flat posture) and weight of the shipped robot."""
    robot = Robot.default()
    out = robot.evaluate([0.0] * robot.n_q)
    pos = np.asarray(out["rotor_positions"], dtype=float)
    return pos, np.asarray(out["cog"], dtype=float), float(out["mass"]) * 9.80665


def test_three_rotors_cannot_hover_level_on_the_shipped_robot() -> None:
    pos, cog, weight = _robot_rotors()
    r = pos[1:] - cog  # rotor 0 lost
    # scipy: thrusts >= 0 with sum = weight and zero roll and pitch moments
    a_eq = np.vstack([np.ones(3), r[:, 1], -r[:, 0]])
    lp = linprog(np.zeros(3), A_eq=a_eq, b_eq=[weight, 0.0, 0.0], bounds=[(0, None)] * 3)
    assert lp.status == 2  # infeasible
    level, tilt = three_rotor_hover_tilt(pos, cog, 0, weight)
    assert level is None
    # nnls over convex weights w >= 0 (sum 1 enforced by a heavy row): the nearest centroid
    big = 1e4
    mat = np.vstack([r[:, :2].T, big * np.ones(3)])
    w, _ = nnls(mat, np.array([0.0, 0.0, big]))
    offset = float(np.linalg.norm(r[:, :2].T @ w))
    assert math.isclose(tilt, math.atan2(offset, abs(float(np.mean(r[:, 2])))), abs_tol=1e-3)
    assert math.degrees(tilt) > 45.0  # far beyond the 30 deg a safe flight allows


def test_a_cog_inside_the_triangle_hovers_level() -> None:
    pos = np.array([[0.1, 0.1, 0.02], [-0.1, 0.1, 0.02], [-0.1, -0.1, 0.02], [0.1, -0.1, 0.02]])
    cog = np.array([0.02, 0.0, 0.0])  # inside the triangle of rotors 0, 2, 3 (rotor 1 lost)
    level, tilt = three_rotor_hover_tilt(pos, cog, 1, 30.0)
    assert level is not None and tilt == 0.0
    r = pos[[0, 2, 3]] - cog
    assert np.allclose([level.sum(), level @ r[:, 1], level @ r[:, 0]], [30.0, 0.0, 0.0])
