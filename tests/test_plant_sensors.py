"""Sensor error models: statistics, saturation, quantisation, frames and determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rdm.plant import ImuNoise, Plant, WrenchNoise
from rdm.plant.sensors import ACCEL_LSB, GYRO_LSB

G = 9.81
N = 4000


def _imu_stream(plant: Plant, n: int, steps_between: int = 0) -> tuple[np.ndarray, ...]:
    gyro, accel, mag = [], [], []
    for _ in range(n):
        if steps_between:
            plant.step(steps_between)
        r = plant.imu()
        gyro.append(r.gyro)
        accel.append(r.accel)
        mag.append(r.mag)
    return np.array(gyro), np.array(accel), np.array(mag)


def _hanging_plant(**kwargs: object) -> Plant:
    """Foot welded to the world, q1 = 90 deg: the arm hangs straight down at rest (the
    3.4 N m servos cannot hold it horizontal)."""
    plant = Plant("rdm", fixed_base=True, ceiling_height=None, **kwargs)  # type: ignore[arg-type]
    q = np.zeros(10)
    q[0] = math.pi / 2
    plant.reset(q0=q)
    return plant


def test_imu_noise_and_bias_match_the_configuration() -> None:
    noise = ImuNoise(
        gyro_std=0.004,
        accel_std=0.05,
        mag_std=0.8,
        gyro_bias=(0.01, -0.02, 0.005),
        accel_bias=(0.1, -0.05, 0.2),
        mag_bias=(2.0, 0.0, -1.0),
        quantize=False,
    )
    plant = _hanging_plant(imu_noise=noise, seed=3)
    gyro, accel, mag = _imu_stream(plant, N)
    # Hanging at rest: the root link's x axis points down, its z axis along world +x.
    truth_accel = np.array([-G, 0.0, 0.0])
    field = plant.options.magnetic_field
    truth_mag = np.array([-field[2], field[1], field[0]])
    for data, truth, bias, std in (
        (gyro, np.zeros(3), noise.gyro_bias, noise.gyro_std),
        (accel, truth_accel, noise.accel_bias, noise.accel_std),
        (mag, truth_mag, noise.mag_bias, noise.mag_std),
    ):
        se = std / math.sqrt(N)
        assert np.all(np.abs(data.mean(axis=0) - truth - np.asarray(bias)) < 5 * se)
        # Std of a sample std ~ std / sqrt(2N): 5 sigma is about 5.6 % here.
        assert np.allclose(data.std(axis=0, ddof=1), std, rtol=0.06)


def test_drawn_biases_follow_the_seed() -> None:
    a = Plant("rdm", fixed_base=True, seed=11).imu_model
    b = Plant("rdm", fixed_base=True, seed=11).imu_model
    c = Plant("rdm", fixed_base=True, seed=12).imu_model
    assert np.array_equal(a.gyro_bias, b.gyro_bias)
    assert not np.array_equal(a.gyro_bias, c.gyro_bias)
    assert np.all(np.abs(a.gyro_bias) < 5 * ImuNoise().gyro_bias_std)


def test_imu_is_in_the_root_link_frame() -> None:
    """Noise-free IMU: hanging arm reads R^T (0, 0, g) with R = Ry(90 deg); a free-falling
    tilted robot reads zero specific force; a spinning one reads its body rate."""
    plant = _hanging_plant()
    plant.step(200)  # stays at rest
    assert np.allclose(plant.imu_ideal().accel, [-G, 0.0, 0.0], atol=1e-3)
    assert np.allclose(plant.imu_ideal().gyro, 0.0, atol=1e-4)
    free = Plant("rdm", ceiling_height=None)
    angle = 0.3
    free.reset(base_quaternion=(math.cos(angle / 2), math.sin(angle / 2), 0.0, 0.0))
    free.step(1)
    assert np.allclose(free.imu_ideal().accel, 0.0, atol=1e-6)
    free.data.qvel[3:6] = [0.0, 0.0, 0.7]  # base angular velocity, foot (= root link) frame
    free.step(1)
    assert np.allclose(free.imu_ideal().gyro, [0.0, 0.0, 0.7], atol=2e-3)


def test_imu_quantisation_and_saturation() -> None:
    plant = _hanging_plant()
    r = plant.imu()
    assert np.allclose(r.gyro / GYRO_LSB, np.round(r.gyro / GYRO_LSB), atol=1e-6)
    assert np.allclose(r.accel / ACCEL_LSB, np.round(r.accel / ACCEL_LSB), atol=1e-6)
    sat = plant.imu_model.sample(np.array([50.0, 0.0, 0.0]), np.zeros(3), np.zeros(3))
    assert sat.saturated and sat.gyro[0] == pytest.approx(math.radians(2000.0), abs=GYRO_LSB)


def test_same_seed_same_streams_different_seed_different() -> None:
    def run(seed: int) -> np.ndarray:
        plant = Plant("rdm", seed=seed, ceiling_height=None)
        plant.reset(thrusts=[8.0, 8.0, 3.0, 3.0])
        plant.set_rotor_thrusts([9.0, 8.0, 3.0, 3.5])
        out = []
        for _ in range(50):
            plant.step(5)
            imu = plant.imu()
            foot = plant.wrench("foot_wrench")
            ee = plant.wrench("end_effector_wrench")
            out.append(np.concatenate([imu.gyro, imu.accel, imu.mag, foot.force, ee.torque]))
        return np.array(out)

    a, b, c = run(5), run(5), run(6)
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)
    # reset() re-seeds: a reset plant repeats a fresh one.
    plant = Plant("rdm", seed=5, ceiling_height=None)
    first = [plant.imu().gyro for _ in range(3)]
    plant.step(10)
    plant.reset()
    assert np.array_equal(np.array(first), np.array([plant.imu().gyro for _ in range(3)]))


def test_end_effector_sensor_reads_the_push_saturates_and_flags() -> None:
    """An external push F on the tool: the sensor (what the robot applies through it) reads
    -F in its frame; above the CFS018CA201 rating (100 N) it clips and flags."""
    plant = Plant("rdm", fixed_base=True, ceiling_height=None)
    plant.model.opt.gravity[:] = 0.0
    push = np.array([-30.0, 5.0, 2.0])
    plant.apply_body_wrench("end_effector", force=push)
    plant.step(1)
    force, torque = plant.wrench_ideal("end_effector_wrench")
    rot = plant.data.xmat[plant.model.body("end_effector").id].reshape(3, 3)
    assert np.allclose(force, -rot.T @ push, atol=1e-6)
    assert np.allclose(torque, 0.0, atol=1e-6)
    reading = plant.wrench("end_effector_wrench")
    assert not reading.any_saturated
    plant.apply_body_wrench("end_effector", force=(-150.0, 0.0, 0.0))
    plant.step(1)
    reading = plant.wrench("end_effector_wrench")
    assert reading.force[0] == 100.0 and reading.saturated[0] and reading.any_saturated
    assert not reading.saturated[1:].any()


def test_wrench_noise_statistics() -> None:
    noise = WrenchNoise(noise_fraction_of_rated=0.004, bias=(1.0, 0, 0, 0, 0, 0.05), quantize=False)
    plant = Plant("rdm", fixed_base=True, ceiling_height=None, wrench_noise=noise, seed=2)
    plant.model.opt.gravity[:] = 0.0
    plant.step(1)
    samples = np.array(
        [np.concatenate([(r := plant.wrench("foot_wrench")).force, r.torque]) for _ in range(N)]
    )
    rated = np.array([150.0, 150.0, 300.0, 4.0, 4.0, 4.0])  # CFS034CA301U (paper Sec. VI-B)
    std = 0.004 * rated
    assert np.all(np.abs(samples.mean(axis=0) - np.asarray(noise.bias)) < 5 * std / math.sqrt(N))
    assert np.allclose(samples.std(axis=0, ddof=1), std, rtol=0.06)
