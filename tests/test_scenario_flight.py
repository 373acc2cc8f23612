"""``rdm sim flight``: Fig. 9's configuration change in flight through every wire.

Outcomes come from MuJoCo's ground truth (foot frame, joint angles, rotor thrusts),
re-derived here with scipy's rotations; the scenario's own analysis is not trusted."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rdm.model import Robot
from rdm.plant import Plant
from rdm.scenarios import SCENARIOS
from rdm.scenarios.flight import (
    PAPER_ATTITUDE_BAND,
    PAPER_ATTITUDE_RMSE,
    PAPER_EE_RMSE_FLIGHT,
    PAPER_POSITION_BAND,
    PAPER_POSITION_RMSE,
    Q_TARGET,
    FlightPlan,
    Reference,
    min_jerk,
    run,
)

# short timeline: 2 s climb, 1 s settle, 6 s change, 2 s hold (12.5 simulated s)
SHORT = FlightPlan(takeoff_s=2.0, hover_s=1.0, change_s=6.0, hold_s=2.0)


def _truth(stack):
    tr = stack.truth
    t = np.array([g.time for g in tr])
    foot = np.array([g.base_position for g in tr])
    quat = np.array([g.base_quaternion for g in tr])  # w, x, y, z
    euler = Rotation.from_quat(quat[:, [1, 2, 3, 0]]).as_euler("ZYX")[:, ::-1]  # roll, pitch, yaw
    q = np.array([g.joint_positions for g in tr])[:, :6]
    thrust = np.array([g.rotor_thrusts for g in tr])
    return t, foot, euler, q, thrust


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    return run(tmp_path_factory.mktemp("flight"), plan=SHORT, log=False, plots=False)


def test_registered():
    assert SCENARIOS["flight"].run is run


def test_min_jerk_derivative_matches_finite_differences():
    s = np.linspace(0.05, 0.95, 19)
    h = 1e-6
    num = (min_jerk(s + h)[0] - min_jerk(s - h)[0]) / (2 * h)
    assert np.allclose(min_jerk(s)[1], num, atol=1e-6)
    assert min_jerk(0.0)[0] == 0.0 and min_jerk(1.0)[0] == 1.0


def test_cog_reference_matches_mujoco():
    """The CoG setpoint that holds the root still is the CoG of MuJoCo's robot at q."""
    ref = Reference(SHORT, Robot.default(), np.zeros(3))
    plant = Plant("rdm")
    for frac in (0.0, 0.5, 1.0):
        q = np.zeros(len(plant.joint_names))
        q[:6] = frac * np.asarray(Q_TARGET)
        plant.reset(q0=q, base_position=(0.0, 0.0, 1.0))
        gt = plant.ground_truth()
        t = SHORT.change_start + frac * SHORT.change_s
        pos, _ = ref.cog_setpoint(t)
        foot_ref = np.asarray(SHORT.foot_target)
        assert np.allclose(pos - foot_ref, gt.cog_position - gt.base_position, atol=1e-6)


def test_configuration_reached(flown):
    _, _, _, q, _ = _truth(flown.stack)
    assert np.abs(q[-1] - np.asarray(Q_TARGET)).max() < 0.05
    assert np.abs(q[0]).max() < 0.02  # it started from q = 0


def test_root_inside_paper_bands_during_change(flown):
    t, foot, euler, _, _ = _truth(flown.stack)
    w = t >= SHORT.change_start
    pos_err = foot[w] - np.asarray(SHORT.foot_target)
    assert np.abs(pos_err).max() < PAPER_POSITION_BAND, np.abs(pos_err).max(axis=0)
    assert np.abs(euler[w]).max() < PAPER_ATTITUDE_BAND, np.abs(euler[w]).max(axis=0)
    # and it really flew there: the foot is at the target height at the end
    assert abs(foot[-1, 2] - SHORT.foot_target[2]) < 0.05


#: "Meets the paper": our RMSE at most 10 % above the paper's.
PAPER_TOLERANCE = 1.1
#: The paper's timeline (the default plan) for the comparisons with Tables VI and X: with
#: the short plan's faster change the root z RMSE is 0.0146 m, above Table VI's 0.012 m.
DEFAULT = FlightPlan()


@pytest.fixture(scope="module")
def flown_default(tmp_path_factory):
    return run(tmp_path_factory.mktemp("flight_default"), plan=DEFAULT, log=False, plots=False)


def _rmse(x: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(x**2, axis=0))


def test_root_rmse_against_table_vi(flown_default):
    """Root position and attitude RMSE over the change window (MuJoCo's truth, scipy's
    Euler angles) within Table VI on every axis."""
    t, foot, euler, _, _ = _truth(flown_default.stack)
    w = t >= DEFAULT.change_start
    pos = _rmse(foot[w] - np.asarray(DEFAULT.foot_target))
    att = _rmse(euler[w])
    assert np.all(pos <= PAPER_TOLERANCE * np.asarray(PAPER_POSITION_RMSE)), pos
    assert np.all(att <= PAPER_TOLERANCE * np.asarray(PAPER_ATTITUDE_RMSE)), att


def test_end_effector_rmse_in_the_hold_against_table_x(flown_default):
    """End-effector position RMSE while holding the new configuration, against MuJoCo's
    fixed-base forward kinematics at the target q put at the root's target: within Table X's
    flight column on every axis."""
    t, _, _, _, _ = _truth(flown_default.stack)
    ee = np.array([g.end_effector_position for g in flown_default.stack.truth])
    fk = Plant("rdm", ceiling_height=None, floor_height=None, fixed_base=True)
    q = np.zeros(len(fk.joint_names))
    q[:6] = Q_TARGET
    fk.reset(q0=q)
    ref = np.asarray(DEFAULT.foot_target) + np.asarray(fk.ground_truth().end_effector_position)
    hold = t >= DEFAULT.change_end + min(1.0, DEFAULT.hold_s / 2)
    assert hold.sum() > 50
    rmse = _rmse(ee[hold] - ref)
    assert np.all(rmse <= PAPER_TOLERANCE * np.asarray(PAPER_EE_RMSE_FLIGHT)), rmse


def test_no_failsafe_and_thrust_within_limits(flown):
    st = flown.stack
    assert not st.spinal.counters.failsafes, st.spinal.counters.failsafes
    assert st.onboard.state.value == "armed"
    _, _, _, _, thrust = _truth(st)
    limits = np.array([r["thrust_max"] for r in Robot.default().rotors])
    assert np.all(thrust >= 0.0) and np.all(thrust <= limits + 1e-9)


def test_without_desire_coordinate_the_root_drifts(tmp_path):
    """Spinal's IMU is on the root link: without the q1 offset it levels the root link,
    the foot pitches with q1 and the x loop pulls the root far outside the paper's band."""
    plan = FlightPlan(takeoff_s=2.0, hover_s=1.0, change_s=6.0, hold_s=0.5)
    r = run(tmp_path, plan=plan, log=False, plots=False, desire_coordinate=False)
    t, foot, _, _, _ = _truth(r.stack)
    err = np.abs(foot[t >= plan.change_start, 0] - plan.foot_target[0])
    assert err.max() > 2 * PAPER_POSITION_BAND
