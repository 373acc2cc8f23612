"""Planner: convergence, every constraint respected on every step and shown to bind,
blocking reports, constraint Jacobians against finite differences, torques against the
model binding, the levelled units against an independent rotation check."""

import re
from collections import Counter

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rdm.model import Robot
from rdm.planner import PlannerSetup, Unreachable, make_core, plan

G = 9.80665
# Default damper thresholds (crates/rdm_core/src/planner/config.rs), (restricted, forbidden).
RHO_R, RHO_F = 3e-4, 1e-4
D_R, D_F = 0.1, 0.01
TOL = 1e-6


def _check_every_step(traj, robot):
    """Joint limits, stall torques, thrust bounds, rho, clearance and rotor spacing."""
    lo, hi = np.array(robot.joint_limits).T
    q = traj.zeta[:, 6:]
    assert np.all(q >= lo - 1e-9) and np.all(q <= hi + 1e-9)
    stall = np.array(robot.stall_torques)
    assert np.all(np.abs(traj.torques) <= stall + TOL)
    tmin = np.array([r["thrust_min"] for r in robot.rotors])
    tmax = np.array([r["thrust_max"] for r in robot.rotors])
    assert np.all(traj.thrusts >= tmin - TOL) and np.all(traj.thrusts <= tmax + TOL)
    assert np.all(traj.rho >= RHO_F - 1e-9)
    # The damper rows are linearised: second-order overshoot of d_F stays below 1 mm,
    # far from contact (d = 0).
    assert np.all(traj.clearance >= D_F - 1e-3)
    assert np.all(traj.airflow >= D_F - 1e-3)


def _with(setup, toml=None, mode=None, **config):
    return PlannerSetup(
        setup.urdf, toml or setup.toml, mode or setup.mode, {**setup.config, **config}
    )


def _bound(traj, name):
    return Counter(b for b in traj.binding if b)[name] > 0


@pytest.fixture(scope="module")
def rdm_setup():
    return PlannerSetup.for_robot("rdm", "perched")


@pytest.fixture(scope="module")
def robot(rdm_setup):
    return Robot.from_strs(rdm_setup.urdf, rdm_setup.toml)


def test_start_is_feasible_with_a_regular_allocation(rdm_setup, robot):
    """At the start Q̄ must be regular (rho clearly > 0; levelling on the wrong branch turns a
    rotor pair and makes it singular) and the static thrusts inside [thrust_min, thrust_max]."""
    for mode in ("perched", "flight"):
        core = make_core(_with(rdm_setup, mode=mode))
        lay = core.layout
        v = core.values
        thrust = v[lay["thrust"][0] : lay["thrust"][0] + 4]
        assert v[lay["rho"][0]] > 4 * RHO_R
        assert np.all(thrust >= 1.0) and np.all(thrust <= 20.0)
        # rho is |det Q̄| about the CoG; independent rebuild from the model's rotor poses.
        z = core.zeta
        ws = robot.evaluate(z[6:], base_pose=list(z[:6]))
        pos, cog = np.array(ws["rotor_positions"]), np.array(ws["cog"])
        sigma = np.array([r["spin"] for r in robot.rotors])
        c = np.array([r["drag_to_thrust"] for r in robot.rotors])
        up = np.array([0.0, 0.0, 1.0])
        cols = [
            np.concatenate([[1.0], np.cross(p - cog, up) - ci * s * up])
            for p, s, ci in zip(pos, sigma, c, strict=True)
        ]
        qbar = np.array(cols).T
        assert v[lay["rho"][0]] == pytest.approx(abs(np.linalg.det(qbar)), rel=1e-9)


def test_units_are_level(rdm_setup, robot):
    """Every rotor axis points straight up after levelling (world frame from the model)."""
    core = make_core(rdm_setup)
    z = core.zeta
    ws = robot.evaluate(z[6:], base_pose=list(z[:6]))
    np.testing.assert_allclose(np.array(ws["rotor_directions"]), [[0, 0, 1]] * 4, atol=1e-12)


@pytest.mark.parametrize("target", [(0.2, -0.3, -0.7), (-0.4, 0.3, -0.3), (0.0, 0.0, -1.1)])
def test_perched_reaches_target_within_1mm(rdm_setup, robot, target):
    traj = plan(rdm_setup, target)
    assert traj.reached, traj.blocking
    assert traj.final_error < 1e-3
    _check_every_step(traj, robot)
    # The foot never moves when perched.
    assert np.all(traj.zeta[:, :6] == traj.zeta[0, :6])


def test_flight_moves_root_and_reaches(rdm_setup, robot):
    traj = plan(_with(rdm_setup, mode="flight"), (0.6, 0.3, -0.7))
    assert traj.reached, traj.blocking
    assert traj.final_error < 1e-3
    _check_every_step(traj, robot)
    assert np.ptp(traj.zeta[:, :3], axis=0).max() > 0.05


def test_unreachable_names_blocking_constraint(rdm_setup, robot):
    traj = plan(rdm_setup, (2.5, 0.0, -0.5))
    assert isinstance(traj, Unreachable) and not traj.reached
    assert traj.blocking == "rotor_thrust"
    assert traj.final_error > 1.0
    _check_every_step(traj, robot)


def test_torque_limit_binds_and_is_respected(rdm_setup):
    toml = re.sub(r"stall_torque = 3\.4", "stall_torque = 2.5", rdm_setup.toml)
    weak = _with(rdm_setup, toml=toml)
    traj = plan(weak, (0.2, -0.3, -0.7))  # needs 3.25 N m on q2 with the real servos
    robot = Robot.from_strs(weak.urdf, weak.toml)
    _check_every_step(traj, robot)
    stall = np.array(robot.stall_torques)
    assert np.max(np.abs(traj.torques[:, :6]) / stall[:6]) > 0.9  # it came close
    assert _bound(traj, "joint_torque")


def test_thrust_limit_binds_and_is_respected(rdm_setup):
    toml = rdm_setup.toml.replace("thrust_max = 20", "thrust_max = 15")
    weak = _with(rdm_setup, toml=toml)
    traj = plan(weak, (0.2, -0.3, -0.7))  # needs 18.2 N with 20 N rotors
    _check_every_step(traj, Robot.from_strs(weak.urdf, weak.toml))
    assert traj.thrusts.max() > 14.0
    assert _bound(traj, "rotor_thrust")


def test_stability_binds_when_the_pairs_line_up(rdm_setup, robot):
    """Straight down: the arm unit moves under the foot unit, Q̄ loses rank (rho -> 0);
    the damper stops rho at rho_F."""
    for mode in ("perched", "flight"):
        traj = plan(_with(rdm_setup, mode=mode), (0.0, 0.0, -1.4))
        assert not traj.reached
        _check_every_step(traj, robot)
        assert traj.rho.min() < RHO_R
        assert traj.blocking == "stability"


def test_ceiling_collision_binds_in_flight(rdm_setup, robot):
    traj = plan(_with(rdm_setup, mode="flight"), (0.3, 0.0, 0.2))  # above the ceiling z = 0
    assert not traj.reached
    _check_every_step(traj, robot)
    assert traj.clearance.min() < D_R
    assert traj.blocking == "collision"


def test_rotor_spacing_binds_with_large_rotors(rdm_setup):
    """With 0.36 m rotors the two units start 0.04 m beyond one diameter apart (eq. 68);
    folding the arm must stop at d_F."""
    toml = rdm_setup.toml.replace("diameter = 0.127", "diameter = 0.36")
    big = _with(rdm_setup, toml=toml)
    traj = plan(big, (0.2, -0.3, -0.7))
    robot = Robot.from_strs(big.urdf, big.toml)
    _check_every_step(traj, robot)
    pos = []
    for z in traj.zeta:
        ws = robot.evaluate(z[6:], base_pose=list(z[:6]))
        pos.append(np.array(ws["rotor_positions"]))
    pos = np.array(pos)
    spacing = min(
        np.linalg.norm(pos[:, i] - pos[:, j], axis=1).min() for i in (0, 1) for j in (2, 3)
    )
    assert spacing - 0.36 >= D_F - 1e-3  # independent of the planner's own airflow value
    assert spacing - 0.36 < 0.02
    assert _bound(traj, "airflow")


def test_joint_limit_binds(rdm_setup, robot):
    traj = plan(rdm_setup, (-0.2, 0.0, -0.15))
    _check_every_step(traj, robot)
    lo, hi = np.array(robot.joint_limits).T
    q = traj.zeta[:, 6:12]
    gap = np.minimum(q - lo[:6], hi[:6] - q).min()
    assert gap < 0.15  # inside the restricted band
    assert traj.blocking == "joint_limit"


def test_orientation_target(rdm_setup):
    core = make_core(rdm_setup)
    pos, quat = core.end_effector_pose()
    rpy = Rotation.from_quat(quat).as_euler("xyz")
    target = (*np.add(pos, (0.05, 0.0, 0.05)), *np.add(rpy, (0.0, 0.0, 0.2)))
    traj = plan(rdm_setup, target)
    assert traj.reached, traj.blocking


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


def test_planner_torques_match_model_binding(rdm_setup, robot):
    """eq. (61) through the planner equals the model's static_torques with the thrusts,
    perching reaction and gravity the planner documents."""
    core = make_core(rdm_setup)
    lay = core.layout
    v = core.values
    thrust = v[lay["thrust"][0] : lay["thrust"][0] + 4]
    tau = v[: lay["torque"][1]]
    z = core.zeta
    perch = 5.0
    out = robot.static_torques(
        z[6:], thrusts=thrust, foot_wrench=[0, 0, -perch, 0, 0, 0], base_pose=list(z[:6])
    )
    np.testing.assert_allclose(tau, out[0], atol=1e-9)
    # Thrusts balance weight plus perching force.
    assert thrust.sum() == pytest.approx(robot.mass * G + perch, rel=1e-6)


def test_plan_command(tmp_path, capsys):
    import json

    from rdm.cli import main

    out = tmp_path / "traj.csv"
    assert main(["plan", "--target", "0.2,-0.3,-0.7", "--out", str(out)]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["reached"] and summary["final_error_m"] < 1e-3
    assert out.stat().st_size > 0
    assert main(["plan", "--target", "2.5,0,-0.5"]) == 1
    assert json.loads(capsys.readouterr().out)["blocking"] == "rotor_thrust"
    assert main(["plan", "--target", "1,2"]) == 2
    # non-finite targets and robots the planner cannot load: a message, exit 2, no traceback
    capsys.readouterr()
    assert main(["plan", "--target", "nan,0,0"]) == 2
    assert "must be finite" in capsys.readouterr().err
    assert main(["plan", "--target", "0.2,0,-0.5,inf,0,0"]) == 2
    assert main(["plan", "--robot", str(tmp_path / "missing"), "--target", "0.2,0,-0.5"]) == 2
    assert "rdm plan:" in capsys.readouterr().err


def _segment_distance(a0, a1, b0, b1):
    """Exact segment-segment distance: the convex quadratic over (s, t) in [0, 1]^2,
    minimised with scipy (independent of the planner's closed form)."""
    from scipy.optimize import minimize

    def f(st):
        d = (a0 + st[0] * (a1 - a0)) - (b0 + st[1] * (b1 - b0))
        return d @ d

    r = minimize(f, [0.5, 0.5], bounds=[(0, 1), (0, 1)], method="L-BFGS-B", tol=1e-14)
    return float(np.sqrt(r.fun))


@pytest.mark.parametrize(
    ("target", "reached"), [((0.2, -0.3, -0.7), True), ((0.3, 0.0, -0.6), False)]
)
def test_capsule_collision_binds_around_an_obstacle(rdm_setup, robot, target, reached):
    """A 3 cm pole (a capsule fixed to the foot frame, i.e. the world when perched) across
    the end link's path: the planner either goes around it or stops at d_F; the end-link
    capsule never touches it (distance from the model's link poses, scipy minimiser)."""
    foot, end = robot.link_names.index("foot"), robot.link_names.index("end_link")
    pole = (np.array([0.2, -0.6, -0.78]), np.array([0.2, 0.6, -0.78]))
    shapes = [*rdm_setup.config["shapes"], ("capsule", foot, tuple(pole[0]), tuple(pole[1]), 0.03)]
    end_shape = next(i for i, sh in enumerate(shapes) if sh[0] == "capsule" and sh[1] == end)
    pairs = [*rdm_setup.config["pairs"], (end_shape, len(shapes) - 1)]
    traj = plan(_with(rdm_setup, shapes=shapes, pairs=pairs), target)
    assert traj.reached == reached
    _check_every_step(traj, robot)
    assert _bound(traj, "collision")
    if not reached:
        assert traj.blocking == "collision"
    _, a, b, r_end = shapes[end_shape][1:]
    gaps = []
    for z in traj.zeta:
        pose = np.array(robot.evaluate(z[6:], base_pose=list(z[:6]))["frames"]["end_link"])
        p0 = pose[:3, :3] @ np.array(a) + pose[:3, 3]
        p1 = pose[:3, :3] @ np.array(b) + pose[:3, 3]
        gaps.append(_segment_distance(p0, p1, *pole) - r_end - 0.03)
    assert min(gaps) >= D_F - 1e-3
    assert min(gaps) < 0.02  # it came close: the constraint was active
