"""Perching controller (paper Sec. IV-B, eqs. 37-49) on the Rust core's QP solvers.

Solver choice: ``solver="active_set"`` (default: dense dual active-set solver on the reduced
problem, Clarabel as fallback) or ``solver="clarabel"`` (Clarabel every tick).

Thin face over :mod:`rdm._rdm`: converts inputs to float64 numpy arrays, returns typed results
and builds scipy sparse matrices of the exact QP the core solves (so tests can hand the same
problem to other solvers). See ``docs/perch.md`` for the formulation.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from rdm._rdm import PERCH_ROTORS, PerchError, WrenchFilter
from rdm._rdm import PerchController as _Controller
from rdm._rdm import PerchQp as _Qp

__all__ = [
    "PERCH_ROTORS",
    "PerchController",
    "PerchError",
    "PerchProblem",
    "PerchQp",
    "PerchResult",
    "WrenchFilter",
]

Array = NDArray[np.float64]


def _vec(x: ArrayLike) -> Array:
    return np.ascontiguousarray(np.asarray(x, dtype=np.float64).reshape(-1))


def _mat(x: ArrayLike) -> Array:
    return np.ascontiguousarray(np.asarray(x, dtype=np.float64))


@dataclass(frozen=True)
class PerchResult:
    """Outcome of one perching tick. ``thrust`` is always finite and inside its bounds."""

    status: str
    thrust: Array
    foot_wrench: Array
    zmp: Array
    friction_margin: Array
    zmp_margin: Array
    thrust_min: Array
    thrust_max: Array
    iterations: int
    fallback: bool = False

    @property
    def ok(self) -> bool:
        """True when the thrust is the QP solution (``rate_limited``: stepping toward the
        solution without eq. 48), False when it is the safe command."""
        return self.status in ("solved", "almost_solved", "rate_limited")

    @classmethod
    def _from(cls, d: dict[str, Any]) -> PerchResult:
        """``cls(**d)`` of the core's dict; when it holds exactly the fields (it always
        does), without the frozen-dataclass ``__init__`` (one per perched control tick)."""
        if d.keys() != _RESULT_FIELDS:
            return cls(**d)
        result = object.__new__(cls)
        result.__dict__.update(d)
        return result


_RESULT_FIELDS = frozenset(PerchResult.__dataclass_fields__)


@dataclass(frozen=True)
class PerchProblem:
    """The scaled QP of the last tick (what the active-set solver reduces and Clarabel is
    sent): min ½xᵀPx + qᵀx s.t. Ax + s = b, s in (zero cone of ``zero_cone`` rows) x
    (nonnegative cone of the rest).

    ``P`` is upper-triangular. Variables are scaled: thrust = ``variable_scale`` * x[:4],
    W_foot,t = ``variable_scale`` * x[4:].
    """

    P: Any
    q: Array
    A: Any
    b: Array
    zero_cone: int
    nonnegative_cone: int
    variable_scale: float

    @classmethod
    def _from(cls, d: dict[str, Any]) -> PerchProblem:
        from scipy import sparse

        n, m = d["n"], d["m"]
        P = sparse.csc_matrix((d["P_nzval"], d["P_rowval"], d["P_colptr"]), shape=(n, n))
        A = sparse.csc_matrix((d["A_nzval"], d["A_rowval"], d["A_colptr"]), shape=(m, n))
        return cls(
            P=P,
            q=d["q"],
            A=A,
            b=d["b"],
            zero_cone=d["zero_cone"],
            nonnegative_cone=d["nonnegative_cone"],
            variable_scale=d["variable_scale"],
        )


class PerchQp:
    """Eq. (49) with every input explicit (no filter, no memory between calls).

    ``params``: overrides of Table VII (keys as in :class:`rdm._rdm.PerchQp`), e.g.
    ``solver="clarabel"``.
    """

    def __init__(self, **params: Any) -> None:
        self._inner = _Qp(params or None)

    def solve(
        self,
        foot_allocation: ArrayLike,
        allocation: ArrayLike,
        mass: float,
        foot_wrench: ArrayLike,
        previous_thrust: ArrayLike,
        previous_foot_wrench: ArrayLike,
        flight_thrust: ArrayLike | None = None,
    ) -> PerchResult:
        """Solve one instance (see docs/perch.md for each argument's frame and sign).

        ``foot_allocation`` 4 x 4 (rows F_n, M_t1, M_t2, M_n): ``foot_wrench`` is in the
        contact plane's coordinates (the ceiling: the foot frame); 6 x 4 (rows F_x .. M_z about
        the foot origin): ``foot_wrench`` is in foot axes and both are carried into the plane
        of the ``contact_normal``/``contact_center`` parameters."""
        d = self._inner.solve(
            _mat(foot_allocation),
            _mat(allocation),
            float(mass),
            _vec(foot_wrench),
            _vec(previous_thrust),
            _vec(previous_foot_wrench),
            None if flight_thrust is None else _vec(flight_thrust),
        )
        return PerchResult._from(d)

    def problem_data(self) -> PerchProblem:
        """The last tick's scaled QP as scipy sparse matrices."""
        return PerchProblem._from(self._inner.problem_data())

    def counters(self) -> dict[str, int]:
        """Calls per status, plus ``"fallback"``: active-set calls Clarabel answered."""
        return self._inner.counters()

    def params(self) -> dict[str, Any]:
        """Parameters in use."""
        return self._inner.params()


class PerchController:
    """The 40 Hz perching step: 1 Hz IIR on the foot wrench, then eq. (49)."""

    def __init__(self, rate_hz: float = 40.0, cutoff_hz: float = 1.0, **params: Any) -> None:
        self._inner = _Controller(params or None, rate_hz, cutoff_hz)

    def tick(
        self,
        foot_wrench: ArrayLike,
        foot_allocation: ArrayLike,
        allocation: ArrayLike,
        mass: float,
        flight_thrust: ArrayLike | None = None,
    ) -> PerchResult:
        """One tick from the raw sensor wrench ``[F_x, F_y, F_z, M_x, M_y, M_z]`` (frames as
        :meth:`PerchQp.solve`: a 4 x 4 ``foot_allocation`` is in plane coordinates, a 6 x 4 one
        in foot axes; the filter runs in plane coordinates)."""
        d = self._inner.tick(
            _vec(foot_wrench),
            _mat(foot_allocation),
            _mat(allocation),
            float(mass),
            None if flight_thrust is None else _vec(flight_thrust),
        )
        return PerchResult._from(d)

    def reset(self, thrust: ArrayLike | None = None) -> None:
        """Start a perching phase from ``thrust`` (zeros if omitted)."""
        self._inner.reset(None if thrust is None else _vec(thrust))

    def filtered_foot_wrench(self) -> Array:
        """Filtered foot wrench of the last finite sample."""
        return self._inner.filtered_foot_wrench()

    def filter_coefficients(self) -> tuple[float, float, float]:
        """``(b0, b1, a1)``: scipy ``lfilter([b0, b1], [1, a1], x)``."""
        return self._inner.filter_coefficients()

    def problem_data(self) -> PerchProblem:
        """The last tick's scaled QP as scipy sparse matrices."""
        return PerchProblem._from(self._inner.problem_data())

    def counters(self) -> dict[str, int]:
        """Ticks per status, plus ``"fallback"``: active-set ticks Clarabel answered."""
        return self._inner.counters()

    def params(self) -> dict[str, Any]:
        """Parameters in use."""
        return self._inner.params()
