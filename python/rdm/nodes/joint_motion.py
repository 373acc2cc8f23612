"""Jerk-limited joint motions for the onboard node (``rdm ctl joints``), planned with ruckig.

A joint goal from the operator is never a step: :func:`plan_joint_motion` gives the
time-optimal path from the present joint targets (at rest) to the goal (at rest) with per-joint
velocity, acceleration and jerk limits (``FlightLimits.joint_max_*``), all joints arriving
together (ruckig's time synchronisation). The node follows it as a trajectory
(``OnboardNode.set_trajectory``): the samples are its points, interpolated linearly between.
"""

from __future__ import annotations

import math

import numpy as np
from ruckig import InputParameter, Result, Ruckig, Trajectory

#: Sampling step of a planned joint motion, s (the node interpolates linearly between).
JOINT_SAMPLE_S = 0.02


def plan_joint_motion(
    start_time: float,
    start: np.ndarray,
    goal: np.ndarray,
    max_velocity: float,
    max_acceleration: float,
    max_jerk: float,
) -> list[tuple[float, np.ndarray]] | None:
    """(node time, joint vector) points of the jerk-limited motion from ``start`` to ``goal``
    (both at rest), every :data:`JOINT_SAMPLE_S` and at the end; None if ruckig refuses
    (non-finite input). A goal equal to the start gives its two end points."""
    start = np.asarray(start, dtype=float)
    goal = np.asarray(goal, dtype=float)
    n = start.size
    if goal.shape != start.shape or not (np.all(np.isfinite(start)) and np.all(np.isfinite(goal))):
        return None
    inp = InputParameter(n)
    inp.current_position = start.tolist()
    inp.current_velocity = [0.0] * n
    inp.current_acceleration = [0.0] * n
    inp.target_position = goal.tolist()
    inp.target_velocity = [0.0] * n
    inp.target_acceleration = [0.0] * n
    inp.max_velocity = [max_velocity] * n
    inp.max_acceleration = [max_acceleration] * n
    inp.max_jerk = [max_jerk] * n
    trajectory = Trajectory(n)
    if Ruckig(n).calculate(inp, trajectory) not in (Result.Working, Result.Finished):
        return None
    duration = float(trajectory.duration)
    steps = max(1, math.ceil(duration / JOINT_SAMPLE_S))
    points = []
    for k in range(steps + 1):
        t = duration * k / steps
        q = np.array(trajectory.at_time(t)[0], dtype=float)
        points.append((start_time + max(t, 1e-6 * k), q))
    points[-1] = (points[-1][0], goal.copy())
    return points
