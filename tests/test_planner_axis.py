"""The planner's tool-axis target (point + axis, rotation about the axis free; the 5-D task
of docs/planner.md "Target kinds"): its rows against finite differences of the end-effector
axis (scipy rotations of the core's own pose), its step against the angle it must shrink,
and plans to it checked by MuJoCo's forward kinematics (angle of MuJoCo's end-effector x
axis to the target axis)."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rdm.planner import PlannerSetup, make_core
from rdm.planner.core import default_start
from rdm.planner.plan import run_core
from rdm.plant import Plant
from rdm.scenarios.perching import PERCH_POSTURE

W_AXIS = 0.1  # s2_ee_orientation of these cores
#: a target axis ~0.5 rad from the default start's end-effector x axis
A_TARGET = np.array([0.6, 0.3, -0.74])


@pytest.fixture(scope="module")
def setup():
    s = PlannerSetup.for_robot("rdm", "perched")
    return PlannerSetup(s.urdf, s.toml, s.mode, {**s.config, "s2_ee_orientation": W_AXIS})


def _pose(core) -> tuple[np.ndarray, np.ndarray]:
    """(position, x axis) of the core's end effector."""
    pos, quat = core.end_effector_pose()
    return np.array(pos), Rotation.from_quat(quat).as_matrix()[:, 0]


def _finite_differences(core, h: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """(d position / d free, d axis / d free), each 3 x n_free, central differences."""
    zeta0 = core.zeta.copy()
    dp, da = [], []
    for k in core.free:
        plus, minus = zeta0.copy(), zeta0.copy()
        plus[k] += h
        minus[k] -= h
        core.set_zeta(plus)
        p1, a1 = _pose(core)
        core.set_zeta(minus)
        p0, a0 = _pose(core)
        dp.append((p1 - p0) / (2 * h))
        da.append((a1 - a0) / (2 * h))
    core.set_zeta(zeta0)
    return np.array(dp).T, np.array(da).T


def test_axis_rows_match_finite_differences_of_the_axis(setup):
    """Rows 0-2: d position; rows 3-4: a basis of the plane normal to the axis a times the
    rotation rate, i.e. their Gram matrix is that of a x (da/dzeta) (the rate that turns a,
    independent of the basis); row 5 is free (weight 0)."""
    core = make_core(setup)
    pos, a = _pose(core)
    rows, _, weights = core.task_rows(list(pos + 0.05), axis=list(A_TARGET))
    dp, da = _finite_differences(core)
    np.testing.assert_allclose(rows[:3], dp, atol=1e-6)
    turn = np.cross(a, da.T).T  # 3 x n_free: the part of the rotation rate across a
    np.testing.assert_allclose(rows[3:5].T @ rows[3:5], turn.T @ turn, atol=1e-6)
    assert np.allclose(rows[5], 0.0) and weights[5] == 0.0
    assert weights[3] == weights[4] == W_AXIS and weights[0] == 1.0
    assert np.linalg.matrix_rank(rows[3:5], tol=1e-6) == 2


def test_axis_step_turns_the_axis_toward_the_target(setup):
    """The least-squares joint step of rows 3-4 toward step[3:5] shrinks the axis angle by
    kappa_orientation (0.03 rad) to first order: a flipped error sign grows it."""
    core = make_core(setup)
    pos, a = _pose(core)
    target = A_TARGET / np.linalg.norm(A_TARGET)
    angle0 = math.acos(float(a @ target))
    assert angle0 > 0.2
    rows, step, _ = core.task_rows(list(pos), axis=list(A_TARGET))
    assert np.linalg.norm(step[3:5]) == pytest.approx(0.03, rel=1e-9)
    dz = np.linalg.lstsq(rows[3:5], np.array(step[3:5]), rcond=None)[0]
    zeta = core.zeta.copy()
    zeta[core.free] += dz
    core.set_zeta(zeta)
    _, a1 = _pose(core)
    assert math.acos(float(a1 @ target)) == pytest.approx(angle0 - 0.03, abs=2e-3)


def test_axis_error_is_the_angle_to_the_target(setup):
    core = make_core(setup)
    pos, a = _pose(core)
    target = A_TARGET / np.linalg.norm(A_TARGET)
    r = core.step(list(pos), None, list(A_TARGET))
    assert r["orientation_error"] == pytest.approx(math.acos(float(a @ target)), abs=1e-12)


@pytest.fixture(scope="module")
def fk():
    return Plant("rdm", ceiling_height=None, floor_height=None, fixed_base=True)


def _mujoco_pose(fk: Plant, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    fk.reset(q0=np.asarray(q, dtype=float))
    g = fk.ground_truth()  # the foot welded at the origin, level
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, np.asarray(g.end_effector_quaternion, dtype=float))
    return np.asarray(g.end_effector_position), rot.reshape(3, 3)[:, 0]


@pytest.mark.parametrize(
    "start, offset, axis",
    [
        ("perch", (0.10, 0.0, 0.15), (0.0, 0.0, -1.0)),  # the valve's: down a vertical hinge
        ("perch", (0.20, 0.0, 0.30), (0.0, 0.0, -1.0)),
        ("default", (0.05, 0.05, 0.10), (0.9, 0.1, -0.4)),
        ("default", (-0.05, 0.0, 0.05), A_TARGET),
    ],
)
def test_plan_to_an_axis_target_holds_it_in_mujoco(setup, fk, start, offset, axis):
    """The planned end state puts MuJoCo's end effector on the point within 1 mm and its x
    axis within 2 mrad of the target axis."""
    zeta = default_start(setup)
    if start == "perch":
        zeta[6:12] = PERCH_POSTURE
    core = make_core(setup, zeta)
    pos, _ = _pose(core)
    goal = pos + np.array(offset)
    tr = run_core(core, tuple(goal), "perched", axis=axis)
    assert tr.reached, getattr(tr, "blocking", None)
    p, x = _mujoco_pose(fk, tr.zeta[-1, 6:])
    unit = np.asarray(axis) / np.linalg.norm(axis)
    assert np.linalg.norm(p - goal) < 1e-3
    assert math.acos(min(1.0, float(x @ unit))) < 2e-3


def test_axis_and_orientation_together_are_a_one_line_error(setup):
    core = make_core(setup)
    with pytest.raises(Exception, match="give at most one"):
        core.step([0.2, 0.0, -0.7], [0.0, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    with pytest.raises(Exception, match="target axis"):
        core.step([0.2, 0.0, -0.7], None, [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="axis: 3 non-zero values"):
        run_core(core, (0.2, 0.0, -0.7, 0.0, 0.0, 0.0), "perched", axis=(1.0, 0.0, 0.0))
