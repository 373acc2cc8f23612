"""The onboard node's reader of Spinal's IMU calibration (sans-IO): when it asks, what it
keeps, what it refuses."""

from __future__ import annotations

import math

import pytest

from rdm.nodes.onboard_calibration import FLOATS_PER_IMU, ImuCalibrationReader

GOOD = [0.001, -0.002, 0.003, 0.05, -0.13, -0.05, 1.0, 2.0, 3.0, 1.0, 1.1, 0.9]


def test_asks_once_then_every_retry_until_answered_and_again_after_a_reset() -> None:
    r = ImuCalibrationReader(retry_s=1.0)
    assert r.request(0.0)
    assert not r.request(0.5)  # the call is out
    assert r.request(1.0)  # no answer within the retry: ask again
    r.on_response(True, GOOD)
    assert not r.request(5.0)  # answered: never again
    r.reset()  # a new handshake
    assert r.calibration is None and r.request(5.0)
    assert r.counts["requested"] == 3


def test_keeps_the_first_imu_in_the_wire_order() -> None:
    r = ImuCalibrationReader()
    r.on_response(True, [*GOOD, *([9.0] * FLOATS_PER_IMU)])  # a second IMU is ignored
    c = r.calibration
    assert c is not None
    assert c.gyro_bias == (0.001, -0.002, 0.003)
    assert c.acc_bias == (0.05, -0.13, -0.05)
    assert c.mag_bias == (1.0, 2.0, 3.0)
    assert c.mag_scale == (1.0, 1.1, 0.9)
    assert c.acc_calibrated and r.counts["received"] == 1


def test_an_empty_accelerometer_calibration_is_counted() -> None:
    r = ImuCalibrationReader()
    r.on_response(True, [0.001] * 3 + [0.0] * 3 + [0.0] * 3 + [1.0] * 3)
    assert r.calibration is not None and not r.calibration.acc_calibrated
    assert r.counts["imu_acc_uncalibrated"] == 1


@pytest.mark.parametrize(
    ("success", "data", "counter"),
    [
        (False, GOOD, "rejected"),  # the firmware refused
        (True, GOOD[:11], "rejected"),  # too short
        (True, [], "rejected"),
        (True, [*GOOD[:3], math.nan, *GOOD[4:]], "malformed"),
        (True, [*GOOD[:5], math.inf, *GOOD[6:]], "malformed"),
    ],
)
def test_bad_answers_are_counted_and_not_kept(success, data, counter) -> None:
    r = ImuCalibrationReader()
    assert r.request(0.0)
    r.on_response(success, data)
    assert r.calibration is None
    assert r.counts[counter] == 1
    assert r.request(1.0)  # it asks again
