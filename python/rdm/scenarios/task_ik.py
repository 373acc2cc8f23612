"""Joint-space inverse kinematics of a tool point for the perched arm (damped least squares
on the onboard model's analytic Jacobians, ``rdm.model.Robot.jacobian``).

Used by the ``painting-panel`` stroke and the wall-reach sweep
(:mod:`rdm.scenarios.wall_reach`), whose tool axis is left free; the other tasks' tool paths
are planned by the Sec. V planner (:mod:`rdm.scenarios.task_plan`, with its point +
tool-axis target where the axis must be held: the wall painting and the valve). This IK
keeps the vectoring apparatus levelled the same way :func:`rdm.scenarios.perching.leveled`
does (q3 stays 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Joints the IK moves (indices in joint_order): q1, q2, q4, q5. q3 stays 0 (the levelling
#: of the arm unit assumes a planar q1..q2 chain) and q6 (tool roll) is set by the task.
IK_JOINTS = (0, 1, 3, 4)


def rpy_of_quaternion(q_wxyz: np.ndarray) -> np.ndarray:
    """ZYX roll, pitch, yaw of a (w, x, y, z) quaternion."""
    w, x, y, z = (float(v) for v in q_wxyz)
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.array([roll, pitch, yaw])


def level(q: np.ndarray) -> np.ndarray:
    """Vectoring angles that keep both rotor pairs horizontal for q3 = 0 (as perching.leveled)."""
    q = np.asarray(q, dtype=float).copy()
    q[6] = 0.0
    q[7] = -q[0]
    q[8] = 0.0
    q[9] = -(q[0] + q[1])
    return q


@dataclass
class IkResult:
    q: np.ndarray
    position_error: float  # m
    iterations: int


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def tool_pose(robot, base: np.ndarray, q: np.ndarray, tool_x: float) -> tuple:
    """(tool point, tool axis) in world for base = [x, y, z, roll, pitch, yaw] (foot frame)."""
    frame = np.asarray(robot.evaluate(q, list(base))["frames"]["end_effector"])
    rot = frame[:3, :3]
    return frame[:3, 3] + rot[:, 0] * tool_x, rot[:, 0]


def solve(
    robot,
    base: np.ndarray,
    q_start: np.ndarray,
    target: np.ndarray,
    tool_x: float,
    q1_ref: float = math.pi / 2,
    q1_weight: float = 0.02,
    damping: float = 1e-3,
    iterations: int = 200,
    tol: float = 1e-4,
) -> IkResult:
    """Joints (q1, q2, q4, q5 free) that put the tool point ``tool_x`` m along the
    end-effector x axis at ``target`` (world), the axis left free. ``q1_weight`` pulls q1
    toward ``q1_ref`` (the root link hanging straight down)."""
    q = level(np.asarray(q_start, dtype=float))
    target = np.asarray(target, dtype=float)
    cols = np.array(IK_JOINTS)
    lo, hi = np.asarray(robot.joint_limits, dtype=float).T
    pos_err = math.inf
    it = 0
    while it < iterations:
        it += 1
        p, x_axis = tool_pose(robot, base, q, tool_x)
        e = target - p
        jac = np.asarray(robot.jacobian("end_effector", np.r_[base, q]), dtype=float)
        jv = jac[:3, 6:][:, cols]
        jw = jac[3:, 6:][:, cols]
        j_tip = jv - _skew(x_axis * tool_x) @ jw  # v_tip = v_ee + w x r
        rows, errs = [j_tip], [e]
        reg = np.zeros((1, cols.size))
        reg[0, 0] = q1_weight
        rows.append(reg)
        errs.append(np.array([q1_weight * (q1_ref - q[0])]))
        a_mat = np.vstack(rows)
        b = np.concatenate(errs)
        pos_err = float(np.linalg.norm(e))
        if pos_err < tol:
            break
        dq = np.linalg.solve(a_mat.T @ a_mat + damping * np.eye(cols.size), a_mat.T @ b)
        step = np.clip(dq, -0.1, 0.1)
        q[cols] += step
        q[cols] = np.clip(q[cols], lo[cols] + 1e-3, hi[cols] - 1e-3)
        q = level(q)
    return IkResult(q, pos_err, it)
