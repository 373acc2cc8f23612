"""Peer solvers measured beside the core in the same run on the same problems.

Each peer is optional (``pip install rdm[bench]``): :func:`availability` says whether its
module imports and, if not, why; a missing peer is reported as skipped, never raised.

* ``scipy_care``: ``scipy.linalg.solve_continuous_are(A, B, Q, R)`` plus ``K = -R⁻¹BᵀP``
  on the very (Ā, B̄) the core builds (``rdm._rdm.augmented_system``), Table V weights.
* ``osqp_*``, ``clarabel_*``: the perching QP exactly as the core last sent it to Clarabel
  (``PerchController.problem_data()`` after each tick). ``setup_solve`` builds a solver
  per tick (what a changing Q̄(q) costs); ``update_solve`` keeps one solver and updates
  ``q``, ``A``'s values and the bounds before solving (the pattern never changes).
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np


def availability(module: str) -> tuple[bool, str]:
    """``(True, version)`` if ``module`` imports, else ``(False, reason)``."""
    try:
        mod = importlib.import_module(module)
    except Exception as exc:  # ImportError, or a broken install raising anything else
        return (
            False,
            f"{module} not importable ({type(exc).__name__}: {exc}); pip install rdm[bench]",
        )
    return True, str(getattr(mod, "__version__", "unknown"))


@dataclass
class PeerRun:
    """Per-call nanoseconds of one peer plus its failures and accuracy against the core."""

    ns: np.ndarray
    failures: int
    max_error: float
    error_kind: str
    settings: dict[str, Any] = field(default_factory=dict)
    failure_statuses: dict[str, int] = field(default_factory=dict)

    def record_failure(self, status: str) -> None:
        """Count one failed call under the solver's own status name."""
        self.failures += 1
        self.failure_statuses[status] = self.failure_statuses.get(status, 0) + 1


def _timed(call: Callable[[], Any]) -> tuple[int, Any]:
    t0 = time.perf_counter_ns()
    out = call()
    return time.perf_counter_ns() - t0, out


# --- scipy CARE ---------------------------------------------------------------------------


def run_scipy_care(
    problems: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
    reference_k: np.ndarray,
) -> PeerRun:
    """Time ``solve_continuous_are`` + K for each (A, B, Q, R); error = max relative
    difference of K against ``reference_k`` (the core's K on the same configuration)."""
    from scipy.linalg import solve_continuous_are

    ns = np.zeros(len(problems), dtype=np.int64)
    run = PeerRun(ns, 0, 0.0, "max |K - K_rdm| / max |K_rdm|", {"balanced": True})
    for i, (a, b, q, r) in enumerate(problems):

        def solve(a=a, b=b, q=q, r=r) -> np.ndarray:
            p = solve_continuous_are(a, b, q, r)
            return -np.linalg.solve(r, b.T @ p)

        try:
            ns[i], k = _timed(solve)
        except (np.linalg.LinAlgError, ValueError) as exc:
            run.record_failure(type(exc).__name__)
            ns[i] = 0
            continue
        ref = reference_k[i]
        if np.all(np.isfinite(ref)):
            err = float(np.max(np.abs(k - ref)) / max(np.max(np.abs(ref)), 1e-300))
            run.max_error = max(run.max_error, err)
    return run


# --- perching QP --------------------------------------------------------------------------


@dataclass(frozen=True)
class QpData:
    """One perching QP: min ½xᵀPx + qᵀx s.t. Ax + s = b, s in {0}^zero x R+^rest."""

    P: Any  # scipy.sparse csc, upper triangle
    q: np.ndarray
    A: Any  # scipy.sparse csc
    b: np.ndarray
    zero_cone: int
    nonnegative_cone: int
    scale: float
    thrust: np.ndarray  # the core's answer (reported thrust) for accuracy

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """OSQP form ``l <= Ax <= u``: equalities on the zero cone, ``Ax <= b`` elsewhere."""
        lower = np.concatenate([self.b[: self.zero_cone], np.full(self.nonnegative_cone, -np.inf)])
        return lower, self.b


def _thrust_error(x: Any, data: QpData) -> float:
    thrust = np.asarray(x, dtype=float)[:4] * data.scale
    return float(np.max(np.abs(thrust - data.thrust)))


#: OSQP variants: the defaults (what a first port would use) and a tight, polished one.
OSQP_VARIANTS: dict[str, dict[str, Any]] = {
    "osqp": {},
    "osqp_eps1e-6": {"eps_abs": 1e-6, "eps_rel": 1e-6, "polishing": True},
}


def run_osqp(problems: list[QpData], settings: dict[str, Any], update: bool) -> PeerRun:
    """OSQP on each problem: a new solver per problem, or one updated solver."""
    import osqp

    ns = np.zeros(len(problems), dtype=np.int64)
    run = PeerRun(ns, 0, 0.0, "max |thrust - thrust_rdm| [N]", dict(settings))
    solver = None
    for i, d in enumerate(problems):
        lower, upper = d.bounds()
        if update and solver is not None:

            def call(d=d, lower=lower, upper=upper) -> Any:
                solver.update(q=d.q, l=lower, u=upper, Ax=d.A.data)
                return solver.solve(raise_error=False)
        else:

            def call(d=d, lower=lower, upper=upper) -> Any:
                nonlocal solver
                solver = osqp.OSQP()
                solver.setup(d.P, d.q, d.A, lower, upper, verbose=False, **settings)
                return solver.solve(raise_error=False)

        ns[i], res = _timed(call)
        if res.info.status != "solved":
            run.record_failure(str(res.info.status))
        else:
            run.max_error = max(run.max_error, _thrust_error(res.x, d))
    return run


def clarabel_settings() -> Any:
    """The core's Clarabel settings (docs/perch.md): no presolve, no equilibration,
    max_iter 50, gap/feasibility tolerances 1e-8."""
    import clarabel

    s = clarabel.DefaultSettings()
    s.verbose = False
    s.presolve_enable = False
    s.equilibrate_enable = False
    s.max_iter = 50
    s.tol_gap_abs = s.tol_gap_rel = s.tol_feas = 1e-8
    return s


def run_clarabel(problems: list[QpData], update: bool) -> PeerRun:
    """Clarabel's Python wheel on each problem: a new solver per problem, or one solver
    updated with ``update(q=, b=, A=values)``."""
    import clarabel

    settings = clarabel_settings()
    ns = np.zeros(len(problems), dtype=np.int64)
    run = PeerRun(
        ns,
        0,
        0.0,
        "max |thrust - thrust_rdm| [N]",
        {"presolve": False, "equilibrate": False, "max_iter": 50, "tol": 1e-8},
    )
    solver = None
    for i, d in enumerate(problems):
        if update and solver is not None:

            def call(d=d) -> Any:
                solver.update(q=d.q, b=d.b, A=d.A.data)
                return solver.solve()
        else:

            def call(d=d) -> Any:
                nonlocal solver
                cones = [
                    clarabel.ZeroConeT(d.zero_cone),
                    clarabel.NonnegativeConeT(d.nonnegative_cone),
                ]
                solver = clarabel.DefaultSolver(d.P, d.q, d.A, d.b, cones, settings)
                return solver.solve()

        ns[i], sol = _timed(call)
        if str(sol.status) not in ("Solved", "AlmostSolved"):
            run.record_failure(str(sol.status))
        else:
            run.max_error = max(run.max_error, _thrust_error(sol.x, d))
    return run
