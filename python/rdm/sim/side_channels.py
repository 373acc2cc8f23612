"""Side channels between the processes of a process-level run: links that are not CAN or UART
wires on the real robot.

* **IMU -> Spinal** (on the board: SPI from the IMU chip). One datagram per IMU sample,
  ``struct`` ``<4sd10d`` little-endian: magic ``b"IMU1"``, simulated time [s], gyro xyz
  [rad/s], accelerometer xyz [m/s^2], magnetometer xyz [uT] (Spinal body frame), battery
  voltage [V] (the ADC reading; carried with every sample so a lost datagram cannot lose it).
* **Mocap -> onboard PC** (on the robot: the motion-capture network link). One JSON object per
  datagram: ``{"mocap": {"position": [x, y, z], "velocity": [vx, vy, vz], "yaw": psi}}``.

Both are Unix datagram sockets in the abstract namespace (no file, no port; Linux only), named
``rdm-<run token>-<channel>``. Datagrams are whole messages; a receiver drains its socket every
tick and keeps the newest sample. Lost or malformed datagrams are counted, never fatal.
"""

from __future__ import annotations

import json
import math
import socket
import struct
from collections.abc import Sequence
from typing import Any

import numpy as np

IMU_FORMAT = struct.Struct("<4sd10d")
IMU_MAGIC = b"IMU1"


def abstract_address(token: str, channel: str) -> str:
    """The abstract-namespace address of ``channel`` in the run ``token``."""
    return f"\0rdm-{token}-{channel}"


def bind_datagram(token: str, channel: str) -> socket.socket:
    """A non-blocking receiving socket for ``channel``."""
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(abstract_address(token, channel))
    sock.setblocking(False)
    return sock


class DatagramSender:
    """Sends datagrams to ``channel``; a missing or full receiver is counted, not raised."""

    def __init__(self, token: str, channel: str) -> None:
        self.address = abstract_address(token, channel)
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.sent = 0
        self.errors = 0

    def send(self, data: bytes) -> None:
        try:
            self.sock.sendto(data, self.address)
            self.sent += 1
        except OSError:  # receiver gone (ECONNREFUSED/ENOENT) or its queue full (EAGAIN)
            self.errors += 1

    def close(self) -> None:
        self.sock.close()


def pack_imu(
    now: float, gyro: Sequence[float], acc: Sequence[float], mag: Sequence[float], volts: float
) -> bytes:
    """One IMU datagram (see the module doc)."""
    return IMU_FORMAT.pack(IMU_MAGIC, now, *gyro, *acc, *mag, volts)


def unpack_imu(data: bytes) -> tuple[float, tuple, tuple, tuple, float] | None:
    """(time, gyro, acc, mag, volts), or None for a datagram that is not a finite IMU sample
    (volts may be NaN: no battery reading yet)."""
    if len(data) != IMU_FORMAT.size:
        return None
    magic, now, *v = IMU_FORMAT.unpack(data)
    if magic != IMU_MAGIC or not all(math.isfinite(x) for x in (now, *v[:9])):
        return None
    return now, tuple(v[0:3]), tuple(v[3:6]), tuple(v[6:9]), v[9]


class ImuSender:
    """Robot-process end of the IMU channel: the plant bridge's ``imu_sink`` and battery sink.
    ``time_of`` returns the simulated time stamped on each sample."""

    def __init__(self, token: str, time_of: Any) -> None:
        self.out = DatagramSender(token, "imu")
        self.time_of = time_of
        self.volts = math.nan

    def set_battery_voltage(self, volts: float) -> None:
        self.volts = float(volts)

    def send_imu(self, gyro: np.ndarray, acc: np.ndarray, mag: np.ndarray) -> None:
        self.out.send(pack_imu(float(self.time_of()), gyro, acc, mag, self.volts))

    def close(self) -> None:
        self.out.close()


class ImuReceiver:
    """Spinal-process end: a node (tick it just before the Spinal mirror) that applies the
    newest IMU sample and battery voltage to ``spinal``."""

    name = "imu_in"

    def __init__(self, token: str, spinal: Any, period: float = 0.001) -> None:
        self.sock = bind_datagram(token, "imu")
        self.spinal = spinal
        self.period = period
        self.samples = 0
        self.malformed = 0
        self.last_time: float | None = None
        self._volts: float | None = None

    def tick(self, now: float) -> None:
        newest = None
        for _ in range(10_000):
            try:
                data = self.sock.recv(256)
            except BlockingIOError:
                break
            sample = unpack_imu(data)
            if sample is None:
                self.malformed += 1
                continue
            newest = sample
            self.samples += 1
        if newest is None:
            return
        t, gyro, acc, mag, volts = newest
        self.last_time = t
        self.spinal.set_imu_sample(gyro, acc, mag)
        if math.isfinite(volts) and volts != self._volts:
            self._volts = volts
            self.spinal.set_battery_voltage(volts)

    def close(self) -> None:
        self.sock.close()


def quaternion_yaw(q_wxyz: Sequence[float]) -> float:
    """ZYX yaw of a (w, x, y, z) quaternion."""
    w, x, y, z = (float(v) for v in q_wxyz)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


class MocapSender:
    """Robot-process motion capture (as ``rdm.scenarios.stack.MocapNode``): the true CoG
    position, its finite-difference velocity and the foot-frame yaw, every ``period``, as a
    JSON datagram to the onboard process."""

    name = "mocap"

    def __init__(self, token: str, plant: Any, period: float = 0.01) -> None:
        self.out = DatagramSender(token, "mocap")
        self.plant = plant
        self.period = period
        self._last: np.ndarray | None = None

    def tick(self, now: float) -> None:
        gt = self.plant.ground_truth()
        p = np.asarray(gt.cog_position, dtype=float)
        v = np.zeros(3) if self._last is None else (p - self._last) / self.period
        self._last = p
        msg = {
            "mocap": {
                "position": p.tolist(),
                "velocity": v.tolist(),
                "yaw": quaternion_yaw(gt.base_quaternion),
            }
        }
        self.out.send(json.dumps(msg).encode())

    def close(self) -> None:
        self.out.close()


class MocapReceiver:
    """Onboard-process end: a node (tick it before the onboard node) that hands every mocap
    datagram to ``onboard.set_mocap``. Datagrams are read with the ground link's bounds
    (:func:`rdm.ground.message.decode`: size and nesting depth); anything else is counted."""

    name = "mocap_in"

    def __init__(self, token: str, onboard: Any, period: float) -> None:
        self.sock = bind_datagram(token, "mocap")
        self.period = period
        self.applied = 0
        self.errors = 0
        self.node = onboard
        #: The latest applied mocap position (world CoG), or None before the first.
        self.position: np.ndarray | None = None

    def tick(self, now: float) -> None:
        from rdm.ground.message import Rejected, decode

        for _ in range(10_000):
            try:
                data = self.sock.recv(65536)
            except BlockingIOError:
                return
            try:
                m = decode(data)["mocap"]
                p = np.asarray(m["position"], dtype=float)
                self.node.set_mocap(m["position"], m["velocity"], m.get("yaw"))
                if p.shape == (3,) and np.all(np.isfinite(p)):
                    self.position = p
                self.applied += 1
            except (Rejected, ValueError, TypeError, KeyError, AttributeError):
                self.errors += 1

    def close(self) -> None:
        self.sock.close()
