"""Whole-robot physics of the plant against hand/numpy statics and kinematics."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest
from test_plant_urdf_oracle import mass_and_cog, robot_files, rotors

from rdm.plant import NoCeilingEffect, Plant, ServoParams, load_robot

G = 9.81
STIFF = ServoParams(kp=1000.0, kv=50.0)  # isolates rotor/mass physics from servo sag


def _oracle(robot: str = "rdm") -> tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    urdf, toml = robot_files(robot)
    mass, cog = mass_and_cog(urdf, {})
    pos, axes, spin, c = rotors(toml, urdf, {})
    assert np.allclose(axes, [0, 0, 1])  # straight arm: every rotor points up
    return mass, cog, pos, spin, c


def _allocation(
    point: np.ndarray, force: float, moment_y: float, pos: np.ndarray, spin, c
) -> np.ndarray:
    """Vertical thrusts giving total ``force`` and moments (0, moment_y, 0) about ``point``,
    zero yaw (drag) torque: least squares on [sum; roll; pitch; yaw]."""
    a = np.vstack([np.ones(4), pos[:, 1] - point[1], -(pos[:, 0] - point[0]), -spin * c])
    b = np.array([force, 0.0, moment_y, 0.0])
    t = np.linalg.lstsq(a, b, rcond=None)[0]
    assert np.allclose(a @ t, b, atol=1e-9)
    return t


def test_free_fall_accelerates_at_g() -> None:
    plant = Plant("rdm", ceiling_height=None)
    plant.reset(base_position=(0.0, 0.0, 5.0))
    t = 0.4
    plant.step(round(t / 0.001))
    z = plant.ground_truth().base_position[2]
    assert z == pytest.approx(5.0 - 0.5 * G * t**2, abs=2e-3)
    assert plant.ground_truth().base_linear_velocity[2] == pytest.approx(-G * t, rel=1e-3)
    assert np.linalg.norm(plant.imu_ideal().accel) < 1e-6  # free fall: no specific force


def test_hover_with_the_static_allocation() -> None:
    mass, cog, pos, spin, c = _oracle()
    thrust = _allocation(cog, mass * G, 0.0, pos, spin, c)
    plant = Plant("rdm", ceiling_height=None, servo=STIFF)
    plant.reset(base_position=(0.0, 0.0, 1.0), thrusts=thrust)
    plant.set_rotor_thrusts(thrust)
    plant.step(1000)
    truth = plant.ground_truth()
    assert np.linalg.norm(truth.base_position - [0.0, 0.0, 1.0]) < 0.01
    tilt = 2 * np.arccos(min(1.0, abs(truth.base_quaternion[0])))
    assert tilt < 0.01
    # Same thrusts, 5 % short: it sinks at about 0.05 g.
    plant.reset(base_position=(0.0, 0.0, 1.0), thrusts=0.95 * thrust)
    plant.set_rotor_thrusts(0.95 * thrust)
    plant.step(500)
    assert plant.ground_truth().base_position[2] == pytest.approx(
        1.0 - 0.5 * 0.05 * G * 0.25, abs=3e-3
    )


@pytest.mark.parametrize("rotor", [0, 1, 2, 3])
def test_drag_torque_sign_follows_eq_9(rotor: int) -> None:
    """Weightless, one rotor on: the only torque about the vertical is the drag torque
    -sigma c T (eq. 9), so the z angular momentum about the CoG grows as -sigma c T t
    (a short window: the off-axis thrust soon rolls the slender arm and tilts the force)."""
    _, _, _, spin, c = _oracle()
    plant = Plant("rdm", ceiling_height=None, servo=STIFF)
    plant.model.opt.gravity[:] = 0.0
    thrust = np.zeros(4)
    thrust[rotor] = 8.0
    plant.reset(base_position=(0.0, 0.0, 1.0), thrusts=thrust)
    plant.set_rotor_thrusts(thrust)
    t = 0.003
    plant.step(round(t / 0.001))
    mujoco.mj_subtreeVel(plant.model, plant.data)
    lz = plant.data.subtree_angmom[plant.model.body("foot").id][2]
    assert lz == pytest.approx(-spin[rotor] * c[rotor] * 8.0 * t, rel=0.02)


def _perch_plant(ceiling_effect=None, stall: float = 50.0) -> Plant:
    # The straight arm cannot be held by 3.4 N m servos against the perching thrust pattern
    # (q2 carries ~4 N m): raise the stall torques so the test isolates the contact.
    desc = load_robot("rdm")
    desc = dataclasses.replace(
        desc, joints=tuple(dataclasses.replace(j, stall_torque=stall) for j in desc.joints)
    )
    return Plant(desc, ceiling_height=2.0, servo=STIFF, ceiling_effect=ceiling_effect)


def _perch_thrusts(normal_force: float) -> np.ndarray:
    """Thrusts pushing the foot up with ``normal_force`` with the ZMP at the plate centre:
    total = m g + N, moment about the foot origin = that of gravity."""
    mass, cog, pos, spin, c = _oracle()
    foot = np.zeros(3)
    return _allocation(foot, mass * G + normal_force, -mass * G * (cog[0] - foot[0]), pos, spin, c)


def test_perched_foot_sensor_reads_thrust_minus_weight() -> None:
    mass, *_ = _oracle()
    thrust = _perch_thrusts(4.0)
    plant = _perch_plant(NoCeilingEffect())
    plant.reset(base_position=(0.0, 0.0, 2.0 - 5e-4), thrusts=thrust)
    plant.set_rotor_thrusts(thrust)
    plant.step(500)
    force, torque = plant.wrench_ideal("foot_wrench")
    assert force[2] == pytest.approx(thrust.sum() - mass * G, abs=0.05)
    assert np.linalg.norm(force[:2]) < 0.05 and np.linalg.norm(torque) < 0.02
    truth = plant.ground_truth()
    assert truth.foot_in_contact and truth.foot_contact_points >= 3
    assert np.allclose(truth.foot_contact_force, force, atol=1e-6)
    assert np.allclose(truth.foot_contact_torque, torque, atol=1e-6)
    assert np.all(np.abs(truth.foot_zmp) < [0.01, 0.01])  # centre of the plate
    assert np.linalg.norm(truth.foot_slip) < 1e-4
    # A perched foot sits still: no jitter in the last 100 ms.
    heights = []
    for _ in range(100):
        plant.step(1)
        heights.append(plant.ground_truth().base_position[2])
    assert np.ptp(heights) < 1e-6
    reading = plant.wrench("foot_wrench")
    assert reading.force[2] == pytest.approx(force[2], abs=5 * 0.003 * 300)


def test_perched_with_ceiling_effect_gains_thrust() -> None:
    """Default ceiling model: every rotor is 0.02 m from the ceiling when perched straight,
    so the foot reads sum(T) * ratio(0.02) - m g (ratio from the written-out formula)."""
    mass, *_ = _oracle()
    r = 0.127 / 2
    ratio = 1.0 / (1.0 - (r / (0.02 + 0.8 * r)) ** 2 / 4.7)
    thrust = _perch_thrusts(4.0) / ratio  # about 4 N of normal force after the gain
    plant = _perch_plant()
    plant.reset(base_position=(0.0, 0.0, 2.0 - 5e-4), thrusts=thrust)
    plant.set_rotor_thrusts(thrust)
    plant.step(500)
    dist = plant.rotor_distances_to_ceiling()
    assert np.allclose(dist, 0.02, atol=3e-3)  # the arm sags a little under stiff servos
    ratios = 1.0 / (1.0 - (r / (dist + 0.8 * r)) ** 2 / 4.7)
    assert np.all(ratios > 1.1)
    force, _ = plant.wrench_ideal("foot_wrench")
    assert force[2] == pytest.approx(thrust @ ratios - mass * G, abs=0.05)
    assert force[2] == pytest.approx(4.0, abs=0.3)


@pytest.mark.parametrize(("fraction", "slips"), [(0.5, False), (0.9, False), (1.5, True)])
def test_tangential_push_slips_only_above_mu_n(fraction: float, slips: bool) -> None:
    normal = 4.0
    mu = load_robot("rdm").friction_xy
    thrust = _perch_thrusts(normal)
    plant = _perch_plant(NoCeilingEffect())
    plant.reset(base_position=(0.0, 0.0, 2.0 - 5e-4), thrusts=thrust)
    plant.set_rotor_thrusts(thrust)
    plant.step(200)
    start = plant.ground_truth().base_position.copy()
    # Push the plate sideways (y) at its contact face: statically no tipping moment.
    plant.apply_body_wrench("foot_plate", force=(0.0, fraction * mu * normal, 0.0))
    tracked = []
    for _ in range(8):
        plant.step(50)
        tracked.append(np.linalg.norm(plant.ground_truth().foot_slip))
    moved = np.linalg.norm((plant.ground_truth().base_position - start)[:2])
    if slips:
        assert moved > 0.01
        assert max(tracked) > 0.005  # the ground-truth slip saw it too
    else:
        assert moved < 1e-4
        assert max(tracked) < 1e-4
        assert plant.ground_truth().foot_in_contact


@pytest.mark.parametrize(("fraction", "turns"), [(0.5, False), (1.5, True)])
def test_yaw_torque_turns_the_foot_only_above_the_torsional_limit(
    fraction: float, turns: bool
) -> None:
    """Per contact point the elliptic cone allows N_i sqrt((mu r)^2 + mu_z^2) of yaw
    moment (r = distance of the plate corner, where box-box contacts sit); the plate's limit
    is that times N (Table VII mu = 0.9, mu_z = 0.5; plate 0.10 x 0.15 m)."""
    normal = 4.0
    desc = load_robot("rdm")
    r = np.hypot(0.05, 0.075)
    limit = normal * np.hypot(desc.friction_xy * r, desc.friction_z)
    thrust = _perch_thrusts(normal)
    plant = _perch_plant(NoCeilingEffect())
    plant.reset(base_position=(0.0, 0.0, 2.0 - 5e-4), thrusts=thrust)
    plant.set_rotor_thrusts(thrust)
    plant.step(200)
    plant.apply_body_wrench("foot_plate", torque=(0.0, 0.0, fraction * limit))
    yaws = []
    for _ in range(8):
        plant.step(50)
        yaws.append(abs(plant.ground_truth().foot_slip_yaw))
    if turns:
        assert max(yaws) > 0.02
    else:
        assert max(yaws) < 1e-3
