"""The tracking scenario (Fig. 13, Table X): the same feed-forward joint path in flight and
perched. End-effector errors from MuJoCo's ground truth, the target re-derived here with
MuJoCo's own forward kinematics (a fixed-base plant) instead of ``rdm.model``."""

from __future__ import annotations

import numpy as np
import pytest

from rdm.plant import Plant
from rdm.scenarios import tracking
from rdm.scenarios.common import truth_arrays
from rdm.scenarios.perching import PERCH_POSTURE

#: one arm pitch/yaw sweep and back (the default has three segments)
SHORT = ((2.5, (1.5708, -0.9, 0.3, 0.5, 0.0, 0.0)), (2.5, PERCH_POSTURE))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    res = tracking.run(tmp_path_factory.mktemp("tracking"), motion=SHORT, log=False, plots=False)
    return res, truth_arrays(res.stack)


def _mujoco_errors(res, a, plan):
    """Position errors of the true EE against MuJoCo FK of the planned q, root as at t0."""
    fk = Plant("rdm", ceiling_height=None, floor_height=None, fixed_base=True)
    motion_s = res.script.motion_s
    t0 = plan[-1][0] - motion_s
    t = a["t"]
    pre = (t >= t0 - tracking.PRE_S) & (t < t0)
    win = (t >= t0) & (t <= t0 + motion_s + tracking.AFTER_S)
    root_p = a["foot"][pre].mean(axis=0)
    w, x, y, z = a["quat"][pre][-1]
    root_r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    times = np.array([p[0] for p in plan])
    qs = np.array([p[1] for p in plan])
    errs = []
    for ti, ee in zip(t[win], a["ee"][win], strict=True):
        q = np.array([np.interp(ti, times, qs[:, j]) for j in range(qs.shape[1])])
        fk.reset(q0=q)
        gt = fk.ground_truth()
        assert np.allclose(gt.base_position, 0.0) and np.allclose(gt.base_quaternion, [1, 0, 0, 0])
        errs.append(ee - (root_p + root_r @ gt.end_effector_position))
    return np.array(errs)


def test_both_stages_ran(run):
    res, a = run
    s = res.script
    assert s.flight_plan and s.perched_plan and s.phase == "done"
    assert not res.stack.spinal.counters.failsafes
    # perched stage: the foot stays on the ceiling without slipping during the motion
    t0 = s.perched_plan[0][0]
    held = a["t"] >= t0
    assert a["contact"][held].all()
    slip = a["slip"][held]
    assert np.max(np.linalg.norm(slip - slip[0], axis=1)) < 1e-3
    # the joints followed the path back to the posture
    assert np.max(np.abs(a["q"][-1, :6] - np.array(PERCH_POSTURE))) < 0.05


def test_errors_match_an_independent_mujoco_reference(run):
    res, a = run
    for stage, plan in (("flight", res.script.flight_plan), ("perched", res.script.perched_plan)):
        ours = res.errors[stage]
        theirs = _mujoco_errors(res, a, plan)
        assert ours.pos_err.shape == theirs.shape
        rmse = np.sqrt(np.mean(theirs**2, axis=0))
        assert np.allclose(ours.pos_rmse, rmse, atol=1e-3), (stage, ours.pos_rmse, rmse)


def test_perched_end_effector_is_steadier_than_in_flight(run):
    res, a = run
    fl = _mujoco_errors(res, a, res.script.flight_plan)
    pe = _mujoco_errors(res, a, res.script.perched_plan)
    rmse_fl = np.linalg.norm(np.sqrt(np.mean(fl**2, axis=0)))
    rmse_pe = np.linalg.norm(np.sqrt(np.mean(pe**2, axis=0)))
    assert rmse_pe < 0.5 * rmse_fl, (rmse_pe, rmse_fl)
    # flight error stays bounded (the flying robot tracked, it did not fall)
    assert np.abs(fl).max() < 0.25
    # the root: perched it does not move, flying it does
    assert np.linalg.norm(res.errors["perched"].root_std) < 0.1 * np.linalg.norm(
        res.errors["flight"].root_std
    )
