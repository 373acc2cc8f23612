"""The tracking scenario (Fig. 13, Table X): joint paths planned by ``rdm.planner`` in flight
(from q = 0) and perched (hanging posture). End-effector errors are re-derived here from
MuJoCo's ground truth with MuJoCo's own forward kinematics (a fixed-base plant at the planned
q) and MuJoCo's quaternion routines, instead of ``rdm.model`` and scipy as the scenario does;
the goals from MuJoCo's kinematics of the paper's configurations (Figs. 9-10)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from rdm.model import Robot
from rdm.plant import Plant
from rdm.scenarios import tracking, tracking_plan
from rdm.scenarios.common import truth_arrays
from rdm.scenarios.perching import PERCH_POSTURE


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    res = tracking.run(tmp_path_factory.mktemp("tracking"), log=False, plots=False)
    return res, truth_arrays(res.stack)


def _window(a, plan):
    t = a["t"]
    pre = (t >= plan.t_start - tracking.PRE_S) & (t < plan.t_start)
    win = (t >= plan.t_start) & (t <= plan.t_end + tracking.AFTER_S)
    return pre, win


def _mat(q_wxyz):
    m = np.zeros(9)
    mujoco.mju_quat2Mat(m, np.asarray(q_wxyz, dtype=float))
    return m.reshape(3, 3)


def _rotvec_between(q_a, q_b):
    """Rotation vector of R_a R_b^T from two (w, x, y, z) quaternions (MuJoCo's routines)."""
    inv, d = np.zeros(4), np.zeros(4)
    mujoco.mju_negQuat(inv, np.asarray(q_b, dtype=float))
    mujoco.mju_mulQuat(d, np.asarray(q_a, dtype=float), inv)
    if d[0] < 0:
        d = -d
    rv = np.zeros(3)
    mujoco.mju_quat2Vel(rv, d, 1.0)
    return rv


def _planned_q(plan):
    """q(t) of a stage's plan: linear between the planned samples, as the node interpolates."""
    times = np.array([p[0] for p in plan.points])
    qs = np.array([p[1] for p in plan.points])
    return lambda t: np.array([np.interp(t, times, qs[:, j]) for j in range(qs.shape[1])])


def _mujoco_errors(res, a, plan):
    """Position and attitude errors of the true EE against MuJoCo FK of the planned q (linear
    between the planned samples, as the node interpolates), root as before the motion."""
    fk = Plant("rdm", ceiling_height=None, floor_height=None, fixed_base=True)
    pre, win = _window(a, plan)
    root_p = a["foot"][pre].mean(axis=0)
    root_q = np.asarray(a["quat"][pre][-1], dtype=float)
    root_r = _mat(root_q)
    planned = _planned_q(plan)
    pos, att = [], []
    for g in (g for g, w in zip(res.stack.truth, win, strict=True) if w):
        fk.reset(q0=planned(g.time))
        ref = fk.ground_truth()  # the foot is welded at the world origin, level
        assert np.allclose(ref.base_position, 0.0)
        assert np.allclose(ref.base_quaternion, [1, 0, 0, 0])
        pos.append(
            np.asarray(g.end_effector_position) - (root_p + root_r @ ref.end_effector_position)
        )
        q_ref = np.zeros(4)
        mujoco.mju_mulQuat(q_ref, root_q, np.asarray(ref.end_effector_quaternion, dtype=float))
        att.append(_rotvec_between(g.end_effector_quaternion, q_ref))
    return np.array(pos), np.array(att)


def _rmse(x):
    return np.sqrt(np.mean(x**2, axis=0))


def test_both_stages_ran_without_failsafe(run):
    res, a = run
    s = res.script
    assert s.phase == "done" and set(s.plans) == {"flight", "perched"}
    assert not res.stack.spinal.counters.failsafes
    t = a["t"]
    fl, pe = s.plans["flight"], s.plans["perched"]
    assert fl.t_end < s.t_perch < pe.t_start
    # flight stage: airborne the whole window
    _, fwin = _window(a, fl)
    assert fwin.sum() > 100 and not a["contact"][fwin].any()
    # perched stage: the foot stays on the ceiling without slipping
    held = t >= pe.t_start - tracking.PRE_S - tracking.SETTLE_S
    assert a["contact"][held].all()
    slip = a["slip"][held]
    assert np.max(np.linalg.norm(slip - slip[0], axis=1)) < 1e-3


def test_joints_follow_the_planned_path_and_come_back(run):
    """The true joints follow the planner's path (sent at 40 Hz) and end at the base posture."""
    res, a = run
    for stage, base in (("flight", tracking.FLIGHT_POSTURE), ("perched", PERCH_POSTURE)):
        plan = res.script.plans[stage]
        assert plan.path is not None and plan.path.plan.reached
        _, win = _window(a, plan)
        q_plan = _planned_q(plan)
        dq = np.array([a["q"][i, :6] - q_plan(a["t"][i])[:6] for i in np.flatnonzero(win)])
        # every moving joint within 0.06 rad of the plan (q2 in flight sags under the arm)
        assert np.abs(dq).max() < 0.06, (stage, np.abs(dq).max(axis=0))
        assert np.sqrt(np.mean(dq**2)) < 0.02
        assert np.max(np.abs(a["q"][win, :6][-1] - np.asarray(base))) < 0.03
        # the path moved the arm: at least 0.25 rad on some joint
        assert np.abs(plan.path.q[:, :6] - np.asarray(base)).max() > 0.25


def _goal_in_world(fk, a, plan, stage):
    """The goal (MuJoCo FK of the paper's configuration) placed at the root before the motion."""
    pre, _ = _window(a, plan)
    _, _, goal_q = tracking_plan.STAGES[stage]
    q = np.zeros(len(fk.joint_names))
    q[:6] = goal_q
    fk.reset(q0=q)
    goal = np.asarray(fk.ground_truth().end_effector_position)
    root_p = a["foot"][pre].mean(axis=0)
    return root_p + _mat(np.asarray(a["quat"][pre][-1], dtype=float)) @ goal


@pytest.mark.parametrize(("stage", "tol"), [("flight", 0.05), ("perched", 0.002)])
def test_tracked_end_effector_reaches_the_goal(run, stage, tol):
    """Mean true end-effector position over the end of the hold against the goal: within
    5 cm in flight (the root moves), 2 mm perched. A goal with a flipped sign, or a plan
    that stops short, misses by more than 0.2 m (the goals are >= 0.3 m from the start)."""
    res, a = run
    fk = Plant("rdm", ceiling_height=None, floor_height=None, fixed_base=True)
    plan = res.script.plans[stage]
    goal = _goal_in_world(fk, a, plan, stage)
    g0, g1 = (plan.t_start + x for x in plan.path.goal_window())
    at = (a["t"] >= g0) & (a["t"] <= g1)
    err = np.linalg.norm(a["ee"][at].mean(axis=0) - goal)
    assert err < tol, (stage, err)
    assert res.facts[stage]["goal_error_m"] == pytest.approx(err, abs=1e-6)


def test_executed_plan_keeps_the_rotor_and_plate_limits(run):
    """Along both executed motions every true rotor thrust stays in [thrust_min, thrust_max];
    perched the foot stays in contact and the ZMP is on the plate's edge (tipping) for at
    most 5 % of the motion (Fig. 10 (E): the ZMP within the footplate)."""
    res, a = run
    robot = Robot.default()
    tmin = np.array([r["thrust_min"] for r in robot.rotors])
    tmax = np.array([r["thrust_max"] for r in robot.rotors])
    for stage in ("flight", "perched"):
        _, win = _window(a, res.script.plans[stage])
        thrust = a["thrust"][win]
        assert np.all(thrust >= tmin - 1e-9) and np.all(thrust <= tmax + 1e-9), stage
    _, win = _window(a, res.script.plans["perched"])
    assert a["contact"][win].all()
    zmp = a["zmp"][win]
    margin = np.minimum(0.05 - np.abs(zmp[:, 0]), 0.075 - np.abs(zmp[:, 1]))
    assert np.mean(margin <= 1e-3) < 0.05
    assert res.facts["perched"]["zmp_edge_fraction"] == pytest.approx(np.mean(margin <= 1e-3))


def test_errors_match_an_independent_mujoco_reference(run):
    res, a = run
    for stage in ("flight", "perched"):
        ours = res.errors[stage]
        pos, att = _mujoco_errors(res, a, res.script.plans[stage])
        assert ours.pos_err.shape == pos.shape and ours.att_err.shape == att.shape
        assert np.allclose(ours.pos_err, pos, atol=1e-6), stage
        assert np.allclose(ours.att_err, att, atol=1e-6), stage
        assert np.allclose(ours.pos_rmse, _rmse(pos), atol=1e-7)
        assert np.allclose(ours.att_rmse, _rmse(att), atol=1e-7)


def test_perched_end_effector_is_steadier_than_in_flight(run):
    res, a = run
    fl_p, fl_a = _mujoco_errors(res, a, res.script.plans["flight"])
    pe_p, pe_a = _mujoco_errors(res, a, res.script.plans["perched"])
    assert np.linalg.norm(_rmse(pe_p)) < 0.5 * np.linalg.norm(_rmse(fl_p))
    assert np.linalg.norm(_rmse(pe_a)) < np.linalg.norm(_rmse(fl_a))
    # Fig. 13 (B): perched errors "generally less than 0.05 m and 0.1 rad"
    assert np.abs(pe_p).max() < 0.05 and np.abs(pe_a).max() < 0.1
    # the flying robot tracked (bounded error), it did not fall
    assert np.abs(fl_p).max() < 0.25
    # the root: perched it does not move, flying it does
    _, fwin = _window(a, res.script.plans["flight"])
    _, pwin = _window(a, res.script.plans["perched"])
    fl_std = np.linalg.norm(np.std(a["foot"][fwin], axis=0))
    pe_std = np.linalg.norm(np.std(a["foot"][pwin], axis=0))
    assert pe_std < 0.1 * fl_std


def test_servo_lead_cancels_the_joint_lag(run):
    """With the scenarios' identified lead the joints the plan moves by 0.1 rad or more do
    not trail it (50 ms without it, docs/scenarios.md), and the perched end effector is within
    Table X's position RMSE on every axis."""
    res, _ = run
    assert res.facts["servo_lead_s"] == pytest.approx(0.05)
    for stage in ("flight", "perched"):
        lags = np.asarray(res.facts[stage]["joint_lag_s"])
        q = res.script.plans[stage].path.q[:, :6]
        big = np.ptp(q, axis=0) >= 0.1
        assert big[1:5].all()  # q2..q5 move in both plans
        assert np.all(np.abs(lags[big]) <= 0.006), (stage, lags)
    perched = np.asarray(res.facts["perched"]["pos_rmse"])
    assert np.all(perched < np.asarray(tracking.PAPER_RMSE_PERCHED[:3]))


#: "Meets the paper": our RMSE at most 10 % above Table X's.
PAPER_TOLERANCE = 1.1
#: Table X entries ours does not meet, held to the present value's band (seed 0, +-20 %):
#: (stage, index into Table X's row x y z roll pitch yaw, band). Flight attitude: the paper's
#: 0.3-1.9 mrad are below what the simulated flying robot holds; perched roll and pitch: the
#: servos' goal resolution alone gives more (test below, docs/scenarios.md).
TABLE_X_PRESENT_BANDS = (
    ("flight", 3, (0.0030, 0.0046)),
    ("flight", 4, (0.0177, 0.0266)),
    ("flight", 5, (0.0137, 0.0206)),
    ("perched", 3, (0.00071, 0.00107)),
    ("perched", 4, (0.00099, 0.00149)),
)


def test_end_effector_rmse_against_table_x(run):
    """End-effector position and attitude RMSE (re-derived from MuJoCo above) against
    Table X: every entry within 10 % of the paper or below it, except the ones listed in
    TABLE_X_PRESENT_BANDS, which are held to their present band."""
    res, a = run
    paper = {"flight": tracking.PAPER_RMSE_FLIGHT, "perched": tracking.PAPER_RMSE_PERCHED}
    bands = {(stage, k): band for stage, k, band in TABLE_X_PRESENT_BANDS}
    for stage in ("flight", "perched"):
        pos, att = _mujoco_errors(res, a, res.script.plans[stage])
        ours = np.concatenate([_rmse(pos), _rmse(att)])
        for k, value in enumerate(ours):
            if (stage, k) in bands:
                lo, hi = bands[stage, k]
                assert lo <= value <= hi, (stage, k, value)
            else:
                assert value <= PAPER_TOLERANCE * paper[stage][k], (stage, k, value)


def test_resolution_floor_matches_mujoco_and_exceeds_table_x_roll_pitch(run):
    """The floor ideal servos reach at the wire's goal resolution (the plan rounded to encoder
    counts), re-derived with Python's own ``round`` and MuJoCo's kinematics; perched it lies
    above Table X's roll and pitch RMSE (docs/scenarios.md), and the measured errors are not
    below it by more than chance allows."""
    res, a = run
    smap = res.stack.onboard.config.servo_map
    fk = Plant("rdm", ceiling_height=None, floor_height=None, fixed_base=True)

    def counts(q):
        out = np.array(q, dtype=float)
        for j in range(min(out.size, smap.n_joints)):
            z, s, k = smap.zero_point[j], smap.angle_sign[j], smap.angle_scale[j]
            out[j] = s * (round(z + s * out[j] / k) - z) * k
        return out

    for stage in ("flight", "perched"):
        plan = res.script.plans[stage]
        pre, win = _window(a, plan)
        planned = _planned_q(plan)
        pos, att = [], []
        for t in a["t"][win]:
            q = planned(t)
            fk.reset(q0=q)
            ref = fk.ground_truth()
            fk.reset(q0=counts(q))
            told = fk.ground_truth()
            pos.append(
                np.asarray(told.end_effector_position) - np.asarray(ref.end_effector_position)
            )
            att.append(_rotvec_between(told.end_effector_quaternion, ref.end_effector_quaternion))
        # the floor in the foot frame; world axes differ by the root's rotation
        root_r = _mat(np.asarray(a["quat"][pre][-1], dtype=float))
        pos_world, att_world = np.array(pos) @ root_r.T, np.array(att) @ root_r.T
        ours = res.errors[stage]
        assert np.allclose(ours.att_floor_rmse, _rmse(att_world), rtol=1e-6, atol=1e-9), stage
        assert np.allclose(ours.pos_floor_rmse, _rmse(pos_world), rtol=1e-6, atol=1e-9), stage
        assert 2e-4 < np.linalg.norm(ours.att_floor_rmse) < 2e-3  # about one count (1.53 mrad)
    pe = res.errors["perched"]
    paper = np.asarray(tracking.PAPER_RMSE_PERCHED[3:5])
    assert np.all(pe.att_floor_rmse[:2] > paper), (pe.att_floor_rmse, paper)
    assert np.all(pe.att_rmse[:2] > 0.5 * pe.att_floor_rmse[:2])


def test_servo_option_builds_the_plant_with_those_servos(tmp_path):
    """``tracking.run(..., servo=...)`` (the stiff-servo check of docs/scenarios.md) puts
    those gains on every joint servo of the MuJoCo model and records them."""
    from dataclasses import asdict

    from rdm.plant.servo import ServoParams

    res = tracking.run(
        tmp_path, duration=0.2, log=False, plots=False, servo=ServoParams(kp=600.0, kv=20.0)
    )
    plant = res.stack.plant
    act = np.asarray(plant._servo_act)
    assert act.size == plant.model.njnt - 1  # every joint but the free root
    assert np.all(plant.model.actuator_gainprm[act, 0] == 600.0)
    assert np.all(plant.model.actuator_biasprm[act, 1:3] == [-600.0, -20.0])
    assert res.facts["servo"] == asdict(ServoParams(kp=600.0, kv=20.0))
