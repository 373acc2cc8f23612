"""Perching QP (eqs. 37-49), both solver choices (the default active-set solver and Clarabel):
the Rust core against clarabel's Python wheel, OSQP and an independent numpy construction of
the paper's QP; constraint checks; failure handling."""

from __future__ import annotations

import dataclasses
import sys

import clarabel
import numpy as np
import osqp
import pytest
from scipy import sparse

from rdm.control.perch import PerchController, PerchError, PerchQp, PerchResult

G = 9.80665
EPS_Z, MU_X, MU_Y, MU_Z, H_X, H_Y, DELTA, LMAX = 1.0, 0.9, 0.9, 0.5, 0.04, 0.07, 5.0, 30.0
DRAG = 0.016


def allocation_rows(positions: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """[F_z, M_x, M_y, M_z] rows of eqs. (8)-(9) for rotors at `positions`."""
    sigma = np.array([1.0, -1.0, 1.0, -1.0])
    v = np.cross(positions, normals) - DRAG * sigma[:, None] * normals
    return np.vstack([normals[:, 2], v[:, 0], v[:, 1], v[:, 2]])


def random_instance(rng: np.random.Generator) -> dict:
    signs = np.array([[-1, -1], [-1, 1], [1, 1], [1, -1]], dtype=float)
    pos = np.column_stack(
        [
            signs[:, 0] * rng.uniform(0.15, 0.6, 4),
            signs[:, 1] * rng.uniform(0.1, 0.4, 4),
            rng.uniform(-0.05, 0.05, 4),
        ]
    )
    n = np.column_stack([rng.uniform(-0.15, 0.15, (4, 2)), np.ones(4)])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    foot = np.array([rng.uniform(-0.7, -0.3), rng.uniform(-0.05, 0.05), rng.uniform(0, 0.1)])
    fz = rng.uniform(0, 30)
    w = np.array(
        [
            rng.uniform(-6, 6),
            rng.uniform(-6, 6),
            fz,
            rng.uniform(-0.6, 0.6),
            rng.uniform(-0.6, 0.6),
            rng.uniform(-1.5, 1.5),
        ]
    )
    return {
        "foot_allocation": allocation_rows(pos - foot, n),
        "allocation": allocation_rows(pos, n),
        "mass": rng.uniform(1, 6),
        "foot_wrench": w,
        "previous_thrust": rng.uniform(0, 0.8 * LMAX, 4),
        "previous_foot_wrench": np.array([fz + rng.uniform(-3, 3), *w[3:]]),
    }


def thrust_max(inst: dict) -> np.ndarray:
    """Eq. (47): λ_rotor_max + Q̄⁻¹ m [-g, 0, 0, 0]."""
    return LMAX + np.linalg.solve(inst["allocation"], [-inst["mass"] * G, 0, 0, 0])


def required_fz(w: np.ndarray) -> float:
    """Smallest F_z meeting eqs. (39)-(44) for the measured wrench (p_ZMP_z = 0)."""
    fx, fy, _, mx, my, mz = w
    return max(EPS_Z, abs(fx) / MU_X, abs(fy) / MU_Y, abs(mz) / MU_Z, abs(my) / H_X, abs(mx) / H_Y)


def rate_box(inst: dict) -> tuple[np.ndarray, np.ndarray]:
    lo = np.maximum(inst["previous_thrust"] - DELTA, 0.0)
    hi = np.minimum(inst["previous_thrust"] + DELTA, thrust_max(inst))
    return lo, hi


def feasibility_margin(inst: dict) -> float:
    lo, hi = rate_box(inst)
    if np.any(hi < lo):
        return float(np.min(hi - lo))
    qz = inst["foot_allocation"][0] * np.array([1, 1, 0, 0])
    best = float(np.sum(np.where(qz > 0, qz * hi, qz * lo)))
    e = inst["previous_foot_wrench"][0] - inst["foot_wrench"][2]
    return best - (required_fz(inst["foot_wrench"]) + e)


def feasible_instances(count: int, seed: int) -> list[dict]:
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        inst = random_instance(rng)
        if np.linalg.cond(inst["allocation"]) < 1e6 and feasibility_margin(inst) > 1e-3:
            out.append(inst)
    return out


def solve_rust(qp: PerchQp, inst: dict):
    return qp.solve(**inst)


def clarabel_solve(prob) -> np.ndarray:
    s = clarabel.DefaultSettings()
    s.verbose = False
    s.presolve_enable = False
    s.tol_gap_abs = s.tol_gap_rel = s.tol_feas = 1e-10
    cones = [clarabel.ZeroConeT(prob.zero_cone), clarabel.NonnegativeConeT(prob.nonnegative_cone)]
    sol = clarabel.DefaultSolver(prob.P, prob.q, prob.A, prob.b, cones, s).solve()
    assert str(sol.status) == "Solved"
    return np.array(sol.x)


def osqp_solve(P, q, A, lo, hi) -> np.ndarray | None:
    """OSQP's polished answer, or None when its ADMM stalls (it does on ~0.5 % of the
    scaled instances: P is singular)."""
    m = osqp.OSQP()
    m.setup(
        sparse.csc_matrix(P),
        q,
        sparse.csc_matrix(A),
        lo,
        hi,
        # P is singular (only the thrusts are weighted), so ADMM alone converges slowly:
        # solve to 1e-6 and require polishing to recover the exact active-set solution.
        eps_abs=1e-6,
        eps_rel=1e-6,
        polishing=True,
        verbose=False,
        max_iter=400000,
    )
    res = m.solve(raise_error=False)  # status is checked below
    if res.info.status != "solved" or res.info.status_polish != 1:
        return None  # not converged, or polishing failed: the answer is not exact
    return np.asarray(res.x)


def paper_qp_osqp(inst: dict) -> np.ndarray:
    """Eq. (49) built here from the paper in unscaled variables z = [λ (4), F_z,t] under
    Table VII's masks (U_mask selects F_z, rotors 1-2 perch), solved with OSQP."""
    qz = inst["foot_allocation"][0] * np.array([1, 1, 0, 0])
    e = inst["previous_foot_wrench"][0] - inst["foot_wrench"][2]
    P = np.diag([2.0, 2.0, 2.0, 2.0, 0.0])
    A = np.zeros((1 + 1 + 4 + 4, 5))
    lo = np.zeros(10)
    hi = np.zeros(10)
    A[0, :4], A[0, 4] = qz, -1.0  # eq. (38): Q̄_perch,z λ - F_z = F_z,t-1 - F̃_z
    lo[0] = hi[0] = e
    A[1, 4] = 1.0  # eqs. (39)-(44) as a lower bound on F_z
    lo[1], hi[1] = required_fz(inst["foot_wrench"]), np.inf
    A[2:6, :4] = np.eye(4)  # eqs. (45)-(47)
    lo[2:6], hi[2:6] = 0.0, thrust_max(inst)
    A[6:10, :4] = np.eye(4)  # eq. (48)
    lo[6:10] = inst["previous_thrust"] - DELTA
    hi[6:10] = inst["previous_thrust"] + DELTA
    x = osqp_solve(P, np.zeros(5), A, lo, hi)
    assert x is not None, "OSQP did not solve the paper-form QP"
    return x[:4]


def check_constraints(inst: dict, res, tol: float = 1e-6) -> None:
    """Eqs. (38)-(48) evaluated independently on the returned thrust and foot wrench."""
    lam, (fz, mx, my, mz) = res.thrust, res.foot_wrench
    fx, fy, fzm, mxm, mym, mzm = inst["foot_wrench"]
    qz = inst["foot_allocation"][0] * np.array([1, 1, 0, 0])
    assert np.allclose([mx, my, mz], [mxm, mym, mzm], atol=tol)  # unmasked rows of eq. (38)
    assert abs(qz @ lam - (fz + inst["previous_foot_wrench"][0] - fzm)) < 1e-5  # eq. (38)
    assert fz >= EPS_Z - tol  # (39)
    assert abs(fx) <= MU_X * fz + tol and abs(fy) <= MU_Y * fz + tol  # (40)
    assert abs(mz) <= MU_Z * fz + tol  # (41)
    px, py = -my / fz, mx / fz  # (43), (44) with p_ZMP_z = 0
    assert abs(px) <= H_X + tol and abs(py) <= H_Y + tol  # (42)
    assert np.allclose(res.zmp, [px, py], atol=1e-9)
    assert np.all(lam >= 0) and np.all(lam <= thrust_max(inst) + 1e-9)  # (45)-(47)
    assert np.all(np.abs(lam - inst["previous_thrust"]) <= DELTA + 1e-9)  # (48)


# Thrust agreement bound. At a weakly active bound (a rotor at λ = 0, where the cost gradient
# 2Nλ vanishes too) an interior-point answer is pinned only to about sqrt(gap tolerance), so
# ~1e-3 N there; 5e-3 N is still ten times finer than one ESC PWM step (~0.06 N). The optimal
# cost, which the solvers do determine tightly, must agree as Clarabel's own gap criterion
# reads: to 1e-8 absolute (its tol_gap_abs) plus 1e-7 relative.
THRUST_ATOL = 5e-3
COST_ATOL, COST_RTOL = 1e-8, 1e-7


def qp_cost(prob, x_scaled: np.ndarray) -> float:
    return float(0.5 * x_scaled @ (prob.P @ x_scaled) + prob.q @ x_scaled)


SOLVERS = ("active_set", "clarabel")


@pytest.mark.slow
@pytest.mark.parametrize("solver", SOLVERS)
def test_rust_qp_matches_clarabel_osqp_and_paper_qp_on_random_instances(solver: str) -> None:
    qp = PerchQp(solver=solver)
    worst = {"clarabel": 0.0, "osqp_same": 0.0, "osqp_paper": 0.0}
    worst_cost = -np.inf
    osqp_stalled = 0
    instances = feasible_instances(2000, seed=1)
    for inst in instances:
        res = solve_rust(qp, inst)
        assert res.status == "solved"
        # The active-set answer is a vertex/face solution to ~1e-10: check it tighter.
        check_constraints(inst, res, tol=1e-8 if solver == "active_set" else 1e-6)
        prob = qp.problem_data()
        s = prob.variable_scale
        x_rust = np.concatenate([res.thrust, res.foot_wrench]) / s
        x_cl = clarabel_solve(prob)
        c_rust, c_cl = qp_cost(prob, x_rust), qp_cost(prob, x_cl)
        worst_cost = max(worst_cost, abs(c_rust - c_cl) - (COST_ATOL + COST_RTOL * abs(c_cl)))
        nnz = prob.nonnegative_cone
        lo = np.concatenate([prob.b[: prob.zero_cone], np.full(nnz, -np.inf)])
        x_os = osqp_solve(prob.P, prob.q, prob.A, lo, prob.b)
        worst["clarabel"] = max(worst["clarabel"], np.max(np.abs(s * x_cl[:4] - res.thrust)))
        if x_os is None:
            osqp_stalled += 1
        else:
            worst["osqp_same"] = max(worst["osqp_same"], np.max(np.abs(s * x_os[:4] - res.thrust)))
        paper = paper_qp_osqp(inst)
        worst["osqp_paper"] = max(worst["osqp_paper"], np.max(np.abs(paper - res.thrust)))
    assert max(worst.values()) < THRUST_ATOL, worst
    assert worst_cost <= 0.0, f"cost beyond tolerance by {worst_cost}"
    assert osqp_stalled <= len(instances) // 100, f"OSQP stalled on {osqp_stalled} instances"
    assert qp.counters()["solved"] == len(instances)
    assert qp.counters()["fallback"] == 0


@pytest.mark.parametrize(("mu_x", "mu_y"), [(0.9, 0.3), (0.3, 0.9)])
def test_friction_coefficients_per_axis_match_the_paper_qp(monkeypatch, mu_x, mu_y) -> None:
    """Eq. (40) with mu_x != mu_y: each axis's force against its own coefficient (a mu_x in
    the y rows passes every test with equal coefficients), against the paper-form QP."""
    module = sys.modules[__name__]
    monkeypatch.setattr(module, "MU_X", mu_x)
    monkeypatch.setattr(module, "MU_Y", mu_y)
    qp = PerchQp(mu_x=mu_x, mu_y=mu_y)
    worst = 0.0
    binding = 0
    for inst in feasible_instances(300, seed=4):
        res = solve_rust(qp, inst)
        assert res.status == "solved"
        check_constraints(inst, res, tol=1e-8)
        worst = max(worst, float(np.max(np.abs(paper_qp_osqp(inst) - res.thrust))))
        fx, fy = inst["foot_wrench"][:2]
        # the smaller coefficient's axis sets the normal force: the case the swap breaks
        small = abs(fy) / mu_y if mu_y < mu_x else abs(fx) / mu_x
        binding += bool(abs(res.foot_wrench[0] - small) < 1e-6)
    assert worst < THRUST_ATOL
    assert binding >= 30, binding  # enough instances where eq. (40) on that axis binds


def test_solver_choice_is_a_parameter_and_bad_names_are_refused() -> None:
    assert PerchQp().params()["solver"] == "active_set"
    assert PerchQp(solver="clarabel").params()["solver"] == "clarabel"
    with pytest.raises(PerchError, match="solver"):
        PerchQp(solver="simplex")
    with pytest.raises(PerchError, match="active_set_max_iter"):
        PerchQp(active_set_max_iter=0)


def test_warm_started_active_set_controller_matches_clarabel_wheel_each_tick() -> None:
    """400 consecutive ticks of the default controller (warm starts from the previous tick's
    active set; the filter and eq. 48 couple the QPs): every tick's problem is re-solved with
    the Clarabel wheel, and a Rust Clarabel controller fed the same inputs agrees on status."""
    base = feasible_instances(2, seed=11)
    a, b = base
    fast, slow = PerchController(), PerchController(solver="clarabel")
    fast.reset(a["previous_thrust"])
    slow.reset(a["previous_thrust"])
    worst, solved = 0.0, 0
    for k in range(400):
        s = 0.5 - 0.5 * np.cos(np.pi * k / 200.0)
        wrench = (1 - s) * a["foot_wrench"] + s * b["foot_wrench"]
        wrench = wrench + 0.3 * np.sin(0.37 * k) * np.array([1, -1, 2, 0.05, -0.05, 0.1])
        foot = (1 - s) * a["foot_allocation"] + s * b["foot_allocation"]
        alloc = (1 - s) * a["allocation"] + s * b["allocation"]
        mass = (1 - s) * a["mass"] + s * b["mass"]
        res = fast.tick(wrench, foot, alloc, mass)
        ref = slow.tick(wrench, foot, alloc, mass)
        assert res.ok == ref.ok, (k, res.status, ref.status)
        if res.ok:
            solved += 1
            prob = fast.problem_data()
            x_cl = prob.variable_scale * clarabel_solve(prob)[:4]
            worst = max(worst, float(np.max(np.abs(x_cl - res.thrust))))
            worst = max(worst, float(np.max(np.abs(ref.thrust - res.thrust))))
    assert solved > 300, solved
    assert worst < THRUST_ATOL, worst
    assert fast.counters()["fallback"] == 0


@pytest.mark.parametrize("solver", SOLVERS)
def test_problem_data_rows_match_the_paper_equations(solver: str) -> None:
    """A x ≤ b rows of problem_data, unscaled, reproduce eqs. (39)-(48) for one instance."""
    inst = feasible_instances(1, seed=5)[0]
    qp = PerchQp(solver=solver)
    res = qp.solve(**inst)
    prob = qp.problem_data()
    x = np.concatenate([res.thrust, res.foot_wrench]) / prob.variable_scale
    slack = prob.b - prob.A @ x
    assert np.all(np.abs(slack[: prob.zero_cone]) < 1e-7)
    assert np.all(slack[prob.zero_cone :] > -1e-7)
    # The thrust-bound rows (17-20) carry λ_max of eq. (47) (rows are normalised to 1).
    assert np.allclose(prob.b[17:21] * prob.variable_scale, thrust_max(inst))
    assert np.allclose(res.thrust_max, thrust_max(inst))


def safe_command(prev: np.ndarray, lmax: np.ndarray) -> np.ndarray:
    hi = np.maximum(lmax, 0.0)
    target = np.clip(prev, 0.0, hi)
    return np.clip(prev + np.clip(target - prev, -DELTA, DELTA), 0.0, hi)


@pytest.mark.parametrize("solver", SOLVERS)
def test_rate_limit_too_tight_is_infeasible_with_safe_command(solver: str) -> None:
    """Eq. (49) as printed (``relax_rate_limit=False``): the safe command holds the thrust."""
    inst = feasible_instances(1, seed=2)[0]
    inst["previous_thrust"] = np.zeros(4)
    qp = PerchQp(thrust_rate_limit=[0.01] * 4, solver=solver, relax_rate_limit=False)
    res = qp.solve(**inst)
    assert res.status == "infeasible"
    assert np.all(np.isfinite(res.thrust))
    assert np.allclose(res.thrust, np.zeros(4))
    assert qp.counters()["infeasible"] == 1


@pytest.mark.parametrize("solver", SOLVERS)
def test_rate_limit_too_tight_steps_toward_the_problem_without_eq_48(solver: str) -> None:
    """The default relaxation: an eq. (49) infeasible only through eq. (48) is solved without
    it (here by the Clarabel wheel, on the strict problem's rows with rows 21-28 removed) and
    the thrust moves toward that solution by at most δλ_perch."""
    rate = 0.5
    for inst in feasible_instances(10, seed=2):
        inst["previous_thrust"] = np.zeros(4)
        strict = PerchQp(thrust_rate_limit=[rate] * 4, solver=solver, relax_rate_limit=False)
        assert strict.solve(**inst).status == "infeasible"
        prob = strict.problem_data()
        keep = np.r_[0:21]  # rows 21-28 are eq. (48)
        relaxed_prob = dataclasses.replace(
            prob,
            A=prob.A[keep, :],
            b=prob.b[keep],
            nonnegative_cone=prob.nonnegative_cone - 8,
        )
        target = prob.variable_scale * clarabel_solve(relaxed_prob)[:4]
        expected = np.clip(np.clip(target, -rate, rate), 0.0, None)
        qp = PerchQp(thrust_rate_limit=[rate] * 4, solver=solver)
        res = qp.solve(**inst)
        assert res.status == "rate_limited" and res.ok
        assert np.allclose(res.thrust, expected, atol=THRUST_ATOL), (res.thrust, expected)
        assert np.all(np.abs(res.thrust) <= rate + 1e-9)
        assert qp.counters()["rate_limited"] == 1 and qp.counters()["infeasible"] == 0


@pytest.mark.parametrize("solver", SOLVERS)
def test_impossible_friction_is_infeasible_with_safe_command(solver: str) -> None:
    qp = PerchQp(solver=solver)
    for k, inst in enumerate(feasible_instances(20, seed=3)):
        inst["foot_wrench"][0] = 500.0  # |F_x| needs F_z > 555 N: beyond any thrust
        res = qp.solve(**inst)
        assert res.status == "infeasible"
        expected = safe_command(inst["previous_thrust"], thrust_max(inst))
        assert np.allclose(res.thrust, expected)
        assert np.all(res.thrust >= 0) and np.all(res.thrust <= np.maximum(res.thrust_max, 0))
        assert np.all(res.thrust <= np.maximum(thrust_max(inst), 0) + 1e-9)
        assert qp.counters()["infeasible"] == k + 1


@pytest.mark.parametrize("solver", SOLVERS)
def test_thrust_limit_below_hover_gives_clipped_safe_command(solver: str) -> None:
    inst = feasible_instances(1, seed=4)[0]
    inst["mass"] = 40.0  # hover thrust above λ_rotor_max: λ_max < 0 for some rotor
    inst["previous_thrust"] = np.array([12.0, 3.0, 9.0, 0.5])
    qp = PerchQp(solver=solver)
    res = qp.solve(**inst)
    assert res.status == "infeasible"
    assert np.allclose(res.thrust, safe_command(inst["previous_thrust"], thrust_max(inst)))
    assert np.all(res.thrust <= np.maximum(thrust_max(inst), 0.0) + 1e-12)


@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize("field", ["foot_wrench", "previous_thrust", "allocation", "mass"])
def test_non_finite_inputs_give_safe_command_and_are_counted(field: str, solver: str) -> None:
    inst = feasible_instances(1, seed=6)[0]
    qp = PerchQp(solver=solver)
    qp.solve(**inst)  # a valid tick first: its λ_max is the fallback bound
    bad = dict(inst)
    if field == "mass":
        bad["mass"] = float("nan")
    else:
        arr = np.array(inst[field], dtype=float)
        arr.flat[1] = np.inf
        bad[field] = arr
    res = qp.solve(**bad)
    assert res.status == "non_finite_input"
    for v in (res.thrust, res.foot_wrench, res.zmp, res.friction_margin, res.thrust_max):
        assert np.all(np.isfinite(v))
    assert np.all(res.thrust >= 0) and np.all(res.thrust <= np.maximum(thrust_max(inst), 0))
    assert qp.counters()["non_finite_input"] == 1


@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize("mass", [0.0, -1.0, -1e300])
def test_a_mass_not_above_zero_gives_the_safe_command(mass: float, solver: str) -> None:
    """Eq. (47) with m <= 0 would raise the thrust ceiling above the rotors' limit: the
    input is refused (status invalid_input, counted), never reported as solved."""
    inst = feasible_instances(1, seed=6)[0]
    qp = PerchQp(solver=solver)
    qp.solve(**inst)
    res = qp.solve(**{**inst, "mass": mass})
    assert res.status == "invalid_input"
    assert not res.ok
    assert np.all(res.thrust >= 0) and np.all(res.thrust <= LMAX)
    assert np.all(np.isfinite(res.thrust_max))
    assert qp.counters()["invalid_input"] == 1


def test_singular_allocation_is_reported() -> None:
    inst = feasible_instances(1, seed=7)[0]
    inst["allocation"] = np.zeros((4, 4))
    qp = PerchQp()
    res = qp.solve(**inst)
    assert res.status == "singular_allocation"
    assert np.all(np.isfinite(res.thrust)) and np.all(res.thrust >= 0)


def test_controller_tracks_filtered_wrench_and_remembers_state() -> None:
    inst = feasible_instances(1, seed=8)[0]
    ctl = PerchController()
    ctl.reset(inst["previous_thrust"])
    prev = inst["previous_thrust"]
    for _ in range(40):
        res = ctl.tick(
            inst["foot_wrench"], inst["foot_allocation"], inst["allocation"], inst["mass"]
        )
        assert res.ok
        assert np.all(np.abs(res.thrust - prev) <= DELTA + 1e-9)
        prev = res.thrust
    assert np.allclose(ctl.filtered_foot_wrench(), inst["foot_wrench"])
    assert ctl.counters()["solved"] == 40


def test_bad_shapes_and_params_name_the_argument() -> None:
    qp = PerchQp()
    inst = feasible_instances(1, seed=9)[0]
    inst["previous_thrust"] = np.zeros(3)
    with pytest.raises(PerchError, match="previous_thrust"):
        qp.solve(**inst)
    with pytest.raises(PerchError, match="bogus"):
        PerchQp(bogus=1.0)
    with pytest.raises(PerchError, match="mu_z"):
        PerchQp(mu_z=-1.0)


def test_result_from_the_cores_dict_is_the_dataclass_of_it() -> None:
    # Oracle: the dataclass constructor of the same fields.
    fields = [f.name for f in dataclasses.fields(PerchResult)]
    d = {k: np.arange(3.0) + i for i, k in enumerate(fields)}
    d.update(status="solved", iterations=4, fallback=False)
    got, want = PerchResult._from(dict(d)), PerchResult(**d)
    assert type(got) is PerchResult and got.ok
    for k in fields:
        assert np.array_equal(getattr(got, k), getattr(want, k)), k
    with pytest.raises(dataclasses.FrozenInstanceError):
        got.status = "x"  # type: ignore[misc]
    with pytest.raises(TypeError):
        PerchResult._from({"status": "solved"})  # fields missing: the constructor's error
