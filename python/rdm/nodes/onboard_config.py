# ruff: noqa: RUF003  (paper notation: Greek letters, minus and times signs)
"""Parameters of the onboard-PC node (:mod:`rdm.nodes.onboard`) and the servo index/unit map.

Everything the paper does not give is an ASSUMPTION named in ``docs/onboard.md``; every field
is configurable here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rdm.nodes.loop_timing import LATE_TOLERANCE_S, check_late_tolerance
from rdm.nodes.onboard_flight import FlightLimits
from rdm.nodes.onboard_mocap import MocapConfig
from rdm.nodes.onboard_monitors import MonitorLimits
from rdm.pwm import HYDRUS_MOTOR_INFO, SQRT_MODE

#: Dynamixel X: 4096 ticks per turn, centre 2048 (``JointProfile.angle_scale`` /
#: ``zero_point_offset`` of JSK's servo_bridge).
#: Window [s] over which ``rp_integration_hold_rate`` measures the IMU link's turn against the
#: CoG frame (the model terms change only with the reported joint angles, 40-100 Hz).
RP_HOLD_WINDOW_S = 0.1
DYNAMIXEL_RAD_PER_TICK = 2.0 * math.pi / 4096.0
DYNAMIXEL_ZERO = 2048


@dataclass(frozen=True)
class ServoMap:
    """Joint (model ``joint_order`` index) <-> servo index and raw ticks.

    ``q = angle_sign * (raw - zero_point) * angle_scale`` (JSK ``servo_bridge`` convention).
    ASSUMPTION: joint j is servo index ``servo_index[j]`` (default j), all servos Dynamixel X.
    """

    servo_index: tuple[int, ...] = tuple(range(10))
    zero_point: tuple[int, ...] = (DYNAMIXEL_ZERO,) * 10
    angle_scale: tuple[float, ...] = (DYNAMIXEL_RAD_PER_TICK,) * 10
    angle_sign: tuple[int, ...] = (1,) * 10

    @classmethod
    def from_can_table(cls, table: list[str], joint_order: tuple[str, ...]) -> ServoMap:
        """Spinal numbers servos by their position in its CAN table (Neurons by slave id,
        then servo index on the Neuron): ``table`` lists the joint of each position."""
        missing = [j for j in joint_order if j not in table]
        if missing:
            raise ValueError(f"ServoMap: joints {missing} are on no Neuron of the CAN table")
        return cls(servo_index=tuple(table.index(j) for j in joint_order))

    def __post_init__(self) -> None:
        n = len(self.servo_index)
        if not (len(self.zero_point) == len(self.angle_scale) == len(self.angle_sign) == n):
            raise ValueError("ServoMap: servo_index, zero_point, angle_scale, angle_sign differ")
        if len(set(self.servo_index)) != n:
            raise ValueError("ServoMap: servo_index has duplicates")
        if any(s not in (-1, 1) for s in self.angle_sign):
            raise ValueError("ServoMap: angle_sign must be +1 or -1")
        if any(not (math.isfinite(k) and k > 0) for k in self.angle_scale):
            raise ValueError("ServoMap: angle_scale must be finite and > 0")

    @property
    def n_joints(self) -> int:
        return len(self.servo_index)

    def joint_of(self, servo_index: int) -> int | None:
        """The joint a servo index drives, or None."""
        try:
            return self.servo_index.index(servo_index)
        except ValueError:
            return None

    def to_rad(self, joint: int, raw: int) -> float:
        return self.angle_sign[joint] * (raw - self.zero_point[joint]) * self.angle_scale[joint]

    def to_raw(self, joint: int, q: float) -> int:
        """Nearest tick, saturated to int16 (the wire type)."""
        raw = round(self.zero_point[joint] + self.angle_sign[joint] * q / self.angle_scale[joint])
        return max(-32768, min(32767, raw))


@dataclass(frozen=True)
class PwmInfoParams:
    """``spinal/PwmInfo`` sent on ``motor_info``: the Hydrus quad example (fact sheet 3.6)."""

    min_pwm: float = 0.59
    max_pwm: float = 0.9375
    min_thrust: float = 1.0
    force_landing_thrust: float = 6.5
    mode: int = SQRT_MODE
    #: rows: voltage, max_thrust, p0..p4
    motor_info: tuple[tuple[float, ...], ...] = tuple(tuple(r) for r in HYDRUS_MOTOR_INFO)


def check_servo_lead(seconds: float) -> float:
    """``seconds`` as a float if it is a usable servo-goal lead (finite, in [0, 1] s), else
    ValueError (:attr:`OnboardConfig.servo_lead_s`, ``rdm sim --servo-lead``)."""
    seconds = float(seconds)
    if not (math.isfinite(seconds) and 0.0 <= seconds <= 1.0):
        raise ValueError(f"servo_lead_s={seconds!r} must be in [0, 1] s")
    return seconds


@dataclass(frozen=True)
class OnboardConfig:
    """All tunables of the onboard node (defaults: paper where it says, else assumptions)."""

    #: Position/perching control rate (paper Sec. VII-A: 40 Hz).
    rate_hz: float = 40.0
    #: LQI synthesis every ``lqi_every`` control ticks (1 = every tick; JSK uses 15 Hz).
    lqi_every: int = 1
    #: Table V weights (None = the core's defaults, JSK order; see docs/lqi.md).
    lqi_q_weights: tuple[float, ...] | None = None
    lqi_r_weights: tuple[float, ...] | None = None
    #: ``spinal/UavInfo``: 4 motors, HYDRUS (under-actuated multilink) model. ASSUMPTION.
    motor_num: int = 4
    uav_model: int = 16
    pwm_info: PwmInfoParams = field(default_factory=PwmInfoParams)
    #: ``uav_info``/``motor_info`` period while starting (JSK ``activate()``: 0.1 s).
    info_period_s: float = 0.1
    #: ARM_ON/ARM_OFF/FORCE_LANDING re-sent this often until acked. ASSUMPTION.
    command_retry_s: float = 0.5
    #: INTEGRATION_CONTROL_ON (160) once the mocap z is this far above the z at arming
    #: (JSK ``start_rp_integration_height``; value an ASSUMPTION).
    rp_integration_height: float = 0.05
    #: Stop Spinal's roll/pitch integration (INTEGRATION_CONTROL_OFF, 161) while the IMU link
    #: turns against the CoG frame faster than this [rad/s] (the change of
    #: ``desire_coordinate`` over :data:`RP_HOLD_WINDOW_S`), and restart it (160) once slower.
    #: Spinal's D term takes the IMU link's rate, so a joint turning that link (q1 for the
    #: root-link IMU) reads as attitude motion and winds the integral up (docs/scenarios.md,
    #: "Where the integral comes from"). None: never stopped (JSK behaviour).
    rp_integration_hold_rate: float | None = None
    #: Mocap older than this is not used. ASSUMPTION.
    mocap_timeout_s: float = 0.2
    #: Ask Spinal for its IMU calibration after each handshake (``imu_calib``
    #: GET_CALIB_DATA; an empty accelerometer calibration is counted as
    #: ``imu_acc_uncalibrated``, docs/onboard.md). Not JSK behaviour; False: never asks.
    read_imu_calibration: bool = True
    #: Armed without usable mocap for this long -> FORCE_LANDING. ASSUMPTION.
    mocap_loss_force_landing_s: float = 1.0
    #: Altitude feed-forward: "hover" = least-squares thrust for m g (pinv(Q̄)[m g,0,0,0]),
    #: "none" = the paper's eq. (29) (integral takes gravity). ASSUMPTION: hover.
    feed_forward: str = "hover"
    #: base_thrust clipped to [0, thrust_max of the robot's rotors]. ASSUMPTION.
    clip_base_thrust: bool = True
    #: Vectoring angles from eqs. (33)-(36) (True) or the joint targets only (False).
    vectoring: bool = True
    #: Eqs. (33)-(34) are singular when the thrust direction is near the parent link's x axis
    #: (|n_z| in the link frame below this): fall back to the α/β targets. ASSUMPTION.
    vectoring_min_nz: float = 0.2
    #: Position-controller keyword overrides (rdm.control.position.PositionController).
    position_gains: dict = field(default_factory=dict)
    #: Perching QP parameters over Table VII (rdm.control.perch.PerchController).
    perch_params: dict = field(default_factory=dict)
    #: Foot wrench IIR cut-off (Sec. VII-B: 1 Hz).
    perch_cutoff_hz: float = 1.0
    #: Foot samples older than this are not used (perching gets the safe command). ASSUMPTION.
    foot_timeout_s: float = 0.1
    #: DATA_START re-sent if no sample for this long. ASSUMPTION.
    foot_restart_s: float = 1.0
    #: Leptrino model of the foot sensor (Sec. VI-B: CFS034CA301U).
    foot_sensor_model: str = "CFS034CA301U"
    #: Raw offset subtracted before conversion (tare). ASSUMPTION: zero (calibrated sensor).
    foot_sensor_offset: tuple[float, ...] = (0.0,) * 6
    #: Joint <-> Spinal servo index. None: from the robot description's default CAN bus
    #: wiring (``rdm.nodes.bus_layout.default_neuron_joints``, as the mirrors are wired).
    servo_map: ServoMap | None = None
    #: q before the first servo/states (joint_order). ASSUMPTION: zeros (arm straight).
    initial_q: tuple[float, ...] | None = None
    gravity: float = 9.80665
    #: Link that carries Spinal's IMU (the processor at the root-link tip, Sec. VI-B); the
    #: node sends its rotation to the CoG frame as ``desire_coordinate`` every tick.
    imu_link: str = "root_link"
    #: Switch every mapped servo's torque on after start-up (``servo/torque_enable``), as JSK's
    #: servo_bridge does; re-sent every ``torque_retry_s`` until ``servo/torque_states``
    #: reports them on. Spinal's ``servo/target_states`` alone never enables a servo.
    servo_torque_on_start: bool = True
    torque_retry_s: float = 0.5
    #: Send ``desire_coordinate`` (False: Spinal controls the IMU link's attitude, correct
    #: only while that link is parallel to the CoG frame, e.g. q1 = 0).
    send_desire_coordinate: bool = True
    #: Servo goals of a :meth:`OnboardNode.set_trajectory` path are taken this far ahead of
    #: ``now`` [s]: feed-forward for the joint servos' lag (their time constant plus the
    #: 40 Hz goal hold and the CAN/RS485 hand-over). 0 = the planned angle at its own time,
    #: as the paper's feed-forward planner and JSK send it. The control model keeps the plan
    #: at ``now``. Identify the value on the robot (docs/scenarios.md, "Servo goals ahead of
    #: the plan").
    servo_lead_s: float = 0.0
    #: ``rdm onboard`` counts a control tick late (status ``loop.late``) when it starts more
    #: than this many seconds after it was due (:class:`rdm.nodes.loop_timing.LoopTiming`).
    late_tolerance_s: float = LATE_TOLERANCE_S
    #: The operator layer: take-off, go-to, landing, touchdown, command hold, tilt limit,
    #: geofence (:class:`rdm.nodes.onboard_flight.FlightLimits`).
    flight: FlightLimits = field(default_factory=FlightLimits)
    #: Monitor thresholds (:class:`rdm.nodes.onboard_monitors.MonitorLimits`).
    monitors: MonitorLimits = field(default_factory=MonitorLimits)
    #: Named position-gain profiles (keyword overrides as ``position_gains``) the operator
    #: switches between (``OnboardNode.set_gain_profile``); "default" is ``position_gains``.
    gain_profiles: dict = field(default_factory=dict)
    #: The marker body of motion capture and the CoG estimate from its pose
    #: (:class:`rdm.nodes.onboard_mocap.MocapConfig`, ``OnboardNode.set_mocap_pose``).
    mocap: MocapConfig = field(default_factory=MocapConfig)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise ValueError(f"rate_hz={self.rate_hz!r} must be finite and > 0")
        if not (isinstance(self.lqi_every, int) and self.lqi_every >= 1):
            raise ValueError(f"lqi_every={self.lqi_every!r} must be an int >= 1")
        if self.feed_forward not in ("hover", "none"):
            raise ValueError(f"feed_forward={self.feed_forward!r}: 'hover' or 'none'")
        for name in (
            "info_period_s",
            "command_retry_s",
            "mocap_timeout_s",
            "mocap_loss_force_landing_s",
            "foot_timeout_s",
            "foot_restart_s",
            "torque_retry_s",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name}={v!r} must be finite and > 0")
        hold = self.rp_integration_hold_rate
        if hold is not None and not (math.isfinite(hold) and hold > 0):
            raise ValueError(f"rp_integration_hold_rate={hold!r} must be None or finite and > 0")
        check_servo_lead(self.servo_lead_s)
        check_late_tolerance(self.late_tolerance_s)
        if len(self.foot_sensor_offset) != 6:
            raise ValueError("foot_sensor_offset needs 6 values")

    def initial_joint_vector(self, n_q: int) -> np.ndarray:
        if self.initial_q is None:
            return np.zeros(n_q)
        q = np.asarray(self.initial_q, dtype=float)
        if q.shape != (n_q,) or not np.all(np.isfinite(q)):
            raise ValueError(f"initial_q must be {n_q} finite values")
        return q
