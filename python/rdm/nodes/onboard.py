"""The onboard-PC node: rosserial server to Spinal, 40 Hz position/perching control, LQI.

Paper Sec. VI-A (Fig. 6) and VII-A: the onboard processor runs the position controller and
the perching QP at 40 Hz and talks to Spinal over a UART; Spinal runs the 200 Hz attitude
loop with the gains the PC synthesizes. Wire facts: ``jsk-wire-protocols.md`` sec. 1, 3.7, 4, 5.

Node pattern (:mod:`rdm.nodes.base`): ``tick(now)`` with the time passed in, no wall clock,
ports drained without blocking. Per tick:

1. UART bytes -> :class:`~rdm.protocol.rosserial.ServerSession` (handshake, time sync);
   ``imu``, ``servo/states``, ``flight_config_ack``, ``battery_voltage_status`` are taken in.
2. Foot sensor bytes -> :class:`~rdm.nodes.onboard_foot.FootSensorReader`.
3. Arming sequence (:class:`~rdm.nodes.onboard_arming.ArmingSequencer`): ``uav_info`` /
   ``motor_info`` every 0.1 s while starting, ARM_ON after them until ack 0, ARM_OFF,
   FORCE_LANDING.
4. Control (:class:`~rdm.nodes.onboard_control.ControlPipeline`) at the present q:
   ``rpy/gain`` after each synthesis, ``p_matrix_pseudo_inverse_inertia`` every tick,
   ``four_axes/command`` every tick while Spinal is armed, ``servo/target_states`` every tick
   once joint targets are known.

Inputs from outside (any thread-free caller between ticks): :meth:`OnboardNode.set_mocap`,
:meth:`set_target`, :meth:`set_joint_targets`, :meth:`set_trajectory`, :meth:`request_perch`,
:meth:`arm`, :meth:`disarm`, :meth:`force_landing`. Every input is validated; bad ones are
counted in :attr:`OnboardNode.counts` and ignored.
"""

from __future__ import annotations

import math
import struct
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any, NamedTuple

import numpy as np

from rdm import _rdm
from rdm.nodes.bus_layout import can_table, default_neuron_joints
from rdm.nodes.joint_motion import plan_joint_motion
from rdm.nodes.onboard_arming import ArmingSequencer, FlightState
from rdm.nodes.onboard_calibration import GET_CALIB_DATA, ImuCalibrationReader
from rdm.nodes.onboard_config import OnboardConfig, ServoMap
from rdm.nodes.onboard_control import ControlCommand, ControlPipeline, Setpoint, State
from rdm.nodes.onboard_flight import FlightMode, FlightSupervisor
from rdm.nodes.onboard_foot import ByteLink, FootSensorReader
from rdm.nodes.onboard_mocap import CogEstimator
from rdm.nodes.onboard_monitors import Monitors, battery_cells
from rdm.protocol.rosserial.codec import RosTime
from rdm.protocol.rosserial.events import MessageReceived, ServiceResponse, SyncLost
from rdm.protocol.rosserial.registry import TypeRegistry, spinal_registry
from rdm.protocol.rosserial.server import PayloadTooLarge, ServerSession, TopicNotNegotiated
from rdm.protocol.rosserial.services import ServiceError

#: ``spinal/FlightConfigCmd`` INTEGRATION_CONTROL_ON_CMD.
INTEGRATION_CONTROL_ON = 160
#: How many distinct ``servo/states`` readings the node keeps the joint writes of.
SERVO_CACHE_SIZE = 8
#: ``spinal/Imu`` payload from byte 20: gyro (3 float32), mag skipped, quaternion (4 float32).
_IMU_GYRO_QUAT = struct.Struct("<3f12x4f")
#: ``spinal/Imu`` payload from byte 8: the accelerometer (3 float32, m/s^2).
_IMU_ACC = struct.Struct("<3f")
_U32 = struct.Struct("<I")
#: ``spinal/ServoStates``: stamp (8 bytes), count (uint32), 7 bytes per ``spinal/ServoState``.
_SERVO_STATES_HEAD, _SERVO_STATE_SIZE = 12, 7
#: ``spinal/ServoState``'s index (uint8) and angle (int16); temp, load, error skipped.
_SERVO_INDEX_ANGLE = struct.Struct("<Bh4x")
_SERVO_STATE_FIELDS = [
    ("index", "uint8", None),
    ("angle", "int16", None),
    ("temp", "uint8", None),
    ("load", "int16", None),
    ("error", "uint8", None),
]


class _ServoReading(NamedTuple):
    """The two fields of a ``spinal/ServoState`` the node reads."""

    index: int
    angle: int


class _ServoReadings:
    """What :meth:`OnboardNode._on_servo_states` reads of a decoded ``spinal/ServoStates``."""

    __slots__ = ("servos",)

    def __init__(self, servos: list[_ServoReading]) -> None:
        self.servos = servos


try:  # the C function np.interp ends in for float data (without its Python layers)
    from numpy._core.multiarray import interp as _compiled_interp
except ImportError:  # another numpy layout: np.interp throughout
    _compiled_interp = None
#: Topics the node publishes (Spinal subscribes).
PUBLISHED_TOPICS = (
    "uav_info",
    "motor_info",
    "flight_config_cmd",
    "four_axes/command",
    "rpy/gain",
    "p_matrix_pseudo_inverse_inertia",
    "servo/target_states",
)


def quaternion_to_euler(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """Roll, pitch, yaw (ZYX) of a unit quaternion."""
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw


_F64 = np.dtype(np.float64)


_finite_float_vector = getattr(_rdm, "finite_float_vector", None)
_servo_target_payload = getattr(_rdm, "servo_target_payload", None)


def _vector(value: Any, n: int) -> np.ndarray | None:
    """``value`` as a finite float vector of length n, else None."""
    if _finite_float_vector is not None:
        # a list/tuple of n exact floats in one Rust call: the array below, False: not finite
        got = _finite_float_vector(value, n)
        if got is not None:
            return None if got is False else got
    return _vector_plain(value, n)


def _vector_plain(value: Any, n: int) -> np.ndarray | None:
    """:func:`_vector` without the Rust call (the reference form)."""
    if type(value) in (tuple, list) and len(value) == n and all(type(v) is float for v in value):
        # the common case (a decoded message field): the same array without numpy's checks
        return np.array(value) if all(map(math.isfinite, value)) else None
    if type(value) is np.ndarray and value.dtype == _F64 and value.shape == (n,):
        # a float vector already (a script's setpoint): the same view as below, its values
        # checked as Python floats (np.isfinite's dispatch costs more than the check)
        return value.reshape(-1) if all(map(math.isfinite, value.tolist())) else None
    try:
        v = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        return None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        return None
    return v


def _floats(values: Any) -> list[float]:
    """``[float(v) for v in values]``; a float64 array's ``tolist`` gives the same floats."""
    if type(values) is np.ndarray and values.dtype == np.float64 and values.ndim == 1:
        return values.tolist()
    return [float(v) for v in values]


def _scalar(value: Any) -> float | None:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def servo_states_decodes(payload: bytes) -> bool:
    """Whether ``spinal/ServoStates`` decodes ``payload`` (a stamp, a count and exactly that
    many 7-byte entries; anything shorter or longer is a decode error)."""
    n = len(payload)
    if n < _SERVO_STATES_HEAD:
        return False
    return n - _SERVO_STATES_HEAD == _SERVO_STATE_SIZE * _U32.unpack_from(payload, 8)[0]


def _four_axis_payload(angles: Sequence[float], base_thrust: Any) -> bytes | None:
    """``spinal/FourAxisCommand`` bytes (float32[3] angles, float32[] base_thrust) of the
    values the message would carry; None when they do not pack (the codec raises then)."""
    thrust = _floats(base_thrust)
    try:
        return struct.pack(f"<3fI{len(thrust)}f", *angles, len(thrust), *thrust)
    except (struct.error, TypeError, OverflowError):
        return None


def default_servo_map(robot: Any) -> ServoMap:
    """Servo map of the robot's default CAN wiring (:mod:`rdm.nodes.bus_layout`, the wiring
    the Neuron mirrors use): Spinal numbers servos by Neuron slave id, then servo index."""
    wiring = default_neuron_joints(
        [r["name"] for r in robot.rotors], robot.vectoring_units, tuple(robot.joint_names)
    )
    return ServoMap.from_can_table(can_table(wiring), tuple(robot.joint_names))


class OnboardNode:
    """The onboard PC (see the module doc). ``uart``/``foot_sensor``: byte links with
    ``read_available()`` and ``write()`` (e.g. :func:`rdm.link.serial.open_serial`)."""

    #: What its tick changes of the lockstep kernel's parts (``rdm.nodes.lockstep_kernel``):
    #: bytes written into the Spinal and Leptrino UARTs. It never touches the plant.
    kernel_touches = ("spinal", "leptrino")

    name = "onboard"

    def __init__(
        self,
        uart: ByteLink,
        foot_sensor: ByteLink | None = None,
        robot: Any = None,
        rate_hz: float | None = None,
        *,
        config: OnboardConfig | None = None,
        time_source: Callable[[float], RosTime] | None = None,
        registry: TypeRegistry | None = None,
    ) -> None:
        if robot is None:
            from rdm.model import Robot

            robot = Robot.default()
        if config is None:
            config = OnboardConfig() if rate_hz is None else OnboardConfig(rate_hz=rate_hz)
        elif rate_hz is not None and rate_hz != config.rate_hz:
            raise ValueError("rate_hz given twice (argument and config) with different values")
        if config.servo_map is None:
            config = replace(config, servo_map=default_servo_map(robot))
        self.config = config
        self.period = 1.0 / config.rate_hz
        self.robot = robot
        self.uart = uart
        reg = registry or spinal_registry()
        kwargs = {} if time_source is None else {"time_source": time_source}
        self.session = ServerSession(reg, **kwargs)
        self._msg = {
            t: reg.msg(n)
            for t, n in (
                ("uav_info", "spinal/UavInfo"),
                ("motor_info", "spinal/PwmInfo"),
                ("motor_unit", "spinal/MotorInfo"),
                ("flight_config_cmd", "spinal/FlightConfigCmd"),
                ("four_axes/command", "spinal/FourAxisCommand"),
                ("rpy/gain", "spinal/RollPitchYawTerms"),
                ("rpy_term", "spinal/RollPitchYawTerm"),
                ("p_matrix_pseudo_inverse_inertia", "spinal/PMatrixPseudoInverseWithInertia"),
                ("pinv_unit", "spinal/PMatrixPseudoInverseUnit"),
                ("servo/target_states", "spinal/ServoControlCmd"),
                ("desire_coordinate", "spinal/DesireCoord"),
                ("servo/torque_enable", "spinal/ServoTorqueCmd"),
            )
        }
        self.arming = ArmingSequencer(config.info_period_s, config.command_retry_s)
        #: Spinal's IMU calibration, read once per handshake (``imu_calib`` GET_CALIB_DATA)
        self.imu_calibration = ImuCalibrationReader()
        self._imu_calib_request = reg.srv("spinal/ImuCalib").request
        self.control = ControlPipeline(robot, config)
        self.foot = (
            None
            if foot_sensor is None
            else FootSensorReader(
                foot_sensor,
                config.foot_sensor_model,
                config.foot_sensor_offset,
                config.foot_restart_s,
            )
        )
        #: the operator layer (take-off, go-to, landing, touchdown) and the health monitors
        self.flight = FlightSupervisor(config.flight)
        self.monitors = Monitors(
            config.monitors,
            config.monitors.battery_cells
            or battery_cells([float(r[0]) for r in config.pwm_info.motor_info]),
        )
        self._flight_setpoint: Setpoint | None = None
        #: the CoG state from marker poses (:meth:`set_mocap_pose`)
        self.cog_estimator = CogEstimator(robot, config.mocap)
        self._imu_at: float | None = None
        self._imu_acc: list[float] | None = None
        self._servo_at: float | None = None
        self._servo_rx = 0
        self._link_up_at: float | None = None
        self._command_at: float | None = None
        self.ground_lost = False
        self.counts: Counter[str] = Counter()
        self.published: Counter[str] = Counter()
        self.bytes_written = 0
        n_q = robot.n_q
        self.present_q = config.initial_joint_vector(n_q)
        self._seen = np.zeros(n_q, dtype=bool)
        self.joint_targets: np.ndarray | None = None
        self._trajectory: tuple[np.ndarray, np.ndarray] | None = None
        self.setpoint = Setpoint(np.zeros(3), np.zeros(3), 0.0)
        self._mocap: tuple[np.ndarray, np.ndarray, float | None] | None = None
        self._mocap_stamp: float | None = None
        #: the sample is a marker pose taken at its stamp (its CoG state is then predicted
        #: to the tick's time, :meth:`_mocap_at`); False: a state given as of now
        self._mocap_latent = False
        self._mocap_lost_since: float | None = None
        # IMU: the newest valid quaternion / gyro of each tick's messages, converted only when
        # read (imu_euler, imu_gyro): several arrive per tick and all but the last are unused
        self._imu_quat: list[float] | None = None
        self._imu_euler: tuple[float, float, float] | None = None
        self._gyro_src: Sequence[float] | None = None
        self._imu_gyro: np.ndarray | None = None
        self.battery_voltage: float | None = None
        self.last_command: ControlCommand | None = None
        #: The joint goals [rad] of the last ``servo/target_states`` sent (the vectoring
        #: joints' angles written over the plan in flight), in joint order.
        self.last_servo_goals: list[float] | None = None
        self.last_alpha_beta: tuple[tuple[float, ...], tuple[float, ...]] | None = None
        self._requests: list[str] = []
        self._perch_request = False
        #: the name of the position-gain profile in effect ("default": ``position_gains``)
        self.gain_profile = "default"
        self._started = False
        self._now = 0.0
        self._last_control: float | None = None
        self._arm_z: float | None = None
        self._announced = False
        self.integration_on_sent = False
        self.servos_torque_on = False
        self._torque_sent_at: float | None = None
        # messages rebuilt only when their content changed (same object -> same bytes)
        self._gains_msg: tuple[tuple[bytes, str, tuple[int, ...]], Any] | None = None
        self._p_matrix_msg: tuple[Any, Any] | None = None
        self._desire_msg: tuple[Any, Any] | None = None
        #: ``servo/states`` readings seen before (the servos hold still for many messages) are
        #: applied from their cached joint writes; False: every message through the loop
        self.reuse_servo_states = True
        self._servo_cache: dict[tuple, tuple[np.ndarray, np.ndarray, int, bool]] = {}
        self._servo_cache_map: ServoMap | None = None
        #: the same entries by the readings' payload bytes after the stamp (deferred path)
        self._servo_raw: dict[bytes, tuple[np.ndarray, np.ndarray, int, bool]] = {}
        self._servo_codec = reg.msg("spinal/ServoStates")
        #: a new ``servo/states`` payload's servo indices and angles unpacked with one
        #: ``struct`` (what :meth:`_on_servo_states` reads), when the layout is the one
        #: ``_SERVO_INDEX_ANGLE`` reads; False: decoded by the codec (the plain form)
        servo_fields = [
            (f.name, f.base_type, f.array_len) for f in reg.msg("spinal/ServoState").spec.fields
        ]
        self.fast_servo_decode = servo_fields == _SERVO_STATE_FIELDS
        imu_size = reg.msg("spinal/Imu").fixed_size
        #: ``imu`` and ``servo/states`` are taken in from their payloads (the session defers
        #: their decoding; only what the node reads is unpacked); False: decoded messages
        self.raw_rx = imu_size == 60  # the layout _IMU_GYRO_QUAT reads
        if self.raw_rx:
            self.session.deferred.update(
                {
                    "imu": ("spinal/Imu", lambda p: len(p) == 60, self._on_imu_payload),
                    "servo/states": (
                        "spinal/ServoStates",
                        servo_states_decodes,
                        self._on_servo_payload,
                    ),
                }
            )
        #: commands serialized by the node where the wire form is a plain struct (rpy/gain,
        #: four_axes/command, servo/target_states) and unchanged messages (pinv, desire) sent
        #: as the payload encoded once; False: every message through the codec
        self.direct_tx = True
        self._payloads: dict[str, tuple[Any, Any, bytes]] = {}
        #: trajectory targets through the C interpolation ``np.interp`` calls for float data,
        #: on contiguous copies of the joint columns (made once per trajectory); False:
        #: ``np.interp`` per joint (the plain form)
        self.fast_interp = _compiled_interp is not None
        self._trajectory_columns: tuple[Any, tuple[np.ndarray, ...]] | None = None
        self._target_ticks: tuple[ServoMap, bytes, list[int]] | None = None
        #: ``servo/target_states`` goals and payload of a :class:`ServoMap` in one Rust call
        #: (``rdm._rdm.servo_target_payload``); False: :meth:`_send_servo_targets_plain`
        self.fast_servo_targets = _servo_target_payload is not None

    # ------------------------------------------------------------------ inputs from outside
    def set_mocap(
        self, position: Sequence[float], velocity: Sequence[float], yaw: float | None = None
    ) -> bool:
        """Motion-capture (or ground-truth) world position/velocity of the controlled point
        and optionally yaw [rad]; stamped with the node's current time. Invalid -> counted,
        ignored (the last command is held)."""
        p, v = _vector(position, 3), _vector(velocity, 3)
        y = None if yaw is None else _scalar(yaw)
        if p is None or v is None or (yaw is not None and y is None):
            self.counts["mocap_invalid"] += 1
            return False
        self._mocap = (p, v, y)
        self._mocap_stamp = self._now
        self._mocap_latent = False
        return True

    def set_mocap_pose(
        self, position: Sequence[float], quaternion: Sequence[float], stamp: float | None = None
    ) -> bool:
        """A motion-capture sample as the system gives it: the world pose of the marker body
        on the root link (position [m], quaternion x, y, z, w) taken at ``stamp`` (node time;
        default: now). The CoG state comes from :class:`rdm.nodes.onboard_mocap.CogEstimator`
        at the present joint angles. Invalid (non-finite, not a unit quaternion within 1 %,
        a stamp more than 0.1 s ahead of the node) -> counted, ignored."""
        p, quat = _vector(position, 3), _vector(quaternion, 4)
        st = self._now if stamp is None else _scalar(stamp)
        norm = 0.0 if quat is None else float(np.linalg.norm(quat))
        if (
            p is None
            or quat is None
            or st is None
            or abs(norm - 1.0) > 0.01
            or st > self._now + 0.1
        ):
            self.counts["mocap_invalid"] += 1
            return False
        cog, velocity, yaw = self.cog_estimator.update(st, p, quat / norm, self.present_q)
        self._mocap = (cog, velocity, yaw)
        self._mocap_stamp = st
        self._mocap_latent = True
        return True

    def set_target(
        self,
        position: Sequence[float],
        yaw: float = 0.0,
        velocity: Sequence[float] | None = None,
    ) -> bool:
        """World target position [m], yaw [rad], optional velocity [m/s]."""
        p = _vector(position, 3)
        v = np.zeros(3) if velocity is None else _vector(velocity, 3)
        y = _scalar(yaw)
        if p is None or v is None or y is None:
            self.counts["target_invalid"] += 1
            return False
        self.setpoint = Setpoint(p, v, y)
        self.flight.manual()
        return True

    def set_joint_targets(self, q: Sequence[float]) -> bool:
        """Joint targets: q1..q6 (vectoring targets kept) or the full joint_order vector."""
        n_q = self.robot.n_q
        arr = _vector(q, 6 if np.size(q) == 6 else n_q)
        if arr is None:
            self.counts["joint_targets_invalid"] += 1
            return False
        base = self.joint_targets if self.joint_targets is not None else self.present_q.copy()
        base = base.copy()
        base[: arr.size] = arr
        self.joint_targets = base
        self._trajectory = None
        return True

    def set_trajectory(self, points: Sequence[tuple[float, Sequence[float]]]) -> bool:
        """Planner output: (node time [s], full joint_order q) pairs, strictly increasing
        times; targets are interpolated linearly and held after the last point."""
        try:
            times = np.array([float(t) for t, _ in points])
            qs = np.array([np.asarray(q, dtype=float).reshape(-1) for _, q in points])
        except (TypeError, ValueError):
            self.counts["trajectory_invalid"] += 1
            return False
        if (
            times.size == 0
            or qs.shape != (times.size, self.robot.n_q)
            or not (np.all(np.isfinite(times)) and np.all(np.isfinite(qs)))
            or np.any(np.diff(times) <= 0)
        ):
            self.counts["trajectory_invalid"] += 1
            return False
        self._trajectory = (times, qs)
        return True

    def move_joints(self, q: Sequence[float]) -> str | None:
        """Move the joints to ``q`` (q1..q6, vectoring targets kept, or the full joint_order
        vector) along a jerk-limited path (:mod:`rdm.nodes.joint_motion`, limits
        ``FlightLimits.joint_max_*``) from the present targets; the refusal reason or None."""
        n_q = self.robot.n_q
        arr = _vector(q, 6 if np.size(q) == 6 else n_q)
        if arr is None:
            self.counts["joint_targets_invalid"] += 1
            return f"q must be 6 or {n_q} finite numbers"
        start = self._current_joint_targets(self._now)
        start = (self.present_q if start is None else start).copy()
        goal = start.copy()
        goal[: arr.size] = arr
        lim = self.config.flight
        points = plan_joint_motion(
            self._now,
            start,
            goal,
            lim.joint_max_velocity,
            lim.joint_max_acceleration,
            lim.joint_max_jerk,
        )
        if points is None or not self.set_trajectory(points):
            return "no joint trajectory to the goal"
        self.counts["joint_motion"] += 1
        return None

    def request_perch(self, on: bool = True) -> None:
        """Switch between flight mode and perching mode (eq. 20's λ_perch on/off) at once,
        without the perch sequence (:meth:`perch`, :meth:`unperch`)."""
        self._perch_request = bool(on)

    def perch(self, speed: float | None = None) -> str | None:
        """The perch sequence: approach (the z setpoint rising at ``speed``, default
        ``FlightLimits.approach_speed``) until the foot sensor reads more than
        ``FlightLimits.contact_fz``, then the perching control (eq. 20) and the
        ``perched_gains`` profile at the contact height. The refusal reason or None."""
        if self.foot is None:
            return "no foot sensor"
        if not self.arming.flying:
            return "not flying"
        profile = self.config.flight.perched_gains
        if profile != "default" and profile not in self.config.gain_profiles:
            return f"FlightLimits.perched_gains names no gain profile ({profile!r})"
        sp = self.setpoint
        return self.flight.request_approach(self._now, sp.position, sp.yaw, speed)

    def unperch(self) -> str | None:
        """Leave the perch: perching control off, a jerk-limited path down, then hover."""
        reason = self.flight.request_unperch(self._now)
        if reason is None:
            self._perch_request = False
        return reason

    def arm(self) -> str | None:
        """Start the arming sequence; the refusal reason (battery) or None."""
        refusal = self.monitors.arm_refusal()
        if refusal is not None:
            self.monitors.trip("arm_refused", refusal, self._now)
            return refusal
        self._requests.append("arm")
        return None

    def disarm(self) -> None:
        """ARM_OFF (the motors stop at once)."""
        self._requests.append("disarm")

    def force_landing(self) -> None:
        """FORCE_LANDING to Spinal; the node then descends under position control while it
        has position feedback, else stays silent so that Spinal's own ramp acts."""
        self._requests.append("force_landing")

    # ------------------------------------------------------------------ operator layer
    def takeoff(self, height: float | None = None) -> str | None:
        """Arm if needed, then climb ``height`` m (default ``FlightLimits.takeoff_height``)
        above the ground z at arming; the refusal reason or None."""
        reason = self.flight.request_takeoff(height)
        if reason is None and self.arming.state in (FlightState.IDLE, FlightState.DISARMING):
            reason = self.arm()
            if reason is not None:
                self.flight.cancel_takeoff()
        return reason

    def land(self) -> str | None:
        """Descend at ``FlightLimits.land_descend_rate``, detect touchdown, disarm."""
        if self.control.perching:
            return "perched: unperch first"
        return self.flight.request_land(self._now)

    def halt(self) -> None:
        """ARM_OFF from any state (JSK ``halt``): the motors stop where the robot is."""
        self.counts["halt"] += 1
        self._requests.append("disarm")

    def goto(self, position: Sequence[float], yaw: float = 0.0) -> str | None:
        """Fly to a world position [m] and yaw [rad] along a jerk-limited path (hover only)."""
        p, y = _vector(position, 3), _scalar(yaw)
        if p is None or y is None:
            self.counts["goto_invalid"] += 1
            return "position must be 3 finite numbers and yaw finite"
        return self.flight.request_goto(p, y, self._now)

    def set_gain_profile(self, name: str, bumpless: bool = True) -> str | None:
        """Switch the position gains to a named profile of ``OnboardConfig.gain_profiles``
        ("default": ``position_gains``), bumplessly unless told otherwise."""
        profiles = {"default": self.config.position_gains, **self.config.gain_profiles}
        if name not in profiles:
            return f"unknown gain profile {name!r}; known: {sorted(profiles)}"
        self.use_position_gains(profiles[name], name, bumpless)
        return None

    def use_position_gains(self, gains: dict, name: str, bumpless: bool = False) -> None:
        """Position gains (``OnboardConfig.position_gains`` keys) under a profile ``name``: a
        script's gain schedule outside the configured profiles. The perch contact switches
        back to ``FlightLimits.perched_gains`` when ``name`` differs from it."""
        self.control.set_position_gains(dict(gains), bumpless=bumpless)
        self.gain_profile = name

    def on_ground_lost(self) -> None:
        """The ground station fell silent: land in flight; perched, hold (or land, as
        ``MonitorLimits.ground_loss_perched`` says)."""
        self.ground_lost = True
        self.monitors.trip("ground_lost", "no ground heartbeat", self._now)
        self._react("ground_lost", self._now)

    def on_ground_restored(self) -> None:
        """The ground station is back (a landing it caused goes on)."""
        self.ground_lost = False
        self.counts["ground_restored"] += 1

    # ---------------------------------------------------------------------------- tick
    def tick(self, now: float) -> None:
        """Advance to ``now`` (s): UART in, foot sensor, arming, control, UART out."""
        if not math.isfinite(now) or (self._started and now < self._now):
            self.counts["bad_time"] += 1
            return
        self._now = now
        if not self._started:
            self.session.start(now)
            self._started = True
        try:
            data = self.uart.read_available()
        except OSError:
            self.counts["uart_read_error"] += 1
            data = b""
        for event in self.session.feed(data, now):
            if event.__class__ is tuple:  # a deferred topic's (handler, payload)
                event[0](event[1])
            else:
                self._on_event(event)
        if self.foot is not None:
            self.foot.poll(now)
        for req in self._requests:
            getattr(self.arming, req)(now)
            if req == "arm":
                self.control.reset_integrators()
                self._arm_z, self.integration_on_sent = None, False
        self._requests.clear()
        if self.counts["rx:servo/states"] != self._servo_rx:
            self._servo_rx, self._servo_at = self.counts["rx:servo/states"], now
        if self.session.outbound:  # Spinal's subscribers are known: the handshake is done
            if self._link_up_at is None:
                self._link_up_at = now
            if not self._announced:
                # uav_info/motor_info once per handshake, so Spinal (motor_number > 0) accepts
                # the gains and the pinv message before arming (assumption, docs/onboard.md)
                self._announced = all(
                    self._publish(topic, self._info_message(topic))
                    for topic in ("uav_info", "motor_info")
                )
            self._read_imu_calibration(now)
            self._arming_messages(now)
            self._torque_on(now)
            self._control(now)
        else:
            self.counts["waiting_for_handshake"] += 1
        self.session.poll(now)
        out = self.session.take_output()
        if out:
            try:
                self.bytes_written += self.uart.write(out)
            except OSError:
                self.counts["uart_write_error"] += 1

    def close(self) -> None:
        """Stop the foot sensor stream (the ports belong to the caller)."""
        if self.foot is not None:
            self.foot.stop()

    # ------------------------------------------------------------------------ receiving
    @property
    def mocap(self) -> tuple[np.ndarray, np.ndarray, float | None] | None:
        """The last accepted mocap sample ``(position, velocity, yaw)`` (None before one)."""
        return self._mocap

    @property
    def imu_euler(self) -> tuple[float, float, float] | None:
        """Roll, pitch, yaw of the newest valid ``imu`` quaternion (None before one)."""
        if self._imu_euler is None and self._imu_quat is not None:
            x, y, z, w = self._imu_quat
            self._imu_euler = quaternion_to_euler(x, y, z, w)
        return self._imu_euler

    @property
    def imu_gyro(self) -> np.ndarray | None:
        """The newest valid ``imu`` gyro vector [rad/s] (None before one)."""
        if self._gyro_src is not None:
            self._imu_gyro, self._gyro_src = np.array(self._gyro_src), None
        return self._imu_gyro

    def _read_imu_calibration(self, now: float) -> None:
        """Ask Spinal for its IMU calibration (once per handshake, retried until answered)."""
        if not self.config.read_imu_calibration or not self.imu_calibration.request(now):
            return
        try:
            self.session.call_service(
                "imu_calib", self._imu_calib_request.new(command=GET_CALIB_DATA, data=[]), now
            )
        except ServiceError:  # not offered (yet) or a call still pending: the retry asks again
            self.imu_calibration.counts["call_refused"] += 1

    def _on_event(self, event: Any) -> None:
        if isinstance(event, SyncLost):
            self.counts["sync_lost"] += 1
            self._link_up_at = None
            self.arming.link_lost()
            self._announced = False
            self.imu_calibration.reset()
            return
        if isinstance(event, ServiceResponse):
            if event.service == "imu_calib":
                r = event.response
                self.imu_calibration.on_response(bool(r.success), r.data)
            return
        if not isinstance(event, MessageReceived):
            return
        msg = event.message
        self.counts[f"rx:{event.topic}"] += 1
        if event.topic == "imu":
            q = [float(v) for v in msg.quaternion]
            if not all(map(math.isfinite, q)) or abs(math.fsum([v * v for v in q]) - 1) > 0.1:
                self.counts["imu_invalid"] += 1
                return
            self._imu_quat, self._imu_euler = q, None
            self._imu_at, self._imu_acc = self._now, [float(v) for v in msg.acc]
            g = msg.gyro
            if type(g) in (tuple, list) and len(g) == 3 and all(type(v) is float for v in g):
                if all(map(math.isfinite, g)):  # what _vector accepts; converted when read
                    self._gyro_src = g
            else:
                arr = _vector(g, 3)
                if arr is not None:
                    self._gyro_src, self._imu_gyro = None, arr
        elif event.topic == "servo/states":
            self._on_servo_states(msg)
        elif event.topic == "servo/torque_states":
            flags = [bool(v) for v in msg.torque_enable]
            indices = self.config.servo_map.servo_index
            self.servos_torque_on = all(i < len(flags) and flags[i] for i in indices)
        elif event.topic == "flight_config_ack":
            before = self.arming.state
            self.arming.on_ack(int(msg.data))
            if before is not FlightState.ARMED and self.arming.state is FlightState.ARMED:
                self.control.reset_integrators()
        elif event.topic == "battery_voltage_status":
            v = float(msg.data)
            if self.monitors.battery(v, self._now):
                self.battery_voltage = v
            else:
                self.counts["battery_invalid"] += 1

    def _on_imu_payload(self, payload: bytes) -> None:
        """An ``imu`` message from its payload (one the codec decodes): what ``_on_event`` does
        with the decoded message, reading only the gyro and the quaternion."""
        self.counts["rx:imu"] += 1
        gx, gy, gz, x, y, z, w = _IMU_GYRO_QUAT.unpack_from(payload, 20)
        q = [x, y, z, w]
        if not all(map(math.isfinite, q)) or abs(math.fsum((x * x, y * y, z * z, w * w)) - 1) > 0.1:
            self.counts["imu_invalid"] += 1
            return
        self._imu_quat, self._imu_euler = q, None
        self._imu_at, self._imu_acc = self._now, list(_IMU_ACC.unpack_from(payload, 8))
        g = [gx, gy, gz]
        if all(map(math.isfinite, g)):
            self._gyro_src = g

    def _on_servo_payload(self, payload: bytes) -> None:
        """A ``servo/states`` message from its payload (one the codec decodes): a reading seen
        before (same bytes after the stamp) applied from its cached entry, else decoded."""
        self.counts["rx:servo/states"] += 1
        body = None
        if self.reuse_servo_states:
            self._servo_cache_valid()
            body = payload[8:]
            hit = self._servo_raw.get(body)
            if hit is not None:
                self._apply_servo_entry(hit)
                return
        if self.fast_servo_decode and servo_states_decodes(payload):
            # the index and angle of each entry, as the codec decodes them (uint8, int16)
            readings = _SERVO_INDEX_ANGLE.iter_unpack(memoryview(payload)[_SERVO_STATES_HEAD:])
            msg = _ServoReadings(list(map(_ServoReading._make, readings)))
        else:
            msg = self._servo_codec.decode(payload)
        entry = self._on_servo_states(msg)
        if body is not None and entry is not None:
            raw = self._servo_raw
            raw[body] = entry
            if len(raw) > SERVO_CACHE_SIZE:
                del raw[next(iter(raw))]  # the oldest

    def _servo_cache_valid(self) -> None:
        """Forget the cached servo entries when the servo map object changed."""
        smap = self.config.servo_map
        if smap is not self._servo_cache_map:
            self._servo_cache.clear()
            self._servo_raw.clear()
            self._servo_cache_map = smap

    def _apply_servo_entry(self, entry: tuple[np.ndarray, np.ndarray, int, bool]) -> None:
        # a reading seen before: the same joint writes and counts as the loop
        joints, values, n_unknown, partial = entry
        self.present_q[joints] = values
        self._seen[joints] = True
        if n_unknown:
            self.counts["servo_unknown_index"] += n_unknown
        if partial:
            self.counts["servo_states_partial"] += 1
        self._hold_present_q()

    def _on_servo_states(self, msg: Any) -> tuple[np.ndarray, np.ndarray, int, bool] | None:
        """Apply one decoded reading; returns its cache entry (None when not cacheable)."""
        smap = self.config.servo_map
        key = None
        if self.reuse_servo_states:
            self._servo_cache_valid()
            try:
                key = tuple([(s.index, s.angle) for s in msg.servos])
                hit = self._servo_cache.get(key)
            except (TypeError, AttributeError):  # not hashable / not servo entries: plain path
                key = hit = None
            if hit is not None:
                self._apply_servo_entry(hit)
                return hit
        covered = set()
        joints, values, n_unknown = [], [], 0
        for s in msg.servos:
            joint = smap.joint_of(int(s.index))
            if joint is None or joint >= self.robot.n_q:
                self.counts["servo_unknown_index"] += 1
                n_unknown += 1
                continue
            value = smap.to_rad(joint, int(s.angle))
            self.present_q[joint] = value
            self._seen[joint] = True
            covered.add(joint)
            joints.append(joint)
            values.append(value)
        partial = len(covered) != self.robot.n_q
        if partial:
            self.counts["servo_states_partial"] += 1
        entry = None
        if key is not None and len(covered) == len(joints):  # no joint written twice
            cache = self._servo_cache
            entry = (np.array(joints, dtype=np.intp), np.array(values), n_unknown, partial)
            cache[key] = entry
            if len(cache) > SERVO_CACHE_SIZE:
                del cache[next(iter(cache))]  # the oldest
        self._hold_present_q()
        return entry

    def _hold_present_q(self) -> None:
        if self.joint_targets is None and self._trajectory is None and self._seen.all():
            self.joint_targets = self.present_q.copy()  # hold where the arm is

    # ------------------------------------------------------------------------- sending
    def _publish(self, topic: str, msg: Any) -> bool:
        return self._send(self.session.publish, topic, msg)

    def _publish_payload(self, topic: str, payload: bytes) -> bool:
        """:meth:`_publish` of a message already serialized with the topic's codec."""
        session = self.session
        if self.direct_tx and session.try_publish_payload(topic, payload):
            self.published[topic] += 1  # as _send counts a send
            return True
        return self._send(session.publish_payload, topic, payload)

    def _send(self, publish: Callable[[str, Any], int], topic: str, what: Any) -> bool:
        """One publish: refusals counted per topic, sends counted in ``published``."""
        try:
            publish(topic, what)
        except TopicNotNegotiated:
            self.counts[f"not_negotiated:{topic}"] += 1
            return False
        except PayloadTooLarge:
            self.counts[f"too_large:{topic}"] += 1
            return False
        self.published[topic] += 1
        return True

    def _publish_same(self, topic: str, msg: Any) -> bool:
        """:meth:`_publish` of a message object the node never mutates: serialized once per
        codec (the topic's codec gives the same bytes for the same unchanged message)."""
        remote = self.session.outbound.get(topic)
        if remote is None or not self.direct_tx:
            return self._publish(topic, msg)
        cached = self._payloads.get(topic)
        if cached is None or cached[0] is not msg or cached[1] is not remote.codec:
            cached = self._payloads[topic] = (msg, remote.codec, remote.codec.encode(msg))
        return self._publish_payload(topic, cached[2])

    def _direct_remote(self, topic: str, type_name: str) -> bool:
        """Whether ``topic`` may be sent as a payload the node packs itself: fast path on and
        the device subscribes to it with ``type_name`` (else the codec path, which raises or
        counts exactly as before)."""
        if not self.direct_tx:
            return False
        remote = self.session.outbound.get(topic)
        return remote is not None and remote.type == type_name

    def _info_message(self, topic: str) -> Any:
        """``uav_info`` or ``motor_info`` from the configuration."""
        c = self.config
        if topic == "uav_info":
            return self._msg[topic].new(motor_num=c.motor_num, uav_model=c.uav_model)
        p = c.pwm_info
        units = [
            self._msg["motor_unit"].new(
                voltage=float(r[0]),
                max_thrust=float(r[1]),
                polynominal=[float(v) for v in r[2:7]],
            )
            for r in p.motor_info
        ]
        return self._msg[topic].new(
            min_pwm=p.min_pwm,
            max_pwm=p.max_pwm,
            min_thrust=p.min_thrust,
            force_landing_thrust=p.force_landing_thrust,
            pwm_conversion_mode=p.mode,
            motor_info=units,
        )

    def _arming_messages(self, now: float) -> None:
        for topic, cmd in self.arming.due(now):
            if topic in ("uav_info", "motor_info"):
                msg = self._info_message(topic)
            else:
                msg = self._msg[topic].new(cmd=int(cmd))
            if self._publish(topic, msg):
                self.arming.sent(topic, now)

    def _current_joint_targets(self, now: float) -> np.ndarray | None:
        trajectory = self._trajectory
        if trajectory is not None:
            times, qs = trajectory
            if self.fast_interp and qs.dtype == np.float64 and qs.ndim == 2:
                # np.interp(x, xp, fp) of a real fp is compiled_interp(x, xp, fp, None, None)
                cached = self._trajectory_columns
                if cached is None or cached[0] is not trajectory:
                    columns = tuple(np.ascontiguousarray(qs[:, j]) for j in range(qs.shape[1]))
                    cached = self._trajectory_columns = (trajectory, columns)
                interp = _compiled_interp
                return np.array([interp(now, times, column, None, None) for column in cached[1]])
            return np.array([np.interp(now, times, qs[:, j]) for j in range(qs.shape[1])])
        return self.joint_targets

    def _mocap_usable(self, now: float) -> bool:
        return (
            self._mocap is not None
            and self._mocap_stamp is not None
            and now - self._mocap_stamp <= self.config.mocap_timeout_s + 1e-9
        )

    def _mocap_at(self, now: float) -> tuple[np.ndarray, np.ndarray, float | None]:
        """The usable mocap state at ``now``: a marker pose's CoG position predicted over the
        sample's age with its estimated velocity (constant velocity, the filter's model:
        motion capture's latency compensated), else the sample as given."""
        assert self._mocap is not None and self._mocap_stamp is not None
        p, v, y = self._mocap
        age = now - self._mocap_stamp
        if self._mocap_latent and age > 0.0:
            p = p + v * age
        return p, v, y

    def _supervise(self, now: float, dt: float) -> None:
        """Monitors, the operator layer's setpoint and touchdown (then ARM_OFF)."""
        flying = self.arming.flying
        p = v = None
        yaw = 0.0
        if self._mocap_usable(now):
            p, v, y = self._mocap_at(now)
            euler = self.imu_euler
            yaw = y if y is not None else (euler[2] if euler is not None else 0.0)
        self._monitor(now, flying, p)
        if self.flight.mode is FlightMode.APPROACH and p is not None:
            self._contact_check(now, float(p[2]))
        landing = self.arming.state is FlightState.LANDING
        sp = self.flight.update(now, flying, landing, p, v, yaw, self.setpoint.position, dt)
        self._flight_setpoint = None if sp is None else Setpoint(*sp)
        if self.flight.mode is FlightMode.LAND and self._perch_request:
            # a landing (force landing, a fault) from the perch: perching control off first
            self._perch_request = False
            self.control.set_perching(False)
            self.counts["perch_released_to_land"] += 1
        if flying and self.flight.mode is FlightMode.LAND and p is None:
            self.flight.imu_touchdown(now, self.imu_gyro, self._imu_acc, self.control.perching)
        if self.flight.take_touchdown():
            self.monitors.trip("touchdown", "landed: ARM_OFF", now)
            self.arming.disarm(now)

    def _contact_check(self, now: float, z: float) -> None:
        """The approach's contact: the foot sensor's fresh normal force above
        ``FlightLimits.contact_fz`` -> perched at the measured height ``z``, the
        ``perched_gains`` profile now and the perching control from the next tick (whose
        synthesis then sees it first, as for :meth:`request_perch`)."""
        lim = self.config.flight
        wrench = None if self.foot is None else self.foot.latest(now, self.config.foot_timeout_s)
        if wrench is None or not float(wrench[2]) > lim.contact_fz:
            return
        self.flight.contact(now, z)
        self._perch_request = True  # the next tick's model update and synthesis perch
        if self.gain_profile != lim.perched_gains:
            self.set_gain_profile(lim.perched_gains, bumpless=False)
        self.monitors.note("contact", f"foot F_z {float(wrench[2]):.2f} N: perched", now)

    def _monitor(self, now: float, flying: bool, position: np.ndarray | None) -> None:
        """Freshness of Spinal's imu and the servos, the foot sensor while perched, the
        geofence and the battery; a trip in flight lands, perched it holds."""
        m, lim = self.monitors, self.config.monitors
        if self._link_up_at is not None:
            last = self._imu_at if self._imu_at is not None else self._link_up_at
            silent = now - last > lim.imu_timeout_s + 1e-9
            if m.stale("spinal_silent", silent, now, f"no imu for {now - last:.3f} s"):
                self._react("spinal_silent", now)
        if flying:
            last = self._servo_at if self._servo_at is not None else self._link_up_at
            stale = last is not None and now - last > lim.servo_timeout_s + 1e-9
            if m.stale("servo_stale", stale, now, "no servo/states"):
                self._react("servo_stale", now)
            if position is not None:
                outside = not self.config.flight.inside_fence(position)
                if m.stale("geofence", outside, now, f"position {position.tolist()} outside"):
                    self._react("geofence", now)
            if m.battery_low(now):
                self._react("battery_low", now)
        if self.foot is not None and self.control.perching:
            missing = self.foot.latest(now, self.config.foot_timeout_s) is None
            m.stale("foot_stale", missing, now, "no foot-sensor sample while perched")

    def _react(self, monitor: str, now: float) -> None:
        """A fault's reaction: in flight land; perched hold (or land when configured)."""
        if not self.arming.flying:
            return
        if self.control.perching:
            if monitor == "ground_lost" and self.config.monitors.ground_loss_perched == "land":
                self._perch_request = False
            else:
                self.counts[f"{monitor}_hold"] += 1
                return
        if self.flight.mode is not FlightMode.LAND:
            self.flight.request_land(now)
            self.counts[f"{monitor}_land"] += 1

    def _control(self, now: float) -> None:
        ctl = self.control
        ctl.update_model(self.present_q)
        ctl.set_perching(self._perch_request)
        if ctl.synthesize_due():
            ok = ctl.synthesize()
            if ctl.gains_wire is not None:  # on failure the last good gains go out again
                self._send_gains()
            if not ok:
                self.counts["gains_kept"] += 1
        pm = ctl.p_matrix_wire()
        if pm is not None:
            cached = self._p_matrix_msg
            if cached is None or cached[0] is not pm:  # the pipeline reuses pm while q holds
                rows, inertia = pm
                unit = self._msg["pinv_unit"]
                msg = self._msg["p_matrix_pseudo_inverse_inertia"].new(
                    pseudo_inverse=[unit.new(r=r, p=p, y=y) for r, p, y in rows],
                    inertia=inertia,
                )
                cached = self._p_matrix_msg = (pm, msg)
            self._publish_same("p_matrix_pseudo_inverse_inertia", cached[1])
        if self.config.send_desire_coordinate and ctl.terms is not None:
            cached_desire = self._desire_msg
            if cached_desire is None or cached_desire[0] is not ctl.terms:
                # a function of the model terms alone: rebuilt when they change
                desire = ctl.desire_coordinate()
                assert desire is not None
                roll, pitch, yaw = desire
                msg = self._msg["desire_coordinate"].new(roll=roll, pitch=pitch, yaw=yaw)
                cached_desire = self._desire_msg = (ctl.terms, msg)
            self._publish_same("desire_coordinate", cached_desire[1])
        targets = self._current_joint_targets(now)
        dt = self.period
        if self._last_control is not None:
            measured = now - self._last_control
            if 0 < measured <= 3 * self.period:
                dt = measured
            else:
                self.counts["dt_irregular"] += 1
        self._last_control = now
        self._supervise(now, dt)
        command = None
        if self.arming.flying:
            command = self._flight_step(now, targets, dt)
        if command is not None:
            self.last_command = command
            self.last_alpha_beta = (command.alpha, command.beta)
            self._command_at = now
        if self.arming.flying and self.last_command is not None:
            held = now - (self._command_at if self._command_at is not None else -math.inf)
            if held <= self.config.flight.command_hold_s + 1e-9:
                self._send_command(self.last_command)
            else:  # no fresh command: silence, so that Spinal's timeout and ramp act
                self.counts["command_withheld"] += 1
        if targets is not None:
            lead = self.config.servo_lead_s
            if lead > 0.0 and self._trajectory is not None:
                goals = self._current_joint_targets(now + lead)
                assert goals is not None
                self._send_servo_targets(goals)
            else:
                self._send_servo_targets(targets)

    def _send_command(self, c: ControlCommand) -> None:
        limit = self.config.flight.max_tilt_cmd
        roll, pitch, yaw_term = c.angles
        limited = abs(roll) > limit or abs(pitch) > limit
        reason = f"roll/pitch target beyond {limit} rad"
        self.monitors.stale("tilt_limit", limited, self._now, reason)
        if limited:  # saturate below Spinal's 1 rad tilt fail-safe
            self.counts["tilt_limited"] += 1
            roll, pitch = max(-limit, min(limit, roll)), max(-limit, min(limit, pitch))
            c = replace(c, angles=(roll, pitch, yaw_term))
        if self._direct_remote("four_axes/command", "spinal/FourAxisCommand"):
            payload = _four_axis_payload(c.angles, c.base_thrust)
            if payload is not None:
                self._publish_payload("four_axes/command", payload)
                return
        self._publish(
            "four_axes/command",
            self._msg["four_axes/command"].new(
                angles=list(c.angles), base_thrust=_floats(c.base_thrust)
            ),
        )

    def _flight_step(
        self, now: float, targets: np.ndarray | None, dt: float
    ) -> ControlCommand | None:
        if not self._mocap_usable(now):
            self.counts["command_held"] += 1
            if self._mocap_lost_since is None:
                self._mocap_lost_since = now
            elif (
                now - self._mocap_lost_since >= self.config.mocap_loss_force_landing_s
                and self.arming.state is FlightState.ARMED
            ):
                self.counts["mocap_lost_force_landing"] += 1
                self.arming.force_landing(now)
            return None
        self._mocap_lost_since = None
        p, v, yaw = self._mocap_at(now)
        self._rp_integration(float(p[2]))
        if yaw is None:
            if self.imu_euler is None:
                self.counts["no_yaw"] += 1
                return None
            yaw = self.imu_euler[2]
        jt = targets if targets is not None else self.present_q
        foot = None if self.foot is None else self.foot.latest(now, self.config.foot_timeout_s)
        setpoint = self._flight_setpoint or self.setpoint
        try:
            return self.control.step(State(p, v, yaw), setpoint, jt, foot, dt)
        except ValueError:
            self.counts["control_error"] += 1
            return None

    def _torque_on(self, now: float) -> None:
        """``servo/torque_enable`` for every mapped servo once Spinal's servo table is up (its
        ``servo/states`` arrive), re-sent until ``servo/torque_states`` shows them all on."""
        if not self.config.servo_torque_on_start or self.servos_torque_on:
            return
        if self.counts["rx:servo/states"] == 0:
            return
        if self._torque_sent_at is not None and now - self._torque_sent_at < (
            self.config.torque_retry_s
        ):
            return
        indices = list(self.config.servo_map.servo_index)
        msg = self._msg["servo/torque_enable"].new(index=indices, torque_enable=[1] * len(indices))
        if self._publish("servo/torque_enable", msg):
            self._torque_sent_at = now
            self.counts["torque_enable_sent"] += 1

    def _rp_integration(self, z: float) -> None:
        """Spinal integrates roll/pitch only after INTEGRATION_CONTROL_ON (160), which JSK
        sends once the robot is ``start_rp_integration_height`` above its take-off height."""
        if self.arming.state is not FlightState.ARMED or self.integration_on_sent:
            return
        if self._arm_z is None:
            self._arm_z = z
        elif z - self._arm_z >= self.config.rp_integration_height:
            msg = self._msg["flight_config_cmd"].new(cmd=INTEGRATION_CONTROL_ON)
            self.integration_on_sent = self._publish("flight_config_cmd", msg)

    def _send_gains(self) -> None:
        wire = self.control.gains_wire
        assert wire is not None
        if (
            wire.dtype == np.int16
            and wire.ndim == 2
            and wire.shape[1] == 7
            and self._direct_remote("rpy/gain", "spinal/RollPitchYawTerms")
        ):
            # count, then 7 int16 per motor (roll_p .. yaw_d): the codec's bytes for the
            # RollPitchYawTerm messages built below (built by the core with these terms)
            built = self.control.gains_payload
            if built is not None and built[0] is wire:
                payload = built[1]
            else:
                payload = _U32.pack(wire.shape[0]) + wire.astype("<i2", copy=False).tobytes()
            self._publish_payload("rpy/gain", payload)
            return
        key = (wire.tobytes(), wire.dtype.str, wire.shape)
        if self._gains_msg is None or self._gains_msg[0] != key:
            term = self._msg["rpy_term"]
            names = ("roll_p", "roll_i", "roll_d", "pitch_p", "pitch_i", "pitch_d", "yaw_d")
            # integer arrays: tolist() gives the same Python ints as int(v), without numpy scalars
            rows = wire.tolist() if wire.dtype.kind in "iu" else wire
            motors = [
                term.new(**{k: int(v) for k, v in zip(names, row, strict=True)}) for row in rows
            ]
            self._gains_msg = (key, self._msg["rpy/gain"].new(motors=motors))
        self._publish("rpy/gain", self._gains_msg[1])

    def _send_servo_targets(self, targets: np.ndarray) -> None:
        arr = np.array(targets, dtype=float)
        smap = self.config.servo_map
        if (
            self.fast_servo_targets
            and smap.__class__ is ServoMap
            and self._direct_remote("servo/target_states", "spinal/ServoControlCmd")
        ):
            assert _servo_target_payload is not None
            vectoring = self.last_alpha_beta if self.arming.flying else None
            done = _servo_target_payload(
                arr,
                vectoring,
                self.control.vectoring_joints,
                smap.zero_point,
                smap.angle_sign,
                smap.angle_scale,
                smap.servo_index,
            )
            if done is not None:  # else the plain form decides (and raises as before)
                self.last_servo_goals, payload = done
                self._publish_payload("servo/target_states", payload)
                return
        self._send_servo_targets_plain(arr)

    def _send_servo_targets_plain(self, arr: np.ndarray) -> None:
        """:meth:`_send_servo_targets` of the float64 array of the targets in Python."""
        # a list of the same Python floats float(q[j]) gives (element writes: same values)
        q = arr.tolist()
        written: list[int] = []
        if self.arming.flying and self.last_alpha_beta is not None:
            alpha, beta = self.last_alpha_beta
            for i, (ja, jb) in enumerate(self.control.vectoring_joints):
                q[ja], q[jb] = float(alpha[i]), float(beta[i])
                written += (ja, jb)
        smap = self.config.servo_map
        n = min(smap.n_joints, len(q))
        self.last_servo_goals = q if n == len(q) else q[:n]
        to_raw = smap.to_raw
        if self._direct_remote("servo/target_states", "spinal/ServoControlCmd"):
            index = smap.servo_index[:n]
            # to_raw is per joint: the targets' ticks (they hold for many ticks) are kept, the
            # vectoring joints' ticks are redone from the angles written over them
            key = arr.tobytes()
            cached = self._target_ticks
            if cached is None or cached[0] is not smap or cached[1] != key:
                base = arr.tolist()
                cached = self._target_ticks = (smap, key, [to_raw(j, base[j]) for j in range(n)])
            angles = cached[2].copy()
            if written and smap.__class__ is ServoMap:
                # ServoMap.to_raw written out (the same expression, rounding and clamp)
                zero, sign, scale = smap.zero_point, smap.angle_sign, smap.angle_scale
                for j in written:
                    if j < n:
                        angles[j] = max(
                            -32768, min(32767, round(zero[j] + sign[j] * q[j] / scale[j]))
                        )
            else:
                for j in written:
                    if j < n:
                        angles[j] = to_raw(j, q[j])
            try:  # uint8[] index, int16[] angles; out of range: the codec's error below
                payload = struct.pack(f"<I{len(index)}BI{n}h", len(index), *index, n, *angles)
            except (struct.error, TypeError):
                payload = None
            if payload is not None:
                self._publish_payload("servo/target_states", payload)
                return
        self._publish(
            "servo/target_states",
            self._msg["servo/target_states"].new(
                index=list(smap.servo_index[:n]),
                angles=[to_raw(j, q[j]) for j in range(n)],
            ),
        )

    # ---------------------------------------------------------------------- diagnostics
    @property
    def state(self) -> FlightState:
        return self.arming.state

    def status(self) -> dict[str, Any]:
        """Counters and the latest values, JSON-friendly."""
        c = self.last_command
        return {
            "time": self._now,
            "flight_state": self.arming.state.value,
            "perching": self.control.perching,
            "negotiated": sorted(self.session.outbound),
            "published": dict(self.published),
            "counts": dict(self.counts),
            "session": dict(self.session.counts),
            "arming": dict(self.arming.counts),
            "control": dict(self.control.counts),
            "foot": {} if self.foot is None else dict(self.foot.counts),
            "imu_calibration": dict(self.imu_calibration.counts),
            "present_q": self.present_q.tolist(),
            "battery_voltage": self.battery_voltage,
            "flight_mode": self.flight.mode.value,
            "flight": dict(self.flight.counts),
            "monitors": self.monitors.status(),
            "uart_link": {
                "errors": getattr(self.uart, "errors", 0),
                "reopens": getattr(self.uart, "reopens", 0),
            },
            "command": None
            if c is None
            else {
                "angles": list(c.angles),
                "base_thrust": c.base_thrust.tolist(),
                "perch_thrust": c.perch_thrust.tolist(),
                "perch_status": None if c.perch is None else c.perch.status,
            },
        }
