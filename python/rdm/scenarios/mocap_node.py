"""Simulated motion capture for the onboard node (:class:`MocapNode`, :class:`MocapSensor`)."""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from rdm.nodes.onboard import OnboardNode
from rdm.nodes.onboard_mocap import rotation_of
from rdm.plant import Plant

_FLOAT64 = np.dtype(np.float64)
#: The sub-stream of the run's seed for the mocap noise.
_MOCAP_STREAM = 0x6D6F6361


@dataclass(frozen=True)
class MocapSensor:
    """What the simulated motion-capture system measures. ASSUMPTIONS: a marker set tracked
    to 0.3 mm and 1 mrad (1 sigma) with 10 ms from capture to the robot's computer, typical
    of an optical system at 100-240 Hz."""

    #: "marker": the marker body's pose (a real system); "truth": the true CoG state.
    source: str = "marker"
    position_noise_m: float = 0.0003
    rotation_noise_rad: float = 0.001
    latency_s: float = 0.01

    def __post_init__(self) -> None:
        if self.source not in ("marker", "truth"):
            raise ValueError(f"MocapSensor.source={self.source!r}: 'marker' or 'truth'")
        for name in ("position_noise_m", "rotation_noise_rad", "latency_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"MocapSensor.{name}={v!r} must be finite and >= 0")


class MocapNode:
    """Motion capture to the onboard node at ``period``. ``sensor.source`` "marker": the world
    pose of the marker body on the root link (``OnboardConfig.mocap``'s offset) with Gaussian
    position and rotation noise, delivered ``latency_s`` after it was taken with its capture
    time as the stamp (``OnboardNode.set_mocap_pose``). "truth": the plant's CoG position
    (the controlled point), its velocity (finite difference of the true CoG) and the
    root-link yaw (``OnboardNode.set_mocap``)."""

    name = "mocap"
    #: What its tick changes of the lockstep kernel's parts: the plant (its lazy forward).
    kernel_touches = ("plant",)

    def __init__(
        self,
        plant: Plant,
        onboard: OnboardNode,
        period: float = 0.01,
        sensor: MocapSensor | None = None,
        seed: int = 0,
    ) -> None:
        self.plant = plant
        self.onboard = onboard
        self.period = period
        self.sensor = sensor or MocapSensor(source="truth")
        self._rng = np.random.default_rng([seed, _MOCAP_STREAM])
        self._pending: deque[tuple[float, float, list[float], list[float]]] = deque()
        self._last: list[float] | None = None
        self.enabled = True

    def tick(self, now: float) -> None:
        if self.sensor.source == "marker":
            self._tick_marker(now)
            return
        gt = self.plant.ground_truth()
        p = self._floats(gt.cog_position)
        last = self._last
        if last is None:
            v = [0.0] * len(p)
        else:
            # Plain floats: the same IEEE operations as ``(p - last) / period`` on arrays, and
            # lists of floats take the onboard node's cheap validation path.
            period = self.period
            v = [(a - b) / period for a, b in zip(p, last, strict=True)]
        self._last = p
        if self.enabled:
            w, x, y, z = self._floats(gt.base_quaternion)
            yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
            self.onboard.set_mocap(p, v, yaw)

    @staticmethod
    def _floats(value: Any) -> list[float]:
        """``np.asarray(value, dtype=float).reshape(-1).tolist()``; a float64 vector's
        ``tolist`` directly (the same floats)."""
        if type(value) is np.ndarray and value.dtype is _FLOAT64 and value.ndim == 1:
            return value.tolist()
        return np.asarray(value, dtype=float).reshape(-1).tolist()

    def _tick_marker(self, now: float) -> None:
        gt = self.plant.ground_truth()
        s, cfg = self.sensor, self.onboard.config.mocap
        w, x, y, z = (float(v) for v in gt.base_quaternion)
        base = (x, y, z, w)
        p = np.asarray(gt.base_position, dtype=float) + rotation_of(base) @ cfg.marker_position
        p = p + self._rng.normal(0.0, s.position_noise_m, 3)
        noise = _quaternion_of_rotvec(self._rng.normal(0.0, s.rotation_noise_rad, 3))
        q = _quaternion_product(_quaternion_product(base, cfg.marker_quaternion), noise)
        self._pending.append((now + s.latency_s, now, p.tolist(), list(q)))
        while self._pending and self._pending[0][0] <= now + 1e-9:
            _, taken, position, quaternion = self._pending.popleft()
            if self.enabled:
                self.onboard.set_mocap_pose(position, quaternion, stamp=taken)


def _quaternion_product(a: Any, b: Any) -> tuple[float, float, float, float]:
    """``a b`` of quaternions (x, y, z, w)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _quaternion_of_rotvec(v: np.ndarray) -> tuple[float, float, float, float]:
    """The unit quaternion (x, y, z, w) of a rotation vector."""
    angle = float(np.linalg.norm(v))
    if angle == 0.0:
        return (0.0, 0.0, 0.0, 1.0)
    x, y, z = (float(c) * math.sin(angle / 2) / angle for c in v)
    return (x, y, z, math.cos(angle / 2))
