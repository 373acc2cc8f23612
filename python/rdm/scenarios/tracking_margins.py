"""The tracking scenario's plan-execution metrics: how close the tracked end effector came to
the planner's goal, how closely the joints followed the plan, and the constraint margins
along the plan, as the planner predicted them and as MuJoCo's ground truth shows them
executed (docs/scenarios.md, "tracking").

* Goal error: |mean true end-effector position over the last ``GOAL_WINDOW_S`` of the hold
  - the goal|, the goal placed in the world with the root as it was before the motion.
* Joint RMSE: true q1..q6 against the sent plan (linear between its 40 Hz samples).
* Planned margins (:func:`rdm.scenarios.tracking_plan.plan_margins`): thrust, torque, rho.
* Executed margins over the motion window: true rotor thrusts to [thrust_min, thrust_max]
  (the thrust constraint, eqs. 63-64, in both stages; pass: >= 0); perched, the true ZMP's
  margin to the foot plate's edge and the time it is within ``EDGE_MM`` of it (Fig. 10 (E):
  "the ZMP was within the footplate area"; information: eq. 70 has no ZMP row and the
  planner's static model keeps the ZMP at the plate centre); in flight, the root's largest
  deviation per axis from its position before the motion (Fig. 9 (B): errors "less than
  +-0.1 m"; information).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from rdm.model import Robot
from rdm.sim import Metric

from .common import truth_arrays
from .perching import EDGE_MM, PLATE_HALF
from .tracking_plan import StagePlan, plan_at, plan_margins

if TYPE_CHECKING:
    from .stack import Stack

#: Goal tolerance [m] of the tracked end effector (a "max" metric): perched, the root is on
#: the ceiling and only the servos' sag and resolution are left (0.2 mm measured); in flight
#: the root itself moves (1.3 cm measured, root deviations up to 0.1 m). ASSUMPTION: the
#: paper states no goal tolerance; Fig. 13 (B)'s perched band is 0.05 m.
GOAL_TOLERANCE = {"flight": 0.05, "perched": 0.002}
#: Fig. 9 (B): root position errors in flight "less than +-0.1 m".
PAPER_FLIGHT_ROOT_ERROR = 0.1


@dataclass
class StageErrors:
    t: np.ndarray
    pos_err: np.ndarray  # (n, 3) [m], world axes
    att_err: np.ndarray  # (n, 3) [rad], rotation vector of R_true R_ref^T, world axes
    pos_rmse: np.ndarray
    att_rmse: np.ndarray
    pos_std: np.ndarray
    pos_max: np.ndarray
    att_max: np.ndarray
    root_std: np.ndarray  # true foot position std over the window [m]
    root_p: np.ndarray  # root position used for the target [m]
    root_r: np.ndarray  # root orientation used for the target
    joint_lag_s: np.ndarray  # q1..q6: how far the true joints trail the plan [s] (NaN: still)
    #: RMSE of the plan rounded to encoder counts against the plan (ideal servos' floor)
    pos_floor_rmse: np.ndarray
    att_floor_rmse: np.ndarray


def _window(t: np.ndarray, plan: StagePlan, after_s: float) -> np.ndarray:
    return (t >= plan.t_start) & (t <= plan.t_end + after_s)


def stage_execution(
    stack: Stack, robot: Robot, plan: StagePlan, errs: StageErrors, after_s: float
) -> dict[str, Any]:
    """Execution figures of one stage (see the module doc); empty for hand-chosen offsets."""
    if plan.path is None:
        return {}
    a = truth_arrays(stack)
    t = a["t"]
    win = _window(t, plan, after_s)
    g0, g1 = (plan.t_start + x for x in plan.path.goal_window())
    at_goal = (t >= g0) & (t <= g1)
    goal = plan.goal_world(errs.root_p, errs.root_r)
    assert goal is not None
    ee_goal = a["ee"][at_goal].mean(axis=0) if at_goal.any() else np.full(3, np.nan)
    q_plan = plan_at(plan.points, t[win])[:, :6]
    dq = a["q"][win, :6] - q_plan
    tmin = np.array([r["thrust_min"] for r in robot.rotors])
    tmax = np.array([r["thrust_max"] for r in robot.rotors])
    thrust = a["thrust"][win]
    out: dict[str, Any] = {
        "goal_foot_frame": plan.path.goal.tolist(),
        "goal_error_m": float(np.linalg.norm(ee_goal - goal)),
        "joint_rmse_rad": np.sqrt(np.mean(dq**2, axis=0)).tolist(),
        "planner_steps": plan.path.plan.steps,
        "planned_margins": plan_margins(plan.path.plan, robot),
        "thrust_margin_low_N": float((thrust - tmin).min()),
        "thrust_margin_high_N": float((tmax - thrust).min()),
        # per axis, as Fig. 9 (B) plots it
        "root_max_deviation_m": np.abs(a["foot"][win] - errs.root_p).max(axis=0).tolist(),
    }
    zmp = a["zmp"][win]
    with np.errstate(invalid="ignore"):
        margin = np.minimum(PLATE_HALF[0] - np.abs(zmp[:, 0]), PLATE_HALF[1] - np.abs(zmp[:, 1]))
    finite = np.isfinite(margin)
    out["zmp_margin_m"] = float(np.nanmin(margin)) if finite.any() else np.nan
    out["zmp_edge_fraction"] = (
        float(np.mean(margin[finite] * 1e3 <= EDGE_MM)) if finite.any() else np.nan
    )
    return out


def execution_metrics(facts: dict[str, dict[str, Any]]) -> list[Metric]:
    """Metric rows of :func:`stage_execution`'s figures per stage ("flight", "perched")."""
    ms: list[Metric] = []
    for stage, f in facts.items():
        if not f:
            continue
        tol = GOAL_TOLERANCE[stage]
        ms.append(
            Metric(f"{stage}: EE goal error (end of hold)", f["goal_error_m"], None, "m", "max",
                   limit=tol)
        )  # fmt: skip
        ms.append(
            Metric(f"{stage}: joint RMSE vs plan (q1..q6, norm)",
                   float(np.linalg.norm(f["joint_rmse_rad"])), None, "rad", "info")
        )  # fmt: skip
        pm = f["planned_margins"]
        ms.append(Metric(f"{stage}: planned min thrust margin", pm["thrust_low_N"], None, "N",
                         "min", limit=0.0))  # fmt: skip
        ms.append(Metric(f"{stage}: planned min torque margin", pm["torque_Nm"], None, "N m",
                         "min", limit=0.0))  # fmt: skip
        ms.append(Metric(f"{stage}: planned min rho (eq. 65)", pm["rho"], None, "", "info"))
        ms.append(
            Metric(f"{stage}: executed min thrust margin (truth)",
                   min(f["thrust_margin_low_N"], f["thrust_margin_high_N"]), None, "N", "min",
                   limit=0.0)
        )  # fmt: skip
        if stage == "perched":
            # the planner's static model puts the ZMP at the plate centre (module doc of
            # tracking_plan); the perching controller's plate rocks on its edges at times
            ms.append(
                Metric("perched: executed min ZMP margin to the plate edge (truth)",
                       f["zmp_margin_m"], None, "m", "info")
            )  # fmt: skip
            ms.append(
                Metric(f"perched: executed time with the ZMP within {EDGE_MM:g} mm of the edge",
                       f["zmp_edge_fraction"], 0.0, "fraction", "info")
            )  # fmt: skip
        else:
            ms.append(
                Metric("flight: max root deviation during the motion, any axis (truth)",
                       max(f["root_max_deviation_m"]), PAPER_FLIGHT_ROOT_ERROR, "m", "info")
            )  # fmt: skip
    return ms
