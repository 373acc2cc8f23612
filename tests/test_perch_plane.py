"""The perching QP on a contact plane of any normal (``contact_normal``/``contact_center``,
docs/perch.md "Contact plane") against the paper's eqs. (38)-(48) written here in foot axes
and solved by Clarabel's wheel; the plane's tangents from scipy's ``Rotation.align_vectors``
(the smallest rotation taking the foot's z to the pressing direction; for a floor, π about
x)."""

from __future__ import annotations

import clarabel
import numpy as np
import pytest
from scipy import sparse
from scipy.spatial.transform import Rotation

from rdm.control.perch import PerchQp

G = 9.80665
EPS, MU_Z, H_X, H_Y, DELTA, LMAX = 1.0, 0.5, 0.04, 0.07, 5.0, 30.0
PERCH = np.array([1.0, 1.0, 0.0, 0.0])
#: a wall in front of the foot's +x face (the side face of the 0.10 x 0.15 x 0.06 plate box)
WALL_NORMAL, WALL_CENTER = np.array([-1.0, 0.0, 0.0]), np.array([0.05, 0.0, -0.03])


def plane_axes(normal: np.ndarray) -> np.ndarray:
    """Columns t1, t2, d (d = -normal) from scipy's smallest rotation z -> d."""
    d = -np.asarray(normal, float)
    if d[2] < -1.0 + 1e-12:  # d = -z: no smallest rotation; the convention is pi about x
        return Rotation.from_rotvec([np.pi, 0.0, 0.0]).as_matrix()
    rot, _ = Rotation.align_vectors([d], [[0.0, 0.0, 1.0]])
    return rot.as_matrix()


def full_rows(positions: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """6 x 4 wrench of unit thrusts along ``directions`` at ``positions`` (about the
    origin; no drag torque: it is the same linear map in both formulations)."""
    return np.vstack([directions.T, np.cross(positions, directions).T])


def instance(rng: np.random.Generator, normal: np.ndarray, center: np.ndarray) -> dict:
    """Rotors below the foot with thrust directions spread around the pressing direction
    and up (the wall's horizontal push and the weight); measured wrench random."""
    d = -normal
    pos = np.column_stack(
        [rng.uniform(-0.6, 0.6, 4), rng.uniform(-0.3, 0.3, 4), rng.uniform(-0.6, 0.0, 4)]
    )
    dirs = 0.6 * d + np.column_stack(
        [rng.uniform(-0.5, 0.5, 4), rng.uniform(-0.5, 0.5, 4), rng.uniform(0.3, 1.0, 4)]
    )
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    foot = full_rows(pos, dirs)
    cog = full_rows(pos - pos.mean(axis=0), dirs)
    allocation = np.vstack([cog[2], cog[3:]])
    w = np.concatenate([rng.uniform(-3, 3, 3) + 8.0 * d, rng.uniform(-0.1, 0.1, 3)])
    return {
        "foot_allocation": foot,
        "allocation": allocation,
        "mass": rng.uniform(0.5, 2.0),
        "foot_wrench": w,
        "previous_thrust": rng.uniform(5, 20, 4),
        "previous_foot_wrench": np.array([rng.uniform(5, 15), *rng.uniform(-0.3, 0.3, 3)]),
    }


def reference(
    inst: dict,
    normal,
    center,
    mu_x: float,
    mu_y: float,
    mask=(1, 0, 0, 0),
    zmp_z: float = 0.0,
    perch=PERCH,
) -> np.ndarray | None:
    """Eqs. (37)-(48) in unscaled z = [λ (4), F_n, M_t1, M_t2, M_n], every quantity taken
    from foot axes here: W̃ in the plane = Rᵀ [F̃, M̃ - c x F̃]; the allocation rows likewise.
    Returns λ, or None when Clarabel finds it infeasible."""
    r = plane_axes(normal)
    c = np.asarray(center, float)
    f, m = inst["foot_wrench"][:3], inst["foot_wrench"][3:]
    fp, mp = r.T @ f, r.T @ (m - np.cross(c, f))
    measured = np.array([fp[2], *mp])
    fq = inst["foot_allocation"][:3] * perch
    mq = (inst["foot_allocation"][3:] - np.cross(c, fq.T).T) * perch
    rows = np.vstack([(r.T @ fq)[2], r.T @ mq])
    lmax = LMAX + np.linalg.solve(inst["allocation"], [-inst["mass"] * G, 0, 0, 0])
    eq_a, eq_b, le_a, le_b = [], [], [], []
    for k in range(4):
        a = np.zeros(8)
        if mask[k]:
            a[:4], a[4 + k] = rows[k], -1.0
            eq_b.append(inst["previous_foot_wrench"][k] - measured[k])
        else:
            a[4 + k] = 1.0
            eq_b.append(measured[k])
        eq_a.append(a)

    def le(coef: dict, rhs: float) -> None:  # sum coef[j] z_j <= rhs
        a = np.zeros(8)
        for j, v in coef.items():
            a[j] += v
        le_a.append(a)
        le_b.append(rhs)

    fn, mt1, mt2, mn = 4, 5, 6, 7
    le({fn: -1.0}, -EPS)  # (39)
    le({fn: -mu_x}, -abs(fp[0]))  # (40), t1
    le({fn: -mu_y}, -abs(fp[1]))  # (40), t2
    for s in (1, -1):
        le({mn: s, fn: -MU_Z}, 0.0)  # (41)
        le({fn: -H_X, mt2: -s}, -s * fp[0] * zmp_z)  # (42), (43)
        le({fn: -H_Y, mt1: s}, -s * fp[1] * zmp_z)  # (42), (44)
    for i in range(4):
        le({i: -1.0}, 0.0)
        le({i: 1.0}, lmax[i])
        le({i: 1.0}, inst["previous_thrust"][i] + DELTA)
        le({i: -1.0}, -inst["previous_thrust"][i] + DELTA)
    a = sparse.csc_matrix(np.vstack(eq_a + le_a))
    b = np.array(eq_b + le_b)
    p = sparse.csc_matrix(np.diag([2.0] * 4 + [0.0] * 4))
    s = clarabel.DefaultSettings()
    s.verbose = False
    s.tol_gap_abs = s.tol_gap_rel = s.tol_feas = 1e-10
    cones = [clarabel.ZeroConeT(4), clarabel.NonnegativeConeT(len(le_b))]
    sol = clarabel.DefaultSolver(p, np.zeros(8), a, b, cones, s).solve()
    if str(sol.status) != "Solved":
        return None
    return np.array(sol.x[:4])


NORMALS = {
    "wall": (WALL_NORMAL, WALL_CENTER),
    "wall_left": (np.array([0.0, 1.0, 0.0]), np.array([0.0, -0.075, -0.03])),
    "tilted": (
        -np.array([np.sin(0.5) * np.cos(0.3), np.sin(0.5) * np.sin(0.3), np.cos(0.5)]),
        np.array([0.01, -0.02, 0.005]),
    ),
    "floor": (np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -0.06])),
}


@pytest.mark.parametrize(
    ("mask", "perch"), [((1, 0, 0, 0), (1, 1, 0, 0)), ((1, 1, 1, 0), (1, 1, 1, 1))]
)
@pytest.mark.parametrize("plane", sorted(NORMALS))
def test_plane_qp_matches_the_paper_qp_in_foot_axes(plane: str, mask, perch) -> None:
    """Table VII's mask (F_n only) and one controlling the tangent moments too (all four
    rotors perching, so the allocation rows about the centre are exercised)."""
    normal, center = NORMALS[plane]
    mu_x, mu_y = 0.4, 0.9
    qp = PerchQp(
        contact_normal=list(normal),
        contact_center=list(center),
        mu_x=mu_x,
        mu_y=mu_y,
        wrench_mask=list(mask),
        perch_rotors=list(perch),
        zmp_z=0.01,
    )
    rng = np.random.default_rng(7)
    solved = infeasible = 0
    for _ in range(150):
        inst = instance(rng, normal, center)
        ref = reference(inst, normal, center, mu_x, mu_y, mask, 0.01, np.array(perch, float))
        res = qp.solve(**inst)
        if ref is None:
            assert res.status in ("infeasible", "rate_limited"), res.status
            infeasible += 1
            continue
        assert res.status == "solved", res.status
        np.testing.assert_allclose(res.thrust, ref, atol=5e-3)
        solved += 1
    # both outcomes occur (the all-rotor mask fixes three rows of λ: mostly infeasible)
    assert solved >= (20 if sum(mask) == 1 else 5) and infeasible >= 5, (solved, infeasible)


def wall_case() -> dict:
    """Foot pressed on the wall (+x), weight partly carried by friction: the measured foot
    force pushes the wall down 6 N (F_t1 = 6, t1 = down) and 1 N sideways (F_t2)."""
    pos = np.array(
        [[-0.02, 0.07, -0.43], [-0.02, -0.07, -0.43], [0.3, 0.1, -0.7], [0.3, -0.1, -0.7]]
    )
    tilt = np.radians(40.0)  # foot rotors' thrust 40 deg from vertical towards the wall
    dirs = np.array(
        [[np.sin(tilt), 0, np.cos(tilt)], [np.sin(tilt), 0, np.cos(tilt)], [0, 0, 1], [0, 0, 1]]
    )
    foot = full_rows(pos, dirs)
    cog = full_rows(pos - np.array([0.1, 0.0, -0.5]), dirs)
    return {
        "foot_allocation": foot,
        "allocation": np.vstack([cog[2], cog[3:]]),
        "mass": 3.7,
        "foot_wrench": np.array([9.0, 1.0, -6.0, 0.0, -0.18, 0.0]),
        "previous_thrust": np.array([12.0, 12.0, 0.0, 0.0]),
        "previous_foot_wrench": np.array([9.0, 0.0, 0.0, 0.0]),
    }


def test_wall_swapped_normal_or_friction_axis_would_change_the_answer() -> None:
    """The QP's thrust equals the paper QP's on a vertical wall, and this instance tells
    the plane's roles apart: μ on the other tangent, or a tangent taken as the normal,
    moves the reference thrust by more than 1 N (so such a bug cannot pass)."""
    inst = wall_case()
    mu_x, mu_y = 0.3, 0.9
    qp = PerchQp(
        contact_normal=list(WALL_NORMAL), contact_center=list(WALL_CENTER), mu_x=mu_x, mu_y=mu_y
    )
    res = qp.solve(**inst)
    ref = reference(inst, WALL_NORMAL, WALL_CENTER, mu_x, mu_y)
    assert ref is not None and res.status == "solved"
    np.testing.assert_allclose(res.thrust, ref, atol=5e-3)
    # F_n = |F_t1| / μ_x = 6 / 0.3 = 20 N is what binds
    assert res.foot_wrench[0] == pytest.approx(20.0, abs=1e-6)
    swapped_mu = reference(inst, WALL_NORMAL, WALL_CENTER, mu_y, mu_x)
    assert swapped_mu is not None and np.max(np.abs(swapped_mu - ref)) > 1.0
    for wrong in ([0.0, 0.0, 1.0], [0.0, -1.0, 0.0]):  # a tangent of the wall as the normal
        other = reference(inst, np.array(wrong), WALL_CENTER, mu_x, mu_y)
        assert other is None or np.max(np.abs(other - ref)) > 1.0


def test_the_ceiling_normal_is_the_foot_frame_bit_for_bit() -> None:
    """(0, 0, -1) at the foot origin, given or default, through the 6-row foot-axes path,
    gives exactly the bytes of the 4-row foot-frame call."""
    rng = np.random.default_rng(3)
    normal, center = np.array([0.0, 0.0, -1.0]), np.zeros(3)
    for _ in range(50):
        inst = instance(rng, normal, center)
        four = {**inst, "foot_allocation": inst["foot_allocation"][2:]}
        a = PerchQp().solve(**four)
        b = PerchQp(contact_normal=[0.0, 0.0, -1.0]).solve(**inst)
        c = PerchQp().solve(**inst)
        for r in (b, c):
            assert r.status == a.status
            assert r.thrust.tobytes() == a.thrust.tobytes()
            assert r.foot_wrench.tobytes() == a.foot_wrench.tobytes()


def test_bad_plane_parameters_name_the_field() -> None:
    from rdm.control.perch import PerchError

    with pytest.raises(PerchError, match="contact_normal"):
        PerchQp(contact_normal=[0.0, 0.0, -2.0])
    with pytest.raises(PerchError, match="contact_center"):
        PerchQp(contact_center=[0.0, float("nan"), 0.0])
    with pytest.raises(PerchError, match="foot_allocation"):
        PerchQp().solve(**{**wall_case(), "foot_allocation": np.zeros((5, 4))})
