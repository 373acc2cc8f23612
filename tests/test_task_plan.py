"""The perched tasks' tool paths (drilling; painting's wall stroke and the valve with a tool-axis
target) planned by ``rdm.planner`` (``rdm.scenarios.task_plan``), checked
against MuJoCo's forward kinematics of a fixed-base plant (tool tip = MuJoCo's end-effector
position + the tool length along MuJoCo's end-effector x axis, the tool axis) and scipy's
rotations for the foot pose."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rdm.model import Robot
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
    assert sum(d for d, _ in way) == pytest.approx(total)
    assert max(d for d, _ in way if d < 0.5) <= 1 / 40 + 1e-12
    first_press = (tasks.MOVE_S + 0.5 * tasks.PRESS_S, tasks.MOVE_S + 1.5 * tasks.PRESS_S)
    assert windows[0] == pytest.approx(first_press)


def test_bad_tool_length_is_a_one_line_error():
    with pytest.raises(ValueError, match="tool_x: must be a finite length"):
        task_plan.ToolPlanner("rdm", BASE, _start_q(), float("nan"))


def _world(fk: Plant, q: np.ndarray, tool_x: float) -> tuple[np.ndarray, np.ndarray]:
    """(tool point ``tool_x`` along MuJoCo's end-effector x axis, that axis), world, with the
    foot at BASE (scipy's ZYX rotation)."""
    fk.reset(q0=np.asarray(q, dtype=float))
    g = fk.ground_truth()
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, np.asarray(g.end_effector_quaternion, dtype=float))
    x = rot.reshape(3, 3)[:, 0]
    foot_r = Rotation.from_euler("ZYX", BASE[[5, 4, 3]]).as_matrix()
    p = BASE[:3] + foot_r @ (np.asarray(g.end_effector_position) + tool_x * x)
    return p, foot_r @ x


def test_planned_wall_stroke_holds_the_brush_axis(fk):
    """Every planned painting move (approach, touch-down, the 52 stroke samples, lift-off)
    ends with MuJoCo's brush point (the free tip or the squeezed centre, as commanded) on its
    world target within 1 mm and the tool axis within 2 mrad of the stroke's axis there; the
    axis turns from the top tilt to the bottom tilt down the stroke."""
    from rdm.scenarios import painting

    lay = obj.TaskLayout().around_foot(BASE[0], BASE[1])
    stroke = painting.stroke_of("painting", lay)
    tool = task_plan.ToolPlanner("rdm", BASE, _start_q(), painting.BRUSH_TIP)
    asked = []

    def go(target, tool_x, duration, linear=False, axis=None):
        m = tool.move(target, duration, axis=axis, tool_x=tool_x, linear=linear)
        asked.append((np.asarray(target), tool_x, axis, m))
        return duration

    painting.waypoints(go, stroke, tasks.HOVER, tasks.MOVE_S, tasks.PRESS_S, tasks.RETRACT_S)
    assert len(asked) == 2 + 3 + painting.STROKE_SAMPLES + 2
    for k, (target, tool_x, axis, m) in enumerate(asked):
        assert m.plan.reached, (k, m.plan.blocking)
        p, x = _world(fk, m.q[-1], tool_x)
        assert np.linalg.norm(p - target) < 1e-3, k
        assert math.acos(min(1.0, float(x @ axis))) < 2e-3, k
    tilt = [math.degrees(math.asin(a[2])) for _, _, a, _ in asked[5:-2]]
    assert tilt[0] < 26.0 and tilt[-1] == pytest.approx(-34.0, abs=1e-9)
    assert np.all(np.diff(tilt) < 0)  # the brush pitches down as it slides down


def test_planned_valve_grip_keeps_the_gripper_on_the_hinge_while_turning(fk):
    """Approach and grip are planned with the tool axis down the hinge; every turn sample
    (q6 only) keeps MuJoCo's gripper centre on the hinge point within 1 mm and the axis
    within 2 mrad of vertical, and turns by the commanded angle about it."""
    lay = tasks._valve_layout(Robot.default()).around_foot(BASE[0], BASE[1])
    tool = task_plan.ToolPlanner("rdm", BASE, _start_q(), obj.GRIPPER_AT)
    way, window, total = task_plan.valve_waypoints(
        tool, lay.valve_axis, tasks.VALVE_HOVER, 3.0, 2.0, tasks.VALVE_TURN, 4.0, 1.0
    )
    assert window == pytest.approx((5.0, 9.0)) and total == pytest.approx(10.0)
    assert sum(d for d, _ in way) == pytest.approx(total)
    down = np.array([0.0, 0.0, -1.0])
    hover = lay.valve_axis + np.array([0.0, 0.0, tasks.VALVE_HOVER])
    for m, goal in zip(tool.moves, (hover, lay.valve_axis), strict=True):
        assert m.plan.reached
        p, x = _world(fk, m.q[-1], obj.GRIPPER_AT)
        assert np.linalg.norm(p - goal) < 1e-3
        assert math.acos(min(1.0, float(x @ down))) < 2e-3
    grip = tool.moves[-1].q[-1]
    turns = [q for _, q in way[-11:]]
    for q in turns:
        p, x = _world(fk, q, obj.GRIPPER_AT)
        assert np.linalg.norm(p - lay.valve_axis) < 1e-3
        assert math.acos(min(1.0, float(x @ down))) < 2e-3
        assert np.allclose(np.delete(q, 5), np.delete(grip, 5))
    assert turns[-1][5] - grip[5] == pytest.approx(tasks.VALVE_TURN)


def test_planned_panel_stroke_puts_the_brush_point_on_its_targets(fk):
    """Every planned panel move (axis free, yaw held: task_plan.POINT_CONFIG) ends with
    MuJoCo's commanded brush point (the free tip, or the squeezed centre along MuJoCo's tool
    axis) on its world target within 1.1 mm (the planner's 1 mm tolerance), the reported
    error equal to MuJoCo's, and q3, q5 within 20 mrad of 0 (the foot is yawed 10 mrad;
    unheld they reach 0.6 and -1.0 rad)."""
    from rdm.scenarios import painting

    lay = obj.TaskLayout().around_foot(BASE[0], BASE[1])
    stroke = painting.stroke_of("painting-panel", lay)
    tool = task_plan.ToolPlanner(
        "rdm", BASE, _start_q(), painting.BRUSH_TIP, task_plan.POINT_CONFIG
    )
    asked = []

    def go(target, tool_x, duration, linear=False, axis=None):
        assert axis is None
        m = tool.move(target, duration, tool_x=tool_x, linear=linear)
        asked.append((np.asarray(target), tool_x, m))
        return duration

    painting.waypoints(go, stroke, tasks.HOVER, tasks.MOVE_S, tasks.PRESS_S, tasks.RETRACT_S)
    assert len(asked) == 1 + 3 + painting.STROKE_SAMPLES + 2
    for k, (target, tool_x, m) in enumerate(asked):
        assert m.plan.reached, (k, m.plan.blocking)
        p, _ = _world(fk, m.q[-1], tool_x)
        err = float(np.linalg.norm(p - target))
        assert err < 1.1e-3, k
        assert m.error == pytest.approx(err, abs=1e-6), k
        assert np.abs(m.q[:, [2, 4]]).max() < 0.02, k
