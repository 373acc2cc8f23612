"""Neuron board mirror: a CAN slave driving one ESC and up to four Dynamixel servos (fact sheet
sec. 2). Byte-compatible with the real Neuron: every frame goes through
:mod:`rdm.protocol.neuron`.

What it does each ``tick(now)``:

1. drains its bus; frames whose slave field is neither 15 nor its own id are dropped as the
   hardware filter would (not counted as errors); every accepted frame resets the watchdog;
2. answers ENUM_REQUEST, INITIAL_CONFIG_REQUEST (CONFIG_0, then CONFIG_1/2/3 per servo), applies
   BOARD_CONFIG sub-commands (and answers each with the full config set), reads its PWM slot,
   applies servo goal / current / torque words;
3. after a servo-angle frame, transmits the state of every servo with ``send_data_flag``, then
   gyro, acc, mag if its IMU flag is set (the angle frame is the transmit trigger);
4. advances the servo models by the elapsed time (unless a plant drives them) and applies the
   100 ms watchdog to the ESC output.

Bad frames (bad DLC, reserved bits, wrong direction, extended/remote/FD) are counted in
``rx_errors`` by reason and ignored; send failures are counted in ``tx_errors``.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence

import can

from rdm.link.can import send_neuron_payload
from rdm.protocol import neuron as nr
from rdm.protocol.neuron.ids import NEURON_SLAVE_IDS

from .base import MAX_FRAMES_PER_TICK
from .esc_model import EscModel
from .servo_model import ServoConfig, ServoModel

#: No frame for more than this many ms stops the motor (``CANDeviceManager::tick``).
WATCHDOG_MS = 100
#: Simulated reboot time after BOARD_CONFIG REBOOT (assumption: the real one is a reset + init).
DEFAULT_REBOOT_MS = 100

_IMU_SCALE = {
    nr.ImuMessage.GYRO: nr.GYRO_SCALE,
    nr.ImuMessage.ACC: nr.ACC_SCALE,
    nr.ImuMessage.MAG: nr.MAG_SCALE,
}


def _int16(value: float) -> int:
    return int(min(max(round(value), -0x8000), 0x7FFF))


class NeuronMirror:
    """One Neuron on ``bus`` with id ``slave_id`` (1..14).

    ``plant_driven=True`` stops the built-in motion model: a plant reads :meth:`servo_goals`
    and feeds back :meth:`set_present_positions` instead.
    """

    def __init__(
        self,
        bus: can.BusABC,
        slave_id: int,
        servos: Sequence[ServoConfig] = (),
        imu: bool = False,
        esc: bool = True,
        *,
        name: str | None = None,
        period: float = 0.001,
        plant_driven: bool = False,
        ttl_rs485_mixed: bool = False,
        pulley_skip_thresh: int = 0,
        reboot_ms: int = DEFAULT_REBOOT_MS,
    ) -> None:
        if not isinstance(slave_id, int) or slave_id not in NEURON_SLAVE_IDS:
            raise ValueError(f"NeuronMirror: slave_id {slave_id!r} not in 1..14")
        if len(servos) > nr.MAX_SERVO_NUM:
            raise ValueError(f"NeuronMirror: {len(servos)} servos > MAX_SERVO_NUM 4")
        self.bus = bus
        self.slave_id = slave_id
        #: Id written by SET_SLAVE_ID; takes effect at the next reboot (read from flash at boot).
        self.flash_slave_id = slave_id
        self.name = name or f"neuron{slave_id}"
        self.period = period
        self.plant_driven = plant_driven
        self.servos = [ServoModel(c) for c in servos]
        self.imu_send_flag = imu
        self.has_esc = esc
        self.esc = EscModel()
        #: One counter bumped by every change of a servo goal / torque or the ESC output, so a
        #: plant bridge reads this board's outputs only after a change.
        self.changes = [0]
        for servo in self.servos:
            servo.changes = self.changes
        self.esc.changes = self.changes
        self.ttl_rs485_mixed = ttl_rs485_mixed
        self.pulley_skip_thresh = pulley_skip_thresh
        self.reboot_ms = reboot_ms
        self.imu_raw: dict[nr.ImuMessage, tuple[int, int, int]] = {
            nr.ImuMessage.GYRO: (0, 0, 0),
            nr.ImuMessage.ACC: (0, 0, 4096),  # 1 g on +z at rest (+-8 g range: 4096 LSB/g)
            nr.ImuMessage.MAG: (0, 0, 0),
        }
        self.rx_count = 0
        self.rx_filtered = 0
        self.rx_errors: Counter[str] = Counter()
        self.rx_kinds: Counter[str] = Counter()
        self.tx_count = 0
        self.tx_errors = 0
        self.reboots = 0
        self._last_rx_ms: int | None = None
        self._last_now: float | None = None
        self._now_ms = 0
        self._rebooting_until: int | None = None

    # ------------------------------------------------------------------ node interface
    def tick(self, now: float) -> None:
        """Advance to ``now`` seconds: receive, answer, move servos, apply the watchdog."""
        now_ms = math.floor(now * 1000.0 + 1e-6)  # base.to_ms, inlined (1 kHz per board)
        self._now_ms = now_ms
        if self._last_rx_ms is None:
            self._last_rx_ms = now_ms  # the watchdog counter starts at boot
        recv = self.bus.recv
        if self._rebooting_until is not None:
            for _ in range(MAX_FRAMES_PER_TICK):
                if recv(timeout=0) is None:
                    break
                self.rx_filtered += 1  # a resetting MCU hears nothing
            if now_ms >= self._rebooting_until:
                self._finish_reboot(now_ms)
        else:
            trigger = False
            for _ in range(MAX_FRAMES_PER_TICK):
                msg = recv(timeout=0)
                if msg is None:
                    break
                trigger |= self._receive(msg, now_ms)
            if trigger:
                self._send_states()
        if not self.plant_driven:
            dt = 0.0 if self._last_now is None else max(0.0, now - self._last_now)
            for servo in self.servos:
                servo.advance(dt)
        self._last_now = now
        self.esc.stopped = (
            self._rebooting_until is not None or now_ms - self._last_rx_ms > WATCHDOG_MS
        )

    @property
    def connected(self) -> bool:
        """False once more than 100 ms passed without an accepted frame (the watchdog)."""
        return self._last_rx_ms is not None and self._now_ms - self._last_rx_ms <= WATCHDOG_MS

    # ------------------------------------------------------------------ plant interface
    def servo_goals(self) -> list[int]:
        """Goal positions (raw ticks) the servos are commanded to, in index order."""
        return [s.goal for s in self.servos]

    def set_present_positions(self, positions: Sequence[float]) -> None:
        """Plant feedback of the joint positions (raw ticks), in index order."""
        if len(positions) != len(self.servos):
            raise ValueError(f"{self.name}: {len(positions)} positions for {len(self.servos)}")
        for servo, p in zip(self.servos, positions, strict=True):
            servo.set_present_position(p)

    def set_imu_raw(
        self,
        gyro: Sequence[int] | None = None,
        acc: Sequence[int] | None = None,
        mag: Sequence[int] | None = None,
    ) -> None:
        """Raw MPU9250/AK8963 int16 samples in the sensor frame (what goes on CAN)."""
        for sensor, xyz in ((nr.ImuMessage.GYRO, gyro), (nr.ImuMessage.ACC, acc)):
            if xyz is not None:
                self.imu_raw[sensor] = self._check_xyz(sensor, xyz)
        if mag is not None:
            self.imu_raw[nr.ImuMessage.MAG] = self._check_xyz(nr.ImuMessage.MAG, mag)

    def set_imu(
        self,
        gyro: Sequence[float] | None = None,
        acc: Sequence[float] | None = None,
        mag: Sequence[float] | None = None,
    ) -> None:
        """Physical values in Spinal's frame (rad/s, m/s^2, uT), converted to raw samples by
        inverting Spinal's scaling and axis remap (rounded, saturated to int16)."""
        for sensor, xyz in ((nr.ImuMessage.GYRO, gyro), (nr.ImuMessage.ACC, acc)):
            if xyz is not None:
                sx, sy, sz = self._finite(sensor, xyz)
                k = _IMU_SCALE[sensor]
                # Spinal: (x, y, z) = (-raw_y, raw_x, raw_z) * k
                self.imu_raw[sensor] = (_int16(sy / k), _int16(-sx / k), _int16(sz / k))
        if mag is not None:
            sx, sy, sz = self._finite(nr.ImuMessage.MAG, mag)
            k = nr.MAG_SCALE
            # Spinal: (x, y, z) = (-raw_x, raw_y, -raw_z) * k
            self.imu_raw[nr.ImuMessage.MAG] = (_int16(-sx / k), _int16(sy / k), _int16(-sz / k))

    @staticmethod
    def _finite(sensor: nr.ImuMessage, xyz: Sequence[float]) -> tuple[float, float, float]:
        if len(xyz) != 3 or not all(math.isfinite(v) for v in xyz):
            raise ValueError(f"{sensor.name.lower()}: need 3 finite values, got {xyz!r}")
        return float(xyz[0]), float(xyz[1]), float(xyz[2])

    @staticmethod
    def _check_xyz(sensor: nr.ImuMessage, xyz: Sequence[int]) -> tuple[int, int, int]:
        if len(xyz) != 3 or not all(isinstance(v, int) and -0x8000 <= v <= 0x7FFF for v in xyz):
            raise ValueError(f"{sensor.name.lower()}: need 3 int16 values, got {xyz!r}")
        return int(xyz[0]), int(xyz[1]), int(xyz[2])

    # ------------------------------------------------------------------ receive
    def _receive(self, msg: can.Message, now_ms: int) -> bool:
        """Handle one frame; True when it triggers the state transmission."""
        if msg.is_error_frame:
            self.rx_errors["error_frame"] += 1
            return False
        if msg.is_remote_frame:
            self.rx_errors["remote"] += 1
            return False
        if msg.is_extended_id:
            self.rx_errors["not_standard_id"] += 1
            return False
        slave_field = msg.arbitration_id & 0xF
        if slave_field not in (nr.BROADCAST_ID, self.slave_id):
            self.rx_filtered += 1
            return False
        self.rx_count += 1
        self._last_rx_ms = now_ms
        if msg.is_fd:
            self.rx_errors["fd"] += 1
            return False
        try:
            frame = nr.decode_frame_cached(
                msg.arbitration_id, bytes(msg.data), nr.Direction.SPINAL_TO_NEURON
            )
        except nr.NeuronFrameError as exc:
            self.rx_errors[exc.reason] += 1
            return False
        self.rx_kinds[frame.KIND] += 1
        return self._dispatch(frame, now_ms)

    def _dispatch(self, frame: nr.NeuronFrame, now_ms: int) -> bool:
        if isinstance(frame, nr.PwmFrame):
            if self.has_esc:
                value = nr.pwm_for_slave(frame, self.slave_id)
                if value is not None:
                    self.esc.held_value = value
        elif isinstance(frame, nr.EnumRequest):
            self._send(nr.EnumResponse(self.slave_id))
        elif isinstance(frame, nr.InitialConfigRequest):
            self._send_config()
        elif isinstance(frame, nr.BoardConfig):
            self._board_config(frame, now_ms)
        elif isinstance(frame, nr.ServoTargetAngles):
            if not self._servo_words_fit(frame):
                return False
            for servo, value, ack in zip(self.servos, frame.values, frame.flags, strict=True):
                servo.command_goal(value, ack)
            return True
        elif isinstance(frame, nr.ServoTargetCurrents) and self._servo_words_fit(frame):
            for servo, value, torque in zip(self.servos, frame.values, frame.flags, strict=True):
                servo.goal_current = value
                servo.set_torque(torque)
        return False

    def _servo_words_fit(self, frame: nr.ServoTargetAngles | nr.ServoTargetCurrents) -> bool:
        if len(frame.values) != len(self.servos):
            self.rx_errors["servo_count"] += 1
            return False
        return True

    def _board_config(self, frame: nr.BoardConfig, now_ms: int) -> None:
        index = getattr(frame, "index", None)
        if index is not None and index >= len(self.servos):
            self.rx_errors["servo_index"] += 1
            return
        servo = self.servos[index] if index is not None else None
        if isinstance(frame, nr.Reboot):
            self._start_reboot(now_ms)
            return
        if isinstance(frame, nr.SetSlaveId):
            self.flash_slave_id = frame.new_id
        elif isinstance(frame, nr.SetImuSendFlag):
            self.imu_send_flag = frame.flag
        elif isinstance(frame, nr.SetDynamixelTtlRs485Mixed):
            self.ttl_rs485_mixed = frame.flag
        elif isinstance(frame, nr.SetServoPulleySkipThresh):
            self.pulley_skip_thresh = frame.thresh
        elif servo is not None:
            self._servo_config(frame, servo)
        self._send_config()

    @staticmethod
    def _servo_config(frame: nr.BoardConfig, servo: ServoModel) -> None:
        if isinstance(frame, nr.SetServoHomingOffset):
            servo.set_homing_offset(frame.offset)
        elif isinstance(frame, nr.SetServoPidGain):
            servo.reconfigure(p_gain=frame.p_gain, i_gain=frame.i_gain, d_gain=frame.d_gain)
        elif isinstance(frame, nr.SetServoProfileVel):
            servo.reconfigure(profile_velocity=frame.profile_velocity)
        elif isinstance(frame, nr.SetSendDataFlag):
            servo.reconfigure(send_data_flag=frame.flag)
        elif isinstance(frame, nr.SetServoCurrentLimit):
            servo.reconfigure(current_limit=frame.current_limit)
        elif isinstance(frame, nr.SetServoRoundOffset):
            servo.round_offset = frame.offset
        elif not servo.torque_enable:  # these two only while torque is off
            if isinstance(frame, nr.SetExternalEncoderFlag):
                servo.reconfigure(external_encoder_flag=frame.flag)
            elif isinstance(frame, nr.SetResolutionRatio):
                servo.reconfigure(
                    joint_resolution=frame.joint_resolution,
                    servo_resolution=frame.servo_resolution,
                )

    def _start_reboot(self, now_ms: int) -> None:
        self.reboots += 1
        self._rebooting_until = now_ms + self.reboot_ms
        self.esc.held_value = nr.pwm.PWM_STOP_VALUE
        for servo in self.servos:
            servo.set_torque(False)

    def _finish_reboot(self, now_ms: int) -> None:
        self._rebooting_until = None
        self.slave_id = self.flash_slave_id
        self._last_rx_ms = now_ms

    # ------------------------------------------------------------------ transmit
    def _send(self, frame: nr.NeuronFrame) -> None:
        self._send_raw(frame.can_id, frame.encode())

    def config_frames(self) -> list[nr.NeuronFrame]:
        """The INITIAL_CONFIG_0..3 set this Neuron sends now."""
        s = self.slave_id
        config0 = nr.InitialConfig0(
            s, len(self.servos), self.imu_send_flag, self.ttl_rs485_mixed, self.pulley_skip_thresh
        )
        triples = []
        for i, servo in enumerate(self.servos):
            c = servo.config
            triples.append(
                (
                    nr.InitialConfig1(s, i, c.dynamixel_id, c.p_gain, c.i_gain, c.d_gain),
                    nr.InitialConfig2(
                        s,
                        i,
                        servo.present_position,
                        c.profile_velocity,
                        c.current_limit,
                        c.send_data_flag,
                        c.external_encoder_flag,
                    ),
                    nr.InitialConfig3(
                        s,
                        i,
                        servo.hardware_error,
                        _int16(servo.goal_current),
                        c.joint_resolution,
                        c.servo_resolution,
                    ),
                )
            )
        return nr.initial_config_reply(config0, triples)

    def _send_config(self) -> None:
        for frame in self.config_frames():
            self._send(frame)

    def state_frames(self) -> list[nr.NeuronFrame]:
        """What the Neuron sends after a servo-angle frame: servo states, then IMU."""
        out: list[nr.NeuronFrame] = []
        for i, servo in enumerate(self.servos):
            if not servo.config.send_data_flag:
                continue
            out.append(
                nr.ServoState(
                    slave=self.slave_id,
                    index=i,
                    angle=servo.reported_angle,
                    temperature=min(max(servo.temperature, 0), 255),
                    force_servo_off=False,
                    moving=servo.moving,
                    goal_reported=servo.send_goal_position,
                    current=_int16(servo.current),
                    servo_error=servo.hardware_error & 0xFF,
                )
            )
        if self.imu_send_flag:
            for sensor in (nr.ImuMessage.GYRO, nr.ImuMessage.ACC, nr.ImuMessage.MAG):
                out.append(nr.ImuFrame(self.slave_id, sensor, *self.imu_raw[sensor]))
        return out

    def _send_states(self) -> None:
        # Same frames as state_frames(), through the memoised encoder (a repeated state is
        # not re-validated and re-packed: the bytes are those the frame class produced).
        slave = self.slave_id
        for i, servo in enumerate(self.servos):
            if not servo.config.send_data_flag:
                continue
            self._send_raw(
                *nr.encode_servo_state_cached(
                    slave,
                    i,
                    servo.reported_angle,
                    min(max(servo.temperature, 0), 255),
                    servo.moving,
                    servo.send_goal_position,
                    _int16(servo.current),
                    servo.hardware_error & 0xFF,
                )
            )
        if self.imu_send_flag:
            for sensor in (nr.ImuMessage.GYRO, nr.ImuMessage.ACC, nr.ImuMessage.MAG):
                self._send(nr.ImuFrame(slave, sensor, *self.imu_raw[sensor]))

    def _send_raw(self, can_id: int, payload: bytes) -> None:
        if send_neuron_payload(self.bus, can_id, payload):
            self.tx_count += 1
        else:
            self.tx_errors += 1

    def close(self) -> None:
        """Shut the bus down (the node owns it)."""
        self.bus.shutdown()
