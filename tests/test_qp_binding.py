"""QpSolver (rdm_core::qp on Clarabel) against clarabel's Python wheel and scipy."""

import clarabel
import numpy as np
import pytest
from scipy import sparse
from scipy.optimize import linprog

from rdm._rdm import QpInputError, QpSolver


def _reference(P, q, A, b, G, h):
    n = len(q)
    Aall = sparse.csc_matrix(np.vstack([A, G]) if len(A) else G)
    cones = ([clarabel.ZeroConeT(len(b))] if len(b) else []) + [clarabel.NonnegativeConeT(len(h))]
    s = clarabel.DefaultSettings()
    s.verbose = False
    sol = clarabel.DefaultSolver(
        sparse.triu(sparse.csc_matrix(P)).tocsc(), q, Aall, np.concatenate([b, h]), cones, s
    )
    r = sol.solve()
    return str(r.status), np.array(r.x[:n])


@pytest.mark.parametrize("seed", range(20))
def test_random_feasible_qps_match_clarabel_wheel(seed):
    rng = np.random.default_rng(seed)
    n, ne, ni = 6, 2, 10
    M = rng.normal(size=(n, n))
    P = M @ M.T + 0.1 * np.eye(n)
    q = rng.normal(size=n)
    A = rng.normal(size=(ne, n))
    x0 = rng.normal(size=n)
    b = A @ x0
    G = rng.normal(size=(ni, n))
    h = G @ x0 + rng.uniform(0.0, 1.0, ni)  # x0 is feasible
    solver = QpSolver(n, ne, ni)
    status, x = solver.solve(P, q, A, b, G, h)
    ref_status, x_ref = _reference(P, q, A, b, G, h)
    assert status == "solved" and ref_status == "Solved"
    np.testing.assert_allclose(x, x_ref, atol=1e-6)
    assert np.all(G @ x <= h + 1e-7) and np.allclose(A @ x, b, atol=1e-7)


def test_lp_matches_scipy_and_solver_is_reused():
    rng = np.random.default_rng(7)
    solver = QpSolver(4, 0, 12)
    for _ in range(5):
        c = rng.normal(size=4)
        G = np.vstack([np.eye(4), -np.eye(4), rng.normal(size=(4, 4))])
        h = np.concatenate([np.ones(4), np.ones(4), rng.uniform(0.5, 1.0, 4)])
        status, x = solver.solve(np.zeros((4, 4)), c, np.zeros((0, 4)), np.zeros(0), G, h)
        ref = linprog(c, A_ub=G, b_ub=h, bounds=[(None, None)] * 4, method="highs")
        assert status == "solved"
        assert c @ x == pytest.approx(ref.fun, abs=1e-6)


def test_infeasible_is_reported():
    solver = QpSolver(2, 0, 2)
    G = np.array([[1.0, 0.0], [-1.0, 0.0]])
    status, x = solver.solve(np.eye(2), np.zeros(2), np.zeros((0, 2)), np.zeros(0), G,
                             np.array([-1.0, -1.0]))  # fmt: skip
    assert status == "primal_infeasible"
    assert np.all(x == 0.0)


def test_bad_input_names_argument():
    solver = QpSolver(2, 0, 1)
    with pytest.raises(QpInputError, match="G"):
        solver.solve(np.eye(2), np.zeros(2), np.zeros((0, 2)), np.zeros(0), np.ones((2, 2)),
                     np.ones(1))  # fmt: skip
    with pytest.raises(QpInputError, match="P"):
        solver.solve(np.full((2, 2), np.nan), np.zeros(2), np.zeros((0, 2)), np.zeros(0),
                     np.ones((1, 2)), np.ones(1))  # fmt: skip


@pytest.mark.parametrize("seed", range(10))
def test_random_infeasible_qps_agree_with_clarabel_wheel(seed):
    """Random constraints plus a contradicting pair hidden in a random direction."""
    rng = np.random.default_rng(100 + seed)
    n, ni = 5, 8
    M = rng.normal(size=(n, n))
    P = M @ M.T + 0.1 * np.eye(n)
    q = rng.normal(size=n)
    G = rng.normal(size=(ni, n))
    h = rng.uniform(0.5, 1.0, ni)
    d = rng.normal(size=n)
    G[0], h[0] = d, -1.0  # d.x <= -1
    G[1], h[1] = -d, -1.0  # d.x >= 1
    A, b = np.zeros((0, n)), np.zeros(0)
    status, x = QpSolver(n, 0, ni).solve(P, q, A, b, G, h)
    ref_status, _ = _reference(P, q, A, b, G, h)
    assert ref_status == "PrimalInfeasible"
    assert status == "primal_infeasible"
    assert np.all(x == 0.0)
    # The same QP without the contradiction is solved and matches the wheel.
    h[1] = 1.5
    status, x = QpSolver(n, 0, ni).solve(P, q, A, b, G, h)
    ref_status, x_ref = _reference(P, q, A, b, G, h)
    if ref_status == "Solved":
        assert status == "solved"
        np.testing.assert_allclose(x, x_ref, atol=1e-6)
    else:
        assert status == "primal_infeasible" and ref_status == "PrimalInfeasible"
