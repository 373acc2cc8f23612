"""The wall reach of the perched arm (rdm.scenarios.wall_reach): the paper's 0.5 m vertical
painting stroke (Sec. VII-D, Fig. 14 B) against the Sec. V planner's point-only tool plans,
checked with MuJoCo's forward kinematics."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from rdm.plant import Plant
from rdm.scenarios import wall_reach

DEPTHS = np.round(np.arange(0.35, 0.8501, 0.05), 3)
WALL_DX = 0.80


@pytest.fixture(scope="module")
def line():
    return wall_reach.wall_line(WALL_DX, DEPTHS)


def _tip_and_axis(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """MuJoCo's brush tip and tool axis (end-effector x) with the foot welded at the origin,
    level (the sweep's foot is level too)."""
    fk = Plant("rdm", ceiling_height=None, floor_height=None, fixed_base=True)
    fk.reset(q0=np.asarray(q, dtype=float))
    g = fk.ground_truth()
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, np.asarray(g.end_effector_quaternion, dtype=float))
    x = rot.reshape(3, 3)[:, 0]
    return np.asarray(g.end_effector_position) + wall_reach.tool_tip() * x, x


def test_tip_is_on_the_wall_by_forward_kinematics(line) -> None:
    """Independent check: the planned joints put MuJoCo's brush tip on the wall plane at its
    depth (not the planner's own error); the tilt is MuJoCo's tool axis' angle to +x; the
    yaw joints stay near 0 (the arm in the x-z plane, y of the tip on the foot's)."""
    for p in line:
        assert p.q is not None
        tip, axis = _tip_and_axis(p.q)
        assert tip[0] == pytest.approx(WALL_DX, abs=wall_reach.POSITION_TOL)
        assert tip[1] == pytest.approx(0.0, abs=wall_reach.POSITION_TOL)
        assert tip[2] == pytest.approx(-p.depth, abs=wall_reach.POSITION_TOL)
        assert p.tilt_deg == pytest.approx(math.degrees(math.acos(axis[0])), abs=1e-3)
        assert abs(p.q[2]) < 0.01 and abs(p.q[4]) < 0.01


def test_half_metre_vertical_stroke_at_0_8_m(line) -> None:
    """ASSUMPTION (wall_reach): tilt <= 50 deg. The wall 0.80 m in front of the foot is
    reachable from 0.35 to 0.85 m below it (tilt up to 45 deg measured): the paper's
    > 0.5 m vertical stroke."""
    top, bottom = wall_reach.longest_stroke(line)
    assert bottom - top >= 0.5 - 1e-9
    assert max(p.tilt_deg for p in line) < 50.0


def test_a_too_close_wall_gives_no_half_metre_stroke() -> None:
    """0.30 m in front of the foot the arm folds: the tip reaches the wall only low down
    (0.90-1.05 m below the foot measured), not 0.4-0.8 m below it."""
    pts = wall_reach.wall_line(0.30, [0.4, 0.6, 0.8])
    assert not any(p.reached for p in pts)


def test_longest_stroke_picks_the_longest_run() -> None:
    def pt(d, ok):
        return wall_reach.WallPoint(d, ok, 0.0, None)

    pts = [pt(0.1, True), pt(0.2, False), pt(0.3, True), pt(0.4, True), pt(0.5, True)]
    assert wall_reach.longest_stroke(pts) == (0.3, 0.5)
    assert all(math.isnan(v) for v in wall_reach.longest_stroke([pt(0.1, False)]))


def test_wall_behind_the_foot_is_refused() -> None:
    with pytest.raises(ValueError, match="wall_dx"):
        wall_reach.wall_line(0.0, DEPTHS)


def test_planner_reaches_a_half_metre_wall_line_behind_the_foot() -> None:
    """The Sec. V planner (orientation free) plans the end-effector origin onto the wall
    0.5 m behind the foot at 0.30 and 0.85 m below it; forward kinematics of the final
    state (Robot.evaluate, not the planner's record) puts it there."""
    from rdm.model import Robot

    robot = Robot.default()
    pts = wall_reach.planner_line(-0.5, [0.30, 0.85])
    for p in pts:
        assert p.reached and p.blocking is None
        z = p.zeta
        frame = np.asarray(robot.evaluate(z[6:], list(z[:6]))["frames"]["end_effector"])
        assert frame[0, 3] == pytest.approx(-0.5, abs=1e-3)
        assert frame[2, 3] == pytest.approx(-p.depth, abs=1e-3)
        assert 0.0 <= p.tilt_deg <= 180.0
    assert pts[1].depth - pts[0].depth >= 0.5


def test_planner_in_front_of_the_foot_is_blocked_by_thrust() -> None:
    """0.8 m in front of the foot the plan stops on a constraint (rotor_thrust measured)."""
    (p,) = wall_reach.planner_line(0.8, [0.6])
    assert not p.reached
    assert p.blocking == "rotor_thrust"
    assert p.error > 0.1
