"""Differential-kinematics motion planner (Sec. V) and design evaluation (Sec. II-A).

>>> from rdm.planner import plan
>>> result = plan("rdm", target=(0.2, -0.3, -0.7))
>>> result.reached, result.final_error < 1e-3
(True, True)

See docs/planner.md for the formulation and every parameter.
"""

from rdm.planner.core import PlannerSetup, default_start, feasible_starts, make_core
from rdm.planner.design import DesignResult, evaluate_design
from rdm.planner.plan import plan
from rdm.planner.trajectory import Trajectory, Unreachable

__all__ = [
    "DesignResult",
    "PlannerSetup",
    "Trajectory",
    "Unreachable",
    "default_start",
    "evaluate_design",
    "feasible_starts",
    "make_core",
    "plan",
]
