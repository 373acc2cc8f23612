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

The node's parts, one module each: :mod:`~rdm.nodes.onboard_operator` (inputs and operator
commands), :mod:`~rdm.nodes.onboard_receive` (what Spinal sends), :mod:`~rdm.nodes.onboard_step`
(the control tick and its supervision), :mod:`~rdm.nodes.onboard_send` (what goes to Spinal);
this module holds the node's state, its tick and its status.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from rdm.nodes.bus_layout import can_table, default_neuron_joints
from rdm.nodes.onboard_arming import ArmingSequencer, FlightState
from rdm.nodes.onboard_calibration import ImuCalibrationReader
from rdm.nodes.onboard_config import OnboardConfig, ServoMap
from rdm.nodes.onboard_control import ControlCommand, ControlPipeline, Setpoint
from rdm.nodes.onboard_flight import FlightSupervisor
from rdm.nodes.onboard_foot import ByteLink, FootSensorReader
from rdm.nodes.onboard_mocap import CogEstimator
from rdm.nodes.onboard_monitors import Monitors, battery_cells
from rdm.nodes.onboard_operator import OnboardOperator
from rdm.nodes.onboard_receive import _SERVO_STATE_FIELDS, OnboardReceive, servo_states_decodes
from rdm.nodes.onboard_send import OnboardSend
from rdm.nodes.onboard_step import OnboardStep
from rdm.protocol.rosserial.codec import RosTime
from rdm.protocol.rosserial.registry import TypeRegistry, spinal_registry
from rdm.protocol.rosserial.server import ServerSession


def default_servo_map(robot: Any) -> ServoMap:
    """Servo map of the robot's default CAN wiring (:mod:`rdm.nodes.bus_layout`, the wiring
    the Neuron mirrors use): Spinal numbers servos by Neuron slave id, then servo index."""
    wiring = default_neuron_joints(
        [r["name"] for r in robot.rotors], robot.vectoring_units, tuple(robot.joint_names)
    )
    return ServoMap.from_can_table(can_table(wiring), tuple(robot.joint_names))


class OnboardNode(OnboardOperator, OnboardReceive, OnboardStep, OnboardSend):
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
        top = max(config.pwm_info.motor_info, key=lambda r: float(r[0]))
        self.monitors = Monitors(
            config.monitors,
            config.monitors.battery_cells
            or battery_cells([float(r[0]) for r in config.pwm_info.motor_info]),
            (float(top[0]), float(top[1])),
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
        #: the command before ``last_command`` (a light rotor's loss is measured past both
        #: targets: :func:`rdm.nodes.onboard_rotor_loss.diverging_axis`)
        self.previous_command: ControlCommand | None = None
        #: when a lost rotor was detected (None: not lost, or disarmed since)
        self.rotor_lost_at: float | None = None
        #: which rotor the last detection named (:func:`rdm.nodes.onboard_rotor_loss.
        #: lost_rotor`; None: none yet, or not named); its gain and gyro-moment rows go out
        #: zero during the arrest (while ``rotor_lost_at`` is set)
        self.lost_rotor: int | None = None
        #: whether the lost rotor carries more than a quarter of the weight (the specific
        #: force dropped below ``MonitorLimits.rotor_loss_specific_force``)
        self.lost_heavy = True
        #: The joint goals [rad] of the last ``servo/target_states`` sent (the vectoring
        #: joints' angles written over the plan in flight), in joint order.
        self.last_servo_goals: list[float] | None = None
        self.last_alpha_beta: tuple[tuple[float, ...], tuple[float, ...]] | None = None
        self._requests: list[str] = []
        self._perch_request = False
        #: node time of the first of the approach ticks whose foot reading has been above
        #: ``FlightLimits.contact_fz`` since (``FlightLimits.contact_hold_s``)
        self._contact_since: float | None = None
        #: the name of the position-gain profile in effect ("default": ``position_gains``)
        self.gain_profile = "default"
        self._started = False
        self._now = 0.0
        self._last_control: float | None = None
        self._arm_z: float | None = None
        self._announced = False
        self.integration_on_sent = False
        #: Spinal's roll/pitch integration stopped (161) for ``rp_integration_hold_rate``
        self.rp_integration_held = False
        self._imu_cog_ref: tuple[float, np.ndarray] | None = None
        self.servos_torque_on = False
        self._torque_sent_at: float | None = None
        # messages rebuilt only when their content changed (same object -> same bytes)
        self._gains_msg: tuple[tuple[bytes, str, tuple[int, ...]], Any] | None = None
        #: (wire terms, message, lost rotor whose row the message zeroes)
        self._p_matrix_msg: tuple[Any, Any, int | None] | None = None
        self._desire_msg: tuple[Any, Any] | None = None
        #: ``servo/states`` readings seen before (the servos hold still for many messages) are
        #: applied from their cached joint writes
        self._servo_cache: dict[tuple, tuple[np.ndarray, np.ndarray, int, bool]] = {}
        self._servo_cache_map: ServoMap | None = None
        #: the same entries by the readings' payload bytes after the stamp
        self._servo_raw: dict[bytes, tuple[np.ndarray, np.ndarray, int, bool]] = {}
        self._servo_codec = reg.msg("spinal/ServoStates")
        servo_fields = [
            (f.name, f.base_type, f.array_len) for f in reg.msg("spinal/ServoState").spec.fields
        ]
        #: whether ``spinal/ServoState`` has the layout ``_SERVO_INDEX_ANGLE`` reads (a new
        #: ``servo/states`` payload's indices and angles then unpacked with one ``struct``;
        #: another message tree's layout: decoded by the codec)
        self._servo_struct = servo_fields == _SERVO_STATE_FIELDS
        # ``imu`` and ``servo/states`` are taken in from their payloads (the session defers
        # their decoding; only what the node reads is unpacked) when ``spinal/Imu`` has the
        # layout _IMU_GYRO_QUAT reads; another message tree's: decoded messages (_on_event)
        if reg.msg("spinal/Imu").fixed_size == 60:
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
        #: unchanged messages (pinv, desire) sent as the payload encoded once per codec
        self._payloads: dict[str, tuple[Any, Any, bytes]] = {}
        #: the trajectory's joint columns as contiguous arrays (made once per trajectory)
        self._trajectory_columns: tuple[Any, tuple[np.ndarray, ...]] | None = None

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
                self.rp_integration_held, self._imu_cog_ref = False, None
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

    # ---------------------------------------------------------------------- state
    @property
    def mocap(self) -> tuple[np.ndarray, np.ndarray, float | None] | None:
        """The last accepted mocap sample ``(position, velocity, yaw)`` (None before one)."""
        return self._mocap

    @property
    def servo_states_at(self) -> float | None:
        """When Spinal's last ``servo/states`` arrived (None before the first)."""
        return self._servo_at

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
