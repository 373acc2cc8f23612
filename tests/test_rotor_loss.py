"""The lost-rotor detection and the feasibility figure behind its reaction
(``rdm.nodes.onboard_rotor_loss``).

* :func:`diverging_axis`: trips only when the error is beyond the angle **and** the gyro turns
  it further beyond the rate (catches a dropped sign test: a swing back to the target is no
  fault; a dropped rate test: a slow lean is none either); with the previous target, only
  past both (the attitude loop following a jumping target is no fault).
* :func:`lost_rotor` on the shipped robot against scipy's ``solve_ivp`` of Euler's rigid-body
  equations (the full inertia, I_xz included): each rotor's hover thrust removed, the body
  rates 20 ms later name that rotor, in the class its thrust puts it in (catches a sign
  flip: the rotor across; swapped roll and pitch rows; an inverted class filter). The
  class boundary and :func:`turning_axis`'s threshold, and ``MonitorLimits``' check of the
  specific-force window.
* :func:`three_rotor_hover_tilt` on the shipped robot against scipy: ``linprog`` finds no
  nonnegative thrusts of the three remaining rotors that balance roll and pitch level, and
  the smallest offset of a thrust centroid from the CoG comes from ``nnls`` over convex
  weights (not the function's segment search).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import linprog, nnls

from rdm.model import Robot
from rdm.nodes.onboard_monitors import MonitorLimits
from rdm.nodes.onboard_rotor_loss import (
    diverging_axis,
    lost_rotor,
    three_rotor_hover_tilt,
    turning_axis,
)

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


def test_a_light_rotor_diverges_past_both_of_the_last_two_targets() -> None:
    """The light rotor's rule (1 deg, 1.5 rad/s) on ticks of simulated runs (deg, rad/s):
    the robustness campaign's seed 36 at 3.55 s, fault-free, follows a roll target that
    jumped from -1.17 to +1.15 deg (noisy motion capture), 1.5 deg off the newest turning
    away from it towards the older one; a dead rotor 2 (mission seed 0, +45 ms) rolls 2 deg
    past both. Catches the previous target ignored, and min/max swapped."""
    light = LIM.rotor_loss_light_tilt_rad
    d = math.radians
    follow = ((d(-0.36), d(-0.54)), (d(1.15), d(-1.54)), (-1.64, -0.02), (d(-1.17), d(-0.51)))
    assert diverging_axis(light, RATE, *follow[:3]) == "roll"  # the newest target alone
    assert diverging_axis(light, RATE, *follow) is None
    dead = ((d(2.14), d(0.16)), (d(0.14), d(0.27)), (1.60, 0.14), (d(-0.49), d(0.64)))
    assert diverging_axis(light, RATE, *dead) == "roll"
    # the mirror image: below both targets, turning further down
    mirror = ((d(-2.14), d(0.16)), (d(-0.14), d(0.27)), (-1.60, 0.14), (d(0.49), d(0.64)))
    assert diverging_axis(light, RATE, *mirror) == "roll"
    # past the newest only (between the two): the loop still on its way to the older one
    between = ((d(1.74), 0.0), (d(0.27), 0.0), (1.82, 0.0), (d(3.0), 0.0))
    assert diverging_axis(light, RATE, *between) is None


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


def _hover_terms() -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The shipped robot's allocation rows (f_z, m_x, m_y, m_z; vertical thrusts, no drag),
    level hover thrusts (least norm: weight, no roll or pitch moment), inertia and weight."""
    robot = Robot.default()
    out = robot.evaluate([0.0] * robot.n_q)
    pos, cog = np.asarray(out["rotor_positions"]), np.asarray(out["cog"])
    weight = float(out["mass"]) * 9.80665
    r = pos - cog
    qbar = np.vstack([np.ones(len(r)), r[:, 1], -r[:, 0], np.zeros(len(r))])
    hover = np.linalg.lstsq(qbar[:3], [weight, 0.0, 0.0], rcond=None)[0]
    return qbar, hover, np.asarray(out["inertia"], dtype=float), weight


@pytest.mark.parametrize("lost", [0, 1, 2, 3])
def test_the_rotor_whose_loss_turns_the_body_is_named(lost: int) -> None:
    qbar, hover, inertia, weight = _hover_terms()
    assert np.all(hover > 0)
    # the moment the lost hover thrust leaves unbalanced, r x (0, 0, -f)
    torque = -hover[lost] * np.array([qbar[1, lost], qbar[2, lost], 0.0])
    inv = np.linalg.inv(inertia)

    def euler(_t: float, w: np.ndarray) -> np.ndarray:
        return inv @ (torque - np.cross(w, inertia @ w))

    w = solve_ivp(euler, (0.0, 0.02), np.zeros(3), rtol=1e-9, atol=1e-12).y[:, -1]
    heavy = bool(hover[lost] > 0.25 * weight)
    assert heavy == (lost in (0, 1))  # the front rotors carry 14.4 of 36.3 N each
    rates = (float(w[0]), float(w[1]))
    assert lost_rotor(qbar, hover, inertia, rates, heavy, weight) == lost
    # the other class has no rotor that turns the body this way... or names another one
    assert lost_rotor(qbar, hover, inertia, rates, not heavy, weight) != lost
    # no turn: no rotor named
    assert lost_rotor(qbar, hover, inertia, (0.0, 0.0), heavy, weight) is None


def test_turning_axis_is_the_faster_rate_beyond_the_threshold() -> None:
    early = LIM.rotor_loss_early_rate_rad_s
    assert turning_axis(early, (-0.7, 0.1)) == "roll"
    assert turning_axis(early, (0.2, 0.9)) == "pitch"
    assert turning_axis(early, (0.4, -0.45)) is None


def test_the_specific_force_window_must_be_ordered() -> None:
    with pytest.raises(ValueError, match="rotor_loss_min_specific_force"):
        MonitorLimits(rotor_loss_min_specific_force=8.0)
    with pytest.raises(ValueError, match="rotor_loss_light_arrest_s"):
        MonitorLimits(rotor_loss_light_arrest_s=0.0)
