"""Spinal's flash accelerometer calibration in the simulated stack (``StackOptions.
imu_acc_calibrated``): the stored bias is the simulated IMU's own, and with it the estimator
reads the resting robot level; without it, the tilt that the bias fakes (closed form)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from rdm.nodes.onboard_calibration import ImuCalibration
from rdm.plant import Plant
from rdm.plant.sensors import imu_model_of_seed
from rdm.scenarios.common import roll_pitch, sim_stack_options
from rdm.scenarios.stack import build_stack, spinal_flash_calibration

G = 9.80665
SEED = 1  # accelerometer bias (0.055, -0.134, -0.055) m/s^2: 0.8 deg of roll if uncalibrated


@pytest.mark.parametrize("seed", [0, 1, 7])
def test_imu_model_of_seed_draws_the_plants_biases(seed: int) -> None:
    plant = Plant("rdm", seed=seed)
    model = imu_model_of_seed(seed)
    for name in ("gyro_bias", "accel_bias", "mag_bias"):
        np.testing.assert_array_equal(getattr(model, name), getattr(plant.imu_model, name))


def test_flash_calibration_follows_the_option() -> None:
    on = sim_stack_options(SEED, "inproc", log=False)
    assert on.imu_acc_calibrated
    bias = imu_model_of_seed(SEED).accel_bias
    assert spinal_flash_calibration(on) == {"acc_bias": bias.tolist()}
    off = sim_stack_options(SEED, "inproc", log=False, imu_acc_calibrated=False)
    assert spinal_flash_calibration(off) == {}


@dataclass
class RestingRun:
    """2 s of the stack on the floor (never armed): Spinal's estimated and the true
    roll/pitch [deg], the plant's accelerometer bias, what the onboard node read from
    ``imu_calib`` GET_CALIB_DATA and its counters."""

    estimate: np.ndarray
    truth: np.ndarray
    bias: np.ndarray
    read: ImuCalibration | None
    counts: dict


def _resting_run(tmp_path, calibrated: bool) -> RestingRun:
    opt = sim_stack_options(SEED, "inproc", log=False, imu_acc_calibrated=calibrated)
    stack = build_stack("flash", tmp_path, opt)
    try:
        stack.loop.run_until(2.0)
        euler = np.degrees(np.asarray(stack.spinal.last_output.euler, dtype=float))
        truth = np.degrees(roll_pitch(stack.plant.ground_truth().base_quaternion[None, :])[0])
        bias = np.asarray(stack.plant.imu_model.accel_bias, dtype=float)
        reader = stack.onboard.imu_calibration
        return RestingRun(euler[:2], truth, bias, reader.calibration, dict(reader.counts))
    finally:
        stack.close()


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory) -> RestingRun:
    return _resting_run(tmp_path_factory.mktemp("on"), calibrated=True)


@pytest.fixture(scope="module")
def uncalibrated(tmp_path_factory) -> RestingRun:
    return _resting_run(tmp_path_factory.mktemp("off"), calibrated=False)


def test_calibrated_estimator_reads_the_resting_robot_level(calibrated) -> None:
    assert np.all(np.abs(calibrated.truth) < 1e-3)  # the robot rests level on the floor
    assert np.all(np.abs(calibrated.estimate - calibrated.truth) < 0.05), calibrated.estimate


def test_uncalibrated_estimator_reads_the_tilt_the_bias_fakes(uncalibrated) -> None:
    """Gravity plus the bias, read as a tilt: roll = atan2(a_y, a_z), pitch =
    atan2(-a_x, hypot(a_y, a_z)) of a = (b_x, b_y, g + b_z)."""
    b = uncalibrated.bias
    a = np.array([b[0], b[1], G + b[2]])
    roll = math.degrees(math.atan2(a[1], a[2]))
    pitch = math.degrees(math.atan2(-a[0], math.hypot(a[1], a[2])))
    assert abs(roll) > 0.5  # the seed's bias is a visible tilt
    np.testing.assert_allclose(uncalibrated.estimate, [roll, pitch], atol=0.05)


def test_onboard_reads_the_flash_calibration_over_the_wire(calibrated, uncalibrated) -> None:
    """``imu_calib`` GET_CALIB_DATA through rosserial: the accelerometer bias arrives as the
    float32 of the plant's; an empty flash arrives as zeros and is counted."""
    got = calibrated.read
    assert got is not None and got.acc_calibrated
    want = np.asarray(calibrated.bias, dtype=np.float32).astype(float)
    np.testing.assert_array_equal(got.acc_bias, want)
    assert got.mag_scale == (1.0, 1.0, 1.0) and got.mag_bias == (0.0, 0.0, 0.0)
    assert calibrated.counts.get("imu_acc_uncalibrated", 0) == 0
    empty = uncalibrated.read
    assert empty is not None and empty.acc_bias == (0.0, 0.0, 0.0)
    assert uncalibrated.counts["imu_acc_uncalibrated"] == 1
