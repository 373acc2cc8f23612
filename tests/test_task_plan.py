"""Drilling's tool paths planned by ``rdm.planner`` (``rdm.scenarios.task_plan``), checked
against MuJoCo's forward kinematics of a fixed-base plant (tool tip = MuJoCo's end-effector
position + the bit length along MuJoCo's end-effector x axis) and scipy's rotations for the
foot pose."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rdm.plant import Plant
from rdm.scenarios import perching, task_plan, tasks
from rdm.scenarios import task_objects as obj


@pytest.fixture(scope="module")
def fk():
    return Plant("rdm", ceiling_height=None, floor_height=None, fixed_base=True)


def _tip_in_foot(fk: Plant, q: np.ndarray) -> np.ndarray:
    fk.reset(q0=np.asarray(q, dtype=float))
    g = fk.ground_truth()  # the foot welded at the origin, level
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, np.asarray(g.end_effector_quaternion, dtype=float))
    return np.asarray(g.end_effector_position) + obj.DRILL_LEN * rot.reshape(3, 3)[:, 0]


def _start_q() -> np.ndarray:
    q = np.zeros(10)
    q[:6] = perching.PERCH_POSTURE
    q[7], q[9] = -q[0], -(q[0] + q[1])  # levelled units
    return q


#: a perched foot a little off the nominal spot, slightly tilted (ZYX roll, pitch, yaw)
BASE = np.array([0.531, 0.012, 1.601, 0.002, -0.003, 0.01])


def test_tool_tip_is_the_planners_end_effector(fk):
    tool = task_plan.ToolPlanner("rdm", np.r_[0, 0, 0, 0, 0, 0], _start_q(), obj.DRILL_LEN)
    pos, _ = tool.core.end_effector_pose()
    assert np.allclose(pos, _tip_in_foot(fk, _start_q()), atol=1e-9)


def test_planned_drill_moves_reach_the_targets_in_the_world(fk):
    """Every move's last state puts the MuJoCo tool tip, placed with the foot pose by scipy,
    on its world target within 1 mm; the hover is 3 cm above and the press 1 mm below."""
    tool = task_plan.ToolPlanner("rdm", BASE, _start_q(), obj.DRILL_LEN)
    lay = obj.TaskLayout().around_foot(BASE[0], BASE[1])
    targets = [lay.board_point(dx, dy) for dx, dy in tasks.DRILL_TARGETS]
    way, windows, total = task_plan.drill_waypoints(
        tool, targets, tasks.HOVER, tasks.PRESS_DEPTH, tasks.MOVE_S, tasks.PRESS_S, tasks.RETRACT_S
    )
    foot_r = Rotation.from_euler("ZYX", BASE[[5, 4, 3]]).as_matrix()
    assert len(tool.moves) == 3 * len(targets)
    for k, m in enumerate(tool.moves):
        assert m.plan.reached, (k, m.plan.blocking)
        tip = BASE[:3] + foot_r @ _tip_in_foot(fk, m.q[-1])
        assert np.linalg.norm(tip - m.target) < 1e-3, k
        target = targets[k // 3]
        depth = -tasks.PRESS_DEPTH if k % 3 == 1 else tasks.HOVER
        assert np.allclose(m.target, target + np.array([0.0, 0.0, depth]), atol=1e-12)
    # timing: the waypoints' seconds add up to the sequence; 40 Hz samples inside the moves
    per_target = tasks.MOVE_S + 1.5 * tasks.PRESS_S + tasks.RETRACT_S
    assert total == pytest.approx(len(targets) * per_target)
    assert sum(d for d, _, _ in way) == pytest.approx(total)
    assert max(d for d, _, _ in way if d < 0.5) <= 1 / 40 + 1e-12
    first_press = (tasks.MOVE_S + 0.5 * tasks.PRESS_S, tasks.MOVE_S + 1.5 * tasks.PRESS_S)
    assert windows[0] == pytest.approx(first_press)


def test_bad_tool_length_is_a_one_line_error():
    with pytest.raises(ValueError, match="tool_x: must be a finite length"):
        task_plan.ToolPlanner("rdm", BASE, _start_q(), float("nan"))
