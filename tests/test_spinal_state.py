"""``rdm._rdm.SpinalMirrorState``: the Spinal mirror's clock, IMU sample and battery task.

Oracles: ``scipy.signal.lfilter`` for the battery low-pass (``v = 0.99 v + 0.01 sample``
from the first sample on), ``math.floor`` for the tick's ms, the firmware's 20 ms battery
period written out.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import lfilter

from rdm._rdm import SpinalMirrorState

LEVEL = ((0.0, 0.0, 0.0), (0.0, 0.0, 9.80665), (30.0, 0.0, -40.0))


def _state(volts: float = 25.2) -> SpinalMirrorState:
    return SpinalMirrorState(volts, *LEVEL)


def test_battery_low_pass_is_a_first_order_filter_every_20_ms() -> None:
    """Raw readings sampled every 20 ms go through ``y = 0.99 y + 0.01 x`` started at the first
    sample (scipy's ``lfilter`` with that initial state); a sample is due exactly 20 ms after
    the last one."""
    rng = np.random.default_rng(7)
    readings = 22.0 + 3.0 * rng.random(200)
    s = _state()
    got, sampled_at = [], []
    k = 0
    for ms in range(200 * 20):
        s.tick_begin(ms / 1000.0)
        if ms >= s.battery_due_ms:
            s.battery_input = float(readings[k])
            assert s.battery_sample(ms)
            got.append(s.battery_voltage)
            sampled_at.append(ms)
            k += 1
    assert sampled_at == list(range(0, 200 * 20, 20))
    want, _ = lfilter([0.01], [1.0, -0.99], readings, zi=[0.99 * readings[0]])
    np.testing.assert_allclose(got, want, rtol=1e-12)


def test_a_non_finite_sample_is_rejected_and_the_voltage_kept() -> None:
    s = _state(24.0)
    assert s.battery_sample(0) and s.battery_voltage == 24.0
    s.adc_scale = math.nan
    assert not s.battery_sample(20)
    assert s.battery_voltage == 24.0 and s.battery_due_ms == 40
    s.adc_scale = 0.5
    assert s.battery_sample(40)
    assert s.battery_voltage == pytest.approx(0.99 * 24.0 + 0.01 * 12.0, rel=1e-15)
    # a control step uses the low-passed voltage once there is one, else the raw reading
    assert s.step_voltage() == s.battery_voltage
    assert _state(23.5).step_voltage() == 23.5


@pytest.mark.parametrize("now", [0.0, 0.0004, 0.0009999996, 0.0015, 1.2345, 17.0009994])
def test_tick_ms_is_the_floor_with_a_microsecond_slack(now: float) -> None:
    s = _state()
    assert s.tick_begin(now) == math.floor(now * 1000.0 + 1e-6)
    assert s.now_s == now


def test_time_never_goes_back_and_a_bad_time_is_refused() -> None:
    s = _state()
    assert s.tick_begin(0.010) == 10
    assert s.tick_begin(0.004) == 10 and s.now_s == 0.010 and s.now_ms == 10
    with pytest.raises(ValueError, match="not a finite time"):
        s.tick_begin(math.nan)


def test_control_due_at_the_next_control_time_within_a_nanosecond() -> None:
    s = _state()
    assert s.control_due()  # no step yet: the first tick steps
    s.next_control = 0.005
    s.tick_begin(0.005 - 5e-10)
    assert s.control_due()
    s2 = _state()
    s2.next_control = 0.005
    s2.tick_begin(0.005 - 2e-9)
    assert not s2.control_due()


def test_imu_sample_is_three_floats_each() -> None:
    s = _state()
    assert (s.gyro, s.acc, s.mag) == LEVEL
    s.set_imu_sample(np.array([0.1, -0.2, 0.3]), [0, 0, 9], (1.5, 2.5, 3.5))
    assert s.gyro == (0.1, -0.2, 0.3) and s.acc == (0.0, 0.0, 9.0)
    assert s.mag == (1.5, 2.5, 3.5)
    with pytest.raises(ValueError, match="length 3"):
        s.set_imu_sample((1.0, 2.0), (0.0, 0.0, 9.0), (1.0, 2.0, 3.0))
