"""Feasible end-effector force of eq. (3) with the authority the perching controller has.

Perched, the flight controller holds every rotor at its hover share
lambda_hover = Q-bar(CoG)^-1 [m g, 0, 0, 0] (eq. 6 with horizontal vectoring units), and the
perching controller adds lambda_perch (eq. 37) on the rotors of the root unit only
(Table VII: Q_perch = Q(q) diag[1, 1, 0, 0] for the RDM, whose root link carries the foot
unit; the RCM's root link carries all four rotors, so all four perch), with
lambda_perch >= 0 (eq. 46) and the total at most the rotor maximum (eq. 47). An
end-effector force F_ee = +-f e_j (j = x, y, z, world = foot axes) is feasible when some
lambda_perch keeps every joint torque within its stall torque (eq. 61) and the foot perched
with Table VII's conditions: normal force >= epsilon_z (eq. 39), friction (eq. 40), yaw
friction (eq. 41) and the ZMP inside H_x, H_y (eq. 42). One LP per axis and sign over
x = [f, lambda_perch of each perching rotor] on the dense QP solver (a tiny regulariser
makes it a QP); the model binding gives the torques and the foot wrench, both affine in x.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rdm import _rdm
from rdm.model import Robot

#: Largest force an LP may return [N] (keeps it bounded).
FORCE_CAP = 200.0
GRAVITY = 9.80665


@dataclass(frozen=True)
class PerchAuthority:
    """The perching controller's limits (Table VII, from ``rdm._rdm.PerchQp``'s defaults)."""

    epsilon_z: float
    mu_xy: float
    mu_z: float
    half_x: float
    half_y: float
    perch_rotors: tuple[int, ...]

    @classmethod
    def from_controller(cls, robot: Robot | None = None) -> PerchAuthority:
        """The perching QP's own parameters; the perching rotors are Table VII's mask, or,
        given ``robot``, the rotors of every vectoring unit on the root link."""
        p = _rdm.PerchQp(None).params()
        rotors = tuple(i for i, w in enumerate(p["perch_rotors"]) if w > 0.0)
        if robot is not None:
            rotors = root_rotors(robot)
        return cls(
            epsilon_z=float(p["epsilon_z"]),
            mu_xy=float(min(p["mu_x"], p["mu_y"])),
            mu_z=float(p["mu_z"]),
            half_x=float(p["half_size_x"]),
            half_y=float(p["half_size_y"]),
            perch_rotors=rotors,
        )


def root_rotors(robot: Robot) -> tuple[int, ...]:
    """Indices of the rotors whose vectoring unit sits on the foot unit's link."""
    units = robot.vectoring_units
    foot = next(u for u in units if u["name"].startswith("foot"))
    root = [u["name"] for u in units if u.get("parent_link") == foot.get("parent_link")]
    return tuple(
        i for i, r in enumerate(robot.rotors) if any(r["parent"].startswith(n) for n in root)
    )


def hover_thrust(robot: Robot, q: np.ndarray) -> np.ndarray:
    """lambda_hover = Q-bar(CoG)^-1 [m g, 0, 0, 0] at joint vector ``q`` (all joints)."""
    ev = robot.evaluate(q)
    return np.linalg.solve(np.asarray(ev["allocation_bar"]), [robot.mass * GRAVITY, 0, 0, 0])


def _loads(robot: Robot, q, foot, thrusts, ee, gravity):
    tau, res = robot.static_torques(
        q, thrusts=list(thrusts), end_effector_wrench=list(ee), gravity=gravity
    )
    f, m = np.asarray(res[:3]), np.asarray(res[3:])
    return np.asarray(tau), -np.concatenate([f, m - np.cross(foot, f)])


def perch_lp(
    robot: Robot, q: np.ndarray, authority: PerchAuthority
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The LP's rows at ``q`` (perched, foot frame = world): ``g_f[s] * f + g_x @ x <= h``
    for the signed axis ``s`` (+x, -x, +y, -y, +z, -z) and x = lambda_perch on the perching
    rotors. Returns ``(g_f (6, m), g_x (m, k), h (m,), lambda_hover, tau_hover)``."""
    q = np.asarray(q, dtype=float)
    ev = robot.evaluate(q)
    foot = np.asarray(ev["frames"]["foot"])[:3, 3]
    hover = np.linalg.solve(np.asarray(ev["allocation_bar"]), [robot.mass * GRAVITY, 0, 0, 0])
    zero = np.zeros(6)
    nr = robot.n_rotors
    tau0, w0 = _loads(robot, q, foot, hover, zero, (0.0, 0.0, -GRAVITY))
    cols = [
        _loads(robot, q, foot, np.eye(nr)[k], zero, (0.0, 0.0, 0.0)) for k in authority.perch_rotors
    ]
    tau_x = np.column_stack([c[0] for c in cols])
    w_x = np.column_stack([c[1] for c in cols])
    signed = []
    for j in range(3):
        for sign in (1.0, -1.0):
            ee = np.zeros(6)
            ee[j] = sign
            signed.append(_loads(robot, q, foot, np.zeros(nr), ee, (0.0, 0.0, 0.0)))
    stall = np.asarray(robot.stall_torques)
    tmax = np.array([robot.rotors[k]["thrust_max"] for k in authority.perch_rotors])
    tmin = np.array([robot.rotors[k]["thrust_min"] for k in authority.perch_rotors])
    a = authority
    k = len(authority.perch_rotors)
    # Rows that are affine in (f, x): (coefficient of f per signed axis, coefficient of x, h)
    rows_f, rows_x, rows_h = [], [], []

    def push(cf, cx, h):
        rows_f.append(cf)
        rows_x.append(cx)
        rows_h.append(h)

    tau_f = np.array([s[0] for s in signed])  # (6, n_q)
    w_f = np.array([s[1] for s in signed])  # (6, 6)
    for i in range(len(stall)):
        push(tau_f[:, i], tau_x[i], stall[i] - tau0[i])
        push(-tau_f[:, i], -tau_x[i], stall[i] + tau0[i])
    for r in range(k):
        e = np.eye(k)[r]
        # eq. (46): lambda_perch >= 0, and the total at least the rotor minimum
        push(np.zeros(6), -e, min(0.0, hover[authority.perch_rotors[r]] - tmin[r]))
        push(np.zeros(6), e, tmax[r] - hover[authority.perch_rotors[r]])  # eq. (47)
    # Normal force N = -w_z >= epsilon_z (eq. 39).
    n_f, n_x, n0 = -w_f[:, 2], -w_x[2], -w0[2]
    push(-n_f, -n_x, n0 - a.epsilon_z)
    for c, lim in ((0, a.mu_xy), (1, a.mu_xy), (5, a.mu_z), (3, a.half_y), (4, a.half_x)):
        push(w_f[:, c] - lim * n_f, w_x[c] - lim * n_x, lim * n0 - w0[c])
        push(-w_f[:, c] - lim * n_f, -w_x[c] - lim * n_x, lim * n0 + w0[c])
    return (np.array(rows_f).T, np.array(rows_x), np.array(rows_h), hover, tau0)


def feasible_force(
    robot: Robot, q: np.ndarray, authority: PerchAuthority | None = None
) -> tuple[np.ndarray, float] | None:
    """Per-axis max |F_ee,j| [N] (x, y, z) and eq. (3)'s F_ee,feasible at joint vector
    ``q`` (all joints, vectoring angles included), perched; None when the foot cannot be
    held even with no end-effector force or the hover share of a rotor that does not perch
    is outside the rotor range (a perching rotor's total hover + lambda_perch must be)."""
    a = authority or PerchAuthority.from_controller(robot)
    g_f, g_x, h, hover, _ = perch_lp(robot, q, a)
    fixed = [i for i in range(robot.n_rotors) if i not in a.perch_rotors]
    tmin = np.array([robot.rotors[i]["thrust_min"] for i in fixed])
    tmax = np.array([robot.rotors[i]["thrust_max"] for i in fixed])
    if np.any(hover[fixed] < tmin) or np.any(hover[fixed] > tmax):
        return None
    k = g_x.shape[1]
    n = 1 + k
    m = len(h) + 2
    solver = _rdm.QpSolver(n, 0, m)
    p = np.eye(n) * 1e-6
    c = np.zeros(n)
    c[0] = -1.0
    per_axis = np.zeros(3)
    any_ok = False
    for s in range(6):
        g = np.zeros((m, n))
        g[: len(h), 0] = g_f[s]
        g[: len(h), 1:] = g_x
        g[len(h), 0] = 1.0
        g[len(h) + 1, 0] = -1.0
        hh = np.concatenate([h, [FORCE_CAP, 0.0]])
        status, x = solver.solve(p, c, np.zeros((0, n)), np.zeros(0), g, hh)
        if status in ("solved", "almost_solved"):
            any_ok = True
            per_axis[s // 2] = max(per_axis[s // 2], max(float(x[0]), 0.0))
    if not any_ok:
        return None
    return per_axis, float(per_axis.max())
