"""Where the perched arm can paint a vertical wall (paper Sec. VII-D, Fig. 14 B: "paints
walls using a brush ... the sliding area length was over 0.5 m in the vertical direction").

The wall is the plane x = foot x + ``wall_dx`` (world), facing the robot (normal -x). For
brush-tip points on a vertical line of that plane (y = foot y) this module plans the brush
tip there with the Sec. V planner (``rdm.planner`` through :class:`rdm.scenarios.task_plan.
ToolPlanner`: perched, every constraint of eq. 70, the tip as the end effector, its axis
free, the yaw joints held as in the tasks' point-only moves, ``task_plan.POINT_CONFIG``),
from the scenarios' hanging posture family (:data:`SEEDS`), and reports, per depth below the
foot, whether the tip lands on the wall and the angle between the tool axis and the wall
normal. The compliant brush (task_objects BRUSH_*) compresses along the tool axis, so a
tilted tool still presses it; ASSUMPTION: tilts up to ``max_tilt_deg`` (default 50 deg, the
horizontal painting stroke already runs at up to ~49 deg) keep the brush pressed and sliding.

The vertical stroke this gives is the longest run of consecutive reachable depths (figures:
docs/scenarios.md, "Painting a wall: reach"). The ``painting`` scenario's wall stands at
0.75 m (:mod:`rdm.scenarios.painting`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import perching, task_plan
from . import task_objects as obj

#: Start postures (q1..q6) of the plans: the perching posture the tasks start from and three
#: others; the best reached solution (smallest tilt) over the starts is kept.
SEEDS: tuple[tuple[float, ...], ...] = (
    tuple(perching.PERCH_POSTURE),
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
    wall_dx: float,
    depths: np.ndarray,
    foot: tuple[float, float, float] | None = None,
    max_tilt_deg: float = 50.0,
    robot: str = "rdm",
) -> list[WallPoint]:
    """Plans of the brush tip onto the wall x = foot x + ``wall_dx`` at each of ``depths``
    [m] below a level foot at ``foot`` (default TaskLayout.nominal_foot), each from every
    start in :data:`SEEDS`."""
    if not wall_dx > 0.0:
        raise ValueError(f"wall_dx: must be > 0 (the wall is in front of the foot), got {wall_dx}")
    fx, fy, fz = foot or obj.TaskLayout().nominal_foot
    base = np.array([fx, fy, fz, 0.0, 0.0, 0.0])
    from rdm.model import Robot
    from rdm.planner.core import PlannerSetup

    setup = PlannerSetup.for_robot(robot, "perched")
    n_q = Robot.from_strs(setup.urdf, setup.toml).n_q
    out = []
    for depth in np.asarray(depths, dtype=float):
        best: WallPoint | None = None
        for seed in SEEDS:
            q0 = perching.leveled(np.asarray(seed, dtype=float), n_q)
            tool = task_plan.ToolPlanner(robot, base, q0, tool_tip(), task_plan.POINT_CONFIG)
            m = tool.move(np.array([fx + wall_dx, fy, fz - depth]), 1.0)
            if m.error >= POSITION_TOL:
                continue
            tool.core.set_zeta(np.asarray(m.plan.zeta[-1], dtype=float))  # the plan's end
            axis = tool.axis_world()
            tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(axis[0])))))
            if best is None or tilt < best.tilt_deg:
                best = WallPoint(float(depth), tilt <= max_tilt_deg, tilt, m.q[-1].copy())
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
    scenarios' hanging posture q1 = pi/2 (:func:`wall_line` starts from that one)."""
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
