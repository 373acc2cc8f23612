"""Faults of the ``mission`` scenario outside the wires: IMU outliers, a dead rotor, a
perching QP made infeasible.

:class:`SpikingImu` replaces the plant's ``imu`` reading (the bridge then samples the IMU in
Python, not in the lockstep kernel); :class:`DeadRotor` is a ceiling-effect model whose
thrust ratio is 0 (the plant then applies rotor thrusts in Python);
:func:`infeasible_perch_qp` gives the node's perching QP a friction limit the contact cannot
satisfy.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from rdm.control.perch import PerchController
from rdm.plant.ceiling import CeilingEffect
from rdm.plant.sensors import ImuReading

#: Probability that one IMU sample is an outlier: at the bridge's 200 Hz IMU rate about three
#: a second. ASSUMPTION: a corrupted sensor read (bus glitch), one sample at a time.
SPIKE_PROBABILITY = 0.015
#: The outlier values: one gyro axis at +-100 rad/s and one accelerometer axis at +-500 m/s^2,
#: both beyond the ICM-20948 ranges Spinal's estimator accepts (34.9 rad/s, 78.5 m/s^2;
#: docs/spinal.md "Estimator guards"). In-range (full-scale) outliers are not injected.
SPIKE_GYRO = 100.0
SPIKE_ACC = 500.0


class SpikingImu:
    """The plant's ``imu()`` with seeded outliers; ``spikes`` counts the samples changed."""

    def __init__(self, imu: Callable[[], ImuReading], seed: int) -> None:
        self._imu = imu
        self._rng = np.random.default_rng([seed, 0x5B1])
        self.spikes = 0

    def __call__(self) -> ImuReading:
        r = self._imu()
        u = self._rng.random(5)
        if u[0] >= SPIKE_PROBABILITY:
            return r
        self.spikes += 1
        gyro = np.array(r.gyro, dtype=float)
        acc = np.array(r.accel, dtype=float)
        gyro[int(u[1] * 3)] = SPIKE_GYRO if u[2] < 0.5 else -SPIKE_GYRO
        acc[int(u[3] * 3)] = SPIKE_ACC if u[4] < 0.5 else -SPIKE_ACC
        return ImuReading(gyro, acc, np.array(r.mag, dtype=float), r.saturated)


class DeadRotor:
    """A rotor whose ESC stopped: thrust ratio 0 at every distance to the ceiling."""

    def __init__(self, effect: CeilingEffect) -> None:
        self.effect = effect

    def thrust_ratio(self, distance_to_ceiling: float) -> float:
        """Always 0: the rotor gives no thrust."""
        return 0.0


def infeasible_perch_qp(control: Any, mu: float) -> None:
    """Replace the perching controller of ``control`` (:class:`rdm.nodes.onboard_control.
    ControlPipeline`) by one whose friction coefficients are ``mu`` on both axes, every other
    parameter kept, started from the thrust it commands now. With ``mu`` below the ratio of
    the contact's tangential to normal force, eq. (49)'s friction rows (eq. 40) have no
    solution: every tick is ``infeasible`` and gives the safe command (docs/perch.md)."""
    old = control.perch
    params = dict(old.params())
    params.update(mu_x=float(mu), mu_y=float(mu))
    rate, cutoff = control.config.rate_hz, control.config.perch_cutoff_hz
    new = PerchController(rate, cutoff, **params)
    new.reset(np.asarray(control.perch_thrust, dtype=float))
    control.perch = new
