"""Per-joint S1 weights of the Sec. V planner (``s1_joint_overrides``, docs/planner.md
"Holding the yaw"): one step against the weighted least-squares step computed with numpy
from a finite-difference Jacobian of MuJoCo's forward kinematics, and point-only plans that
keep the yaw joints where they started (``rdm.scenarios.task_plan.POINT_CONFIG``)."""

from __future__ import annotations

import numpy as np
import pytest

from rdm._rdm import PlannerError
from rdm.planner.core import PERCHED_START_Q, PlannerSetup, make_core
from rdm.planner.plan import run_core
from rdm.plant import Plant
from rdm.scenarios import task_plan

W_YAW = 1e-2


@pytest.fixture(scope="module")
def fk():
    return Plant("rdm", ceiling_height=None, floor_height=None, fixed_base=True)


def _ee(fk: Plant, q6: np.ndarray) -> np.ndarray:
    """MuJoCo's end-effector position (foot welded at the origin, level)."""
    q = np.zeros(10)
    q[:6] = q6
    fk.reset(q0=q)
    return np.asarray(fk.ground_truth().end_effector_position, dtype=float)


def _fd_jacobian(fk: Plant, q6: np.ndarray, h: float = 1e-6) -> np.ndarray:
    cols = []
    for j in range(6):
        e = np.zeros(6)
        e[j] = h
        cols.append((_ee(fk, q6 + e) - _ee(fk, q6 - e)) / (2 * h))
    return np.array(cols).T


def _setup(**config) -> PlannerSetup:
    s = PlannerSetup.for_robot("rdm", "perched")
    return PlannerSetup(s.urdf, s.toml, "perched", {**s.config, **config})


@pytest.mark.parametrize("hold", [False, True])
def test_step_is_the_weighted_least_squares_step(fk, hold):
    """A 5 mm point step sideways (y, which the yaw joints serve best): the core's joint step
    equals argmin dq' S1 dq + |J dq - dx|^2 with J from central differences of MuJoCo and S1
    = 1e-4 except W_YAW on q3, q5 when held. The two predictions differ by far more than
    the tolerance, so an ignored (or misplaced) override fails."""
    cfg = {"s1_joint_overrides": [(2, W_YAW), (4, W_YAW)]} if hold else {}
    core = make_core(_setup(**cfg))
    q0 = np.asarray(core.zeta, dtype=float)[6:12].copy()
    p0 = _ee(fk, q0)
    dx = np.array([0.0, 0.005, 0.0])
    core.step(list(p0 + dx))
    dq = np.asarray(core.zeta, dtype=float)[6:12] - q0
    jac = _fd_jacobian(fk, q0)
    pred = {}
    for name, w in (("free", 1e-4), ("held", W_YAW)):
        s1 = np.full(6, 1e-4)
        s1[[2, 4]] = w
        pred[name] = np.linalg.solve(np.diag(s1) + jac.T @ jac, jac.T @ dx)
    want, other = (pred["held"], pred["free"]) if hold else (pred["free"], pred["held"])
    assert np.linalg.norm(want - other) > 20 * 1e-5
    np.testing.assert_allclose(dq, want, atol=1e-5)
    assert np.allclose(q0, PERCHED_START_Q)


def test_point_plan_keeps_the_yaw_it_starts_from(fk):
    """A point-only plan from the hanging perching posture down and forward (the panel
    stroke's region): held, q3 and q5 stay within 1 mrad of 0 and MuJoCo's end effector ends
    within 1 mm of the target; with the default S1 the same plan turns the yaw joints."""
    q0 = np.zeros(16)
    q0[6:12] = (np.pi / 2, -0.5, 0.0, 0.0, 0.0, 0.0)
    target = (0.25, 0.0, -0.95)
    for cfg, held in ((task_plan.POINT_CONFIG, True), ({}, False)):
        core = make_core(_setup(**cfg), q0)
        tr = run_core(core, target, "perched")
        assert tr.reached
        q = np.asarray(tr.zeta[-1], dtype=float)[6:12]
        yaw = np.abs(np.asarray(tr.zeta, dtype=float)[:, [8, 10]]).max()
        if held:
            assert yaw < 1e-3
            assert np.linalg.norm(_ee(fk, q) - target) < 1e-3
        else:
            assert yaw > 0.05


@pytest.mark.parametrize("bad", [[(6, 1.0)], [(2, -1.0)], [(40, 1.0)], [(2, float("nan"))]])
def test_bad_override_is_a_one_line_error(bad):
    with pytest.raises(PlannerError, match="s1_joint_overrides") as e:
        make_core(_setup(s1_joint_overrides=bad))
    assert "\n" not in str(e.value)
