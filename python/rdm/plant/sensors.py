"""Sensor error models: IMU (gyro, accelerometer, magnetometer) and 6-axis wrench sensors.

MuJoCo computes the ideal values; these classes add a constant bias drawn once from a seeded
generator, white noise, saturation and quantisation, so the same seed always gives the same
stream. Scales follow the real parts: IMU LSBs from Spinal's CAN rescaling
(jsk-wire-protocols.md sec. 2.4: +-2000 dps over 32767, 9.80665/4096 m/s^2, 4912/32760 uT),
Leptrino raw 10000 = rated capacity (sec. 5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rdm._rdm import ImuNoiseCore, NormalStreamCore, WrenchNoiseCore
from rdm.plant.description import WrenchSensorSpec

GYRO_LSB = math.radians(2000.0 / 32767.0)  # rad/s
ACCEL_LSB = 9.80665 / 4096.0  # m/s^2
MAG_LSB = 4912.0 / 32760.0  # uT
GYRO_RANGE = math.radians(2000.0)  # +-2000 dps
ACCEL_RANGE = 8.0 * 9.80665  # +-8 g
LEPTRINO_FULL_SCALE_COUNTS = 10000.0
#: Standard normals drawn per refill of a model's normal stream (``rdm._rdm.NormalStreamCore``,
#: the one owner of the model's generator from its construction on: the IMU's after its
#: biases are drawn; a take of ``k`` gives what ``k`` more ``rng.normal(0.0, 1.0)`` draws would).
NORMAL_CHUNK = 1024


@dataclass(frozen=True)
class ImuNoise:
    """IMU error model (ASSUMPTIONS: ICM-20948-class datasheet levels, docs/plant.md).

    ``*_std``: white noise per sample; ``*_bias_std``: std of the constant per-axis bias
    drawn at construction (or set ``*_bias`` explicitly to fix it).
    """

    gyro_std: float = math.radians(0.1)
    gyro_bias_std: float = math.radians(0.5)
    accel_std: float = 0.03
    accel_bias_std: float = 0.05
    mag_std: float = 0.5
    mag_bias_std: float = 1.0
    gyro_bias: tuple[float, float, float] | None = None
    accel_bias: tuple[float, float, float] | None = None
    mag_bias: tuple[float, float, float] | None = None
    quantize: bool = True


@dataclass(frozen=True)
class ImuReading:
    """One IMU sample in the IMU (root-link) frame."""

    gyro: np.ndarray  # rad/s
    accel: np.ndarray  # specific force, m/s^2 (reads +g up at rest)
    mag: np.ndarray  # uT
    saturated: bool


def _bias_property(attr: str, doc: str) -> property:
    """A read-only bias array whose assignment rebuilds the model's Rust core."""

    def get(self) -> np.ndarray:
        return getattr(self, attr)

    def set_(self, value) -> None:
        setattr(self, attr, _frozen(np.array(value, dtype=float)))
        self._rebuild()

    return property(get, set_, doc=doc)


class ImuModel:
    """Adds bias, noise, saturation and quantisation to ideal IMU values.

    The per-sample float work runs in Rust (``rdm._rdm.ImuNoiseCore``): ``x + bias + std * e``
    per axis, saturation flags and clipping of gyro and accelerometer, quantisation to the
    LSB with ties to even (numpy's ``np.round(v / lsb) * lsb``, signed zeros kept); the
    normals stay numpy's.
    The bias arrays are read-only: assign a new array to change one.
    """

    def __init__(self, noise: ImuNoise, rng: np.random.Generator) -> None:
        def bias(explicit: tuple[float, float, float] | None, std: float) -> np.ndarray:
            drawn = rng.normal(0.0, std, 3)  # always drawn: the stream does not depend on it
            return drawn if explicit is None else np.asarray(explicit, dtype=float)

        self._noise = noise
        self._gyro_bias = _frozen(bias(noise.gyro_bias, noise.gyro_bias_std))
        self._accel_bias = _frozen(bias(noise.accel_bias, noise.accel_bias_std))
        self._mag_bias = _frozen(bias(noise.mag_bias, noise.mag_bias_std))
        self._normals = NormalStreamCore(rng, NORMAL_CHUNK)
        self._rebuild()

    def _rebuild(self) -> None:
        n = self._noise
        self._core = ImuNoiseCore(
            self._gyro_bias.tolist(),
            self._accel_bias.tolist(),
            self._mag_bias.tolist(),
            [float(n.gyro_std), float(n.accel_std), float(n.mag_std)],
            [GYRO_RANGE, ACCEL_RANGE],
            [GYRO_LSB, ACCEL_LSB, MAG_LSB] if n.quantize else None,
        )

    @property
    def noise(self) -> ImuNoise:
        """The error model (assigning a new one takes effect at the next sample)."""
        return self._noise

    @noise.setter
    def noise(self, value: ImuNoise) -> None:
        self._noise = value
        self._rebuild()

    gyro_bias = _bias_property("_gyro_bias", "Constant gyro bias (rad/s), read-only array.")
    accel_bias = _bias_property("_accel_bias", "Constant accelerometer bias (m/s^2), read-only.")
    mag_bias = _bias_property("_mag_bias", "Constant magnetometer bias (uT), read-only array.")

    def sample(self, gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray) -> ImuReading:
        """Corrupt one ideal sample (nine normals of the generator's stream)."""
        return self.sample_lists(gyro.tolist(), accel.tolist(), mag.tolist())

    def sample_lists(self, gyro: list[float], accel: list[float], mag: list[float]) -> ImuReading:
        """:meth:`sample` of three float lists (what the plant reads from ``sensordata``)."""
        g, a, m, saturated = self._core.sample(gyro, accel, mag, self._normals.take(9))
        return ImuReading(g, a, m, saturated)

    def sample_at(
        self, sensordata: np.ndarray, gyro_adr: int, accel_adr: int, mag_adr: int
    ) -> ImuReading:
        """:meth:`sample_lists` of the three ideal values read from ``sensordata`` (MuJoCo's
        array) at their addresses, in one Rust call; ValueError if one lies outside it."""
        g, a, m, saturated = self._core.sample_at(
            sensordata, gyro_adr, accel_adr, mag_adr, self._normals.take(9)
        )
        return ImuReading(g, a, m, saturated)


def _frozen(a: np.ndarray) -> np.ndarray:
    """``a`` made read-only (the Rust core holds a copy: an in-place change would be lost)."""
    a.flags.writeable = False
    return a


def sensor_seed_sequences(seed: int | None, n_wrench: int) -> list[np.random.SeedSequence]:
    """The plant's sensor seeds: the IMU's first, then one per wrench sensor (children of
    ``SeedSequence(seed)``; a child depends only on its index, not on how many exist)."""
    return np.random.SeedSequence(seed).spawn(1 + n_wrench)


def imu_model_of_seed(seed: int, noise: ImuNoise | None = None) -> ImuModel:
    """The IMU error model that ``rdm.plant.Plant(seed=seed)`` draws (same biases, same
    stream). What a process without the plant (the HIL Spinal process) needs to know the
    simulated IMU's constant biases, e.g. for the flash calibration
    (``rdm.scenarios.stack``)."""
    imu_seed = sensor_seed_sequences(seed, 0)[0]
    return ImuModel(noise or ImuNoise(), np.random.default_rng(imu_seed))


@dataclass(frozen=True)
class WrenchNoise:
    """Wrench sensor error model (ASSUMPTION: noise 0.3 % of rated capacity per axis).

    The paper reports the foot sensor as noisy at times (Sec. VII-B) without numbers.
    ``bias``: constant offset (Fx, Fy, Fz, Mx, My, Mz); zero = freshly calibrated.
    """

    noise_fraction_of_rated: float = 0.003
    bias: tuple[float, float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    quantize: bool = True


@dataclass(frozen=True)
class WrenchReading:
    """One 6-axis sample in the sensor frame: the wrench the robot applies through it."""

    force: np.ndarray  # N
    torque: np.ndarray  # N m, about the sensor frame origin
    saturated: np.ndarray  # bool per axis (Fx, Fy, Fz, Mx, My, Mz): clipped at rated capacity

    @property
    def any_saturated(self) -> bool:
        """True if any axis hit its rated capacity."""
        return bool(np.any(self.saturated))


class WrenchSensorModel:
    """Leptrino-style 6-axis sensor: rated-capacity clipping, noise, 1/10000 resolution.

    The per-sample float work runs in Rust (``rdm._rdm.WrenchNoiseCore``): ``x + bias +
    fraction * rated * e`` per axis, saturation flags (``|v| >= rated``), clipping at the
    rated capacity, quantisation to rated / 10000 with ties to even; the normals stay numpy's.
    """

    def __init__(self, spec: WrenchSensorSpec, noise: WrenchNoise, rng: np.random.Generator):
        self.spec = spec
        self.rated = _frozen(np.array([*spec.force_range, *spec.torque_range], dtype=float))
        self._rated_list = self.rated.tolist()
        self._normals = NormalStreamCore(rng, NORMAL_CHUNK)
        self.noise = noise

    @property
    def noise(self) -> WrenchNoise:
        """The error model (assigning a new one takes effect at the next sample)."""
        return self._noise

    @noise.setter
    def noise(self, value: WrenchNoise) -> None:
        self._noise = value
        self._core = WrenchNoiseCore(
            self._rated_list,
            [float(b) for b in value.bias],
            float(value.noise_fraction_of_rated),
            bool(value.quantize),
            LEPTRINO_FULL_SCALE_COUNTS,
        )

    def sample(self, force: np.ndarray, torque: np.ndarray) -> WrenchReading:
        """Corrupt one ideal sample (six normals of the generator's stream)."""
        return self.sample_list(force.tolist() + torque.tolist())

    def sample_list(self, wrench: list[float]) -> WrenchReading:
        """:meth:`sample` of the six floats (Fx, Fy, Fz, Mx, My, Mz)."""
        force, torque, saturated = self._core.sample(wrench, self._normals.take(6))
        return WrenchReading(force, torque, saturated)

    def sample_at(self, sensordata: np.ndarray, force_adr: int, torque_adr: int) -> WrenchReading:
        """:meth:`sample_list` of the ideal force and torque read from ``sensordata`` (MuJoCo's
        array) at their addresses, in one Rust call; ValueError if one lies outside it."""
        force, torque, saturated = self._core.sample_at(
            sensordata, force_adr, torque_adr, self._normals.take(6)
        )
        return WrenchReading(force, torque, saturated)
