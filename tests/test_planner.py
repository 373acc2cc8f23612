"""Planner: convergence, every constraint respected on every step, blocking reports,
constraint Jacobians against finite differences, torques against the model binding."""

import re

import numpy as np
import pytest

from rdm.model import Robot
from rdm.planner import PlannerSetup, Unreachable, make_core, plan
from rdm.planner.core import default_start

G = 9.80665


def _check_every_step(traj, robot, setup):
    lo, hi = np.array(robot.joint_limits).T
    q = traj.zeta[:, 6:12]
    assert np.all(q >= lo[:6] - 1e-9) and np.all(q <= hi[:6] + 1e-9)
    stall = np.array(robot.stall_torques)
    assert np.all(np.abs(traj.torques) <= stall + 1e-3)
    rotors = robot.rotors
    tmin = np.array([r["thrust_min"] for r in rotors])
    tmax = np.array([r["thrust_max"] for r in rotors])
    assert np.all(traj.thrusts >= tmin - 1e-3) and np.all(traj.thrusts <= tmax + 1e-3)
    assert np.all(traj.rho > 0.0)
    assert np.all(traj.clearance >= -1e-4)
    assert np.all(traj.airflow >= -1e-4)


@pytest.fixture(scope="module")
def rdm_setup():
    return PlannerSetup.for_robot("rdm", "perched")


@pytest.mark.parametrize("target", [(0.6, 0.0, -0.5), (0.3, 0.2, -0.7), (0.8, -0.1, -0.3)])
def test_perched_reaches_target_within_1mm(rdm_setup, target):
    traj = plan(rdm_setup, target)
    assert traj.reached, traj.blocking
    assert traj.final_error < 1e-3
    robot = Robot.from_strs(rdm_setup.urdf, rdm_setup.toml)
    _check_every_step(traj, robot, rdm_setup)
    # The foot never moves when perched.
    assert np.all(traj.zeta[:, :6] == traj.zeta[0, :6])


def test_flight_moves_root_and_reaches(rdm_setup):
    setup = PlannerSetup.for_robot("rdm", "flight")
    traj = plan(setup, (1.2, 0.3, -0.4))
    assert traj.reached, traj.blocking
    assert np.ptp(traj.zeta[:, :3], axis=0).max() > 0.05


def test_unreachable_names_blocking_constraint(rdm_setup):
    traj = plan(rdm_setup, (2.5, 0.0, -0.5))
    assert isinstance(traj, Unreachable) and not traj.reached
    assert traj.blocking in {"joint_limit", "joint_torque", "rotor_thrust", "collision"}
    assert traj.final_error > 0.5


def test_torque_limit_binds_and_is_respected():
    setup = PlannerSetup.for_robot("rdm", "perched")
    toml = re.sub(r"stall_torque = 3\.4", "stall_torque = 1.2", setup.toml)
    weak = PlannerSetup(setup.urdf, toml, "perched", setup.config)
    traj = plan(weak, (0.9, 0.0, -0.3))
    robot = Robot.from_strs(weak.urdf, weak.toml)
    stall = np.array(robot.stall_torques)
    assert np.all(np.abs(traj.torques) <= stall + 1e-3)
    assert np.max(np.abs(traj.torques[:, :6]) / stall[:6]) > 0.9  # it did bind
    assert "joint_torque" in traj.binding


def test_thrust_limit_binds_and_is_respected():
    setup = PlannerSetup.for_robot("rdm", "perched")
    toml = setup.toml.replace("thrust_max = 20", "thrust_max = 9")
    weak = PlannerSetup(setup.urdf, toml, "perched", setup.config)
    traj = plan(weak, (0.9, 0.0, -0.3))
    assert np.all(traj.thrusts <= 9.0 + 1e-3)
    assert traj.thrusts.max() > 8.0
    assert "rotor_thrust" in traj.binding


def test_ceiling_collision_binds(rdm_setup):
    traj = plan(rdm_setup, (0.7, 0.0, 0.2))  # above the ceiling plane z = 0
    assert not traj.reached
    assert np.all(traj.clearance >= -1e-4)
    assert "collision" in traj.binding


def test_joint_limit_binds(rdm_setup):
    traj = plan(rdm_setup, (-0.2, 0.0, -0.15))
    robot = Robot.from_strs(rdm_setup.urdf, rdm_setup.toml)
    _check_every_step(traj, robot, rdm_setup)


def test_constraint_jacobian_matches_finite_differences(rdm_setup):
    core = make_core(rdm_setup)
    jac = core.linearize()
    z0 = core.zeta.copy()
    v0 = core.values.copy()
    free = core.free
    h = 1e-5
    for c, k in enumerate(free):
        zp, zm = z0.copy(), z0.copy()
        zp[k] += h
        zm[k] -= h
        core.set_zeta(zp)
        vp = core.values.copy()
        core.set_zeta(zm)
        vm = core.values.copy()
        fd = (vp - vm) / (2 * h)
        np.testing.assert_allclose(jac[:, c], fd, atol=1e-4 * (1 + np.abs(fd).max()))
    core.set_zeta(z0)
    np.testing.assert_allclose(core.values, v0)


def test_planner_torques_match_model_binding(rdm_setup):
    """eq. (61) through the planner equals the model's static_torques with the thrusts,
    perching reaction and gravity the planner documents."""
    core = make_core(rdm_setup)
    lay = core.layout
    v = core.values
    thrust = v[lay["thrust"][0] : lay["thrust"][0] + 4]
    tau = v[: lay["torque"][1]]
    robot = Robot.from_strs(rdm_setup.urdf, rdm_setup.toml)
    z = core.zeta
    perch = 5.0
    out = robot.static_torques(
        z[6:], thrusts=thrust, foot_wrench=[0, 0, -perch, 0, 0, 0], base_pose=list(z[:6])
    )
    ref = out[0]
    np.testing.assert_allclose(tau, ref, atol=1e-9)
    # Thrusts balance weight plus perching force.
    assert thrust.sum() == pytest.approx(robot.mass * G + perch, rel=1e-6)
