"""PC-side read of Spinal's IMU calibration (``imu_calib`` GET_CALIB_DATA) after the handshake.

Spinal subtracts an accelerometer bias that its flash holds (jsk-wire-protocols.md sec. 3.2,
``imu_calib`` CALIB_ACC then SAVE_CALIB_DATA). An empty flash is easy to miss: in flight the
position loop hides the tilt that the bias fakes, but perched the attitude loop drives the
biased estimate to level and presses the foot plate onto an edge (docs/sim.md item 9). The
onboard node therefore asks once per handshake and keeps the answer; an all-zero accelerometer
bias is counted as ``imu_acc_uncalibrated``. Not JSK behaviour (their PC does not ask).

Sans-IO: :meth:`ImuCalibrationReader.request` says whether to call now (the node makes the
call); :meth:`ImuCalibrationReader.on_response` takes the service's answer.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass

#: spinal/ImuCalib commands
GET_CALIB_DATA = 0
#: floats per IMU in GET_CALIB_DATA's answer: gyro bias, acc bias, mag bias, mag scale
FLOATS_PER_IMU = 12


@dataclass(frozen=True)
class ImuCalibration:
    """One IMU's calibration as Spinal reports it (SI units, body frame). ``gyro_bias`` is
    the one in use when Spinal answered: zero while its start-up window still runs."""

    gyro_bias: tuple[float, float, float]
    acc_bias: tuple[float, float, float]
    mag_bias: tuple[float, float, float]
    mag_scale: tuple[float, float, float]

    @property
    def acc_calibrated(self) -> bool:
        """False for an empty flash (an accelerometer bias of exactly zero)."""
        return any(v != 0.0 for v in self.acc_bias)


class ImuCalibrationReader:
    """Asks Spinal for its IMU calibration once per handshake, retrying every ``retry_s``
    until an answer comes; keeps the first IMU's calibration."""

    def __init__(self, retry_s: float = 1.0) -> None:
        self.retry_s = retry_s
        self.calibration: ImuCalibration | None = None
        self.counts: Counter[str] = Counter()
        self._next_request: float | None = None

    def reset(self) -> None:
        """A new handshake: ask again."""
        self.calibration = None
        self._next_request = None

    def request(self, now: float) -> bool:
        """True when the node should call ``imu_calib`` GET_CALIB_DATA now."""
        if self.calibration is not None:
            return False
        if self._next_request is not None and now < self._next_request:
            return False
        self._next_request = now + self.retry_s
        self.counts["requested"] += 1
        return True

    def on_response(self, success: bool, data: Sequence[float]) -> None:
        """The service's answer: ``success`` and the float array."""
        values = [float(v) for v in data]
        if not success or len(values) < FLOATS_PER_IMU:
            self.counts["rejected"] += 1
            return
        if not all(map(math.isfinite, values[:FLOATS_PER_IMU])):
            self.counts["malformed"] += 1
            return
        v = values[:FLOATS_PER_IMU]
        self.calibration = ImuCalibration(
            (v[0], v[1], v[2]), (v[3], v[4], v[5]), (v[6], v[7], v[8]), (v[9], v[10], v[11])
        )
        self.counts["received"] += 1
        if not self.calibration.acc_calibrated:
            self.counts["imu_acc_uncalibrated"] += 1
