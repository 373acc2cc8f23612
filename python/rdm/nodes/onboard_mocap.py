"""The CoG state from motion capture: what a motion-capture system gives (the time-stamped pose
of a marker rigid body fixed to the root link, no velocity) turned into the CoG position,
velocity and yaw the position controller needs.

* Root link pose: ``R_root = R_marker R_off^T``, ``p_root = p_marker - R_root p_off``, with the
  marker's pose ``(p_off, R_off)`` in the root link frame from :class:`MocapConfig`.
* CoG: ``p_cog = p_root + R_root c(q)``, ``c(q)`` the CoG in the root link frame from the
  model's kinematics at the measured joint angles (``Robot.evaluate(q)["cog"]``).
* Velocity: the finite difference of successive CoG positions over their stamps, low-passed
  by a first-order filter at ``velocity_cutoff_hz``, 10 Hz (JSK's mocap plugin uses a finite
  difference and a 20 Hz low-pass, ``jsk-flight-navigation.md`` sec. 9; with 0.3 mm / 1 mrad
  of marker noise and 10 ms of latency the simulated robot's lightly damped x/pitch loop
  (Table V's gains) diverged in ``rdm sim mission`` at 20 Hz and held at 10 Hz). A gap longer than ``max_gap_s``
  (or a stamp that does not advance) restarts the filter: the velocity is then 0 until the
  next sample.
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
    velocity_cutoff_hz: float = 10.0
    max_gap_s: float = 0.1

    def __post_init__(self) -> None:
        if len(self.marker_position) != 3 or not all(map(math.isfinite, self.marker_position)):
            raise ValueError("MocapConfig.marker_position needs 3 finite values")
        q = self.marker_quaternion
        if len(q) != 4 or not all(map(math.isfinite, q)) or abs(math.hypot(*q) - 1.0) > 1e-6:
            raise ValueError("MocapConfig.marker_quaternion must be a unit quaternion x,y,z,w")
        for name in ("velocity_cutoff_hz", "max_gap_s"):
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
        self._last: tuple[float, np.ndarray] | None = None
        self.velocity = np.zeros(3)
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
        last = self._last
        if last is None or not (0.0 < stamp - last[0] <= self.config.max_gap_s):
            if last is not None:
                self.counts["velocity_restarted"] += 1
            self.velocity = np.zeros(3)
        else:
            dt = stamp - last[0]
            raw = (cog - last[1]) / dt
            a = 1.0 - math.exp(-2.0 * math.pi * self.config.velocity_cutoff_hz * dt)
            self.velocity = self.velocity + a * (raw - self.velocity)
        self._last = (stamp, cog)
        yaw = math.atan2(r_root[1, 0], r_root[0, 0])
        return cog, self.velocity.copy(), yaw
