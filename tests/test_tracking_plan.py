"""The tracking scenario's planned joint paths (``rdm.scenarios.tracking_plan``), checked
against MuJoCo: the goals are where the paper's configurations put the end effector (MuJoCo's
forward kinematics of a fixed-base plant), the planner's last state puts it there, the static
thrusts the planner's thrust constraint (eqs. 63-64) bounds are recomputed from MuJoCo's
rotor sites, actuator gears and body masses with numpy, and the time parameterisation is
checked by finite differences."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from rdm.model import Robot
from rdm.planner import timing
from rdm.plant import Plant
from rdm.plant.mjcf import rotor_actuator, rotor_site
from rdm.scenarios import tracking_plan as tp

#: planner's "reached" tolerance (rdm.planner.plan.TOLERANCE) plus MuJoCo-vs-model rounding
REACHED_M = 1.5e-3


@pytest.fixture(scope="module")
def fk():
    return Plant("rdm", ceiling_height=None, floor_height=None, fixed_base=True)


def _at(fk: Plant, q: np.ndarray) -> mujoco.MjData:
    q_full = np.zeros(len(fk.joint_names))
    q = np.asarray(q, dtype=float)
    q_full[: q.size] = q
    fk.reset(q0=q_full)
    d = fk.data
    mujoco.mj_kinematics(fk.model, d)
    mujoco.mj_comPos(fk.model, d)
    return d


def _ee(fk: Plant, q: np.ndarray) -> np.ndarray:
    _at(fk, q)
    return np.asarray(fk.ground_truth().end_effector_position, dtype=float)


def static_thrusts(fk: Plant, q: np.ndarray, perch_force: float) -> np.ndarray:
    """Rotor thrusts that carry the weight with no moment about the CoG, plus (perched) a pure
    upward ``perch_force`` through the foot: from MuJoCo's rotor sites (position, axis), each
    actuator's gear (yaw drag), the bodies' masses and centres and the model's gravity."""
    m = fk.model
    d = _at(fk, q)
    masses = m.body_mass[1:]
    cog = (masses[:, None] * d.xipos[1:]).sum(axis=0) / masses.sum()
    weight = masses.sum() * -m.opt.gravity[2]
    names = fk.rotor_names

    def allocation(about: np.ndarray) -> np.ndarray:
        cols = []
        for n in names:
            site = m.site(rotor_site(n)).id
            gear = m.actuator(rotor_actuator(n)).gear
            rot = d.site_xmat[site].reshape(3, 3)
            force = rot @ gear[:3]
            torque = rot @ gear[3:] + np.cross(d.site_xpos[site] - about, force)
            cols.append([force[2], *torque])
        return np.array(cols).T  # rows f_z, m_x, m_y, m_z

    lam = np.linalg.solve(allocation(cog), [weight, 0.0, 0.0, 0.0])
    if perch_force:
        foot = d.xpos[1]  # the welded root body: the foot frame at the origin
        lam = lam + np.linalg.solve(allocation(foot), [perch_force, 0.0, 0.0, 0.0])
    return lam


@pytest.mark.parametrize("stage", ["flight", "perched"])
def test_goal_is_where_the_papers_configuration_puts_the_end_effector(fk, stage):
    _, _, goal_q = tp.STAGES[stage]
    path = tp.stage_path(stage)
    assert np.allclose(path.goal, _ee(fk, np.asarray(goal_q)), atol=1e-6)


@pytest.mark.parametrize("stage", ["flight", "perched"])
def test_planned_path_reaches_the_goal_from_the_stage_posture(fk, stage):
    mode, start, goal_q = tp.STAGES[stage]
    path = tp.stage_path(stage)
    assert path.mode == mode and path.plan.reached
    assert np.allclose(path.q[0, :6], start, atol=1e-12)
    at_goal = path.q[np.searchsorted(path.times, path.go_s)]
    # the goal comes from MuJoCo, independent of the planner's model
    assert np.linalg.norm(_ee(fk, at_goal) - _ee(fk, np.asarray(goal_q))) < REACHED_M
    # the joints at the goal are the planner's own, not the paper's configuration
    assert np.abs(at_goal[:6] - np.asarray(goal_q)).max() > 0.1
    # the end effector moved (the goal is not the start)
    assert np.linalg.norm(path.goal - _ee(fk, path.q[0])) > 0.2


@pytest.mark.parametrize("stage", ["flight", "perched"])
def test_static_thrusts_of_the_plan_stay_inside_the_rotor_limits(fk, stage):
    """Every planner state: the thrusts recomputed from MuJoCo equal the planner's and lie in
    [thrust_min, thrust_max] (the ``rotor_thrust`` constraint held)."""
    path = tp.stage_path(stage)
    robot = Robot.default()
    tmin = np.array([r["thrust_min"] for r in robot.rotors])
    tmax = np.array([r["thrust_max"] for r in robot.rotors])
    perch = 5.0 if path.mode == "perched" else 0.0  # the planner's perch_force
    lam = np.array([static_thrusts(fk, z[6:], perch) for z in path.plan.zeta])
    # the flight plan moves its base by <= 2 mm / 2 mrad, MuJoCo's base stays put
    assert np.allclose(lam, path.plan.thrusts, atol=0.05)
    assert np.all(lam >= tmin) and np.all(lam <= tmax)


def static_joint_torques(fk: Plant, q: np.ndarray, thrusts: np.ndarray) -> np.ndarray:
    """Torques the joints hold at rest in ``q`` with the rotors at ``thrusts``: MuJoCo's bias
    forces (gravity) minus the rotor actuators' generalised forces (``mj_forward``)."""
    m = fk.model
    d = _at(fk, q)
    d.qvel[:] = 0.0
    for n, lam in zip(fk.rotor_names, thrusts, strict=True):
        d.ctrl[m.actuator(rotor_actuator(n)).id] = lam
    mujoco.mj_forward(m, d)
    dofs = [m.jnt_dofadr[m.joint(n).id] for n in fk.joint_names]  # joint_order
    return (d.qfrc_bias - d.qfrc_actuator)[dofs]


@pytest.mark.parametrize("stage", ["flight", "perched"])
def test_static_joint_torques_of_the_plan_stay_under_stall(fk, stage):
    """Every planner state: MuJoCo's static joint torques under the MuJoCo-recomputed thrusts
    equal the planner's eq. (61) torques and stay under the stall torques (the
    ``joint_torque`` constraint held)."""
    path = tp.stage_path(stage)
    robot = Robot.default()
    stall = np.asarray(robot.stall_torques, dtype=float)
    perch = 5.0 if path.mode == "perched" else 0.0
    for z, tau_plan in zip(path.plan.zeta, path.plan.torques, strict=True):
        tau = static_joint_torques(fk, z[6:], static_thrusts(fk, z[6:], perch))
        assert np.allclose(np.abs(tau[: tau_plan.size]), np.abs(tau_plan), atol=0.02)
        assert np.all(np.abs(tau) <= stall)


@pytest.mark.parametrize("stage", ["flight", "perched"])
def test_plan_keeps_joint_limits_and_rotor_airflow(fk, stage):
    """Every planner state: the joints inside MuJoCo's joint ranges by at least the state
    damper's forbidden band (0.01 rad, eqs. 58-60) unless the start already sits there (the
    hanging posture's q1 = pi/2), and every rotor of one unit more than a rotor diameter from
    every rotor of the other (eq. 68), from MuJoCo's rotor sites."""
    path = tp.stage_path(stage)
    m = fk.model
    lo, hi = np.array([m.joint(n).range for n in fk.joint_names]).T
    start = path.plan.zeta[0][6:]
    diameter = max(r["diameter"] for r in Robot.default().rotors)
    names = fk.rotor_names
    for z in path.plan.zeta:
        q = z[6:]
        room = np.minimum(q - lo, hi - q)
        at_start = np.minimum(start - lo, hi - start)
        assert np.all((room >= 0.01 - 1e-9) | (room >= at_start - 1e-9)), q
        d = _at(fk, q)
        pos = {n: d.site_xpos[m.site(rotor_site(n)).id].copy() for n in names}
        for a in names[:2]:
            for b in names[2:]:
                assert np.linalg.norm(pos[a] - pos[b]) > diameter


def test_dropping_the_thrust_constraint_breaks_the_thrust_check(fk):
    """A planted bug: the thrust damper's forbidden band moved 100 N below the limit (the
    ``rotor_thrust`` constraint dropped). Toward a goal 20 % beyond the flight goal the planner
    with the constraint keeps every rotor above thrust_min (MuJoCo recomputation); without it
    the path needs negative thrust, which the same check catches."""
    path = tp.stage_path("flight")
    start = _ee(fk, path.q[0])
    goal = tuple(start + 1.2 * (path.goal - start))
    kept = tp.plan_stage("flight", goal=goal)
    dropped = tp.plan_stage("flight", goal=goal, thrust=(2.0, -100.0, 0.5))
    lam_kept = np.array([static_thrusts(fk, z[6:], 0.0) for z in kept.zeta])
    lam_dropped = np.array([static_thrusts(fk, z[6:], 0.0) for z in dropped.zeta])
    assert lam_kept.min() >= 1.0
    assert lam_dropped.min() < 1.0


def test_time_parameterisation_follows_the_plan_within_the_limits():
    path = tp.stage_path("flight")
    t, q = path.times, path.q[:, :6]
    dt = np.diff(t)
    go = np.diff(t[t <= path.go_s])
    assert np.allclose(go[:-1], timing.SAMPLE_S) and 0 < go[-1] <= timing.SAMPLE_S  # 40 Hz
    assert np.all(dt > 0)
    vel = np.diff(q, axis=0) / dt[:, None]
    assert np.abs(vel).max() <= tp.MAX_VELOCITY * (1 + 1e-6)
    # starts and ends at rest: the first and last steps are far below the top speed
    assert np.abs(vel[0]).max() < 0.05 * tp.MAX_VELOCITY
    assert np.abs(vel[-1]).max() < 0.05 * tp.MAX_VELOCITY
    # hold at the goal, then back to the start along the same states
    hold = (t >= path.hold[0]) & (t <= path.hold[1])
    assert np.ptp(q[hold], axis=0).max() == 0.0
    assert np.allclose(q[-1], q[0], atol=1e-12)
    # every sample lies on the planner's polyline (distance to its nearest segment)
    states = np.asarray(path.plan.zeta)[:, 6:12]
    a, b = states[:-1], states[1:]
    for x in q[::7]:
        ab = b - a
        s = np.clip(((x - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-30), 0.0, 1.0)
        assert np.min(np.linalg.norm(a + s[:, None] * ab - x, axis=1)) < 1e-9


def test_unknown_stage_is_a_one_line_error():
    with pytest.raises(ValueError, match="stage='nope': one of"):
        tp.plan_stage("nope")
