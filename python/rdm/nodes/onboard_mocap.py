"""The CoG state from motion capture: what a motion-capture system gives (the time-stamped pose
of a marker rigid body fixed to the root link, no velocity) turned into the CoG position,
velocity and yaw the position controller needs.

* Root link pose: ``R_root = R_marker R_off^T``, ``p_root = p_marker - R_root p_off``, with the
  marker's pose ``(p_off, R_off)`` in the root link frame from :class:`MocapConfig`.
* CoG: ``p_cog = p_root + R_root c(q)``, ``c(q)`` the CoG in the root link frame from the
  model's kinematics at the measured joint angles (``Robot.evaluate(q)["cog"]``).
* Position and velocity: a constant-velocity Kalman filter per axis on the CoG positions at
  their stamps (measurement noise ``position_noise_m``, white acceleration
  ``acceleration_sigma``). JSK's mocap plugin differentiates and low-passes at 20 Hz
  (``jsk-flight-navigation.md`` sec. 9); with 0.3 mm / 1 mrad of marker noise and 10 ms of
  latency that let the simulated robot's lightly damped x/pitch loop (Table V's gains)
  diverge in ``rdm sim mission``, and the filter here holds it. A gap longer than
  ``max_gap_s`` (or a stamp that goes back) restarts the filter at the measured position with
  zero velocity; samples with the same stamp are fused without a prediction.
* Yaw: the root link's ZYX yaw (the frame the controller's yaw refers to).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class MocapConfig:
    """Where the marker body sits and how the velocity is filtered (ASSUMPTIONS)."""

    #: Marker body origin in the root link frame, m.
    marker_position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: Marker body orientation in the root link frame, quaternion x, y, z, w.
    marker_quaternion: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    #: Measurement noise of the CoG from one pose (marker noise and its rotation's lever), m.
    position_noise_m: float = 0.0007
    #: White acceleration driving the constant-velocity model, m/s^2.
    acceleration_sigma: float = 3.0
    #: Velocity uncertainty at a (re)start, m/s.
    velocity_sigma: float = 0.5
    max_gap_s: float = 0.1

    def __post_init__(self) -> None:
        if len(self.marker_position) != 3 or not all(map(math.isfinite, self.marker_position)):
            raise ValueError("MocapConfig.marker_position needs 3 finite values")
        q = self.marker_quaternion
        if len(q) != 4 or not all(map(math.isfinite, q)) or abs(math.hypot(*q) - 1.0) > 1e-6:
            raise ValueError("MocapConfig.marker_quaternion must be a unit quaternion x,y,z,w")
        for name in ("position_noise_m", "acceleration_sigma", "velocity_sigma", "max_gap_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"MocapConfig.{name}={v!r} must be finite and > 0")


def rotation_of(q: Any) -> np.ndarray:
    """The rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = (float(v) for v in q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


class CogEstimator:
    """Marker poses in, CoG state out (see the module doc)."""

    def __init__(self, robot: Any, config: MocapConfig) -> None:
        self.robot = robot
        self.config = config
        self._r_off_t = rotation_of(config.marker_quaternion).T
        self._p_off = np.array(config.marker_position, dtype=float)
        self._cog_of: tuple[bytes, np.ndarray] | None = None
        self._stamp: float | None = None
        self.position = np.zeros(3)
        self.velocity = np.zeros(3)
        # per-axis covariance of (position, velocity), the same for the three axes
        self._cov = np.zeros((2, 2))
        self.counts: Counter[str] = Counter()

    def cog_in_root(self, q: np.ndarray) -> np.ndarray:
        """The CoG in the root link frame at ``q`` (kept while ``q`` holds)."""
        key = q.tobytes()
        if self._cog_of is None or self._cog_of[0] != key:
            self._cog_of = (key, np.asarray(self.robot.evaluate(q)["cog"], dtype=float))
        return self._cog_of[1]

    def update(
        self, stamp: float, position: np.ndarray, quaternion: np.ndarray, q: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, float]:
        """The CoG position, velocity and the root link's yaw for one marker pose."""
        r_root = rotation_of(quaternion) @ self._r_off_t
        p_root = position - r_root @ self._p_off
        cog = p_root + r_root @ self.cog_in_root(q)
        cfg = self.config
        r = cfg.position_noise_m**2
        last = self._stamp
        if last is None or not (0.0 <= stamp - last <= cfg.max_gap_s):
            if last is not None:
                self.counts["velocity_restarted"] += 1
            self.position, self.velocity = cog.copy(), np.zeros(3)
            self._cov = np.diag([r, cfg.velocity_sigma**2])
        else:
            dt = stamp - last
            f = np.array([[1.0, dt], [0.0, 1.0]])
            qa = cfg.acceleration_sigma**2
            qn = qa * np.array([[dt**4 / 4, dt**3 / 2], [dt**3 / 2, dt**2]])
            cov = f @ self._cov @ f.T + qn
            gain = cov[:, 0] / (cov[0, 0] + r)
            predicted = self.position + self.velocity * dt
            innovation = cog - predicted
            self.position = predicted + gain[0] * innovation
            self.velocity = self.velocity + gain[1] * innovation
            self._cov = cov - np.outer(gain, cov[0, :])
        self._stamp = stamp
        yaw = math.atan2(r_root[1, 0], r_root[0, 0])
        return self.position.copy(), self.velocity.copy(), yaw
