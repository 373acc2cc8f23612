"""Tool paths of the perched tasks planned by the Sec. V planner (``rdm.planner``, perched
mode, every constraint kind of eq. 70): drilling, painting (wall and panel), the valve, and
the wall-reach sweep (:mod:`rdm.scenarios.wall_reach`).

The tool point is made the planner's end effector: the robot description gets a massless
``tool_tip`` link ``tool_x`` m along the end-effector x axis (the tool flange's axis) and its
``[frames] end_effector`` names it, so eq. (52)'s end-effector pose is the tool tip's and a
3-D target places the tip (the tool's axis is left to the planner) and a 5-D target the tip
and the tool axis. The perched planner's frame is the foot's: world targets are brought into
it with the foot pose the PC knows (mocap).

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
#: A target for a point other than the tip with the axis left free (:meth:`ToolPlanner.move`)
#: is shifted along the axis the plan ends with; re-planned from the same start until the
#: point is within POINT_TOL of its target, at most POINT_PASSES plans.
POINT_TOL = 1e-4
POINT_PASSES = 4
#: q indices of the yaw joints q3, q5 and their S1 weight in point-only plans
#: (``s1_joint_overrides``; the other joints weigh ``s1_joint`` = 1e-4). ASSUMPTION: YAW_HOLD
#: keeps a point-only plan near the yaw it starts from (docs/planner.md, "Holding the yaw").
YAW_JOINTS = (2, 4)
YAW_HOLD = 1e-2
#: Planner configuration of the point-only tool paths, which hold the yaw (drilling,
#: painting-panel, the wall-reach sweep).
POINT_CONFIG = {"s1_joint_overrides": [(j, YAW_HOLD) for j in YAW_JOINTS]}


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


def rpy_of_quaternion(q_wxyz: np.ndarray) -> np.ndarray:
    """ZYX roll, pitch, yaw of a (w, x, y, z) quaternion."""
    w, x, y, z = (float(v) for v in q_wxyz)
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.array([roll, pitch, yaw])


def tool_pose(robot, base: np.ndarray, q: np.ndarray, tool_x: float) -> tuple:
    """(tool point, tool axis) in the world of the onboard model ``robot``
    (``rdm.model.Robot``) for the foot at ``base`` = [x, y, z, roll, pitch, yaw] and joints
    ``q``: the point ``tool_x`` m along the end-effector x axis, that axis."""
    frame = np.asarray(robot.evaluate(q, list(base))["frames"]["end_effector"])
    rot = frame[:3, :3]
    return frame[:3, 3] + rot[:, 0] * tool_x, rot[:, 0]


def _rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    """ZYX roll, pitch, yaw -> rotation matrix (as :func:`rpy_of_quaternion`)."""
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
    #: m between the commanded tool point and the target at the move's end, for a target of
    #: a point other than the tip with the axis free; None: the plan's own error (the tip's)
    point_error: float | None = None

    @property
    def error(self) -> float:
        """m between the planned tool point and the target at the move's end."""
        return self.plan.final_error if self.point_error is None else self.point_error

    def waypoints(self) -> list[tuple[float, np.ndarray]]:
        """(seconds after the previous sample, q) per sample: the tasks' waypoints (the
        onboard node interpolates linearly between them)."""
        steps = np.diff(self.times, prepend=0.0)
        return [(float(d), q) for d, q in zip(steps, self.q, strict=True)]


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

    def axis_world(self) -> np.ndarray:
        """The planner's present tool axis (end-effector x) in the world."""
        _, (x, y, z, w) = self.core.end_effector_pose()
        a = np.array([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)])
        return self._foot_r @ a

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
        x) must reach, the rotation about it free (the planner's 5-D target). ``tool_x``: the
        target is for the point ``tool_x`` m along the axis instead of the tip: with ``axis``
        the tip's target is shifted along it; without, the axis is the planner's choice and
        the target is shifted along the axis the plan ends with (:meth:`_point_move`).
        ``linear``: followed at constant speed (one of successive samples of a path) instead
        of rest to rest. A move that stops short (``Unreachable``) keeps its last state; its
        ``error`` says by how much."""
        target = np.asarray(target_world, dtype=float)
        axis_foot = None
        point_error = None
        if axis is not None:
            a = np.asarray(axis, dtype=float)
            a = a / np.linalg.norm(a)
            axis_foot = tuple(self._foot_r.T @ a)
            if tool_x is not None:
                target = target + a * (self.tool_x - tool_x)
        if axis is None and tool_x is not None and tool_x != self.tool_x:
            tr, point_error = self._point_move(target, tool_x)
        else:
            tr = run_core(self.core, tuple(self.to_foot(target)), "perched", axis=axis_foot)
        q = np.asarray(tr.zeta, dtype=float)[:, 6:]
        times, qs = over_duration(q, duration, linear=linear)
        m = PlannedMove(np.asarray(target_world, dtype=float), tr, times, qs, point_error)
        self.moves.append(m)
        return m

    def _point_move(self, target: np.ndarray, tool_x: float) -> tuple[Trajectory, float]:
        """Plan the point ``tool_x`` m along the free tool axis to ``target`` (world): the
        tip's target is ``target`` shifted along the axis, first the axis at the start, then
        the axis the last plan ended with, each plan from the same start (a fixed point:
        the axis at the goal depends on the goal), until the shifted target moves less than
        POINT_TOL. The core is left at the last plan's last state (the last waypoint).
        Returns (plan, m between the point and ``target``)."""
        start = np.asarray(self.core.zeta, dtype=float).copy()
        shift = self.tool_x - tool_x
        a = self.axis_world()
        tr = run_core(self.core, tuple(self.to_foot(target + a * shift)), "perched")
        for _ in range(POINT_PASSES - 1):
            self.core.set_zeta(np.asarray(tr.zeta[-1], dtype=float))
            a_end = self.axis_world()
            if np.linalg.norm(a_end - a) * abs(shift) < POINT_TOL:
                break
            a = a_end
            self.core.set_zeta(start)
            tr = run_core(self.core, tuple(self.to_foot(target + a * shift)), "perched")
        self.core.set_zeta(np.asarray(tr.zeta[-1], dtype=float))
        err = float(np.linalg.norm(self.tip_world() - self.axis_world() * shift - target))
        return tr, err


def drill_waypoints(
    tool: ToolPlanner,
    targets: list[np.ndarray],
    hover: float,
    press_depth: float,
    move_s: float,
    press_s: float,
    retract_s: float,
) -> tuple[list[tuple[float, np.ndarray]], list[tuple[float, float]], float]:
    """The drilling sequence at each target (world, on the board's top): to ``hover`` above
    it in ``move_s``, down to ``press_depth`` below the surface in ``press_s``, held there
    ``press_s / 2``, back up in ``retract_s``. Returns (waypoints, press windows as (start,
    end) s from the sequence start, total seconds)."""
    way: list[tuple[float, np.ndarray]] = []
    windows: list[tuple[float, float]] = []
    t = 0.0
    for target in targets:
        up = np.asarray(target, dtype=float) + np.array([0.0, 0.0, hover])
        for goal, duration in ((up, move_s), (up - [0.0, 0.0, hover + press_depth], press_s)):
            way += tool.move(goal, duration).waypoints()
            t += duration
        windows.append((t - 0.5 * press_s, t + 0.5 * press_s))
        way.append((0.5 * press_s, way[-1][1]))  # hold the press
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
) -> tuple[list[tuple[float, np.ndarray]], tuple[float, float], float]:
    """The valve sequence: the gripper centre to ``hover`` above ``axis_point`` (world, on
    the hinge axis) in ``approach_s`` and down onto it in ``grip_s``, the tool axis pointing
    down the hinge (the planner's 5-D target: the rotation about the axis is the tool roll
    q6's), then q6 turned by ``turn`` rad in ``samples`` linear steps over ``turn_s`` and held
    ``hold_s``. The q6 axis is the tool axis, so the turn keeps the planned gripper centre
    and axis. Returns (waypoints, turn window (start, end) s, total seconds)."""
    down = np.array([0.0, 0.0, -1.0])
    point = np.asarray(axis_point, dtype=float)
    way: list[tuple[float, np.ndarray]] = []
    way += tool.move(point + np.array([0.0, 0.0, hover]), approach_s, axis=down).waypoints()
    way += tool.move(point, grip_s, axis=down).waypoints()
    t0 = approach_s + grip_s
    q = way[-1][1]
    for k in range(1, samples + 1):
        qk = q.copy()
        qk[5] = q[5] + turn * k / samples
        way.append((turn_s / samples, qk))
    way.append((hold_s, way[-1][1]))
    return way, (t0, t0 + turn_s), t0 + turn_s + hold_s
