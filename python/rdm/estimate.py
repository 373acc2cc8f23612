"""Attitude estimation as the Spinal flight controller runs it.

:class:`AttitudeEstimator` is the firmware's complementary filter on the gravity and magnetic
vectors (``jsk-wire-protocols.md`` sec. 3.2-3.3): gyro bias calibration at start, first-order
IIR filters (factors 12 and 42), accelerometer correction ``g = (600 g + a)/601`` on every
third valid sample (72 < |a|^2 < 133), magnetic correction with factor 250 and outlier
rejection, attitude rows (x_b, y_b, z_b). Outputs: rotation (body -> world), quaternion
x-y-z-w, Euler angles (ArduPilot ZYX), filtered body rate. By default it adds guards the
firmware lacks: samples outside the sensor's range (gyro +-2000 dps, acc +-8 g) are rejected,
the filter vectors stay bounded and are re-initialised after a gross disagreement with a
valid accelerometer, and the status says "degraded" while the gravity estimate is more than
20 deg off; ``firmware_exact=True`` drops them. See ``docs/spinal.md``.

Example::

    est = AttitudeEstimator(rate_hz=200.0)
    status = est.step(gyro, acc, mag)  # one of ESTIMATE_STATUSES
    roll, pitch, yaw = est.euler
"""

from __future__ import annotations

from rdm._rdm import AttitudeEstimator

#: Status names returned by :meth:`AttitudeEstimator.step`.
ESTIMATE_STATUSES = ("ok", "calibrating", "attitude_undefined", "degraded", "invalid_input")

#: Firmware loop rate (``DELTA_T = 0.001``); the mirror runs 200 Hz by default.
FIRMWARE_RATE_HZ = 1000.0

__all__ = ["ESTIMATE_STATUSES", "FIRMWARE_RATE_HZ", "AttitudeEstimator"]
