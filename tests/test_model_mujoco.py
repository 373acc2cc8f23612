"""The Rust model against MuJoCo built from the SAME URDF, at many random configurations.

MuJoCo fixes the URDF root link (the foot) at the world origin, so MuJoCo quantities are
base-at-identity; our floating base is checked by transforming MuJoCo's frames.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from rdm.model import Robot, shipped_robot_files

N_CONFIGS = 40


def _mujoco(name: str) -> tuple[mujoco.MjModel, mujoco.MjData]:
    with shipped_robot_files(name) as (urdf, _toml):
        model = mujoco.MjModel.from_xml_path(str(urdf))
    return model, mujoco.MjData(model)


def _set_q(model: mujoco.MjModel, data: mujoco.MjData, names: list[str], q: np.ndarray) -> None:
    for name, value in zip(names, q, strict=True):
        data.qpos[model.jnt_qposadr[model.joint(name).id]] = value
    mujoco.mj_forward(model, data)


def _random_q(robot, rng: np.random.Generator) -> np.ndarray:
    lim = robot.joint_limits
    return rng.uniform(lim[:, 0], lim[:, 1])


def _pose(data: mujoco.MjData, body: int) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = data.xmat[body].reshape(3, 3)
    t[:3, 3] = data.xpos[body]
    return t


def _mujoco_inertia_about_com(model, data, com) -> np.ndarray:
    """Composite inertia about `com` (world axes) from MuJoCo's per-body principal inertia."""
    total = np.zeros((3, 3))
    for b in range(1, model.nbody):
        r = data.ximat[b].reshape(3, 3)
        d = data.xipos[b] - com
        m = model.body_mass[b]
        total += r @ np.diag(model.body_inertia[b]) @ r.T + m * (d @ d * np.eye(3) - np.outer(d, d))
    return total


def _euler_zyx(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch),
                              np.cos(yaw), np.sin(yaw))  # fmt: skip
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


@pytest.mark.parametrize("name", ["rdm", "rcm"])
def test_mass_cog_inertia_and_frames_match_mujoco(name: str) -> None:
    robot = Robot.shipped(name)
    model, data = _mujoco(name)
    foot = model.body("foot").id
    rng = np.random.default_rng(1)
    assert robot.mass == pytest.approx(model.body_mass.sum(), abs=1e-12)
    for _ in range(N_CONFIGS):
        q = _random_q(robot, rng)
        _set_q(model, data, robot.joint_names, q)
        out = robot.evaluate(q)
        assert out["mass"] == pytest.approx(model.body_mass.sum(), abs=1e-12)
        np.testing.assert_allclose(out["cog"], data.subtree_com[foot], atol=1e-10)
        inertia = _mujoco_inertia_about_com(model, data, data.subtree_com[foot])
        np.testing.assert_allclose(out["inertia_world"], inertia, atol=1e-9)
        # CoG frame = foot axes; the foot is at identity here.
        np.testing.assert_allclose(out["inertia"], inertia, atol=1e-9)
        for link in robot.link_names:
            np.testing.assert_allclose(
                out["frames"][link], _pose(data, model.body(link).id), atol=1e-10, err_msg=link
            )


def test_floating_base_transforms_every_frame_and_rotor() -> None:
    robot = Robot.default()
    model, data = _mujoco("rdm")
    rng = np.random.default_rng(2)
    rotors = robot.rotors
    for _ in range(N_CONFIGS):
        q = _random_q(robot, rng)
        base6 = np.concatenate([rng.uniform(-2, 2, 3), rng.uniform(-1.4, 1.4, 3)])
        base = np.eye(4)
        base[:3, :3] = _euler_zyx(*base6[3:])
        base[:3, 3] = base6[:3]
        _set_q(model, data, robot.joint_names, q)
        out_matrix = robot.evaluate(q, base)
        out_euler = robot.evaluate(q, base6)
        for link in robot.link_names:
            expected = base @ _pose(data, model.body(link).id)
            np.testing.assert_allclose(out_matrix["frames"][link], expected, atol=1e-10)
            np.testing.assert_allclose(out_euler["frames"][link], expected, atol=1e-10)
        for i, r in enumerate(rotors):
            parent = base @ _pose(data, model.body(r["parent"]).id)
            np.testing.assert_allclose(
                out_matrix["rotor_positions"][i], parent[:3, :3] @ r["offset"] + parent[:3, 3],
                atol=1e-10,
            )  # fmt: skip
            np.testing.assert_allclose(
                out_matrix["rotor_directions"][i], parent[:3, :3] @ r["axis"], atol=1e-12
            )
        # The CoG frame has the foot's axes: inertia in it is invariant to the base pose.
        np.testing.assert_allclose(out_matrix["inertia"], robot.evaluate(q)["inertia"], atol=1e-10)
        np.testing.assert_allclose(
            out_matrix["cog"], base[:3, :3] @ data.subtree_com[1] + base[:3, 3], atol=1e-10
        )


def test_allocation_matrix_matches_rotor_wrench_about_mujoco_com() -> None:
    """Q(q) lambda equals the rotor wrench about MuJoCo's CoG, built from MuJoCo's frames."""
    robot = Robot.default()
    model, data = _mujoco("rdm")
    foot = model.body("foot").id
    rng = np.random.default_rng(3)
    for _ in range(N_CONFIGS):
        q = _random_q(robot, rng)
        lam = rng.uniform(1, 20, robot.n_rotors)
        _set_q(model, data, robot.joint_names, q)
        com = data.subtree_com[foot]
        force = np.zeros(3)
        moment = np.zeros(3)
        for i, r in enumerate(robot.rotors):
            parent = _pose(data, model.body(r["parent"]).id)
            u = parent[:3, :3] @ r["axis"]
            p = parent[:3, :3] @ r["offset"] + parent[:3, 3]
            force += lam[i] * u
            moment += np.cross(p - com, lam[i] * u) - r["drag_to_thrust"] * r["spin"] * lam[i] * u
        out = robot.evaluate(q)
        wrench = out["allocation"] @ lam
        np.testing.assert_allclose(wrench[:3], force, atol=1e-10)
        np.testing.assert_allclose(wrench[3:], moment, atol=1e-10)
        np.testing.assert_allclose(out["allocation_bar"], out["allocation"][2:], atol=0)
        # rho of eq. (65), recomputed with numpy.
        qb = out["allocation"][2:]
        assert out["rho"] == pytest.approx(np.sqrt(max(np.linalg.det(qb @ qb.T), 0.0)), rel=1e-9)


def test_allocation_on_a_tilted_base_is_the_world_wrench_in_cog_axes() -> None:
    """Q(q) is in the CoG frame (the foot's axes): with the base tilted, Q lambda equals the
    world-frame rotor wrench (MuJoCo's frames moved by the base pose) rotated by R_C^T. Using
    R_C in place of R_C^T moves it by the tilt (0.6 and more at these tilts)."""
    robot = Robot.default()
    model, data = _mujoco("rdm")
    foot = model.body("foot").id
    rng = np.random.default_rng(4)
    for _ in range(N_CONFIGS):
        q = _random_q(robot, rng)
        lam = rng.uniform(1, 20, robot.n_rotors)
        rpy = rng.uniform(0.3, 1.2, 3) * rng.choice([-1.0, 1.0], 3)
        base = np.eye(4)
        base[:3, :3] = _euler_zyx(*rpy)
        base[:3, 3] = rng.uniform(-2, 2, 3)
        _set_q(model, data, robot.joint_names, q)
        com = base[:3, :3] @ data.subtree_com[foot] + base[:3, 3]
        force = np.zeros(3)
        moment = np.zeros(3)
        for i, r in enumerate(robot.rotors):
            parent = base @ _pose(data, model.body(r["parent"]).id)
            u = parent[:3, :3] @ r["axis"]
            p = parent[:3, :3] @ r["offset"] + parent[:3, 3]
            force += lam[i] * u
            moment += np.cross(p - com, lam[i] * u) - r["drag_to_thrust"] * r["spin"] * lam[i] * u
        r_cog = (base @ _pose(data, foot))[:3, :3]
        out = robot.evaluate(q, base)
        wrench = out["allocation"] @ lam
        np.testing.assert_allclose(wrench[:3], r_cog.T @ force, atol=1e-9)
        np.testing.assert_allclose(wrench[3:], r_cog.T @ moment, atol=1e-9)
        np.testing.assert_allclose(out["allocation_bar"], out["allocation"][2:], atol=0)


@pytest.mark.parametrize("frame", ["end_effector", "foot", "middle_link", "arm_unit_pitch"])
def test_joint_jacobian_columns_match_mujoco_jacbody(frame: str) -> None:
    robot = Robot.default()
    model, data = _mujoco("rdm")
    body = model.body(frame).id
    rng = np.random.default_rng(4)
    jacp = np.zeros((3, model.nv))
    jacr = np.zeros((3, model.nv))
    for _ in range(N_CONFIGS):
        q = _random_q(robot, rng)
        _set_q(model, data, robot.joint_names, q)
        mujoco.mj_jacBody(model, data, jacp, jacr, body)
        jac = robot.jacobian(frame, np.concatenate([np.zeros(6), q]))
        assert jac.shape == (6, 6 + robot.n_q)
        for k, name in enumerate(robot.joint_names):
            dof = model.jnt_dofadr[model.joint(name).id]
            np.testing.assert_allclose(jac[:3, 6 + k], jacp[:, dof], atol=1e-10, err_msg=name)
            np.testing.assert_allclose(jac[3:, 6 + k], jacr[:, dof], atol=1e-10, err_msg=name)


def test_cog_jacobian_matches_mujoco_subtree_com_jacobian() -> None:
    robot = Robot.default()
    model, data = _mujoco("rdm")
    rng = np.random.default_rng(5)
    jacp = np.zeros((3, model.nv))
    for _ in range(N_CONFIGS):
        q = _random_q(robot, rng)
        _set_q(model, data, robot.joint_names, q)
        mujoco.mj_jacSubtreeCom(model, data, jacp, model.body("foot").id)
        jac = robot.jacobian("cog", np.concatenate([np.zeros(6), q]))
        for k, name in enumerate(robot.joint_names):
            dof = model.jnt_dofadr[model.joint(name).id]
            np.testing.assert_allclose(jac[:3, 6 + k], jacp[:, dof], atol=1e-10, err_msg=name)


@pytest.mark.parametrize("frame", ["end_effector", "foot", "cog", "rotor3"])
def test_full_jacobian_matches_finite_differences_of_frames(frame: str) -> None:
    """All 16 columns (base position, ZYX Euler angles, q) against central differences."""
    robot = Robot.default()
    rng = np.random.default_rng(6)
    h = 1e-6
    for _ in range(10):
        zeta = np.concatenate(
            [rng.uniform(-1, 1, 3), rng.uniform(-1.3, 1.3, 3), _random_q(robot, rng)]
        )
        jac = robot.jacobian(frame, zeta)
        for k in range(zeta.size):
            plus, minus = zeta.copy(), zeta.copy()
            plus[k] += h
            minus[k] -= h
            tp = robot.evaluate(plus[6:], plus[:6])["frames"][frame]
            tm = robot.evaluate(minus[6:], minus[:6])["frames"][frame]
            dp = (tp[:3, 3] - tm[:3, 3]) / (2 * h)
            skew = (tp[:3, :3] - tm[:3, :3]) / (2 * h) @ tp[:3, :3].T
            dw = np.array([skew[2, 1], skew[0, 2], skew[1, 0]])
            np.testing.assert_allclose(jac[:3, k], dp, atol=2e-6)
            np.testing.assert_allclose(jac[3:, k], dw, atol=2e-6)
