"""What the plant's sensors and actuators read now: the noisy IMU and wrench samples (and the
noise-free values), the servo positions, velocities, torques and
currents, the applied rotor thrusts and the rotors' distances to the ceiling.

:class:`PlantReadings` is a part of :class:`rdm.plant.plant.Plant`: every reading refers to
the present time (the plant's lazy forward pass runs first where a derived quantity is read).
"""

from __future__ import annotations

import numpy as np

from rdm.plant.sensors import ImuReading, WrenchReading


class PlantReadings:
    """The readings of :class:`rdm.plant.plant.Plant` (a part of it)."""

    def _sensor(self, name: str, size: int = 3) -> np.ndarray:
        adr = self._sensor_adr[name]
        return self._fresh().sensordata[adr : adr + size].copy()

    def imu(self) -> ImuReading:
        """One noisy IMU sample in the IMU frame (root link, at the processor)."""
        if self._state.stale:
            self.sync()
        g, a, m = self._imu_adr
        # One Rust call reads the three ideal values from the sensordata view.
        return self.imu_model.sample_at(self._v_sensordata, g, a, m)

    def imu_ideal(self) -> ImuReading:
        """The noise-free IMU values (gyro, accelerometer, magnetometer)."""
        return ImuReading(
            self._sensor("gyro"), self._sensor("accelerometer"), self._sensor("magnetometer"), False
        )

    def wrench_ideal(self, sensor: str) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free (force, torque) of a wrench sensor: what the robot applies through it,
        in the sensor frame, torque about the sensor origin."""
        if sensor not in self.wrench_models:
            raise ValueError(f"sensor: unknown wrench sensor {sensor!r}")
        return self._sensor(f"{sensor}_force"), self._sensor(f"{sensor}_torque")

    def _wrench_address(self, sensor: str) -> tuple[int, int]:
        """(force, torque) addresses of a wrench sensor in ``sensordata``, the state synced."""
        adr = self._wrench_adr.get(sensor)
        if adr is None:
            raise ValueError(f"sensor: unknown wrench sensor {sensor!r}")
        if self._state.stale:
            self.sync()
        return adr

    def wrench(self, sensor: str) -> WrenchReading:
        """One noisy sample of a wrench sensor (``foot_wrench``, ``end_effector_wrench``)."""
        adr = self._wrench_address(sensor)
        f, t = adr
        return self.wrench_models[sensor].sample_at(self._v_sensordata, f, t)

    def wrench_values(self, sensor: str) -> tuple[float, float, float, float, float, float]:
        """(Fx, Fy, Fz, Mx, My, Mz) of :meth:`wrench` as one tuple of floats (the bridge's
        1 kHz foot-sensor read into the Leptrino mirror): the same normals and numbers."""
        adr = self._wrench_address(sensor)
        model = self.wrench_models[sensor]
        return model._core.sample_values_at(
            self._v_sensordata, adr[0], adr[1], model._normals.take(6)
        )

    def servo_positions(self) -> np.ndarray:
        """Present joint positions (joint_order) [rad]."""
        return self._data.qpos[self._qadr]  # fancy indexing copies; qpos is current

    def servo_velocities(self) -> np.ndarray:
        """Present joint velocities (joint_order) [rad/s]."""
        return self._data.qvel[self._vadr]

    def servo_torques(self) -> np.ndarray:
        """Servo output torques (joint_order) [N m], limited to the stall torques."""
        return self._fresh().actuator_force[self._servo_act].copy()

    def servo_currents(self) -> np.ndarray:
        """Servo currents (joint_order) [A] from a linear torque constant (ASSUMPTION)."""
        return self.servo_torques() / self._kt

    def rotor_thrusts(self) -> np.ndarray:
        """Thrusts applied in the last step, ceiling effect included [N]."""
        return self._thrusts

    def rotor_distances_to_ceiling(self) -> np.ndarray:
        """Distance of each rotor to the ceiling along its axis [m] (inf: none ahead)."""
        return self._rotor_distances()
