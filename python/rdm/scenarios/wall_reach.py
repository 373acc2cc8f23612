"""Where the perched arm can paint a vertical wall (paper Sec. VII-D, Fig. 14 B: "paints
walls using a brush ... the sliding area length was over 0.5 m in the vertical direction").

The wall is the plane x = foot x + ``wall_dx`` (world), facing the robot (normal -x). For
brush-tip points on a vertical line of that plane (y = foot y) this module solves the
perched arm's tool-point IK (:func:`rdm.scenarios.task_ik.solve`: q1, q2, q4, q5 free, q3 = 0,
vectoring units levelled) and reports, per depth below the foot, whether the tip lands on
the wall and the angle between the tool axis and the wall normal. The compliant brush
(task_objects BRUSH_*) compresses along the tool axis, so a tilted tool still presses it;
ASSUMPTION: tilts up to ``max_tilt_deg`` (default 50 deg, the horizontal painting stroke
already runs at up to ~47 deg) keep the brush pressed and sliding.

The vertical stroke this gives is the longest run of consecutive reachable depths. Measured
(5 cm steps, foot level at TaskLayout.nominal_foot): a wall 0.80 m in front of the foot is
reached from 0.35 to 0.85 m below it with tilts 0-37 deg (0.5 m, the paper's stroke); 0.70 m:
0.45-0.95 m, tilts up to 46 deg; 0.30 m: only 0.90-1.10 m below the foot (the arm folds).
The ``painting`` scenario's wall stands at 0.75 m (:mod:`rdm.scenarios.painting`: at 0.80 m
the pressed brush is out of reach at the bottom of the stroke).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import task_ik
from . import task_objects as obj

#: IK seeds (q1..q6): the elbow-forward branch of the painting stroke and three others; the
#: best reachable solution (smallest tilt) over the seeds is kept.
SEEDS: tuple[tuple[float, ...], ...] = (
    (math.pi / 2, -0.7, 0.0, 1.45, 0.0, 0.0),
    (1.2, -0.3, 0.0, 0.8, 0.0, 0.0),
    (1.0, -1.0, 0.0, 1.5, 0.0, 0.0),
    (1.5, 0.3, 0.0, -0.5, 0.0, 0.0),
)
#: m: a tip farther than this from its target is not on the wall.
POSITION_TOL = 2e-3


@dataclass
class WallPoint:
    """One target on the wall's vertical line."""

    depth: float  # m below the foot
    reached: bool  # tip within POSITION_TOL and tilt within the bound
    tilt_deg: float  # angle tool axis <-> wall normal (nan: no solution within POSITION_TOL)
    q: np.ndarray | None  # joint vector of the best solution


def tool_tip() -> float:
    """m along the end-effector x axis to the tip of the free (uncompressed) brush."""
    return obj.BRUSH_AT + obj.BRUSH_RADIUS


def wall_line(
    robot,
    wall_dx: float,
    depths: np.ndarray,
    foot: tuple[float, float, float] | None = None,
    max_tilt_deg: float = 50.0,
) -> list[WallPoint]:
    """IK of the brush tip on the wall x = foot x + ``wall_dx`` at each of ``depths`` [m]
    below a level foot at ``foot`` (default TaskLayout.nominal_foot)."""
    if not wall_dx > 0.0:
        raise ValueError(f"wall_dx: must be > 0 (the wall is in front of the foot), got {wall_dx}")
    fx, fy, fz = foot or obj.TaskLayout().nominal_foot
    base = np.array([fx, fy, fz, 0.0, 0.0, 0.0])
    tip = tool_tip()
    pad = np.zeros(robot.n_q - 6)
    out = []
    for depth in np.asarray(depths, dtype=float):
        best: WallPoint | None = None
        for seed in SEEDS:
            res = task_ik.solve(
                robot,
                base,
                task_ik.level(np.r_[seed, pad]),
                [fx + wall_dx, fy, fz - depth],
                tip,
                iterations=300,
            )
            if res.position_error >= POSITION_TOL:
                continue
            _, axis = task_ik.tool_pose(robot, base, res.q, tip)
            tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(axis[0])))))
            if best is None or tilt < best.tilt_deg:
                best = WallPoint(float(depth), tilt <= max_tilt_deg, tilt, res.q)
        out.append(best or WallPoint(float(depth), False, math.nan, None))
    return out


def longest_stroke(points: list[WallPoint]) -> tuple[float, float]:
    """(top depth, bottom depth) [m] of the longest run of consecutive reached points
    (equal depths when none or one is reached: (nan, nan) when none)."""
    best = (math.nan, math.nan)
    start = None
    for i, p in enumerate([*points, WallPoint(math.nan, False, math.nan, None)]):
        if p.reached and start is None:
            start = i
        elif not p.reached and start is not None:
            top, bottom = points[start].depth, points[i - 1].depth
            if math.isnan(best[0]) or bottom - top > best[1] - best[0]:
                best = (top, bottom)
            start = None
    return best


@dataclass
class PlannedPoint:
    """One wall target planned by the Sec. V planner (``rdm.planner.plan``)."""

    depth: float  # m below the foot
    reached: bool
    error: float  # m, final end-effector position error
    blocking: str | None  # the constraint that stopped the plan (None: reached)
    zeta: np.ndarray  # final planner state [p, eta, q]
    tilt_deg: float  # angle end-effector x axis <-> wall normal into the wall


def planner_line(wall_dx: float, depths: np.ndarray, robot: str = "rdm") -> list[PlannedPoint]:
    """Plan the end-effector frame origin (orientation free) to x = ``wall_dx``, y = 0,
    z = -depth in the perched planner's frame (foot at the origin), each target from the
    planner's default perched start.

    Measured (5 cm steps): a wall 0.50 m behind the foot (``wall_dx`` = -0.5) is reached from
    0.30 to 0.85 m below it (0.55 m), elsewhere "joint_limit"; in front (+0.3 to +0.8 m) the
    plans stop on "rotor_thrust" / "joint_torque" (+0.3 m: only 0.85-0.95 m below the foot).
    With the orientation free the tool axis is not into the wall (-0.5 m: tilts ~49-58 deg at
    depths 0.30, 0.60, 0.85 m, the axis partly along y): a brush stroke needs 6-D targets.
    The planner's frame is its own (q = (1.2, 0.8, 0, -0.9, 0, 0) start), not the task
    scenarios' hanging posture q1 = pi/2 (see :mod:`rdm.scenarios.task_ik`)."""
    from rdm.model import Robot
    from rdm.planner.core import PlannerSetup, make_core
    from rdm.planner.plan import run_core

    setup = PlannerSetup.for_robot(robot, "perched")
    model = Robot.from_strs(setup.urdf, setup.toml)
    into = math.copysign(1.0, wall_dx)
    out = []
    for depth in np.asarray(depths, dtype=float):
        tr = run_core(make_core(setup), (float(wall_dx), 0.0, -float(depth)), "perched")
        zeta = np.asarray(tr.zeta[-1], dtype=float)
        frame = np.asarray(model.evaluate(zeta[6:], list(zeta[:6]))["frames"]["end_effector"])
        cos = max(-1.0, min(1.0, into * float(frame[0, 0])))
        out.append(
            PlannedPoint(
                float(depth),
                bool(tr.reached),
                float(tr.error[-1]),
                getattr(tr, "blocking", None),
                zeta,
                math.degrees(math.acos(cos)),
            )
        )
    return out
