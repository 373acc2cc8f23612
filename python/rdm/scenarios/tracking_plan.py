"""The tracking scenario's joint paths, planned by the Sec. V planner (Fig. 6: "the motion
planner calculates the current target states such as the pose and joint angles based on the
final target states"; Sec. VII-C-2: "The target pose is determined by the planner").

A stage's path: :func:`rdm.planner.plan.run_core` from the stage's start posture (the
posture the phase machine leaves the robot in) to an end-effector goal, in the stage's planner
mode (``flight``: base free, foot task, the thrust limits of the hover share; ``perched``:
foot fixed, the thrust limits with the perching share, eq. 64), with every constraint kind of
eq. (70): ``joint_limit``, ``joint_torque``, ``rotor_thrust``, ``stability``, ``collision``,
``airflow``. The planner's states (one per step, eq. 51) are a joint-space polyline; it is
time-parameterised along its arc length with ruckig (:mod:`rdm.planner.timing`:
jerk-limited, at rest at both ends), sampled at the 40 Hz position-control rate (Sec. VII-A),
held at the goal, and retraced back to the start (the same states in reverse order, so
every state of the return is a planned, constraint-checked state too). The phase machine
then continues from the start posture.

Goals (docs/scenarios.md, "tracking"):

* flight: where Fig. 9 (A)'s end configuration q = [0.5, -0.5, 0.2, 0.8, 0.6, 0] puts the end
  effector in the foot frame (the paper's in-flight configuration change);
* perched: where the middle pose of the perched motion (``perching.PERCHED_MOTION``, the
  arm pitch and yaw sweep of Fig. 10) puts it.

Only the position is a goal (3-D target): the planner chooses the joints (it does not return
to the paper's q, the paths are redundant).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from rdm.model import Robot
from rdm.planner.core import PlannerSetup, make_core
from rdm.planner.plan import run_core
from rdm.planner.timing import time_parameterise
from rdm.planner.trajectory import Trajectory

from .perching import PERCH_POSTURE, PERCHED_MOTION

#: Fig. 9 (A): "the joints between links q were varied from [0, 0, 0, 0, 0, 0] to
#: [0.5, -0.5, 0.2, 0.8, 0.6, 0.0]" (flight).
FIG9_END_Q = (0.5, -0.5, 0.2, 0.8, 0.6, 0.0)
#: Fig. 10's perched arm pose (``perching.PERCHED_MOTION``'s middle goal).
FIG10_POSE_Q = tuple(PERCHED_MOTION[1][1])
#: Stage -> (planner mode, start posture q1..q6, posture whose end effector is the goal).
STAGES: dict[str, tuple[str, tuple[float, ...], tuple[float, ...]]] = {
    "flight": ("flight", (0.0,) * 6, FIG9_END_Q),
    "perched": ("perched", tuple(PERCH_POSTURE), FIG10_POSE_Q),
    # the flying robot in the hanging posture, to the perched stage's goal
    "flight-hanging": ("flight", tuple(PERCH_POSTURE), FIG10_POSE_Q),
}
#: Planner parameters of a flight plan (docs/planner.md). ASSUMPTION: the foot task weight
#: S2'' (eq. 57) raised from 1e-2 to 100: the position controller holds the root where it
#: was (Sec. VII-C-2: feedback "not in the motion planner but in position and attitude
#: control"), so the plan must not count on moving it; with 1e-2 the planned base wanders
#: 29 mm (the joints alone then miss the goal by 3 mm), with 100 less than 0.1 mm.
FLIGHT_CONFIG: dict[str, float] = {"s2_foot": 100.0}
#: Path limits along the arc length (largest joint step, q1..q6) [rad/s, rad/s^2, rad/s^3].
#: ASSUMPTION: Sec. V assumes the joint motion "sufficiently slow" (q_ddot = 0 in eq. 61);
#: 0.15 rad/s is the peak speed of the hand-chosen sweep the flying robot tracked (0.4 rad in
#: a 4 s cosine), the acceleration and jerk the smallest that keep its ~4 s duration.
MAX_VELOCITY = 0.15
MAX_ACCELERATION = 0.15
MAX_JERK = 0.5
#: s held at the goal before the return (the goal error is averaged over its last 0.5 s).
HOLD_S = 2.0
GOAL_WINDOW_S = 0.5


def end_effector_in_foot(robot: Robot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """End-effector position (3,) and rotation (3, 3) in the foot frame for joints ``q``
    (q1..q6 or the full joint vector)."""
    full = np.zeros(robot.n_q)
    q = np.asarray(q, dtype=float)
    full[: q.size] = q
    fr = robot.evaluate(full)["frames"]
    rel = np.linalg.solve(np.asarray(fr["foot"], float), np.asarray(fr["end_effector"], float))
    return rel[:3, 3], rel[:3, :3]


@dataclass
class StagePath:
    """A stage's planned joint path, relative times from the motion start."""

    stage: str
    mode: str
    goal: np.ndarray  # (3,) end-effector goal in the foot frame [m]
    plan: Trajectory  # the planner's output, start -> goal
    times: np.ndarray  # (m,) [s] from the motion start
    q: np.ndarray  # (m, n_q) full joint vector (vectoring angles as the planner levels them)
    go_s: float  # s from the start to the goal
    hold: tuple[float, float]  # (start, end) [s] of the hold at the goal

    @property
    def duration(self) -> float:
        """s from the motion start to the return's last sample."""
        return float(self.times[-1])

    def goal_window(self) -> tuple[float, float]:
        """The last ``GOAL_WINDOW_S`` of the hold [s from the motion start]."""
        return self.hold[1] - GOAL_WINDOW_S, self.hold[1]


class PlanFailed(RuntimeError):
    """The planner did not reach a stage's goal (the stage would not run the paper's test)."""


def plan_stage(
    stage: str,
    robot: str = "rdm",
    goal: Sequence[float] | None = None,
    require_reached: bool = True,
    **config: Any,
) -> Trajectory:
    """The planner's path of ``stage`` (a key of :data:`STAGES`) from its start to its goal
    (``goal``: another end-effector position in the foot frame); ``config``: planner
    parameters (docs/planner.md). :class:`PlanFailed` if not reached and
    ``require_reached``."""
    if stage not in STAGES:
        raise ValueError(f"stage={stage!r}: one of {sorted(STAGES)}")
    mode, start, goal_q = STAGES[stage]
    if mode == "flight":
        config = {**FLIGHT_CONFIG, **config}
    setup = PlannerSetup.for_robot(robot, mode, **config)
    model = Robot.from_strs(setup.urdf, setup.toml)
    if goal is None:
        goal, _ = end_effector_in_foot(model, np.asarray(goal_q))
    zeta0 = np.zeros(6 + model.n_q)
    zeta0[6:12] = start
    tr = run_core(make_core(setup, zeta0), tuple(goal), mode)
    if require_reached and not tr.reached:
        raise PlanFailed(
            f"{stage}: the planner stopped {tr.final_error:.3f} m from the goal ({tr.blocking})"
        )
    return tr


@lru_cache(maxsize=8)
def _stage_path(stage: str) -> StagePath:
    tr = plan_stage(stage)
    q_plan = np.asarray(tr.zeta, float)[:, 6:]
    t_go, q_go = time_parameterise(q_plan, MAX_VELOCITY, MAX_ACCELERATION, MAX_JERK)
    go = float(t_go[-1])
    t_back = go + HOLD_S + t_go
    q_back = q_go[::-1]
    times = np.concatenate([t_go, t_back])
    q = np.vstack([q_go, q_back])
    mode = STAGES[stage][0]
    return StagePath(stage, mode, np.array(tr.target[:3]), tr, times, q, go, (go, go + HOLD_S))


def stage_path(stage: str) -> StagePath:
    """The planned, time-parameterised path of ``stage`` (go, hold, return); planned once per
    process (the planner is deterministic)."""
    p = _stage_path(stage)
    return StagePath(
        p.stage, p.mode, p.goal.copy(), p.plan, p.times.copy(), p.q.copy(), p.go_s, p.hold
    )


def plan_margins(tr: Trajectory, robot: Robot) -> dict[str, float]:
    """Smallest margin of the planned states to each constraint's limit (the planner's own
    predictions, eqs. 61-68): thrust to [thrust_min, thrust_max] [N], torque to stall [N m],
    rho [-], shape clearance [m], rotor airflow clearance [m]."""
    tmin = np.array([r["thrust_min"] for r in robot.rotors])
    tmax = np.array([r["thrust_max"] for r in robot.rotors])
    stall = np.asarray(robot.stall_torques, float)[: tr.torques.shape[1]]
    return {
        "thrust_low_N": float((tr.thrusts - tmin).min()),
        "thrust_high_N": float((tmax - tr.thrusts).min()),
        "torque_Nm": float((stall - np.abs(tr.torques)).min()),
        "rho": float(np.min(tr.rho)),
        "clearance_m": float(np.min(tr.clearance)),
        "airflow_m": float(np.min(tr.airflow)),
    }


@dataclass
class StagePlan:
    """The joint path a stage sent and when its motion ran."""

    points: list[tuple[float, np.ndarray]]
    t_start: float  # first sample of the motion
    t_end: float  # last sample of the motion
    #: the planner's path (None: hand-chosen offsets)
    path: StagePath | None = None

    def goal_world(self, root_p: np.ndarray, root_r: np.ndarray) -> np.ndarray | None:
        """The planned end-effector goal in the world with the root at (root_p, root_r)."""
        return None if self.path is None else root_p + root_r @ self.path.goal


def plan_arrays(points: list[tuple[float, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """(times (m,), full q (m, n_q)) of a planned path's samples."""
    return np.array([p[0] for p in points]), np.array([p[1] for p in points])


def plan_at(points: list[tuple[float, np.ndarray]], t: np.ndarray) -> np.ndarray:
    """Planned full q at times ``t``: linear between the samples, held outside (as the node)."""
    times, qs = plan_arrays(points)
    return np.column_stack([np.interp(t, times, qs[:, j]) for j in range(qs.shape[1])])
