"""Physics sanity of the RDM model: aerial ZMP in the straight vertical configuration
(Sec. II-A-1) and the static joint torques of Table II's arm-unit positions (eq. 61)."""

from __future__ import annotations

import numpy as np
import pytest

from rdm.model import VERTICAL_Q, Robot

STALL = 3.4  # XH430-W350-R stall torque, N m


def test_vertical_configuration_hangs_straight_down_with_thrust_up() -> None:
    robot = Robot.default()
    out = robot.evaluate(VERTICAL_Q)
    foot = out["frames"]["foot"][:3, 3]
    ee = out["frames"]["end_effector"][:3, 3]
    np.testing.assert_allclose(ee[:2], foot[:2], atol=1e-12)  # arm vertical
    assert ee[2] < foot[2] - 1.0
    np.testing.assert_allclose(
        out["rotor_directions"], np.tile([0.0, 0.0, 1.0], (4, 1)), atol=1e-12
    )


def test_vertical_configuration_aerial_zmp_inside_the_quad_rotor_polygon() -> None:
    robot = Robot.default()
    out = robot.evaluate(VERTICAL_Q)
    assert out["zmp_inside"] and not out["zmp_degenerate"]
    # Independent: CoG projection against the rhombus of the four rotors (numpy geometry).
    pts = out["rotor_positions"][:, :2]
    c = out["cog"][:2]
    hull = pts[np.argsort(np.arctan2(*(pts - pts.mean(0)).T[::-1]))]
    dists = []
    for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True):
        edge = b - a
        normal = np.array([-edge[1], edge[0]]) / np.linalg.norm(edge)
        dists.append(np.dot(c - a, normal))
    assert min(dists) > 0.03
    assert out["zmp_margin"] == pytest.approx(min(dists), abs=1e-12)


def test_vertical_with_parallel_rotor_pairs_has_no_support_area() -> None:
    """With both rotor pairs parallel the rotors are collinear: no interior (Fig. 2 A/B)."""
    robot = Robot.default()
    q = list(VERTICAL_Q)
    q[8] = 0.0  # alpha2: arm pair parallel to the foot pair
    out = robot.evaluate(q)
    assert out["zmp_degenerate"] and not out["zmp_inside"] and out["zmp_margin"] <= 0.0


def test_eq73_with_hover_thrusts_equals_cog_projection_when_thrust_is_vertical() -> None:
    robot = Robot.default()
    out = robot.evaluate(VERTICAL_Q)
    target = np.array([out["mass"] * 9.80665, 0, 0, 0])
    lam = np.linalg.lstsq(out["allocation_bar"], target, rcond=None)[0]
    z = robot.aerial_zmp_from_thrusts(VERTICAL_Q, lam)
    np.testing.assert_allclose(z["aerial_zmp"], out["cog"][:2], atol=1e-9)


def _hover_torques(robot, q):
    out = robot.evaluate(q)
    target = np.array([out["mass"] * 9.80665, 0, 0, 0])
    lam = np.linalg.lstsq(out["allocation_bar"], target, rcond=None)[0]
    tau, residual = robot.static_torques(q, lam)
    return tau, residual, lam


def test_horizontal_hover_with_arm_unit_at_the_end_stays_below_stall_torque() -> None:
    robot = Robot.default()  # arm unit at the end of the middle link (Table II "End")
    q = np.zeros(robot.n_q)
    tau, residual, lam = _hover_torques(robot, q)
    np.testing.assert_allclose(residual, 0.0, atol=1e-9)  # hover thrust balances gravity
    assert np.all(lam > 0) and np.all(lam < 20)
    link = [robot.joint_names.index(n) for n in ("q1", "q2", "q3", "q4", "q5", "q6")]
    assert np.all(np.abs(tau[link]) < STALL), tau


def test_static_torques_match_mujoco_subtree_moments() -> None:
    """Eq. (61) per joint == minus the axial moment of all loads beyond the joint, built from
    MuJoCo's body masses, CoMs and joint anchors (random configurations and thrusts)."""
    import mujoco

    from rdm.model import shipped_robot_files

    robot = Robot.default()
    with shipped_robot_files("rdm") as (urdf, _):
        model = mujoco.MjModel.from_xml_path(str(urdf))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(8)
    g = np.array([0.0, 0.0, -9.80665])
    rotor_body = [model.body(r["parent"]).id for r in robot.rotors]
    ee_body = model.body("end_effector").id
    for _ in range(20):
        lim = robot.joint_limits
        q = rng.uniform(lim[:, 0], lim[:, 1])
        lam = rng.uniform(0, 20, 4)
        ee_wrench = rng.normal(size=6)
        for name, v in zip(robot.joint_names, q, strict=True):
            data.qpos[model.jnt_qposadr[model.joint(name).id]] = v
        mujoco.mj_forward(model, data)
        tau, _ = robot.static_torques(q, lam, end_effector_wrench=ee_wrench)
        out = robot.evaluate(q)
        for k, name in enumerate(robot.joint_names):
            jid = model.joint(name).id
            child = model.jnt_bodyid[jid]
            anchor, axis = data.xanchor[jid], data.xaxis[jid]

            def beyond(b: int, child: int = child) -> bool:
                while b > 0:
                    if b == child:
                        return True
                    b = model.body_parentid[b]
                return False

            moment = np.zeros(3)
            for b in range(1, model.nbody):
                if beyond(b):
                    moment += np.cross(data.xipos[b] - anchor, model.body_mass[b] * g)
            for i, r in enumerate(robot.rotors):
                if beyond(rotor_body[i]):
                    f = lam[i] * out["rotor_directions"][i]
                    moment += np.cross(out["rotor_positions"][i] - anchor, f)
                    moment -= r["drag_to_thrust"] * r["spin"] * f
            if beyond(ee_body):
                moment += np.cross(data.xpos[ee_body] - anchor, ee_wrench[:3]) + ee_wrench[3:]
            assert tau[k] == pytest.approx(-axis @ moment, abs=1e-9), name


def test_horizontal_hover_with_arm_unit_at_the_root_exceeds_stall_torque() -> None:
    root_case = Robot.variant("rdm", arm_unit_position=0.0)
    q = np.zeros(root_case.n_q)
    q2 = root_case.joint_names.index("q2")
    # The arm rotors sit on the q2 axis, so their thrust cannot relieve q2 at all.
    tau_a, _ = root_case.static_torques(q, [10.0, 10.0, 0.0, 0.0])
    tau_b, _ = root_case.static_torques(q, [10.0, 10.0, 20.0, 20.0])
    assert tau_a[q2] == pytest.approx(tau_b[q2], abs=1e-12)
    assert abs(tau_a[q2]) > STALL
    end_case = Robot.default()
    tau_end, _, _ = _hover_torques(end_case, q)
    assert abs(tau_end[q2]) < abs(tau_a[q2])
