"""The estimator's guards (docs/spinal.md "Estimator guards") on synthetic rotations whose
true attitude is scipy's Rotation: out-of-range samples are rejected, the filter recovers
from a gyro spike and from a 5 s spin at the wire's full scale, and the status says
"degraded" while the estimate is far off."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rdm.estimate import AttitudeEstimator

RATE = 200.0
DT = 1.0 / RATE
G = 9.80665
MAG_WORLD = np.array([20.0, 3.0, -40.0])  # uT, a mid-latitude field
FULL_SCALE = np.deg2rad(2000.0)  # +-2000 dps = 34.9 rad/s (jsk-wire-protocols.md sec. 3.2)
SPIN = 34.9  # rad/s, just inside the full scale


def imu_of(truth: Rotation, omega_body: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ideal samples of body->world rotations ``truth`` (n) turning at ``omega_body`` (n, 3):
    specific force R^T (0, 0, g) (+g up at rest) and field R^T m_world."""
    inv = truth.inv()
    acc = inv.apply(np.array([0.0, 0.0, G]))
    mag = inv.apply(MAG_WORLD)
    return np.asarray(omega_body, float), acc, mag


def tilt_error_deg(rotations: np.ndarray, truth: Rotation) -> np.ndarray:
    """Angle between the estimated and the true world-up direction in the body frame. The
    estimate's third row is world z in body coordinates; the truth's is R^T e_z."""
    est_up = rotations[:, 2, :]
    true_up = truth.inv().apply(np.array([0.0, 0.0, 1.0]))
    cos = np.clip(np.einsum("ij,ij->i", est_up, true_up), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def still(n: int, attitude: Rotation | None = None):
    truth = Rotation.identity(n) if attitude is None else Rotation.concatenate([attitude] * n)
    return (*imu_of(truth, np.zeros((n, 3))), truth)


def spin_then_still(est: AttitudeEstimator, before_s: float, spin_s: float, after_s: float):
    """Still, then spinning about body x at SPIN rad/s, then still at the final attitude.
    Returns the estimator's outputs over the whole run, the truth and the spin's end index."""
    n0, n1, n2 = round(before_s * RATE), round(spin_s * RATE), round(after_s * RATE)
    t = np.arange(1, n1 + 1) * DT
    spinning = Rotation.from_rotvec(np.outer(SPIN * t, [1.0, 0.0, 0.0]))
    end = spinning[-1]
    parts = [
        still(n0),
        (*imu_of(spinning, np.tile([SPIN, 0.0, 0.0], (n1, 1))), spinning),
        still(n2, end),
    ]
    gyro = np.vstack([p[0] for p in parts])
    acc = np.vstack([p[1] for p in parts])
    mag = np.vstack([p[2] for p in parts])
    truth = Rotation.concatenate([p[3] for p in parts])
    return est.run(gyro, acc, mag), truth, n0 + n1


def test_a_gyro_spike_beyond_full_scale_is_rejected_and_leaves_no_trace() -> None:
    """One finite sample of 1e8 rad/s: the firmware's filter overflows to NaN and stays
    `attitude_undefined` for good. Guarded, the sample is rejected (recovery time 0): the
    estimate equals, bit for bit, that of a run which never saw it."""
    gyro, acc, mag, _truth = still(2000)
    spiked = AttitudeEstimator(RATE, gyro_calib_duration_s=0.0)
    clean = AttitudeEstimator(RATE, gyro_calib_duration_s=0.0)
    spiked.run(gyro[:1000], acc[:1000], mag[:1000])
    clean.run(gyro[:1000], acc[:1000], mag[:1000])
    assert spiked.step([1e8, 0.0, 0.0], acc[0], mag[0]) == "invalid_input"
    after = spiked.run(gyro[1000:], acc[1000:], mag[1000:])
    reference = clean.run(gyro[1000:], acc[1000:], mag[1000:])
    assert set(after["status"]) == {"ok"}
    np.testing.assert_array_equal(after["rotation"], reference["rotation"])
    assert spiked.counters["out_of_range"] == 1


@pytest.mark.parametrize(
    ("gyro", "acc", "accepted"),
    [
        ([-32768 * (2000 / 32767) * np.pi / 180, 0.0, 0.0], [0.0, 0.0, G], True),  # int16 min
        ([34.95, 0.0, 0.0], [0.0, 0.0, G], False),
        ([0.0, 0.0, 0.0], [0.0, -32768 * G / 4096, 0.0], True),  # sec. 2.4: x 9.80665/4096
        ([0.0, 0.0, 0.0], [0.0, 0.0, 8.01 * G], False),
    ],
)
def test_range_edges(gyro, acc, accepted: bool) -> None:
    est = AttitudeEstimator(RATE, gyro_calib_duration_s=0.0)
    status = est.step(gyro, acc, MAG_WORLD)
    assert (status != "invalid_input") is accepted
    assert est.counters["out_of_range"] == (0 if accepted else 1)


def test_a_spike_inside_a_raised_range_is_survived_within_the_stated_bound() -> None:
    """With the range raised to 1e9 rad/s the 1e8 rad/s sample enters the filter: the
    filtered rate (1e8/12, decaying by 11/12 a sample) whirls the vectors for about 1.2 s.
    Bound: the vectors stay finite (scaled back when too long), and the tilt error is below
    2 deg within 30 s of the spike (the gyro's decay, then at worst a direction just under
    the 60 deg re-initialisation threshold converging at the firmware's 9 s time constant:
    below 2 deg after 29 s), with status "ok" from then on."""
    gyro, acc, mag, truth = still(12000)
    est = AttitudeEstimator(RATE, gyro_calib_duration_s=0.0, gyro_range=1e9)
    est.run(gyro[:2000], acc[:2000], mag[:2000])
    gyro = gyro.copy()
    gyro[2000] = [1e8, 0.0, 0.0]
    out = est.run(gyro[2000:], acc[2000:], mag[2000:])
    assert np.all(np.isfinite(out["rotation"]))
    error = tilt_error_deg(out["rotation"], truth[2000:])
    status = np.array(out["status"])
    assert error.max() > 20.0  # the spike did reach the filter
    bound = round(30.0 * RATE)
    assert error[bound:].max() < 2.0
    assert set(status[bound:]) == {"ok"}
    assert est.counters["rescaled_vectors"] > 0


def test_a_full_scale_spin_reports_degraded_while_the_error_is_large_and_converges() -> None:
    """5 s at 34.9 rad/s about body x (inside the +-2000 dps range), then still. The
    firmware's first-order rotation loses about theta - atan(theta) = 1.8 mrad a step at
    theta = 0.17 rad; the gravity vector grows by e^15. Guarded: "degraded" whenever the
    tilt error exceeds 25 deg after the spin starts, and below 2 deg within 3 s of the spin's
    end (the accelerometer filter settles, then 0.5 s of a > 60 deg disagreement re-initialises
    the gravity vector), "ok" from then on."""
    est = AttitudeEstimator(RATE, gyro_calib_duration_s=0.0)
    out, truth, spin_end = spin_then_still(est, 10.0, 5.0, 20.0)
    error = tilt_error_deg(out["rotation"], truth)
    status = np.array(out["status"])
    spin_start = round(10.0 * RATE)
    assert error[spin_start - 1] < 1.0
    large = error[spin_start:] > 25.0
    assert large.any()
    assert set(status[spin_start:][large]) <= {"degraded"}
    settled = spin_end + round(3.0 * RATE)
    assert error[settled:].max() < 2.0
    assert set(status[settled:]) == {"ok"}
    assert est.counters["reinitialisations"] >= 1
    assert est.counters["degraded_steps"] > 0


def test_firmware_exact_keeps_the_poisoned_filter_for_bit_exact_comparison() -> None:
    """The firmware-exact option has none of the guards: the same spin leaves a tilt error
    above 90 deg 20 s later with the status "ok"; a 1e8 rad/s sample leaves it undefined."""
    est = AttitudeEstimator(RATE, gyro_calib_duration_s=0.0, firmware_exact=True)
    out, truth, _spin_end = spin_then_still(est, 10.0, 5.0, 20.0)
    error = tilt_error_deg(out["rotation"], truth)
    assert error[-1] > 90.0 and out["status"][-1] == "ok"
    assert est.config["firmware_exact"] and est.config["gyro_range"] is None

    gyro, acc, mag, _truth = still(4000)
    poisoned = AttitudeEstimator(RATE, gyro_calib_duration_s=0.0, firmware_exact=True)
    poisoned.run(gyro[:2000], acc[:2000], mag[:2000])
    poisoned.step([1e8, 0.0, 0.0], acc[0], mag[0])
    status = poisoned.run(gyro[2000:], acc[2000:], mag[2000:])["status"]
    assert set(status[1000:]) == {"attitude_undefined"}  # the vectors overflowed to NaN


def test_guard_parameters_are_checked_and_named() -> None:
    with pytest.raises(Exception, match="gyro_range"):
        AttitudeEstimator(RATE, gyro_range=0.0)
    with pytest.raises(Exception, match="reinit_angle_rad"):
        AttitudeEstimator(RATE, degraded_angle_rad=1.0, reinit_angle_rad=0.5)
    with pytest.raises(Exception, match="firmware_exact"):
        AttitudeEstimator(RATE, firmware_exact=True, acc_range=50.0)
    cfg = AttitudeEstimator(RATE).config
    assert cfg["gyro_range"] == pytest.approx(FULL_SCALE, rel=1e-4)
    assert cfg["acc_range"] == pytest.approx(8 * G, rel=1e-4)
    assert not cfg["firmware_exact"]
