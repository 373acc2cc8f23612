"""Time parameterisation of a planned path (Fig. 6: the planner's states become the joint
targets sent to the servos).

A plan (:class:`rdm.planner.Trajectory`) is a sequence of states, one per step (eq. 51):
in joint space a polyline. It is followed along its arc length ``s`` (the largest change of
the arm joints q1..q6 per step, summed, so that every joint moves at most as fast as ``s``)
with a rest-to-rest profile ``s(t)``, and sampled every ``sample_s``: between the vertices
the samples lie on the polyline's segments, so every commanded state lies between two
planned, constraint-checked states.

* :func:`time_parameterise`: jerk-limited, time-optimal for given speed, acceleration and
  jerk limits (ruckig);
* :func:`over_duration`: a cosine profile over a given duration (zero end velocities).
"""

from __future__ import annotations

import math

import numpy as np
from ruckig import InputParameter, Result, Ruckig
from ruckig import Trajectory as RuckigTrajectory

#: Sampling step [s]: the 40 Hz position control rate (Sec. VII-A).
SAMPLE_S = 1.0 / 40.0
#: Columns of the joint vector the arc length measures (q1..q6; the vectoring angles follow).
ARM_JOINTS = 6


def arc_length(q: np.ndarray) -> np.ndarray:
    """Cumulative path parameter (m,) of the joint states ``q`` (m, k): the largest change of
    the first ``ARM_JOINTS`` columns per step, summed (so |dq_j/ds| <= 1 for those joints)."""
    q = np.asarray(q, dtype=float)[:, :ARM_JOINTS]
    steps = np.abs(np.diff(q, axis=0)).max(axis=1) if len(q) > 1 else np.zeros(0)
    return np.concatenate([[0.0], np.cumsum(steps)])


def _sample(q: np.ndarray, s: np.ndarray, along: np.ndarray) -> np.ndarray:
    return np.column_stack([np.interp(along, s, q[:, j]) for j in range(q.shape[1])])


def _check(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or len(q) == 0 or not np.all(np.isfinite(q)):
        raise ValueError("q: expected a non-empty (steps, joints) array of finite values")
    return q


def time_parameterise(
    q: np.ndarray,
    max_velocity: float,
    max_acceleration: float,
    max_jerk: float,
    sample_s: float = SAMPLE_S,
) -> tuple[np.ndarray, np.ndarray]:
    """(times (m,) from 0, q (m, n)) of the polyline ``q`` (k, n) followed from rest to rest
    with ruckig's jerk-limited profile along its arc length, sampled every ``sample_s`` and at
    the end. Each arm joint's speed is at most ``max_velocity``."""
    q = _check(q)
    s = arc_length(q)
    length = float(s[-1])
    if length <= 0.0:
        return np.array([0.0]), q[:1].copy()
    inp = InputParameter(1)
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [0.0], [0.0]
    inp.target_position, inp.target_velocity, inp.target_acceleration = [length], [0.0], [0.0]
    inp.max_velocity = [max_velocity]
    inp.max_acceleration = [max_acceleration]
    inp.max_jerk = [max_jerk]
    profile = RuckigTrajectory(1)
    if Ruckig(1).calculate(inp, profile) not in (Result.Working, Result.Finished):
        raise ValueError("time_parameterise: ruckig refused the limits (positive and finite?)")
    duration = float(profile.duration)
    n = max(1, math.ceil(duration / sample_s))
    times = np.minimum(np.arange(n + 1) * sample_s, duration)
    times[-1] = duration
    along = np.clip([profile.at_time(float(t))[0][0] for t in times], 0.0, length)
    along[-1] = length
    return times, _sample(q, s, along)


def over_duration(
    q: np.ndarray, duration: float, sample_s: float = SAMPLE_S, linear: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """(times (m,) in (0, duration], q (m, n)) of the polyline ``q`` (k, n) followed from rest
    to rest in ``duration`` s with ``s(t) = L (1 - cos(pi t / duration)) / 2`` (``linear``:
    at constant speed, ``s(t) = L t / duration``, for a path cut into successive moves),
    sampled every ``sample_s`` and at the end (the start state itself is not repeated)."""
    q = _check(q)
    if not duration > 0.0:
        raise ValueError(f"duration: must be > 0 s, got {duration}")
    s = arc_length(q)
    n = max(1, math.ceil(duration / sample_s))
    times = np.minimum(np.arange(1, n + 1) * sample_s, duration)
    times[-1] = duration
    frac = times / duration if linear else 0.5 * (1.0 - np.cos(np.pi * times / duration))
    along = float(s[-1]) * frac
    out = _sample(q, s, along)
    out[-1] = q[-1]
    return times, out
