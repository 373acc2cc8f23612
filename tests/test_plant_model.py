"""The generated MuJoCo model against an independent reading of the URDF/TOML."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest
from scipy import signal
from test_plant_urdf_oracle import joint_limits, mass_and_cog, robot_files, rotors

from rdm.cli import main as cli_main
from rdm.plant import DescriptionError, Plant, ServoParams, load_robot
from rdm.plant.description import robot_toml
from rdm.plant.mjcf import rotor_site, servo_actuator

JOINTS = ("q1", "q2", "q3", "q4", "q5", "q6", "alpha1", "beta1", "alpha2", "beta2")


def _random_q(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.concatenate([rng.uniform(-1.2, 1.2, 6), rng.uniform(-2.5, 2.5, 4)])


@pytest.mark.parametrize("robot", ["rdm", "rcm"])
@pytest.mark.parametrize("seed", [None, 1, 2])
def test_mass_and_cog_match_urdf(robot: str, seed: int | None) -> None:
    q = np.zeros(10) if seed is None else _random_q(seed)
    plant = Plant(robot, ceiling_height=None)
    plant.reset(q0=q, base_position=(0.0, 0.0, 0.0))
    urdf, _ = robot_files(robot)
    mass, cog = mass_and_cog(urdf, dict(zip(JOINTS, q, strict=True)))
    foot = plant.model.body("foot").id
    assert plant.model.body_subtreemass[foot] == pytest.approx(mass, abs=1e-9)
    assert np.allclose(plant.data.subtree_com[foot], cog, atol=1e-9)
    assert np.allclose(plant.ground_truth().cog_position, cog, atol=1e-9)


@pytest.mark.parametrize("robot", ["rdm", "rcm"])
def test_rotor_sites_match_toml(robot: str) -> None:
    q = _random_q(7)
    plant = Plant(robot, ceiling_height=None)
    plant.reset(q0=q, base_position=(0.0, 0.0, 0.0))
    urdf, toml = robot_files(robot)
    pos, axes, spin, c = rotors(toml, urdf, dict(zip(JOINTS, q, strict=True)))
    for i, name in enumerate(plant.rotor_names):
        sid = plant.model.site(rotor_site(name)).id
        assert np.allclose(plant.data.site_xpos[sid], pos[i], atol=1e-9)
        assert np.allclose(plant.data.site_xmat[sid].reshape(3, 3)[:, 2], axes[i], atol=1e-9)
        gear = plant.model.actuator(f"{name}_thrust").gear
        assert np.allclose(gear, [0, 0, 1, 0, 0, -spin[i] * c[i]])


def test_joint_ranges_and_stall_torques() -> None:
    plant = Plant("rdm")
    urdf, _ = robot_files("rdm")
    limits = joint_limits(urdf)
    desc = load_robot("rdm")
    for name in JOINTS:
        jid = plant.model.joint(name).id
        assert np.allclose(plant.model.jnt_range[jid], limits[name])
        assert plant.model.jnt_limited[jid]
        act = plant.model.actuator(servo_actuator(name))
        stall = desc.joint(name).stall_torque
        assert np.allclose(act.forcerange, [-stall, stall])
        # No joint-level clamp: it would also clamp the rotor forces at that joint.
        assert not plant.model.jnt_actfrclimited[jid]


def test_servo_saturates_at_stall_torque_under_a_large_load() -> None:
    """A 5 N m torque about the end link's roll axis against q6 (stall 3.4 N m, TOML): the
    servo gives exactly its stall torque and the joint accelerates at (5 - 3.4) / I, I from
    the URDF (end_link ixx) plus the servo armature."""
    plant = Plant("rdm", fixed_base=True, ceiling_height=None)
    plant.model.opt.gravity[:] = 0.0  # the load is the external torque alone
    stall = load_robot("rdm").joint("q6").stall_torque
    load = 5.0
    plant.apply_body_wrench("end_link", torque=(load, 0.0, 0.0))
    i = JOINTS.index("q6")
    plant.step(20)  # the servo ramps up to its limit within a few ms (kv qdot grows)
    v0, t0 = plant.servo_velocities()[i], plant.time
    plant.step(30)
    v1, t1 = plant.servo_velocities()[i], plant.time
    assert plant.servo_torques()[i] == pytest.approx(-stall, abs=1e-9)
    inertia = 2.1375e-05 + ServoParams().armature
    assert (v1 - v0) / (t1 - t0) == pytest.approx((load - stall) / inertia, rel=0.01)
    # Current from the XH430-W350 linear torque constant (3.4 N m at 2.3 A, ASSUMPTION).
    assert abs(plant.servo_currents()[i]) == pytest.approx(2.3, rel=1e-9)


def test_unloaded_servo_follows_the_linear_second_order_model() -> None:
    """q6 (end roll: inertia on its axis, no gravity torque) vs scipy's step response of
    (I + armature) s^2 + kv s + kp with the URDF inertia."""
    servo = ServoParams()
    plant = Plant("rdm", fixed_base=True, ceiling_height=None, servo=servo)
    q = np.zeros(10)
    q[5] = 0.2
    plant.set_servo_targets(q)
    n = 300
    trace = []
    for _ in range(n):
        plant.step(1)
        trace.append(plant.servo_positions()[5])
    inertia = 2.1375e-05 + servo.armature  # end_link ixx (+ massless end-effector frame)
    sys_ = signal.lti([servo.kp], [inertia, servo.kv, servo.kp])
    t = np.arange(1, n + 1) * 1e-3
    _, y = signal.step(sys_, T=t)
    assert np.max(np.abs(np.array(trace) - 0.2 * y)) < 0.004
    assert max(trace) <= 0.2 + 1e-6  # no overshoot: a first-order-like response


def test_servo_goal_filter_follows_the_filtered_second_order_model() -> None:
    """With ``goal_filter_s`` tau the loop follows the goal through 1 / (tau s + 1): q6's
    step response against scipy's (kp / ((I + armature) s^2 + kv s + kp)) / (tau s + 1).
    Catches a filter not applied (the unfiltered response leads by ~tau), a wrong time
    constant and a filter state starting at 0 instead of the reset posture."""
    servo = ServoParams(kp=150.0, kv=5.0, goal_filter_s=0.05)
    plant = Plant("rdm", fixed_base=True, ceiling_height=None, servo=servo)
    q0 = np.zeros(10)
    q0[5] = 0.3
    plant.reset(q0=q0)
    plant.step(50)
    assert plant.servo_positions()[5] == pytest.approx(0.3, abs=1e-9)  # at rest on q0
    q = q0.copy()
    q[5] = 0.5
    plant.set_servo_targets(q)
    n = 400
    trace = []
    for _ in range(n):
        plant.step(1)
        trace.append(plant.servo_positions()[5] - 0.3)
    inertia = 2.1375e-05 + servo.armature
    tau = servo.goal_filter_s
    den = np.polymul([tau, 1.0], [inertia, servo.kv, servo.kp])
    t = np.arange(1, n + 1) * 1e-3
    _, y = signal.step(signal.lti([servo.kp], den), T=t)
    assert np.max(np.abs(np.array(trace) - 0.2 * y)) < 0.004
    with pytest.raises(ValueError, match="goal_filter_s"):
        ServoParams(goal_filter_s=-0.01)


def test_cli_export_loads_in_mujoco(tmp_path) -> None:
    out = tmp_path / "model.xml"
    assert cli_main(["plant", "--export", str(out), "--robot", "rcm"]) == 0
    model = mujoco.MjModel.from_xml_path(str(out))
    assert model.nu == 10 + 4
    assert model.body_subtreemass[1] == pytest.approx(3.7)
    assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "ceiling") >= 0


def test_bad_inputs_raise_clear_errors() -> None:
    with pytest.raises(DescriptionError, match="robot"):
        load_robot("no_such_robot")
    plant = Plant("rdm")
    with pytest.raises(ValueError, match="thrusts"):
        plant.set_rotor_thrusts([1.0, 2.0])
    with pytest.raises(ValueError, match="base_quaternion"):
        plant.reset(base_quaternion=(0, 0, 0, 0))
    plant.set_servo_targets([np.nan] + [0.1] * 9)
    assert plant.rejected_commands == 1
    assert plant.data.ctrl[plant.model.actuator("q1_servo").id] == 0.0
    with pytest.raises(ValueError, match="sensor"):
        plant.wrench("nope")


def test_description_with_modified_joints_builds() -> None:
    desc = load_robot("rdm")
    stiff = dataclasses.replace(
        desc, joints=tuple(dataclasses.replace(j, stall_torque=9.0) for j in desc.joints)
    )
    plant = Plant(stiff)
    assert np.allclose(plant.model.actuator("q1_servo").forcerange, [-9.0, 9.0])


def test_a_toml_number_past_its_physical_bound_is_refused(tmp_path) -> None:
    """The plant's reader bounds the TOML's numbers as the core loader does: a rotor offset
    of 1e308 m is finite but its products overflow; the message names the field and rule."""
    src = robot_toml("rdm")
    text = src.read_text()
    (tmp_path / "rdm.urdf").write_bytes((src.parent / "rdm.urdf").read_bytes())
    bad = tmp_path / "rdm.toml"
    bad.write_text(text.replace("offset = [0.0, 0.07, 0.03]", "offset = [0.0, 1e308, 0.03]", 1))
    with pytest.raises(DescriptionError) as err:
        load_robot(bad)
    assert str(err.value) == "rotors[0].offset: 1e+308 is outside the length bound |x| <= 1000 m"
    bad.write_text(text.replace("friction_z = 0.5", "friction_z = nan", 1))
    with pytest.raises(DescriptionError, match=r"foot\.friction_z: NaN or infinite"):
        load_robot(bad)
    bad.write_text(text)
    assert load_robot(bad).rotors[0].offset == (0.0, 0.07, 0.03)
