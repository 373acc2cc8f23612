"""Thrust -> PWM conversion against independent formulas (numpy.roots, numpy.polyval) over a
sweep of thrusts and voltages, with the Hydrus example of jsk-wire-protocols.md sec. 3.6."""

from __future__ import annotations

import numpy as np
import pytest

from rdm._rdm import RdmError
from rdm.pwm import (
    HYDRUS_MOTOR_INFO,
    POLYNOMIAL_MODE,
    SQRT_MODE,
    PwmConverter,
    duty_to_can,
    duty_to_dshot,
    duty_to_pwm_report,
    hydrus_converter,
)

P2, P1, P0 = 0.07983707, -6.627443098, 12.3593793002


def sqrt_duty(f: float) -> float:
    """Larger root of 0.1 p2 x^2 + 0.1 p1 x + (p0 - f) = 0, x in %, as duty."""
    f = max(f, 0.0)
    return float(np.max(np.roots([0.1 * P2, 0.1 * P1, P0 - f]).real)) / 100.0


@pytest.mark.parametrize("voltage", [21.0, 22.5, 24.0, 25.2, 26.1])
def test_sqrt_mode_sweep(voltage: float) -> None:
    conv = hydrus_converter()
    assert conv.update_voltage(voltage, 1.0)
    vf = (25.2 / voltage) ** 2
    assert conv.voltage_factor == pytest.approx(vf, rel=1e-15)
    assert conv.thrust_limit == pytest.approx(20.0 / vf, rel=1e-15)
    min_duty = sqrt_duty(vf * 1.0)
    assert conv.min_duty == pytest.approx(min_duty, abs=1e-12)
    thrust = np.linspace(-2.0, 25.0, 271)
    raw = conv.raw_duty(thrust)
    expected = np.array([sqrt_duty(vf * f) for f in thrust])
    np.testing.assert_allclose(raw, expected, rtol=0, atol=1e-12)
    # round trip: f(x) gives back the (voltage-scaled) thrust where it is not clipped at 0
    x = raw * 100.0
    f_back = 0.1 * P2 * x**2 + 0.1 * P1 * x + P0
    pos = thrust > 0
    np.testing.assert_allclose(f_back[pos], vf * thrust[pos], rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(conv.duty(thrust), np.clip(expected, min_duty, 0.9375), atol=1e-12)


def test_reference_selection_every_500_ms() -> None:
    curves = np.array(
        [
            [25.2, 20.0, P0, P1, P2, 0, 0],
            [24.2, 19.0, P0 + 0.3, P1, P2, 0, 0],
            [23.2, 18.0, P0 + 0.6, P1, P2, 0, 0],
            [22.2, 17.0, P0 + 0.9, P1, P2, 0, 0],
        ]
    )
    conv = PwmConverter(0.55, 0.92, 0.0, 6.5, SQRT_MODE, curves)
    assert conv.update_voltage(23.4, 0.0)
    assert conv.reference_index == 2
    assert conv.voltage_factor == pytest.approx((23.2 / 23.4) ** 2)
    assert conv.min_duty == 0.55  # min_thrust 0: min_pwm stays
    assert not conv.update_voltage(24.3, 0.5)  # not more than 500 ms later
    assert conv.reference_index == 2
    assert conv.update_voltage(24.3, 0.5001)
    assert conv.reference_index == 1
    assert not conv.update_voltage(np.nan, 2.0)
    assert conv.rejected_voltages == 1 and conv.reference_index == 1


def test_polynomial_mode_against_polyval() -> None:
    coeffs = [50.0, 12.0, -1.5, 0.2, -0.01]  # pwm% = sum p_j (f/10)^j
    curves = np.array([[25.2, 30.0, *coeffs], [22.2, 26.0, *[c * 1.05 for c in coeffs]]])
    conv = PwmConverter(0.55, 0.92, 2.0, 13.0, POLYNOMIAL_MODE, curves)
    for voltage in (22.0, 23.5, 25.0):
        conv.force_voltage(voltage)
        idx = int(np.argmin(np.abs(curves[:, 0] - voltage)))
        assert conv.reference_index == idx
        vf = (curves[idx, 0] / voltage) ** 1.5
        assert conv.voltage_factor == pytest.approx(vf, rel=1e-14)
        thrust = np.linspace(0.0, 30.0, 61)
        expected = np.polyval(curves[idx, 2:][::-1], vf * thrust / 10.0) / 100.0
        np.testing.assert_allclose(conv.raw_duty(thrust), expected, rtol=1e-13, atol=1e-13)
        min_duty = np.polyval(curves[idx, 2:][::-1], vf * 2.0 / 10.0) / 100.0
        assert conv.min_duty == pytest.approx(min_duty, rel=1e-13)


def test_rotor_divider_halves_thrust() -> None:
    conv = hydrus_converter()
    conv.force_voltage(25.2)
    full = conv.raw_duty(np.array([8.0]))
    conv.set_rotor_divider(2.0)
    conv.force_voltage(25.2)
    np.testing.assert_allclose(conv.raw_duty(np.array([16.0])), full, atol=1e-15)


def test_duty_encodings() -> None:
    duty = np.linspace(0.4, 1.1, 701)
    np.testing.assert_array_equal(duty_to_pwm_report(duty), np.trunc(duty * 2000).astype(np.uint16))
    # Neuron CAN value pulse - 1000 us, clamped to the slot's valid 0..1000 (sec. 2.4).
    can = np.clip(np.trunc(duty * 2000 - 1000), 0, 1000).astype(np.uint16)
    np.testing.assert_array_equal(duty_to_can(duty), can)
    dshot = np.clip(np.trunc(np.clip((duty - 0.5) / 0.5 * 1999 + 48, 0, None)), 48, 2047)
    np.testing.assert_array_equal(duty_to_dshot(duty), dshot.astype(np.uint16))
    assert duty_to_pwm_report(np.array([0.59]))[0] == 1180  # fact sheet: min_pwm 0.59 = 1180 us


def test_bad_pwm_info_is_rejected() -> None:
    with pytest.raises(RdmError, match="mode"):
        PwmConverter(0.55, 0.92, 0.0, 6.5, 7, HYDRUS_MOTOR_INFO)
    with pytest.raises(RdmError, match="voltage"):
        PwmConverter(0.55, 0.92, 0.0, 6.5, SQRT_MODE, np.array([[0.0, 20.0, 1, 1, 1, 0, 0]]))
    with pytest.raises(RdmError, match="polynomial"):
        PwmConverter(0.55, 0.92, 0.0, 6.5, SQRT_MODE, np.array([[25.0, 20.0, np.nan, 1, 1, 0, 0]]))
    with pytest.raises(RdmError, match="shape"):
        PwmConverter(0.55, 0.92, 0.0, 6.5, SQRT_MODE, np.zeros((1, 5)))
