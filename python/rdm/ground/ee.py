"""End-effector targets of the ground link: an ``ee`` command planned with
:func:`rdm.planner.plan` and handed to the node as a timed joint path.

The target is a point in the foot frame (the perched robot's foot at the origin, as
``rdm plan`` takes it). The plan starts at the node's present joint vector in the planner's
``perched`` mode: ASSUMPTION, ``ee`` is accepted only while the robot is perched (the
node's ``status()["perching"]`` is true), because a flight plan moves the base too and the
node follows joint paths only.

The path is the node's present q, then the planner's states (each re-levels the vectoring
units). Each segment lasts ``max|dq| / joint_speed`` (at least ``min_segment_s``), so no
joint moves faster than ``joint_speed`` on the node's linear interpolation. The first point
is stamped with the node time at which the plan is handed over.

Planning runs on a worker thread: the planner's loop is Python between its Rust QP steps
(~0.6 ms each), so the interpreter keeps switching to the nodes' thread and the robot keeps
its rate. A reachable target takes a few tens of ms, the step cap (800 steps) ~0.5 s.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import Executor, Future, ThreadPoolExecutor
from typing import Any

import numpy as np

from rdm.ground.message import Reason, Rejected

#: Fastest joint motion of an ``ee`` path [rad/s]. ASSUMPTION: 0.2 rad/s, the scenarios'
#: perched motions' order (a 0.8 rad fold in 4-8 s); slow enough for the perched robot's
#: servos (docs/scenarios.md "Servo goals ahead of the plan") to follow without a lead.
EE_JOINT_SPEED = 0.2
#: Shortest segment of an ``ee`` path [s] (strictly increasing stamps for the node).
EE_MIN_SEGMENT_S = 0.02

PlanFn = Callable[[Sequence[float], np.ndarray], Any]


def timed_points(
    qs: np.ndarray, t0: float, joint_speed: float = EE_JOINT_SPEED,
    min_segment_s: float = EE_MIN_SEGMENT_S,
) -> list[tuple[float, list[float]]]:  # fmt: skip
    """``(t, q)`` pairs for the rows of ``qs`` from ``t0``: each segment lasts
    ``max|dq| / joint_speed``, at least ``min_segment_s``."""
    qs = np.asarray(qs, dtype=float)
    steps = np.abs(np.diff(qs, axis=0)).max(axis=1) / joint_speed
    times = t0 + np.concatenate(([0.0], np.cumsum(np.maximum(steps, min_segment_s))))
    return [(float(t), q.tolist()) for t, q in zip(times, qs, strict=True)]


class EePlanner:
    """Plans ``ee`` targets for the shipped robot ``robot`` (``rdm``, ``rcm``) or a TOML
    path, one at a time, on ``executor`` (default: one worker thread)."""

    def __init__(
        self,
        robot: str,
        joint_speed: float = EE_JOINT_SPEED,
        executor: Executor | None = None,
        plan_fn: PlanFn | None = None,
    ) -> None:
        if not joint_speed > 0:
            raise ValueError(f"ee joint speed {joint_speed!r}: must be > 0 rad/s")
        self.robot = robot
        self.joint_speed = joint_speed
        self._executor = executor
        self._own_executor = executor is None
        self._plan_fn = plan_fn
        self._setup: Any = None

    def _plan(self, target: Sequence[float], q_start: np.ndarray) -> Any:
        if self._plan_fn is not None:
            return self._plan_fn(target, q_start)
        from rdm.planner import PlannerSetup, plan

        if self._setup is None:
            self._setup = PlannerSetup.for_robot(self.robot, "perched")
        zeta0 = np.concatenate((np.zeros(6), q_start))
        return plan(self._setup, target, start_zeta=zeta0, mode="perched")

    def submit(self, target: Sequence[float], q_start: Sequence[float]) -> Future:
        """Start planning from ``q_start`` (the node's full joint vector) to ``target``."""
        if self._executor is None:
            self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="ee-plan")
        q0 = np.array(q_start, dtype=float)
        return self._executor.submit(self._plan, list(target), q0)

    def points(self, future: Future, q_start: Sequence[float], t0: float) -> list:
        """The timed path of a finished plan, or :class:`Rejected` (``plan_failed``) with the
        planner's reason."""
        try:
            traj = future.result(timeout=0)
        except Exception as exc:  # the planner's refusal (RdmError: a start it cannot take)
            raise Rejected(Reason.PLAN_FAILED, f"{type(exc).__name__}: {exc}") from None
        if not traj.reached:
            raise Rejected(
                Reason.PLAN_FAILED,
                f"unreachable: blocked by {traj.blocking} "
                f"(end-effector {traj.final_error:.3f} m from the target)",
            )
        qs = np.vstack((np.asarray(q_start, dtype=float), traj.zeta[:, 6:]))
        return timed_points(qs, t0, self.joint_speed)

    def close(self) -> None:
        """Stop the worker (a plan under way is abandoned)."""
        if self._own_executor and self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
