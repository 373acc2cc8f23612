"""The MuJoCo plant of a rotor-distributed manipulator: physics + actuators + sensors.

A :class:`Plant` owns one compiled model and its data, the rotor ESC models, the ceiling
effect and the sensor error models. It runs at the physics rate (1 kHz by default); callers
(a SITL/HIL loop) decide how often to read sensors and send commands.

Per physics step: kinematics (``mj_step1``), each ESC's lag advances, each rotor's thrust is
scaled by the ceiling effect at its present distance to the ceiling, then ``mj_step2``
integrates. After ``step(n)`` a final ``mj_forward`` makes every reading refer to the
current time.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import mujoco
import numpy as np

from rdm.plant.ceiling import CeilingEffect, ParametricCeilingEffect
from rdm.plant.description import RobotDescription, load_robot
from rdm.plant.esc import Esc, EscParams
from rdm.plant.mjcf import (
    CEILING_GEOM,
    FLOOR_GEOM,
    FOOT_PLATE_BODY,
    BuildOptions,
    ContactParams,
    build_spec,
    rotor_actuator,
    rotor_site,
    servo_actuator,
)
from rdm.plant.sensors import (
    ImuModel,
    ImuNoise,
    ImuReading,
    WrenchNoise,
    WrenchReading,
    WrenchSensorModel,
)
from rdm.plant.servo import ServoParams, torque_constant
from rdm.plant.truth import FootContactTracker, GroundTruth


def _vector(values: Sequence[float] | np.ndarray, n: int, name: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (n,):
        raise ValueError(f"{name}: expected {n} values, got {arr.size}")
    return arr


class Plant:
    """MuJoCo plant of one robot; deterministic for a given seed.

    Args:
        robot: shipped robot name (``"rdm"``, ``"rcm"``), a TOML path, or a loaded description.
        seed: seeds every sensor error model (same seed and calls, same numbers).
        timestep: physics step [s] (1 ms = 1 kHz).
        ceiling_height: height of the ceiling plane [m] (None: no ceiling).
        floor_height: height of a floor plane [m] (None: no floor).
        fixed_base: weld the foot to the world (bench tests of servos and sensors).
        ceiling_effect: one model for all rotors, or None for the default
            :class:`ParametricCeilingEffect` built from each rotor's radius.
        esc: ESC parameters (thrust_max defaults to each rotor's TOML value).
        battery_voltage: battery voltage [V] of the duty -> thrust map.
    """

    def __init__(
        self,
        robot: str | Path | RobotDescription = "rdm",
        *,
        seed: int = 0,
        timestep: float = 0.001,
        ceiling_height: float | None = 2.0,
        floor_height: float | None = None,
        fixed_base: bool = False,
        ceiling_effect: CeilingEffect | None = None,
        esc: EscParams | None = None,
        battery_voltage: float | None = None,
        servo: ServoParams | None = None,
        contact: ContactParams | None = None,
        imu_noise: ImuNoise | None = None,
        wrench_noise: WrenchNoise | None = None,
    ) -> None:
        if not (math.isfinite(timestep) and timestep > 0):
            raise ValueError(f"timestep: must be > 0, got {timestep}")
        self.description = robot if isinstance(robot, RobotDescription) else load_robot(robot)
        desc = self.description
        self.options = BuildOptions(
            timestep=timestep,
            ceiling_height=ceiling_height,
            floor_height=floor_height,
            fixed_base=fixed_base,
            servo=servo or ServoParams(),
            contact=contact,
        )
        self.spec = build_spec(desc, self.options)
        self.model = self.spec.compile()
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.seed = seed
        self.joint_names: tuple[str, ...] = desc.joint_order
        self.rotor_names: tuple[str, ...] = tuple(r.name for r in desc.rotors)

        jids = [m.joint(n).id for n in self.joint_names]
        self._qadr = np.array([m.jnt_qposadr[j] for j in jids])
        self._vadr = np.array([m.jnt_dofadr[j] for j in jids])
        self._servo_act = np.array([m.actuator(servo_actuator(n)).id for n in self.joint_names])
        self._rotor_act = np.array([m.actuator(rotor_actuator(n)).id for n in self.rotor_names])
        self._rotor_site = np.array([m.site(rotor_site(n)).id for n in self.rotor_names])
        self._kt = np.array(
            [
                torque_constant(desc.joint(n).servo, desc.joint(n).stall_torque)
                for n in self.joint_names
            ]
        )
        self._foot_body = m.body(desc.foot_frame).id
        self._plate_body = m.body(FOOT_PLATE_BODY).id
        self._ee_body = m.body(desc.end_effector_frame).id
        env = {m.geom(g).id for g in (CEILING_GEOM, FLOOR_GEOM) if _has_geom(m, g)}
        self._tracker = FootContactTracker(m, self._plate_body, env)
        self._sensor_adr = {m.sensor(i).name: m.sensor_adr[i] for i in range(m.nsensor)}

        base = esc or EscParams()
        self.escs = [
            Esc(
                EscParams(base.p2, base.p1, base.p0, base.v_ref, r.thrust_max, base.tau)
                if esc is None
                else base,
                battery_voltage,
            )
            for r in desc.rotors
        ]
        if ceiling_effect is None:
            self.ceiling_effects: list[CeilingEffect] = [
                ParametricCeilingEffect(radius=r.radius) for r in desc.rotors
            ]
        else:
            self.ceiling_effects = [ceiling_effect for _ in desc.rotors]
        self._imu_noise = imu_noise or ImuNoise()
        self._wrench_noise = wrench_noise or WrenchNoise()
        self.rejected_commands = 0
        self._thrusts = np.zeros(len(self.rotor_names))
        self._external: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._seed_sensors()
        self.reset()

    # ----------------------------------------------------------------- set-up and reset
    def _seed_sensors(self) -> None:
        sensors = self.description.wrench_sensors
        seeds = np.random.SeedSequence(self.seed).spawn(1 + len(sensors))
        self.imu_model = ImuModel(self._imu_noise, np.random.default_rng(seeds[0]))
        self.wrench_models = {
            key: WrenchSensorModel(spec, self._wrench_noise, np.random.default_rng(s))
            for (key, spec), s in zip(sensors.items(), seeds[1:], strict=True)
        }

    def reset(
        self,
        q0: Sequence[float] | np.ndarray | None = None,
        base_position: Sequence[float] | np.ndarray = (0.0, 0.0, 1.0),
        base_quaternion: Sequence[float] | np.ndarray = (1.0, 0.0, 0.0, 0.0),
        thrusts: Sequence[float] | np.ndarray | None = None,
    ) -> None:
        """Restart at rest: joints at ``q0`` (joint_order, servo targets too), foot frame at
        ``base_position``/``base_quaternion`` (ignored with ``fixed_base``), rotors already
        spinning at ``thrusts`` (default stopped). Sensor generators are re-seeded."""
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        q = (
            np.zeros(len(self.joint_names))
            if q0 is None
            else _vector(q0, len(self.joint_names), "q0")
        )
        d.qpos[self._qadr] = q
        d.ctrl[self._servo_act] = q
        if not self.options.fixed_base:
            quat = _vector(base_quaternion, 4, "base_quaternion")
            norm = np.linalg.norm(quat)
            if not np.isfinite(norm) or norm < 1e-9:
                raise ValueError("base_quaternion: must be a non-zero quaternion")
            d.qpos[0:3] = _vector(base_position, 3, "base_position")
            d.qpos[3:7] = quat / norm
        t = (
            np.zeros(len(self.escs))
            if thrusts is None
            else _vector(thrusts, len(self.escs), "thrusts")
        )
        for esc, value in zip(self.escs, t, strict=True):
            esc.reset(float(value))
        self._tracker.reset()
        self._external.clear()
        self._seed_sensors()
        mujoco.mj_forward(m, d)
        self._apply_rotor_thrusts()
        mujoco.mj_forward(m, d)

    # ---------------------------------------------------------------------- commands
    def set_rotor_duties(self, duties: Sequence[float] | np.ndarray) -> None:
        """PWM duty per rotor in [0.5, 1] (0.5 stops the motor); goes through the ESC model."""
        for esc, duty in zip(self.escs, _vector(duties, len(self.escs), "duties"), strict=True):
            esc.command_duty(float(duty))

    def set_rotor_thrusts(self, thrusts: Sequence[float] | np.ndarray) -> None:
        """Steady thrust command per rotor [N] (the ESC lag still applies)."""
        for esc, thrust in zip(self.escs, _vector(thrusts, len(self.escs), "thrusts"), strict=True):
            esc.command_thrust(float(thrust))

    def set_battery_voltage(self, voltage: float) -> None:
        """Battery voltage [V] seen by every ESC (affects later duty commands)."""
        for esc in self.escs:
            esc.set_voltage(voltage)

    def set_servo_targets(self, q: Sequence[float] | np.ndarray) -> None:
        """Goal positions (joint_order) [rad]; non-finite entries keep the previous goal."""
        q = _vector(q, len(self.joint_names), "q")
        ok = np.isfinite(q)
        self.rejected_commands += int(np.count_nonzero(~ok))
        self.data.ctrl[self._servo_act[ok]] = q[ok]

    def apply_body_wrench(
        self,
        body: str,
        force: Sequence[float] | np.ndarray = (0.0, 0.0, 0.0),
        torque: Sequence[float] | np.ndarray = (0.0, 0.0, 0.0),
        point: Sequence[float] | np.ndarray | None = None,
    ) -> None:
        """Hold an external world-frame force/torque on a body until changed (zero force and
        torque remove it). The force acts at ``point`` (world, default the body frame
        origin), a point that then moves with the body; e.g. a push on ``end_effector``
        (the end-effector sensor then reads it)."""
        bid = self.model.body(body).id
        f = _vector(force, 3, "force")
        t = _vector(torque, 3, "torque")
        rot = self.data.xmat[bid].reshape(3, 3)
        origin = self.data.xpos[bid]
        at = origin if point is None else _vector(point, 3, "point")
        self._external[bid] = (f, t, rot.T @ (at - origin))
        if not (f.any() or t.any()):
            del self._external[bid]
            self.data.xfrc_applied[bid] = 0.0
        self._apply_external()

    def _apply_external(self) -> None:
        d = self.data
        for bid, (f, t, local) in self._external.items():
            at = d.xpos[bid] + d.xmat[bid].reshape(3, 3) @ local
            # xfrc_applied acts at the body's centre of mass: carry the force's moment over.
            d.xfrc_applied[bid, :3] = f
            d.xfrc_applied[bid, 3:] = t - np.cross(d.xipos[bid] - at, f)

    # -------------------------------------------------------------------------- physics
    def _rotor_distances(self) -> np.ndarray:
        h = self.options.ceiling_height
        dist = np.full(len(self.rotor_names), np.inf)
        if h is None:
            return dist
        for i, sid in enumerate(self._rotor_site):
            axis_z = self.data.site_xmat[sid][8]  # z component of the site z axis
            if axis_z > 1e-6:
                dist[i] = max(h - self.data.site_xpos[sid][2], 0.0) / axis_z
        return dist

    def _apply_rotor_thrusts(self) -> None:
        dist = self._rotor_distances()
        for i, (esc, effect) in enumerate(zip(self.escs, self.ceiling_effects, strict=True)):
            self._thrusts[i] = esc.thrust * effect.thrust_ratio(float(dist[i]))
        self.data.ctrl[self._rotor_act] = self._thrusts

    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics steps."""
        m, d = self.model, self.data
        dt = m.opt.timestep
        for _ in range(int(n)):
            mujoco.mj_step1(m, d)
            for esc in self.escs:
                esc.update(dt)
            self._apply_rotor_thrusts()
            if self._external:
                self._apply_external()
            mujoco.mj_step2(m, d)
            self._tracker.update(d)  # contacts of this step's start: keep the slip anchor
        if self._external:  # re-aim held forces at the bodies' new poses before reading
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            self._apply_external()
        mujoco.mj_forward(m, d)

    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return float(self.data.time)

    # -------------------------------------------------------------------------- sensors
    def _sensor(self, name: str, size: int = 3) -> np.ndarray:
        adr = self._sensor_adr[name]
        return self.data.sensordata[adr : adr + size].copy()

    def imu(self) -> ImuReading:
        """One noisy IMU sample in the IMU frame (root link, at the processor)."""
        return self.imu_model.sample(
            self._sensor("gyro"), self._sensor("accelerometer"), self._sensor("magnetometer")
        )

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

    def wrench(self, sensor: str) -> WrenchReading:
        """One noisy sample of a wrench sensor (``foot_wrench``, ``end_effector_wrench``)."""
        force, torque = self.wrench_ideal(sensor)
        return self.wrench_models[sensor].sample(force, torque)

    def servo_positions(self) -> np.ndarray:
        """Present joint positions (joint_order) [rad]."""
        return self.data.qpos[self._qadr].copy()

    def servo_velocities(self) -> np.ndarray:
        """Present joint velocities (joint_order) [rad/s]."""
        return self.data.qvel[self._vadr].copy()

    def servo_torques(self) -> np.ndarray:
        """Servo output torques (joint_order) [N m], limited to the stall torques."""
        return self.data.actuator_force[self._servo_act].copy()

    def servo_currents(self) -> np.ndarray:
        """Servo currents (joint_order) [A] from a linear torque constant (ASSUMPTION)."""
        return self.servo_torques() / self._kt

    def rotor_thrusts(self) -> np.ndarray:
        """Thrusts applied in the last step, ceiling effect included [N]."""
        return self._thrusts.copy()

    def rotor_distances_to_ceiling(self) -> np.ndarray:
        """Distance of each rotor to the ceiling along its axis [m] (inf: none ahead)."""
        return self._rotor_distances()

    # ---------------------------------------------------------------------- ground truth
    def ground_truth(self) -> GroundTruth:
        """The true state now (see :class:`GroundTruth`)."""
        d = self.data
        points, force, torque, zmp, slip, yaw = self._tracker.measure(d)
        fb = self._foot_body
        if self.options.fixed_base:
            lin = np.zeros(3)
            ang = np.zeros(3)
        else:
            lin = d.qvel[0:3].copy()
            ang = d.qvel[3:6].copy()
        ee_quat = np.zeros(4)
        mujoco.mju_mat2Quat(ee_quat, d.xmat[self._ee_body])
        return GroundTruth(
            time=float(d.time),
            base_position=d.xpos[fb].copy(),
            base_quaternion=d.xquat[fb].copy(),
            base_linear_velocity=lin,
            base_angular_velocity=ang,
            joint_positions=self.servo_positions(),
            joint_velocities=self.servo_velocities(),
            cog_position=d.subtree_com[fb].copy(),
            end_effector_position=d.xpos[self._ee_body].copy(),
            end_effector_quaternion=ee_quat,
            rotor_thrusts=self.rotor_thrusts(),
            foot_in_contact=points > 0,
            foot_contact_points=points,
            foot_contact_force=force,
            foot_contact_torque=torque,
            foot_zmp=zmp,
            foot_slip=slip,
            foot_slip_yaw=yaw,
        )

    def to_xml(self) -> str:
        """The generated MJCF (opens in ``python -m mujoco.viewer --mjcf``)."""
        return self.spec.to_xml()


def _has_geom(model: mujoco.MjModel, name: str) -> bool:
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name) >= 0
