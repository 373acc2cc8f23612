"""ESC model: the inverse of the firmware's SQRT-mode thrust -> duty conversion, plus lag."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import curve_fit

from rdm.plant import Esc, EscParams, NoCeilingEffect, Plant

# Hydrus quad MotorInfo.yaml, 25.2 V reference (jsk-wire-protocols.md sec. 3.6).
P2, P1, P0, VREF = 0.07983707, -6.627443098, 12.3593793002, 25.2


def firmware_duty(thrust: float, voltage: float) -> float:
    """Firmware forward map, re-derived: the larger root x of
    0.1 p2 x^2 + 0.1 p1 x + p0 = (Vref/V)^2 f, duty = x / 100."""
    roots = np.roots([0.1 * P2, 0.1 * P1, P0 - (VREF / voltage) ** 2 * thrust])
    return float(np.max(roots.real)) / 100.0


@pytest.mark.parametrize("voltage", [25.2, 23.0, 22.2])
@pytest.mark.parametrize("duty", [0.59, 0.65, 0.72, 0.8, 0.88, 0.93])
def test_steady_thrust_is_the_inverse_of_the_firmware(duty: float, voltage: float) -> None:
    params = EscParams(thrust_max=1e3)  # no motor saturation in this comparison
    thrust = params.steady_thrust(duty, voltage)
    assert thrust > 0
    assert firmware_duty(thrust, voltage) == pytest.approx(duty, abs=1e-12)


@pytest.mark.parametrize("thrust", [1.0, 5.0, 10.0, 19.5])
def test_duty_for_thrust_matches_the_firmware(thrust: float) -> None:
    assert EscParams().duty_for_thrust(thrust, 24.0) == pytest.approx(firmware_duty(thrust, 24.0))


def test_hydrus_table_end_points() -> None:
    """min_pwm 0.59 gives about the 1 N minimum, max_pwm 0.9375 about 20 N (MotorInfo.yaml)."""
    params = EscParams(thrust_max=1e3)
    assert params.steady_thrust(0.59, VREF) == pytest.approx(1.0, abs=0.1)
    assert params.steady_thrust(0.9375, VREF) == pytest.approx(20.0, abs=0.5)


def test_idle_duty_stops_and_saturation_and_nan() -> None:
    esc = Esc()
    esc.command_duty(0.5)
    assert esc.target_thrust == 0.0
    esc.command_duty(0.3)
    assert esc.duty == 0.5 and esc.target_thrust == 0.0
    esc.command_duty(1.0)
    assert esc.target_thrust == 20.0  # the motor's 20 N ceiling (Sec. VI-B)
    esc.command_thrust(math.nan)
    esc.command_duty(math.inf)
    assert esc.rejected == 2 and esc.target_thrust == 0.0


def test_lag_has_the_chosen_time_constant() -> None:
    tau = 0.05
    esc = Esc(EscParams(tau=tau))
    esc.command_thrust(12.0)
    dt = 0.001
    t = np.arange(1, 301) * dt
    y = np.array([esc.update(dt) for _ in t])

    def model(tt: np.ndarray, k: float, tc: float) -> np.ndarray:
        return k * (1.0 - np.exp(-tt / tc))

    (k, tc), _ = curve_fit(model, t, y, p0=(10.0, 0.1))
    assert k == pytest.approx(12.0, rel=1e-6)
    assert tc == pytest.approx(tau, rel=1e-6)


def test_plant_rotor_force_follows_the_duty_through_the_lag() -> None:
    """Duty 0.75 at 24 V: the applied rotor force settles at the firmware inverse value."""
    plant = Plant("rdm", ceiling_height=None, ceiling_effect=NoCeilingEffect())
    plant.set_battery_voltage(24.0)
    duty = 0.75
    plant.set_rotor_duties([duty] * 4)
    plant.step(50)  # one time constant
    steady = EscParams(thrust_max=20.0).steady_thrust(duty, 24.0)
    assert firmware_duty(steady, 24.0) == pytest.approx(duty)
    rotor_force = plant.data.actuator_force[plant._rotor_act]
    assert np.allclose(rotor_force, steady * (1 - math.exp(-1.0)), rtol=0.01)
    plant.step(500)
    assert np.allclose(plant.data.actuator_force[plant._rotor_act], steady, rtol=1e-4)
