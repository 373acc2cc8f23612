"""Static ceiling of the end-effector force a perched robot can hold (push scenario analysis).

For a perched posture q, the largest amplitude ``a`` of a force ``+-a e_k`` (``e_k`` the
end-effector frame's axis k) at the end effector such that the foot wrench still satisfies
the contact conditions of the perching QP (paper eqs. 39-44): F_z >= eps_z, |F_x|, |F_y| <=
mu F_z, |M_z| <= mu_z F_z, |M_y| <= H_x F_z, |M_x| <= H_y F_z. Static: no dynamics, no filter
lag; a linear programme (scipy ``linprog``) per axis with one thrust vector per sign.

Two models of who pushes the plate:

* ``"perch"``: the perching QP's own authority: the flight thrust carries the weight with no
  moment about the CoG (hover thrust), the perch rotors (Table VII ``diag[1,1,0,0]``, the
  foot rotors) add λ_perch in ``[0, thrust_max - hover]`` (eq. 47). This is the ceiling of
  the controller the paper describes (U_mask = diag[1,0,0,0]: only F_z is raised).
* ``"all"``: any controller: every rotor's total thrust in ``[thrust_min, thrust_max]``,
  gravity at the CoG, contact limits at the plate's half-widths.

Wrench the foot applies to the surface, foot frame (z into the ceiling, F_z > 0 presses),
about the plate centre: thrust + gravity + the external force (its moment p_ee x f).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog

from rdm.nodes.onboard_control import foot_allocation

from .perching import MU, leveled

GRAVITY = 9.80665
#: Table VII's ZMP bounds H_x, H_y (eq. 42), inside the 0.10 x 0.15 m plate
QP_HALF = (0.04, 0.07)
PLATE = (0.05, 0.075)


def ceiling(
    robot,
    q6,
    model: str = "perch",
    epsilon_z: float = 8.0,
    half: tuple[float, float] | None = None,
    mu: tuple[float, float, float] = MU,
    perch_rotors: tuple[int, ...] = (0, 1),
    thrust_min: float = 1.0,
    thrust_gain: np.ndarray | None = None,
) -> np.ndarray:
    """Largest |F| [N] along each end-effector axis (x, y, z), pushed and pulled, that the
    contact conditions allow at posture ``q6`` (q1..q6; vectoring levelled as the scenario
    does). ``half`` defaults to Table VII's H for ``"perch"``, the plate for ``"all"``.
    ``thrust_gain``: per-rotor factor on the thrust a command produces (the ceiling effect's
    T/T0 near the surface), applied to ``thrust_max``; default 1."""
    if model not in ("perch", "all"):
        raise ValueError(f"model={model!r}: 'perch' or 'all'")
    half = half or (QP_HALF if model == "perch" else PLATE)
    o = robot.evaluate(leveled(np.asarray(q6, dtype=float), robot.n_q))
    qf = foot_allocation(np.asarray(o["allocation"]), np.asarray(o["foot_in_cog"]))
    tmax = np.array([r["thrust_max"] for r in robot.rotors], dtype=float)
    if thrust_gain is not None:
        tmax = tmax * np.asarray(thrust_gain, dtype=float)
    mg = float(o["mass"]) * GRAVITY
    ee = np.asarray(o["frames"]["end_effector"], dtype=float)
    p_ee, rot = ee[:3, 3], ee[:3, :3]
    if model == "perch":
        hover = np.linalg.lstsq(np.asarray(o["allocation_bar"]), [mg, 0, 0, 0], rcond=None)[0]
        cols = list(perch_rotors)
        alloc = qf[:, cols]  # rows F_z, M_x, M_y, M_z
        const = np.zeros(4)  # hover thrust + gravity: no force, no moment
        bounds = [(0.0, float(tmax[i] - hover[i])) for i in cols]
    else:
        p_cog = np.asarray(o["frames"]["cog"], dtype=float)[:3, 3]
        alloc = qf
        const = np.r_[-mg, np.cross(p_cog, [0.0, 0.0, -mg])]
        bounds = [(thrust_min, float(t)) for t in tmax]
    n = alloc.shape[1]
    out = np.full(3, np.nan)
    for k in range(3):
        e = rot[:, k]
        w = np.r_[e, np.cross(p_ee, e)]  # F_x, F_y, F_z, M_x, M_y, M_z per unit a
        a_ub, b_ub = [], []
        for j, sign in enumerate((1.0, -1.0)):

            def expr(wi: float, row: np.ndarray | None, c: float, j=j, sign=sign):
                v = np.zeros(1 + 2 * n)
                v[0] = sign * wi
                if row is not None:
                    v[1 + j * n : 1 + (j + 1) * n] = row
                return v, c

            fz = expr(w[2], alloc[0], const[0])
            fx, fy = expr(w[0], None, 0.0), expr(w[1], None, 0.0)
            mx, my, mz = (expr(w[3 + i], alloc[1 + i], const[1 + i]) for i in range(3))
            a_ub.append(-fz[0])
            b_ub.append(fz[1] - epsilon_z)  # F_z >= eps_z
            for x, lim in ((fx, mu[0]), (fy, mu[1]), (mz, mu[2]), (my, half[0]), (mx, half[1])):
                for s in (1.0, -1.0):  # s X - lim F_z <= 0
                    a_ub.append(s * x[0] - lim * fz[0])
                    b_ub.append(-(s * x[1] - lim * fz[1]))
        res = linprog(
            np.r_[-1.0, np.zeros(2 * n)],
            A_ub=np.array(a_ub),
            b_ub=np.array(b_ub),
            bounds=[(0.0, 1e3), *bounds, *bounds],
        )
        if res.success:
            out[k] = float(res.x[0])
    return out
