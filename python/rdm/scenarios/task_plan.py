"""Tool paths of the perched tasks planned by the Sec. V planner (``rdm.planner``, perched
mode, every constraint kind of eq. 70), used by the drilling task.

The tool point is made the planner's end effector: the robot description gets a massless
``tool_tip`` link ``tool_x`` m along the end-effector x axis (the tool flange's axis) and its
``[frames] end_effector`` names it, so eq. (52)'s end-effector pose is the tool tip's and a
3-D target places the tip (the tool's axis is left to the planner, as the joint-space IK of
:mod:`rdm.scenarios.task_ik` left it). The perched planner's frame is the foot's: world
targets are brought into it with the foot pose the PC knows (mocap).

Each move plans from where the previous one ended (the planner's state carries over) and
its states are followed along their arc length in the move's duration
(:func:`rdm.planner.timing.over_duration`, 40 Hz samples).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rdm.planner.core import PlannerSetup, make_core
from rdm.planner.plan import run_core
from rdm.planner.timing import over_duration
from rdm.planner.trajectory import Trajectory

TOOL_LINK = "tool_tip"
#: S2' orientation weight of the tool-axis rows (docs/planner.md "Target kinds"); the position
#: rows weigh 1. ASSUMPTION: 0.1, as a 6-D target's.
AXIS_WEIGHT = 0.1


def with_tool_tip(urdf: str, toml: str, tool_x: float) -> tuple[str, str]:
    """(urdf, toml) texts with a ``tool_tip`` link ``tool_x`` m along the end-effector frame's
    x axis, named as the end effector."""
    if not (math.isfinite(tool_x) and tool_x >= 0.0):
        raise ValueError(f"tool_x: must be a finite length >= 0 m, got {tool_x}")
    key = 'end_effector = "end_effector"'
    if key not in toml or "</robot>" not in urdf:
        raise ValueError('robot description: expected [frames] end_effector = "end_effector"')
    joint = (
        f'  <joint name="{TOOL_LINK}_mount" type="fixed">\n'
        f'    <parent link="end_effector"/>\n    <child link="{TOOL_LINK}"/>\n'
        f'    <origin xyz="{tool_x!r} 0 0" rpy="0 0 0"/>\n  </joint>\n'
        f'  <link name="{TOOL_LINK}">\n  </link>\n'
    )
    return urdf.replace("</robot>", joint + "</robot>"), toml.replace(
        key, f'end_effector = "{TOOL_LINK}"'
    )


def _rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    """ZYX roll, pitch, yaw -> rotation matrix (as :func:`task_ik.rpy_of_quaternion`)."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp = math.cos(r), math.sin(r), math.cos(p), math.sin(p)
    cy, sy = math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


@dataclass
class PlannedMove:
    """One planned move of the tool tip."""

    target: np.ndarray  # world [m]
    plan: Trajectory
    times: np.ndarray  # (m,) s from the move's start, in (0, duration]
    q: np.ndarray  # (m, n_q) joint vectors at those times

    @property
    def error(self) -> float:
        """m between the planned tip and the target at the move's end."""
        return self.plan.final_error

    def waypoints(self) -> list[tuple[float, np.ndarray, bool]]:
        """(seconds after the previous sample, q, True) per sample: the tasks' linear
        waypoints (the onboard node interpolates linearly between them)."""
        steps = np.diff(self.times, prepend=0.0)
        return [(float(d), q, True) for d, q in zip(steps, self.q, strict=True)]


@dataclass
class ToolPlanner:
    """Plans successive tool-tip moves of the perched robot from ``q_start`` (full joint
    vector) with the foot at ``base`` = [x, y, z, roll, pitch, yaw] (world, ZYX)."""

    robot: str
    base: np.ndarray
    q_start: np.ndarray
    tool_x: float
    config: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        setup = PlannerSetup.for_robot(self.robot, "perched")
        urdf, toml = with_tool_tip(setup.urdf, setup.toml, self.tool_x)
        cfg = {"s2_ee_orientation": AXIS_WEIGHT, **setup.config, **self.config}
        self.setup = PlannerSetup(urdf, toml, "perched", cfg)
        base = np.asarray(self.base, dtype=float)
        self._foot_p = base[:3]
        self._foot_r = _rpy_matrix(base[3:])
        q = np.asarray(self.q_start, dtype=float)
        zeta = np.zeros(6 + q.size)
        zeta[6:] = q
        self.core = make_core(self.setup, zeta)
        self.moves: list[PlannedMove] = []

    def to_foot(self, p_world: np.ndarray) -> np.ndarray:
        """A world point in the planner's (foot) frame."""
        return self._foot_r.T @ (np.asarray(p_world, dtype=float) - self._foot_p)

    def tip_world(self) -> np.ndarray:
        """The planner's present tool tip in the world."""
        pos, _ = self.core.end_effector_pose()
        return self._foot_p + self._foot_r @ np.asarray(pos, dtype=float)

    def move(
        self,
        target_world: np.ndarray,
        duration: float,
        axis: np.ndarray | None = None,
        tool_x: float | None = None,
        linear: bool = False,
    ) -> PlannedMove:
        """Plan the tip from where the last move ended to ``target_world`` and follow the
        states in ``duration`` s. ``axis`` (world): the direction the tool axis (end-effector
        x) must reach, the rotation about it free (the planner's 5-D target). ``tool_x``
        (needs ``axis``): the target is for the point ``tool_x`` m along the axis instead of
        the tip (the tip's target is shifted along the target axis). ``linear``: followed
        at constant speed (one of successive samples of a path) instead of rest to rest.
        A move that stops short
        (``Unreachable``) keeps its last state; its ``error`` says by how much."""
        target = np.asarray(target_world, dtype=float)
        axis_foot = None
        if axis is not None:
            a = np.asarray(axis, dtype=float)
            a = a / np.linalg.norm(a)
            axis_foot = tuple(self._foot_r.T @ a)
            if tool_x is not None:
                target = target + a * (self.tool_x - tool_x)
        elif tool_x is not None:
            raise ValueError("tool_x: needs an axis (the tip is shifted along it)")
        tr = run_core(self.core, tuple(self.to_foot(target)), "perched", axis=axis_foot)
        q = np.asarray(tr.zeta, dtype=float)[:, 6:]
        times, qs = over_duration(q, duration, linear=linear)
        m = PlannedMove(target, tr, times, qs)
        self.moves.append(m)
        return m


def drill_waypoints(
    tool: ToolPlanner,
    targets: list[np.ndarray],
    hover: float,
    press_depth: float,
    move_s: float,
    press_s: float,
    retract_s: float,
) -> tuple[list[tuple[float, np.ndarray, bool]], list[tuple[float, float]], float]:
    """The drilling sequence at each target (world, on the board's top): to ``hover`` above
    it in ``move_s``, down to ``press_depth`` below the surface in ``press_s``, held there
    ``press_s / 2``, back up in ``retract_s``. Returns (waypoints, press windows as (start,
    end) s from the sequence start, total seconds)."""
    way: list[tuple[float, np.ndarray, bool]] = []
    windows: list[tuple[float, float]] = []
    t = 0.0
    for target in targets:
        up = np.asarray(target, dtype=float) + np.array([0.0, 0.0, hover])
        for goal, duration in ((up, move_s), (up - [0.0, 0.0, hover + press_depth], press_s)):
            way += tool.move(goal, duration).waypoints()
            t += duration
        windows.append((t - 0.5 * press_s, t + 0.5 * press_s))
        way.append((0.5 * press_s, way[-1][1], True))  # hold the press
        t += 0.5 * press_s
        way += tool.move(up, retract_s).waypoints()
        t += retract_s
    return way, windows, t


def valve_waypoints(
    tool: ToolPlanner,
    axis_point: np.ndarray,
    hover: float,
    approach_s: float,
    grip_s: float,
    turn: float,
    turn_s: float,
    hold_s: float,
    samples: int = 10,
) -> tuple[list[tuple[float, np.ndarray, bool]], tuple[float, float], float]:
    """The valve sequence: the gripper centre to ``hover`` above ``axis_point`` (world, on
    the hinge axis) in ``approach_s`` and down onto it in ``grip_s``, the tool axis pointing
    down the hinge (the planner's 5-D target: the rotation about the axis is the tool roll
    q6's), then q6 turned by ``turn`` rad in ``samples`` linear steps over ``turn_s`` and held
    ``hold_s``. The q6 axis is the tool axis, so the turn keeps the planned gripper centre
    and axis. Returns (waypoints, turn window (start, end) s, total seconds)."""
    down = np.array([0.0, 0.0, -1.0])
    point = np.asarray(axis_point, dtype=float)
    way: list[tuple[float, np.ndarray, bool]] = []
    way += tool.move(point + np.array([0.0, 0.0, hover]), approach_s, axis=down).waypoints()
    way += tool.move(point, grip_s, axis=down).waypoints()
    t0 = approach_s + grip_s
    q = way[-1][1]
    for k in range(1, samples + 1):
        qk = q.copy()
        qk[5] = q[5] + turn * k / samples
        way.append((turn_s / samples, qk, True))
    way.append((hold_s, way[-1][1], True))
    return way, (t0, t0 + turn_s), t0 + turn_s + hold_s
