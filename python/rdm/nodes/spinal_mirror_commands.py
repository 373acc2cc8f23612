"""What reaches the Spinal mirror on its UART: the rosserial events of each received chunk,
the subscribers routed into the core and the CAN master (each through its message handler;
a leading run of the five steady command frames applied in one Rust call,
``rdm._rdm.spinal_apply_commands``, which makes the core calls of those handlers), their
rejections, and the services.

:class:`SpinalCommands` is a part of :class:`rdm.nodes.spinal_mirror.SpinalMirror`: its
methods read and change the mirror's state (``session``, ``core``, ``servos``, ``counters`` ...).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from rdm import _rdm
from rdm.control.attitude import ARM_OFF, CommandRejectedError
from rdm.nodes.can_master import IDLE_DUTY, MasterState
from rdm.nodes.onboard_monitors import MonitorLimits, battery_cells
from rdm.nodes.spinal_servo_bridge import MirrorRejection, target_rejection
from rdm.protocol.rosserial import constants as C
from rdm.protocol.rosserial.events import (
    Configured,
    DroppedMessage,
    FrameRejected,
    MessageReceived,
    ServiceHandled,
    SyncLost,
)

#: The steady commands ``rdm._rdm.spinal_apply_commands`` decodes and applies, with the
#: message type whose layout it reads (a slot of another type or layout is routed as a
#: message).
_COMMAND_TYPES = {
    "four_axes/command": "spinal/FourAxisCommand",
    "rpy/gain": "spinal/RollPitchYawTerms",
    "p_matrix_pseudo_inverse_inertia": "spinal/PMatrixPseudoInverseWithInertia",
    "desire_coordinate": "spinal/DesireCoord",
    "servo/target_states": "spinal/ServoControlCmd",
}
#: ``rdm._rdm.spinal_apply_commands``' kind codes of those topics.
_COMMAND_KINDS = {
    "four_axes/command": 1,
    "rpy/gain": 2,
    "p_matrix_pseudo_inverse_inertia": 3,
    "desire_coordinate": 4,
    "servo/target_states": 5,
}
_apply_commands = _rdm.spinal_apply_commands
_IMU_CALIB_GET = 0  # spinal/ImuCalib GET_CALIB_DATA
_IMU_CALIB_GYRO = 2  # spinal/ImuCalib CALIB_GYRO
_MAG_SET = 1  # spinal/MagDeclination SET


def rejection_reason(text: str) -> str:
    """Counter key for a :class:`CommandRejectedError` message of the core."""
    lowered = text.lower()
    for needle, reason in (
        ("length", "wrong_length"),
        ("not finite", "non_finite"),
        ("not armed", "not_armed"),
        ("force_landing_thrust", "below_force_landing_thrust"),
        ("motor number unknown", "motor_number_unknown"),
        ("rotors of this core", "too_many_motors"),
        ("arm_on ignored", "not_activated"),
        ("unknown value", "unknown_flight_config"),
        ("motor_info", "invalid_pwm_info"),
    ):
        if needle in lowered:
            return reason
    return "rejected"


class SpinalCommands:
    """The receive side of :class:`rdm.nodes.spinal_mirror.SpinalMirror` (a part of it)."""

    def _receive(self, now_ms: int) -> None:
        if not self._runs_armed:  # the command runs, once
            runs = any(self._command_kinds)
            self.session.command_run = self._apply_command_run if runs else None
            self._runs_armed = True
        data = self.uart.read()
        for event in self.session.spin(data, now_ms):
            if isinstance(event, MessageReceived):
                self._route(event.topic, event.message)
            elif isinstance(event, ServiceHandled):
                self.counters.received[event.service] += 1
            elif isinstance(event, FrameRejected):
                self.counters.frames_rejected[event.bad.reason] += 1
            elif isinstance(event, DroppedMessage):
                self.counters.dropped += 1
            elif isinstance(event, Configured):
                self.counters.configured += 1
            elif isinstance(event, SyncLost):
                self.counters.sync_lost += 1
        # the ms from here up to hi need no spin while no byte comes (tick's skip)
        self._idle_lo, self._idle_hi = self.session.idle_window()

    def _route(self, topic: str, msg: Any) -> None:
        handler = self._routes.get(topic)
        if handler is None:
            self.counters.received[topic] += 1  # accepted, no effect in this mirror
            return
        try:
            handler(msg)
        except ValueError as exc:
            self._route_failed(topic, exc)
        else:
            self.counters.received[topic] += 1

    def _route_failed(self, topic: str, exc: ValueError) -> None:
        """A handler's rejection: counted (and logged) by kind."""
        if isinstance(exc, MirrorRejection):
            self._reject(exc.reason, str(exc), log=True)
        elif isinstance(exc, CommandRejectedError):
            # The core emits a "rejected" event for the ones the firmware logs; logged there.
            self._reject(rejection_reason(str(exc)), str(exc), log=False)
        else:  # shapes the core refuses (RdmError), bad arrays
            self._reject("invalid", f"{topic}: {exc}", log=True)

    def _apply_command_run(self, items: list) -> int:
        """``ClientSession.command_run``: the leading steady command frames of ``items``
        (the parser's good frames) applied in one call, ``rdm._rdm.spinal_apply_commands``:
        the core calls of each frame's message handler, with its counters and rejections.
        Returns how many frames are done; the session hands the rest to the usual path."""
        n, exc = _apply_commands(
            items,
            self._command_kinds,
            C.FIRST_USER_TOPIC_ID,
            self.core,
            self.servos.command_core(),
            self._now_s,
        )
        topics = self._command_topics
        first = C.FIRST_USER_TOPIC_ID
        received = self.counters.received
        for i in range(n):
            received[topics[items[i][0] - first]] += 1
        if exc is not None:  # item n's core call raised: routed as _route does
            topic = topics[items[n][0] - first]
            if not isinstance(exc, ValueError):
                raise exc
            if topic == "servo/target_states":
                exc = target_rejection(exc)
            self._route_failed(topic, exc)
            n += 1
        return n

    def _reject(self, reason: str, text: str, log: bool) -> None:
        self.counters.rejected[reason] += 1
        if log:
            self._log(C.LogLevel.ERROR, text)

    # ---------------------------------------------------------------- subscribers
    def _on_four_axis_command(self, msg: Any) -> None:
        angles = [float(a) for a in msg.angles]
        self.core.four_axis_command_list(angles, msg.base_thrust, self._now_s)

    def _on_gain(self, msg: Any) -> None:
        rows = [
            (m.roll_p, m.roll_i, m.roll_d, m.pitch_p, m.pitch_i, m.pitch_d, m.yaw_d)
            for m in msg.motors
        ]
        self.core.set_gains_wire_rows(rows)

    def _on_pinv_inertia(self, msg: Any) -> None:
        pinv = [(u.r, u.p, u.y) for u in msg.pseudo_inverse]
        self.core.set_pinv_inertia_wire_rows(pinv, [int(v) for v in msg.inertia])

    def _on_torque_allocation_inv(self, msg: Any) -> None:
        rows = np.array([[v.x, v.y, v.z] for v in msg.rows], dtype=np.int16).reshape(-1, 3)
        self.core.set_torque_allocation_inv_wire(rows)

    def _on_motor_info(self, msg: Any) -> None:
        table = np.array(
            [[m.voltage, m.max_thrust, *m.polynominal] for m in msg.motor_info], dtype=np.float64
        ).reshape(-1, 7)
        self.core.set_pwm_info(
            float(msg.min_pwm),
            float(msg.max_pwm),
            float(msg.min_thrust),
            float(msg.force_landing_thrust),
            int(msg.pwm_conversion_mode),
            table,
        )
        self.reference_voltage = float(table[:, 0].max())

    def _on_uav_info(self, msg: Any) -> None:
        before = self.core.motor_number
        self.core.set_uav_info(int(msg.motor_num), int(msg.uav_model))
        if before > 0 and self.core.motor_number == 0:
            self._log(C.LogLevel.ERROR, "ATTENTION: motor number is 0")

    def _on_flight_config(self, msg: Any) -> None:
        self.core.flight_config(int(msg.cmd), self._now_s)
        if int(msg.cmd) == ARM_OFF:
            self.pwm_test = None

    def _on_desire_coordinate(self, msg: Any) -> None:
        self.core.set_desire_coordinate(float(msg.roll), float(msg.pitch), float(msg.yaw))

    def _on_pwm_test(self, msg: Any) -> None:
        """Test mode (sec. 3.7): non-empty ``pwms`` enters it, empty leaves it."""
        pwms = [float(p) for p in msg.pwms]
        if not pwms:
            self.pwm_test = None
            return
        pwms = [p if math.isfinite(p) and 0.5 <= p <= 1.0 else IDLE_DUTY for p in pwms]
        n = max(self.master.motor_number, self.core.motor_number, 1)
        duties = list(self.pwm_test or [IDLE_DUTY] * n)
        duties += [IDLE_DUTY] * (n - len(duties))
        if not msg.motor_index:
            duties = [pwms[0]] * n
        else:
            if len(msg.motor_index) != len(pwms):
                raise MirrorRejection(
                    "wrong_length",
                    f"pwm_test: {len(msg.motor_index)} indices but {len(pwms)} pwms",
                )
            for i, p in zip(msg.motor_index, pwms, strict=True):
                if i < n:
                    duties[i] = p
        self.pwm_test = duties

    def _on_adc_scale(self, msg: Any) -> None:
        """``set_adc_scale``. The firmware takes any positive scale; unless
        :attr:`firmware_adc_scale`, a scale that would put the present battery reading outside
        the plausible range of the battery (``rdm.nodes.onboard_monitors``: 3.0..4.45 V per
        cell, cells from ``motor_info``'s highest reference voltage) is rejected: one such
        message made the battery reading 1.75 V and the voltage factor drove every rotor to
        full duty."""
        scale = float(msg.data)
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"set_adc_scale: {scale!r} is not a positive finite scale")
        if not self.firmware_adc_scale:
            cells = battery_cells([self.reference_voltage])
            lo, hi = (c * cells for c in MonitorLimits().cell_plausible)
            volts = self.battery_input * scale
            if not lo <= volts <= hi:
                raise MirrorRejection(
                    "adc_scale_implausible",
                    f"set_adc_scale: {scale!r} makes the battery {volts:.2f} V, outside "
                    f"{lo:.2f}..{hi:.2f} V ({cells} cells)",
                )
        self.adc_scale = scale

    # ---------------------------------------------------------------- services
    def _srv_imu_calib(self, req: Any) -> Any:
        """GET_CALIB_DATA answers the calibration in use (12 floats: gyro bias, accelerometer
        bias from the flash, magnetometer bias and scale); CALIB_GYRO restarts the gyro bias
        calibration; the other commands (calibrating the accelerometer or magnetometer,
        writing the flash) are not mirrored and answer ``success = False``."""
        command = int(req.command)
        if command == _IMU_CALIB_GET:
            data = list(self.core.calibration_data())
            return self._srv.imu_calib.new(success=True, data=data)
        if command == _IMU_CALIB_GYRO:
            self.core.restart_gyro_calibration()
            return self._srv.imu_calib.new(success=True, data=[])
        return self._srv.imu_calib.new(success=False, data=[])

    def _srv_set_attitude_control(self, req: Any) -> Any:
        self.core.set_attitude_control(bool(req.data))
        return self._srv.set_bool.new(success=True, message="")

    def _srv_mag_declination(self, req: Any) -> Any:
        if int(req.command) == _MAG_SET:
            self.mag_declination = float(req.data)  # stored; no effect on R (sec. 3.3)
        return self._srv.mag.new(success=True, data=self.mag_declination)

    def _srv_get_board_info(self, _req: Any) -> Any:
        boards = []
        for neuron in self.master.neurons if self.master.state is MasterState.RUNNING else []:
            servos = [
                self._msg.servo_info.new(
                    id=s.dynamixel_id,
                    p_gain=s.p_gain,
                    i_gain=s.i_gain,
                    d_gain=s.d_gain,
                    profile_velocity=s.profile_velocity,
                    current_limit=s.current_limit,
                    send_data_flag=int(s.send_data_flag),
                    external_encoder_flag=int(s.external_encoder_flag),
                    joint_resolution=s.joint_resolution,
                    servo_resolution=s.servo_resolution,
                )
                for s in neuron.servos
            ]
            boards.append(
                self._msg.board_info.new(
                    slave_id=neuron.slave,
                    imu_send_data_flag=int(neuron.imu_send_flag),
                    dynamixel_ttl_rs485_mixed=int(neuron.ttl_rs485_mixed),
                    servo_pulley_skip_thresh=neuron.pulley_skip_thresh,
                    servos=servos,
                )
            )
        return self._srv.board_info.new(boards=boards)
