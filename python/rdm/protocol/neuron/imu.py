"""Neuron IMU frames (fact sheet sec. 2.4 "IMU"): raw MPU9250 int16 x, y, z per sensor.

Spinal's scaling: gyro x (2000/32767)*pi/180 rad/s (+-2000 dps), acc x 9.80665/4096 m/s^2
(+-8 g), mag x 4912/32760 uT (AK8963). Axis remap into Spinal's frame:
gyro/acc ``(-y, x, z)``, mag ``(-x, y, -z)``.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import ClassVar

from .base import NeuronFrame, check_dlc, check_int
from .ids import Device, Direction, ImuMessage, check_slave

GYRO_SCALE = (2000.0 / 32767.0) * math.pi / 180.0  # rad/s per LSB
ACC_SCALE = 9.80665 / 4096.0  # m/s^2 per LSB
MAG_SCALE = 4912.0 / 32760.0  # uT per LSB

_SCALE = {ImuMessage.GYRO: GYRO_SCALE, ImuMessage.ACC: ACC_SCALE, ImuMessage.MAG: MAG_SCALE}
_UNIT = {ImuMessage.GYRO: "rad/s", ImuMessage.ACC: "m/s^2", ImuMessage.MAG: "uT"}


@dataclass(frozen=True)
class ImuFrame(NeuronFrame):
    """N->S IMU sample; ``sensor`` is ``ImuMessage.GYRO``/``ACC``/``MAG`` (message id 0/1/2)."""

    slave: int
    sensor: ImuMessage
    x: int
    y: int
    z: int

    KIND: ClassVar[str] = "imu"
    DIRECTION: ClassVar[Direction] = Direction.NEURON_TO_SPINAL
    DEVICE: ClassVar[int] = Device.IMU

    def __post_init__(self) -> None:
        check_slave(self.slave)
        if not isinstance(self.sensor, ImuMessage):
            object.__setattr__(self, "sensor", ImuMessage(check_sensor(self.sensor)))
        for name in ("x", "y", "z"):
            check_int(name, getattr(self, name), -0x8000, 0x7FFF)

    def _message_id(self) -> int:
        return int(self.sensor)

    def encode(self) -> bytes:
        return struct.pack("<hhh", self.x, self.y, self.z)

    @classmethod
    def decode_payload(cls, slave: int, sensor: int, data: bytes) -> ImuFrame:
        check_dlc(cls.KIND, data, (6,))
        return cls(slave, ImuMessage(sensor), *struct.unpack("<hhh", data))

    @property
    def unit(self) -> str:
        return _UNIT[self.sensor]

    def spinal_frame(self) -> tuple[float, float, float]:
        """Scaled and axis-remapped as Spinal does (rad/s, m/s^2 or uT)."""
        k = _SCALE[self.sensor]
        if self.sensor == ImuMessage.MAG:
            return (-self.x * k, self.y * k, -self.z * k)
        return (-self.y * k, self.x * k, self.z * k)

    def as_dict(self) -> dict:
        out = super().as_dict()
        out["sensor"] = self.sensor.name.lower()
        return out


def check_sensor(sensor: object) -> int:
    check_int("sensor", sensor, 0, 2)
    return sensor  # type: ignore[return-value]
