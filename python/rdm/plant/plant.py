"""The MuJoCo plant of a rotor-distributed manipulator: physics + actuators + sensors.

A :class:`Plant` owns one compiled model and its data, the rotor ESC models, the ceiling
effect and the sensor error models. It runs at the physics rate (1 kHz by default); callers
(a SITL/HIL loop) decide how often to read sensors and send commands.

Per physics step: kinematics (``mj_step1``), each ESC's lag advances, each rotor's thrust is
scaled by the ceiling effect at its present distance to the ceiling, then ``mj_step2``
integrates. Every reading refers to the current time: the ``mj_forward`` that makes the
derived quantities (sensors, body poses, actuator forces) current runs lazily, once, before
the first reading or command after a step (a step that nobody reads costs no forward pass;
the trajectory is bit-identical to forwarding after every step, see docs/plant.md).

The readings (:mod:`rdm.plant.readings`) and the ground truth (:mod:`rdm.plant.truth_readout`)
are parts of :class:`Plant` in modules of their own.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable, Sequence
from pathlib import Path

import mujoco
import numpy as np

from rdm._rdm import ContactGateCore, PlantStateCore, PlantStepCore, RotorPlantCore
from rdm.plant.ceiling import CeilingEffect, NoCeilingEffect, ParametricCeilingEffect
from rdm.plant.contact_gate import build_contact_gate
from rdm.plant.description import RobotDescription, load_robot
from rdm.plant.esc import Esc, EscParams
from rdm.plant.mjcf import (
    CEILING_GEOM,
    CONTACT_SURFACE_PREFIX,
    FLOOR_GEOM,
    FOOT_PLATE_BODY,
    BuildOptions,
    ContactParams,
    build_spec,
    rotor_actuator,
    rotor_site,
    servo_actuator,
)
from rdm.plant.option_flags import SEARCH_BYTES, disableflags_address
from rdm.plant.readings import PlantReadings
from rdm.plant.sensors import (
    ImuModel,
    ImuNoise,
    WrenchNoise,
    WrenchSensorModel,
    sensor_seed_sequences,
)
from rdm.plant.servo import ServoParams, torque_constant
from rdm.plant.sleep import SLEEP_AVAILABLE, SLEEP_ENABLE_BIT, RestingSleep
from rdm.plant.truth import TRUTH_FIELDS, FootContactTracker, GroundTruth
from rdm.plant.truth_readout import PlantTruthReadout


def _vector(values: Sequence[float] | np.ndarray, n: int, name: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (n,):
        raise ValueError(f"{name}: expected {n} values, got {arr.size}")
    return arr


class Plant(PlantReadings, PlantTruthReadout):
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
        scene: edits the MjSpec before it is compiled, to add world objects (the tasks'
            boards, panels, valves); must not touch the robot.
        sleep: let MuJoCo put the robot to sleep while it rests with unchanged controls
            (:class:`rdm.plant.sleep.RestingSleep`; a no-op on a MuJoCo without sleeping,
            and with a ``scene``: with sleeping on, MuJoCo computes the poses of static bodies
            once, and the tasks move their objects by editing ``model.body_pos``).
        contact_gate: skip MuJoCo's collision detection in steps that provably have no
            contact (:mod:`rdm.plant.contact_gate`; the same numbers either way; not with a
            ``scene`` or a fixed base).
        lazy_sensors: compute MuJoCo's sensors only in the forward pass a reading runs
            (:meth:`sync`), not in every step: ``mjDSBL_SENSOR`` is set while
            ``mj_step1``/``mj_step2`` run and cleared again after them. Sensors do not act
            on the dynamics, and every reading of ``sensordata`` goes through :meth:`sync`,
            so the numbers are the same either way (docs/plant.md "Lazy sensors").
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
        scene: Callable[[mujoco.MjSpec], None] | None = None,
        sleep: bool = True,
        contact_gate: bool = True,
        lazy_sensors: bool = True,
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
        if scene is not None:
            # extra world objects (task targets, walls), before compiling: every id the plant
            # uses is looked up by name after this, so shifted geom ids cannot go stale
            scene(self.spec)
        self.model = self.spec.compile()
        self._data = mujoco.MjData(self.model)
        #: The lazy forward pass (stale after a step until the ``mj_forward`` of :meth:`sync`
        #: ran; whether the next step runs ``mj_step1``), the state version the ground-truth
        #: cache keys on (every step / reset / outside access to ``data`` moves it), the
        #: rejected servo goals and whether a step can run in Rust: one Rust object this
        #: face and the lockstep kernel both change.
        self._state = PlantStateCore()
        self._truth_cache: tuple[int, GroundTruth] | None = None
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
        env |= {g for g in range(m.ngeom) if m.geom(g).name.startswith(CONTACT_SURFACE_PREFIX)}
        self._tracker = FootContactTracker(m, self._plate_body, env)
        self._sensor_adr = {m.sensor(i).name: int(m.sensor_adr[i]) for i in range(m.nsensor)}
        adr = self._sensor_adr
        self._imu_adr = (adr["gyro"], adr["accelerometer"], adr["magnetometer"])
        self._wrench_adr = {
            key: (adr[f"{key}_force"], adr[f"{key}_torque"]) for key in desc.wrench_sensors
        }

        base = esc or EscParams()
        self._escs = tuple(
            Esc(
                EscParams(base.p2, base.p1, base.p0, base.v_ref, r.thrust_max, base.tau)
                if esc is None
                else base,
                battery_voltage,
            )
            for r in desc.rotors
        )
        self._ceiling_z = ceiling_height
        self._imu_noise = imu_noise or ImuNoise()
        self._wrench_noise = wrench_noise or WrenchNoise()
        self._thrusts_list = [0.0] * len(self.rotor_names)
        # Cached views on the MjData buffers (stable for the data's lifetime): attribute
        # access through the bindings costs more than the arithmetic at 1 kHz.
        d = self._data
        self._v_site_xmat = d.site_xmat
        self._v_site_xpos = d.site_xpos
        self._v_ctrl = d.ctrl
        self._v_qpos = d.qpos
        self._v_sensordata = d.sensordata
        self._v_qvel = d.qvel
        self._v_xpos = d.xpos
        self._v_xquat = d.xquat
        self._v_xmat = d.xmat
        self._v_subtree_com = d.subtree_com
        self._rotor_site_list = self._rotor_site.tolist()
        acts = self._rotor_act.tolist()
        contiguous = acts == list(range(acts[0], acts[0] + len(acts))) if acts else False
        self._rotor_act_slice = slice(acts[0], acts[0] + len(acts)) if contiguous else None
        self._external: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        # The per-step rotor work (ESC lags, ceiling ratios, rotor ctrl) in one Rust call; the
        # ESCs keep their thrusts in it (one source of truth for both paths).
        self._rotors = RotorPlantCore(
            self._rotor_site_list, acts, ceiling_height, d.site_xpos, d.site_xmat, d.ctrl
        )
        for i, e in enumerate(self._escs):
            e.attach(self._rotors, i)
        # Where the ground truth's one-call copy reads MjData (:meth:`_ground_truth`).
        self._rotors.set_truth_layout(
            self._foot_body,
            self._ee_body,
            self._qadr.tolist(),
            self._vadr.tolist(),
            self.options.fixed_base,
        )
        # The whole record in one call (:meth:`_ground_truth`).
        self._rotors.set_truth_record(object.__new__, GroundTruth, TRUTH_FIELDS, self._plate_body)
        self._v_ee_xmat = d.xmat[self._ee_body]
        self.ceiling_effects = (
            [ParametricCeilingEffect(radius=r.radius) for r in desc.rotors]
            if ceiling_effect is None
            else [ceiling_effect for _ in desc.rotors]
        )
        robot_root = m.body_rootid[self._foot_body]
        robot_trees = [
            int(m.body_treeid[b]) for b in range(m.nbody) if m.body_rootid[b] == robot_root
        ]
        #: The robot's sleep at rest (None: always awake; see :mod:`rdm.plant.sleep`).
        self.sleep: RestingSleep | None = (
            RestingSleep(m, d, robot_trees, self._rotor_act.tolist())
            if sleep and scene is None and SLEEP_AVAILABLE and any(t >= 0 for t in robot_trees)
            else None
        )
        #: The collision gate (None: contacts always on; see :mod:`rdm.plant.contact_gate`).
        self._contact_gate: ContactGateCore | None = (
            # a fixed base has no free root: build_contact_gate refuses it
            build_contact_gate(m, d, int(robot_root)) if contact_gate and scene is None else None
        )
        sensor_bit = int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
        # A sleeping tree keeps the sensor values of its last computed step, so while a
        # tree may sleep every step computes them (see step); sleeping outside RestingSleep's
        # control (a model that enables it itself) keeps them in every step.
        sleeps_unwatched = self.sleep is None and bool(m.opt.enableflags & SLEEP_ENABLE_BIT)
        #: The bit set in ``opt.disableflags`` while a step runs (0: sensors in every step,
        #: also when the model disables them itself).
        self._sensor_bit = (
            sensor_bit
            if lazy_sensors and not m.opt.disableflags & sensor_bit and not sleeps_unwatched
            else 0
        )
        #: Where the kernel writes that bit (None: through ``opt.disableflags``).
        self._flags_address = disableflags_address(m) if self._sensor_bit else None
        plant = weakref.proxy(self)  # the step's callbacks hold the plant weakly
        #: The physics step and the forward pass (:meth:`step`, :meth:`sync`) in Rust, the
        #: one form the lockstep kernel calls too; Python only where the state needs it.
        self._stepper = PlantStepCore(
            m,
            d,
            [
                mujoco.mj_step1,
                mujoco.mj_step2,
                mujoco.mj_forward,
                mujoco.mj_sensorPos,
                mujoco.mj_sensorVel,
            ],
            (self._flags_address, getattr(m, "_address", None), SEARCH_BYTES),
            m.opt,
            self._sensor_bit,
            self._state,
            self._rotors,
            self._contact_gate,
            self._tracker._core,
            None if self.sleep is None else self.sleep._core,
            [
                lambda: plant._step_rotors(),
                lambda: plant._apply_external(),
                lambda: plant._aim_external(),
                self._tracker.update,
            ],
        )
        self._seed_sensors()
        self.reset()

    @property
    def contact_gate(self) -> ContactGateCore | None:
        """The collision gate (its ``off_steps`` / ``on_steps`` count the steps after which
        contacts were off / on), or None."""
        return self._contact_gate

    @property
    def escs(self) -> tuple[Esc, ...]:
        """The ESC model per rotor (fixed: each keeps its state in the rotor core at its rotor
        index, the state :meth:`set_rotor_duties` commands in one call)."""
        return self._escs

    @property
    def rejected_commands(self) -> int:
        """Servo goals refused (non-finite entries of :meth:`set_servo_targets`)."""
        return self._state.rejected_commands

    @property
    def ceiling_effects(self) -> tuple[CeilingEffect, ...]:
        """Ceiling-effect model per rotor (assign a new sequence to change them)."""
        return self._ceiling_effects

    @ceiling_effects.setter
    def ceiling_effects(self, effects: Sequence[CeilingEffect]) -> None:
        effects = tuple(effects)
        if len(effects) != len(self.rotor_names):
            raise ValueError(f"ceiling_effects: expected {len(self.rotor_names)} models")
        self._ceiling_effects = effects
        # The Rust step covers the shipped models; any other model keeps the Python path.
        self._state.rotors_in_core = all(
            _core_ceiling(self._rotors, i, e) for i, e in enumerate(effects)
        )

    # ----------------------------------------------------------------- lazy forward
    @property
    def data(self) -> mujoco.MjData:
        """The MuJoCo data, brought up to date (:meth:`sync`) before it is handed out. The
        caller may change the state through it, so the next step recomputes everything."""
        if self._state.stale:
            self.sync()
        self._state.touched()  # the caller may change the state: mj_step1, no cached truth
        if self.sleep is not None:
            self.sleep.wake_next()
        if self._contact_gate is not None:
            self._contact_gate.enable()  # a changed state is collided in full
        return self._data

    def _fresh(self) -> mujoco.MjData:
        """The data after :meth:`sync`, for the plant's own reads and ctrl/xfrc writes."""
        if self._state.stale:
            self.sync()
        return self._data

    def sync(self) -> None:
        """Make every derived quantity refer to the present state: held external wrenches
        re-aimed at the bodies' new poses, then one ``mj_forward``. Runs by itself before a
        reading or a command; calling it again before the next step does nothing."""
        self._stepper.sync()

    def _aim_external(self) -> None:
        """Before a forward pass with held wrenches: kinematics, then the wrenches re-aimed."""
        m, d = self.model, self._data
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        self._apply_external()

    # ----------------------------------------------------------------- set-up and reset
    def _seed_sensors(self) -> None:
        sensors = self.description.wrench_sensors
        seeds = sensor_seed_sequences(self.seed, len(sensors))
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
        m, d = self.model, self._data
        self._state.reset()
        if self._contact_gate is not None:
            self._contact_gate.enable()
        mujoco.mj_resetData(m, d)
        if self.sleep is not None:
            self.sleep.wake_next()
        q = (
            np.zeros(len(self.joint_names))
            if q0 is None
            else _vector(q0, len(self.joint_names), "q0")
        )
        d.qpos[self._qadr] = q
        d.ctrl[self._servo_act] = q
        if self.options.servo.goal_filter_s > 0:  # the smoothed goal starts at rest on q
            d.act[m.actuator_actadr[self._servo_act]] = q
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
        for i, esc in enumerate(self.escs):  # per ESC, 1 - exp(-dt/tau), kept by the core
            self._rotors.set_alpha(i, esc.lag_factor(m.opt.timestep))
        self._tracker.reset()
        self._external.clear()
        self._state.wrenches_held = False
        self._seed_sensors()
        mujoco.mj_forward(m, d)
        self._apply_rotor_thrusts()
        mujoco.mj_forward(m, d)

    # ---------------------------------------------------------------------- commands
    def set_rotor_duties(self, duties: Sequence[float] | np.ndarray) -> None:
        """PWM duty per rotor in [0.5, 1] (0.5 stops the motor); goes through the ESC model:
        every ESC's clamp, non-finite count and duty -> thrust map in one Rust call (the
        numbers and counters of :meth:`Esc.command_duty`; every ESC's voltage factor is a
        positive finite number, so the core holds every map)."""
        self._rotors.command_duties(_vector(duties, len(self._escs), "duties").tolist())

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
        self._state.reject(int(np.count_nonzero(~ok)))
        # Sync first: readings taken after this command still see the forward
        # pass of the previous ctrl, as when the forward ran right after the step.
        self._fresh().ctrl[self._servo_act[ok]] = q[ok]

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
        rot = self._fresh().xmat[bid].reshape(3, 3)
        origin = self._fresh().xpos[bid]
        at = origin if point is None else _vector(point, 3, "point")
        self._external[bid] = (f, t, rot.T @ (at - origin))
        if self.sleep is not None:  # a push wakes the robot in the next step
            self.sleep.wake_next()
        if not (f.any() or t.any()):
            del self._external[bid]
            self._fresh().xfrc_applied[bid] = 0.0
        self._state.wrenches_held = bool(self._external)
        self._apply_external()

    def _apply_external(self) -> None:
        d = self._data  # called inside step and sync: never the syncing property
        for bid, (f, t, local) in self._external.items():
            at = d.xpos[bid] + d.xmat[bid].reshape(3, 3) @ local
            # xfrc_applied acts at the body's centre of mass: carry the force's moment over.
            d.xfrc_applied[bid, :3] = f
            d.xfrc_applied[bid, 3:] = t - np.cross(d.xipos[bid] - at, f)

    # -------------------------------------------------------------------------- physics
    def _rotor_distances(self) -> np.ndarray:
        h = self._ceiling_z
        dist = np.full(len(self.rotor_names), np.inf)
        if h is None:
            return dist
        d = self._fresh()
        for i, sid in enumerate(self._rotor_site):
            axis_z = d.site_xmat[sid][8]  # z component of the site z axis
            if axis_z > 1e-6:
                dist[i] = max(h - d.site_xpos[sid][2], 0.0) / axis_z
        return dist

    def _apply_rotor_thrusts(self) -> None:
        """Ceiling-scaled ESC thrusts into the rotor actuators (kinematics must be current).

        Every model a :class:`ParametricCeilingEffect` / :class:`NoCeilingEffect`: one Rust
        call (``RotorPlantCore.apply``, the same IEEE operations as the Python form below).
        Kept in Python because a caller's own :class:`CeilingEffect` (any other class, or
        coefficients whose ``**`` overflows in Python) is Python code the Rust core cannot
        call per rotor: its ``thrust_ratio`` scales the thrusts here, in plain floats in one
        pass (the distance arithmetic of :meth:`_rotor_distances`).
        """
        if self._state.rotors_in_core:
            self._rotors.apply()
            return
        h = self._ceiling_z
        thrusts = self._thrusts_list
        effects = self.ceiling_effects
        if h is None:
            for i, esc in enumerate(self.escs):
                thrusts[i] = esc._thrust * effects[i].thrust_ratio(math.inf)
        else:
            # ``item`` reads one element as a Python float (the rotor sites only).
            xmat_at = self._v_site_xmat.item
            xpos_at = self._v_site_xpos.item
            for i, (esc, sid) in enumerate(zip(self.escs, self._rotor_site_list, strict=True)):
                az = xmat_at(sid, 8)  # z component of the site z axis
                dist = max(h - xpos_at(sid, 2), 0.0) / az if az > 1e-6 else math.inf
                thrusts[i] = esc._thrust * effects[i].thrust_ratio(dist)
        self._rotors.set_applied(thrusts)
        if self._rotor_act_slice is not None:
            self._v_ctrl[self._rotor_act_slice] = thrusts
        else:
            self._v_ctrl[self._rotor_act] = thrusts

    @property
    def _thrusts(self) -> np.ndarray:
        return np.array(self._rotors.applied(), dtype=float)

    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics steps (readings then refer to the new time).

        Per step (``PlantStepCore``): ``mj_step1`` unless a forward pass (:meth:`sync`) already
        ran on this very state (its position and velocity stages depend on neither ctrl nor
        xfrc_applied: bit-identical, docs/plant.md), the ESC lags and ceiling-scaled thrusts
        into ctrl (:meth:`_step_rotors` for a model outside the rotor core), the held external
        wrenches, the sleep rule, ``mj_step2`` with MuJoCo's sensors off while the robot
        cannot fall asleep (lazy sensors), the foot contact tracker and the collision gate.
        """
        self._stepper.step(int(n))

    def _step_rotors(self) -> None:
        """The ESC lags (exact discretisation) and the ceiling-scaled thrusts into ctrl for a
        ceiling model outside the rotor core."""
        self._rotors.advance_lag()
        self._apply_rotor_thrusts()

    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return self._data.time

    def to_xml(self) -> str:
        """The generated MJCF (opens in ``python -m mujoco.viewer --mjcf``)."""
        return self.spec.to_xml()


def _core_ceiling(rotors: RotorPlantCore, i: int, effect: CeilingEffect) -> bool:
    """Give rotor ``i``'s model to the Rust core if it is one it reproduces bit for bit."""
    if type(effect) is NoCeilingEffect:
        rotors.set_ceiling_unity(i)
        return True
    if type(effect) is ParametricCeilingEffect:
        e = effect
        params = (e.radius, e.k1, e.k2_over_radius, e.max_ratio)
        try:
            # Python's float ** raises on overflow where Rust gives inf: keep such
            # coefficients on the Python path (q = R / (z + k2) <= R / k2 for z >= 0).
            ok = all(map(math.isfinite, params)) and math.isfinite((e.radius / e._k2) ** 2)
        except OverflowError:
            ok = False
        if ok:
            rotors.set_ceiling_parametric(i, *params)
        return ok
    return False


def _has_geom(model: mujoco.MjModel, name: str) -> bool:
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name) >= 0
