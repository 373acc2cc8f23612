"""The flight envelope of the paper's controller at one configuration (docs/scenarios.md).

Two limits decide whether a joint motion flies:

* **static thrust** (:func:`hover_thrusts`, :func:`largest_scale`): with zero lateral demand
  eqs. (33)-(36) level both vectoring units (thrust vertical in the CoG frame) and the
  position loop keeps the CoG frame level, so the four rotor thrusts alone must give
  f_z = m g and zero moment about the CoG: four equations, four unknowns, one solution
  ``Q̄(q)⁻¹ [m g, 0, 0, 0]``. When it leaves [thrust_min, thrust_max] the robot cannot hover
  at q with this controller;
* **the horizontal loops through the attitude loop** (:func:`horizontal_loop_poles`): the
  position PID of eq. (30) commands a roll (y) or pitch (x) target (eqs. 31-32) that the
  LQI loop of eqs. (21)-(27) follows; the linearised closed loop's eigenvalues say whether
  that cascade is stable at q.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from rdm.control.lqi import LqiSynthesizer

GRAVITY = 9.80665
#: JSK state order of the LQI: [z, ż, φ, φ̇, θ, θ̇, ψ, ψ̇, ∫z, ∫φ, ∫θ, ∫ψ]
_ROLL, _PITCH = 2, 4


def levelled_configuration(robot, joints: Sequence[float]) -> np.ndarray:
    """Full q (``robot.n_q``): the first joints as given (q1..q6), each vectoring unit turned
    so that its thrust axis is the CoG frame's z (eqs. 33-34 with n = e_z in the unit's parent
    link; |alpha| <= pi/2). The parent links do not depend on their own unit's
    angles, so one pass suffices."""
    names = list(robot.joint_names)
    q = np.zeros(robot.n_q)
    joints = np.asarray(joints, dtype=float)
    q[: joints.size] = joints
    out = robot.evaluate(q)
    for unit, c_from_link in zip(robot.vectoring_units, out["unit_parent_rotations"], strict=True):
        n = np.asarray(c_from_link, dtype=float).T @ np.array([0.0, 0.0, 1.0])
        # alpha as eq. (33)'s principal value (|alpha| <= pi/2, 0 when n lies on the unit's x
        # axis: the hanging posture's foot unit, where alpha would only turn the rotor pair
        # about its thrust axis and the node keeps the trajectory's 0); beta in any quadrant
        # so that the axis is +n, also past pi/2 (q1 = 1.5708 > pi/2)
        alpha = math.atan(-n[1] / n[2]) if n[2] != 0.0 else math.copysign(math.pi / 2, -n[1])
        if n[1] == 0.0:
            alpha = 0.0
        beta = math.atan2(n[0], -n[1] * math.sin(alpha) + n[2] * math.cos(alpha))
        q[names.index(unit["roll_joint"])] = alpha
        q[names.index(unit["pitch_joint"])] = beta
    return q


def hover_thrusts(robot, joints: Sequence[float], gravity: float = GRAVITY) -> np.ndarray:
    """Static rotor thrusts [N] that hover the robot at ``joints`` with the CoG frame level and
    both units levelled: the solution of Q̄(q) λ = [m g, 0, 0, 0] (rows f_z, m_x, m_y, m_z)."""
    out = robot.evaluate(levelled_configuration(robot, joints))
    qbar = np.asarray(out["allocation_bar"], dtype=float)
    return np.linalg.solve(qbar, [out["mass"] * gravity, 0.0, 0.0, 0.0])


def thrust_margin(robot, joints: Sequence[float]) -> float:
    """Smallest distance [N] of a hover thrust to its rotor's limits (negative: outside)."""
    t = hover_thrusts(robot, joints)
    lo = np.array([r["thrust_min"] for r in robot.rotors], dtype=float)
    hi = np.array([r["thrust_max"] for r in robot.rotors], dtype=float)
    return float(np.min(np.minimum(t - lo, hi - t)))


def largest_scale(
    robot,
    base: Sequence[float],
    offset: Sequence[float],
    samples: int = 21,
    upper: float = 4.0,
    tol: float = 1e-3,
) -> float:
    """Largest k such that every configuration ``base + s k offset`` (s in [0, 1], ``samples``
    points) keeps all hover thrusts inside the rotor limits; 0 if ``base`` itself does not,
    ``upper`` if even that scale does. Bisection to ``tol``."""
    base = np.asarray(base, dtype=float)
    offset = np.asarray(offset, dtype=float)
    grid = np.linspace(0.0, 1.0, samples)

    def ok(k: float) -> bool:
        return all(thrust_margin(robot, base + s * k * offset) >= 0.0 for s in grid)

    if not ok(0.0):
        return 0.0
    if ok(upper):
        return upper
    lo, hi = 0.0, upper
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return lo


def horizontal_loop_poles(
    robot,
    q: Sequence[float],
    pid: Sequence[float],
    axis: str,
    k_tilt: float = 1.0,
    gravity: float = GRAVITY,
    q_weights: Sequence[float] | None = None,
    r_weights: Sequence[float] | None = None,
    inertia_scale: float = 1.0,
) -> np.ndarray:
    """Eigenvalues of the linearised hover at full configuration ``q``: the LQI loop (Table V
    weights, gains synthesised at q as the onboard node does) closed around the rigid body, and
    the position PID ``pid`` = (P, I, D) of eq. (30) on ``axis`` "y" (roll target
    φ_d = -k_tilt a_y / g, eq. 31, a_y = -g φ) or "x" (pitch target θ_d = k_tilt a_x / g,
    eq. 32, a_x = g θ). Lateral vectoring, delays and the firmware's per-rotor yaw spread are
    not modelled. Any eigenvalue with a positive real part: that cascade diverges at q.
    ``q_weights`` (12, JSK order), ``r_weights`` (4): LQI weights other than Table V's;
    ``inertia_scale``: the inertia the LQI is synthesised for and acts on, times this."""
    if axis not in ("x", "y"):
        raise ValueError(f"axis={axis!r}: 'x' or 'y'")
    out = robot.evaluate(np.asarray(q, dtype=float))
    res = LqiSynthesizer(
        q_weights=None if q_weights is None else np.asarray(q_weights, dtype=float),
        r_weights=None if r_weights is None else np.asarray(r_weights, dtype=float),
        clamp_gain=False,
    ).synthesize(
        out["mass"],
        np.asarray(out["inertia"]) * inertia_scale,
        np.asarray(out["allocation_bar"]),
    )
    k, b = np.asarray(res.k, dtype=float), np.asarray(res.b, dtype=float)
    n = 15  # 12 LQI states, then horizontal position, velocity and its error integral
    f = np.zeros((n, n))
    for ax in range(4):
        f[2 * ax, 2 * ax + 1] = 1.0  # d/dt angle = rate
        f[8 + ax, 2 * ax] = -1.0  # d/dt integral = -(state - target)
    f[:12, :12] += b @ k
    state, sign = (_ROLL, -1.0) if axis == "y" else (_PITCH, 1.0)
    kp, ki, kd = (float(v) for v in pid)
    # target angle as a row over the state (target position 0): a = -(kp p + ki ∫p + kd v)
    target = np.zeros(n)
    target[12], target[13], target[14] = (-sign * k_tilt * g / gravity for g in (kp, kd, ki))
    f[:12] += np.outer(-b @ k[:, state], target)  # λ = K (x - x_target)
    f[8 + state // 2] += target  # the attitude integral integrates (target - angle)
    f[12, 13] = 1.0
    f[13, state] = sign * gravity
    f[14, 12] = 1.0
    return np.linalg.eigvals(f)


def least_damped_pair(poles: np.ndarray, below: float = 20.0) -> tuple[float, float]:
    """(damping ratio, natural frequency [rad/s]) of the least-damped oscillatory pole pair
    slower than ``below`` rad/s (the position loop's mode); (nan, nan) if there is none."""
    osc = [complex(e) for e in poles if abs(e.imag) > 1e-6 and abs(e) < below]
    if not osc:
        return math.nan, math.nan
    e = min(osc, key=lambda v: -v.real / abs(v))
    return -e.real / abs(e), abs(e)
