"""Thrust -> PWM conversion as Spinal's ``pwmConversion`` (``jsk-wire-protocols.md`` sec. 3.6).

:class:`PwmConverter` selects the reference curve closest to the battery voltage (every
500 ms), applies the voltage factor ((Vref/V)^2 SQRT, ^1.5 POLY), inverts the thrust curve and
clamps to ``[min_duty, max_duty]`` (``min_duty`` from ``min_thrust``, never above
``max_duty``; a non-finite duty gives ``min_duty``). A battery voltage outside the plausible
window (cells from the reference curves x 3.0..4.45 V) is rejected, counted and replaced by
the last good one (``voltage_guard=False``: firmware-exact). The encoders give the
``motor_pwms`` report (duty x 2000), the Neuron CAN value (duty x 2000 - 1000, clamped to
0..1000) and DShot.
"""

from __future__ import annotations

import numpy as np

from rdm._rdm import PwmConverter, duty_to_can, duty_to_dshot, duty_to_pwm_report

SQRT_MODE = 0
POLYNOMIAL_MODE = 1

#: Hydrus quad ``MotorInfo.yaml`` reference curve (fact sheet sec. 3.6): voltage, max
#: thrust, p0..p4 (SQRT mode uses p0..p2).
HYDRUS_MOTOR_INFO = np.array([[25.2, 20.0, 12.3593793002, -6.627443098, 0.07983707, 0.0, 0.0]])


def hydrus_converter() -> PwmConverter:
    """The Hydrus quad example: SQRT mode, duty 0.59-0.9375, min thrust 1 N."""
    return PwmConverter(0.59, 0.9375, 1.0, 6.5, SQRT_MODE, HYDRUS_MOTOR_INFO)


__all__ = [
    "HYDRUS_MOTOR_INFO",
    "POLYNOMIAL_MODE",
    "SQRT_MODE",
    "PwmConverter",
    "duty_to_can",
    "duty_to_dshot",
    "duty_to_pwm_report",
    "hydrus_converter",
]
