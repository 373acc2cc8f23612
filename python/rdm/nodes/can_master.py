"""Spinal's CAN-master role (fact sheet sec. 2.5-2.7), as a component the Spinal mirror composes.

Time is Spinal's ``HAL_GetTick()``: whole milliseconds passed to :meth:`CanMaster.tick_ms`
(:meth:`CanMaster.tick` takes seconds, as every node does). Call it once per millisecond.

Start-up (simulated time, no sleeping): wait ``boot_delay_ms`` (5000), broadcast ENUM_REQUEST
and collect ENUM_RESPONSEs for 200 ms, sort the Neurons by slave id, then per Neuron
INITIAL_CONFIG_REQUEST and a 200 ms wait, then 100 ms of IMU init per Neuron (no CAN traffic
in this mirror), then infer the robot model. No Neuron: ``DISABLED``.

Run time, at the start of each 1 ms tick: even ms: PWM broadcast (message 0, plus message 1
with more than 6 motors); odd ms: servo target angle then target current to ONE Neuron,
round-robin. Servo states and IMU frames fill ``servo_states`` / ``imu``. No frame for more than
100 ms: a ``"CAN disconnected!!"`` log event, at most once per second.
"""

from __future__ import annotations

import enum
import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import can

from rdm.link.can import send_neuron_payload_via
from rdm.protocol import neuron as nr
from rdm.protocol.neuron.pwm import PWM_MAX_MOTORS
from rdm.protocol.neuron.servo import WORD_VALUE_MAX, WORD_VALUE_MIN

from .base import MAX_FRAMES_PER_TICK, to_ms

BOOT_DELAY_MS = 5000
ENUM_WAIT_MS = 200
CONFIG_WAIT_MS = 200
IMU_INIT_MS = 100
DISCONNECT_MS = 100
DISCONNECT_LOG_INTERVAL_MS = 1000
#: ``CAN_TX_PAUSE_TIME``: no transmission for this long after a board-config request.
TX_PAUSE_MS = 2000
#: After a REBOOT request Spinal asks the Neuron for its config again after this long.
REBOOT_REQUEST_MS = 5000
#: In real time a late tick replays at most this many missed milliseconds of the schedule.
MAX_CATCH_UP_MS = 10
IDLE_DUTY = 0.5
#: The frame class of a servo state report (the fast branch of ``CanMaster._receive``).
_SERVO_STATE = nr.ServoState


class MasterState(enum.Enum):
    BOOTING = "booting"
    ENUMERATING = "enumerating"
    CONFIGURING = "configuring"
    RUNNING = "running"
    DISABLED = "disabled"


class UavModel(enum.IntEnum):
    """``uav_model`` values Spinal infers from the gimbal-servo count (sec. 2.7)."""

    HYDRUS = 16
    HYDRUS_XI = 17
    DRAGON = 32


@dataclass(frozen=True)
class LogEvent:
    """A log line Spinal would publish over rosserial (``level``: debug/info/warn/error)."""

    stamp_ms: int
    level: str
    text: str


@dataclass
class ServoEntry:
    """Spinal's record of one servo: config (INITIAL_CONFIG_1/2/3), command, last state."""

    slave: int
    index: int
    dynamixel_id: int = 0
    p_gain: int = 0
    i_gain: int = 0
    d_gain: int = 0
    profile_velocity: int = 0
    current_limit: int = 0
    send_data_flag: bool = False
    external_encoder_flag: bool = False
    hardware_error_status: int = 0
    joint_resolution: int = 0
    servo_resolution: int = 0
    # command side
    goal_position: int = 0
    #: Bit 15 of the angle word: set once the Neuron's reported goal was taken (handshake).
    goal_valid: bool = False
    torque_enable: bool = False
    goal_current: int = 0
    # state side (ServoState frames)
    angle: int = 0
    temperature: int = 0
    moving: bool = False
    force_servo_off: bool = False
    current: int = 0
    error: int = 0
    stamp_ms: int | None = None

    @property
    def is_gimbal(self) -> bool:
        """Spinal's "gimbal servo": one without send_data_flag (sec. 2.7)."""
        return not self.send_data_flag


@dataclass
class NeuronEntry:
    slave: int
    servo_num: int = 0
    imu_send_flag: bool = False
    ttl_rs485_mixed: bool = False
    pulley_skip_thresh: int = 0
    configured: bool = False
    servos: list[ServoEntry] = field(default_factory=list)


@dataclass(frozen=True)
class ImuReading:
    """One Neuron's latest IMU samples, scaled and axis-remapped as Spinal does."""

    gyro: tuple[float, float, float] | None = None
    acc: tuple[float, float, float] | None = None
    mag: tuple[float, float, float] | None = None
    stamp_ms: int | None = None


class CanMaster:
    """Spinal's side of the Neuron bus. Owns ``bus``; never blocks; never reads a clock."""

    def __init__(
        self,
        bus: can.BusABC,
        *,
        name: str = "can_master",
        boot_delay_ms: int = BOOT_DELAY_MS,
        start_ms: int = 0,
    ) -> None:
        self._bus = bus
        self._send_standard = getattr(bus, "send_standard", None)
        self.name = name
        self.period = 0.001
        self.boot_delay_ms = boot_delay_ms
        self.state = MasterState.BOOTING
        self.neurons: list[NeuronEntry] = []
        self.imu: dict[int, ImuReading] = {}
        self.events: list[LogEvent] = []
        self.motor_number = 0
        self.uav_model: int | None = None
        self.rx_count = 0
        self.rx_errors: Counter[str] = Counter()
        self.rx_kinds: Counter[str] = Counter()
        self.tx_count = 0
        self.tx_errors = 0
        self._duties: list[float] = []
        self._pwm_of: list[float] | None = None  # the duty list _pwm_values was made from
        self._pwm_values: tuple[int, ...] = ()
        self._phase_end = start_ms + boot_delay_ms
        self._config_cursor = 0
        self._enumerated: set[int] = set()
        self._round_robin = 0
        self._last_ms: int | None = None
        self._last_rx_ms = start_ms
        self._last_disconnect_log: int | None = None
        self._tx_pause_until: int | None = None
        self._pending_board: list[nr.BoardConfig] = []
        self._rerequest: dict[int, int] = {}  # slave -> ms of the next INITIAL_CONFIG_REQUEST

    @property
    def bus(self) -> can.BusABC:
        """The CAN bus (assignable: the fast send path follows it)."""
        return self._bus

    @bus.setter
    def bus(self, bus: can.BusABC) -> None:
        self._bus = bus
        self._send_standard = getattr(bus, "send_standard", None)

    # ------------------------------------------------------------------ node interface
    def tick(self, now: float) -> None:
        """Node interface: ``now`` in seconds; runs :meth:`tick_ms` on whole milliseconds."""
        self.tick_ms(to_ms(now))

    def tick_ms(self, now_ms: int) -> None:
        """One 1 kHz core-task tick (``HAL_GetTick() == now_ms``): receive, then schedule.

        A tick that skips milliseconds (a late real-time loop) replays the schedule for at most
        ``MAX_CATCH_UP_MS`` of them; repeated or older times only receive.
        """
        recv = self._bus.recv
        for _ in range(MAX_FRAMES_PER_TICK):
            msg = recv(timeout=0)
            if msg is None:
                break
            self._receive(msg, now_ms)
        last = self._last_ms
        if last is None or now_ms == last + 1:  # the usual case: one new millisecond
            self._step(now_ms)
            self._last_ms = now_ms
        elif now_ms > last:
            for t in range(max(last + 1, now_ms - MAX_CATCH_UP_MS + 1), now_ms + 1):
                self._step(t)
            self._last_ms = now_ms

    # ------------------------------------------------------------------ commands
    def set_motor_duties(self, duties: Sequence[float]) -> None:
        """Duties 0.5 (stop) .. 1.0 of motors 0..motor_number-1 (sent as ``duty*2000-1000``)."""
        if len(duties) != self.motor_number:
            raise ValueError(f"set_motor_duties: {len(duties)} duties for {self.motor_number}")
        for i, d in enumerate(duties):
            if not isinstance(d, (int, float)) or not math.isfinite(d) or not 0.5 <= d <= 1.0:
                raise ValueError(f"set_motor_duties: duties[{i}]={d!r} not in 0.5..1.0")
        self._duties = [float(d) for d in duties]

    def servo(self, slave: int, index: int) -> ServoEntry:
        """The entry of servo ``index`` on Neuron ``slave`` (KeyError if unknown)."""
        for neuron in self.neurons:
            if neuron.slave == slave and 0 <= index < len(neuron.servos):
                return neuron.servos[index]
        raise KeyError(f"no servo {index} on Neuron {slave}")

    def set_servo_targets(self, targets: Mapping[tuple[int, int], int]) -> None:
        """Goal positions (raw ticks, 15-bit signed) keyed by ``(slave, index)``.

        Until the Neuron's goal report was acknowledged (``goal_valid``), a report overwrites
        this target with the Neuron's own goal, as on Spinal.
        """
        entries = []
        for (slave, index), value in targets.items():
            if not isinstance(value, int) or not WORD_VALUE_MIN <= value <= WORD_VALUE_MAX:
                raise ValueError(f"servo ({slave}, {index}) target {value!r} not a 15-bit int")
            entries.append((self.servo(slave, index), value))
        for entry, value in entries:
            entry.goal_position = value

    def set_servo_torque(self, slave: int, index: int, enable: bool) -> None:
        """Torque enable of one servo; refused while the Neuron reports force-off; turning it
        off invalidates the goal (the handshake restarts at the next enable)."""
        entry = self.servo(slave, index)
        if entry.force_servo_off:
            return
        entry.torque_enable = bool(enable)
        if not enable:
            entry.goal_valid = False

    def set_servo_current(self, slave: int, index: int, current: int) -> None:
        if not isinstance(current, int) or not WORD_VALUE_MIN <= current <= WORD_VALUE_MAX:
            raise ValueError(f"servo ({slave}, {index}) current {current!r} not a 15-bit int")
        self.servo(slave, index).goal_current = current

    def configure_board(self, frame: nr.BoardConfig) -> None:
        """Send one BOARD_CONFIG_REQUEST at the next tick; then all CAN transmission pauses for
        2000 ms. After REBOOT the Neuron's config is requested again 5000 ms later."""
        if not isinstance(frame, nr.BoardConfig):
            raise TypeError(f"configure_board: {type(frame).__name__} is not a BoardConfig")
        self._pending_board.append(frame)

    # ------------------------------------------------------------------ views
    @property
    def servo_states(self) -> dict[tuple[int, int], ServoEntry]:
        """Every known servo keyed by ``(slave, index)``, Neurons in slave-id order."""
        return {(n.slave, s.index): s for n in self.neurons for s in n.servos}

    @property
    def slaves(self) -> list[int]:
        return [n.slave for n in self.neurons]

    @property
    def connected(self) -> bool:
        return self._last_ms is not None and self._last_ms - self._last_rx_ms <= DISCONNECT_MS

    def pop_events(self) -> list[LogEvent]:
        """Log events not yet taken (the Spinal mirror forwards them over rosserial)."""
        out, self.events = self.events, []
        return out

    # ------------------------------------------------------------------ schedule
    def _step(self, t: int) -> None:
        if self.state is MasterState.BOOTING:
            if t >= self._phase_end:
                self.state = MasterState.ENUMERATING
                self._send(nr.EnumRequest())
                self._phase_end = t + ENUM_WAIT_MS
        elif self.state is MasterState.ENUMERATING:
            if t >= self._phase_end:
                self._end_enumeration(t)
        elif self.state is MasterState.CONFIGURING:
            if t >= self._phase_end:
                self._next_config(t)
        elif self.state is MasterState.RUNNING:
            self._run(t)

    def _end_enumeration(self, t: int) -> None:
        self.neurons = [NeuronEntry(s) for s in sorted(self._enumerated)]
        if not self.neurons:
            self.state = MasterState.DISABLED
            self._log(t, "error", "no Neuron answered ENUM_REQUEST: CAN master disabled")
            return
        self.state = MasterState.CONFIGURING
        self._config_cursor = 0
        self._send(nr.InitialConfigRequest(self.neurons[0].slave))
        self._phase_end = t + CONFIG_WAIT_MS

    def _next_config(self, t: int) -> None:
        self._config_cursor += 1
        n = len(self.neurons)
        if self._config_cursor < n:
            self._send(nr.InitialConfigRequest(self.neurons[self._config_cursor].slave))
            self._phase_end = t + CONFIG_WAIT_MS
        elif self._config_cursor < 2 * n:  # can_imu_.init(): 100 ms per Neuron
            self._phase_end = t + IMU_INIT_MS
        else:
            self._start_running(t)

    def _start_running(self, t: int) -> None:
        for neuron in self.neurons:
            if not neuron.configured:
                self._log(t, "warn", f"Neuron {neuron.slave} sent no INITIAL_CONFIG_0")
        self.motor_number = len(self.neurons)
        self._duties = [IDLE_DUTY] * self.motor_number
        gimbals = sum(s.is_gimbal for n in self.neurons for s in n.servos)
        if gimbals == 0:
            self.uav_model = UavModel.HYDRUS
        elif gimbals == self.motor_number:
            self.uav_model = UavModel.HYDRUS_XI
        elif gimbals == 2 * self.motor_number:
            self.uav_model = UavModel.DRAGON
        else:
            self.uav_model = None
            self._log(t, "warn", f"{gimbals} gimbal servos on {self.motor_number} Neurons")
        self.state = MasterState.RUNNING
        self._last_rx_ms = max(self._last_rx_ms, t)
        self._log(
            t,
            "info",
            f"CAN: {self.motor_number} Neurons {self.slaves}, uav_model {self.uav_model}",
        )

    def _run(self, t: int) -> None:
        if t - self._last_rx_ms > DISCONNECT_MS:
            last = self._last_disconnect_log
            if last is None or t - last >= DISCONNECT_LOG_INTERVAL_MS:
                self._last_disconnect_log = t
                self._log(t, "error", "CAN disconnected!!")
        if self._rerequest:
            for slave, when in list(self._rerequest.items()):
                if t >= when:
                    del self._rerequest[slave]
                    self._send(nr.InitialConfigRequest(slave))
        if self._tx_pause_until is not None:
            if t < self._tx_pause_until:
                return
            self._tx_pause_until = None
        if self._pending_board:
            frame = self._pending_board.pop(0)
            self._send(frame)
            self._tx_pause_until = t + TX_PAUSE_MS
            if isinstance(frame, nr.Reboot):
                self._rerequest[frame.slave] = t + REBOOT_REQUEST_MS
            return
        if t % 2 == 0:
            # The PWM words of the present duty list (``_duties`` is only ever replaced, never
            # changed in place): converted once per list instead of every other millisecond.
            duties = self._duties
            if self._pwm_of is not duties:
                self._pwm_values = tuple(nr.duty_to_pwm_value(d) for d in duties[:PWM_MAX_MOTORS])
                self._pwm_of = duties
            values = self._pwm_values
            for can_id, payload in nr.encode_pwm_cached(values):
                self._send_raw(can_id, payload)
            return
        neuron = self.neurons[self._round_robin % len(self.neurons)]
        self._round_robin = (self._round_robin + 1) % len(self.neurons)
        if not neuron.servos:
            return  # a DLC-0 servo frame is not a valid frame of this protocol
        servos = neuron.servos
        # Memoised ServoTargetAngles / ServoTargetCurrents (same bytes, checks on a miss).
        self._send_raw(
            *nr.encode_servo_words_cached(
                False,
                neuron.slave,
                tuple(s.goal_position for s in servos),
                tuple(s.goal_valid for s in servos),
            )
        )
        self._send_raw(
            *nr.encode_servo_words_cached(
                True,
                neuron.slave,
                tuple(s.goal_current for s in servos),
                tuple(s.torque_enable and not s.force_servo_off for s in servos),
            )
        )

    # ------------------------------------------------------------------ receive
    def _receive(self, msg: can.Message, now_ms: int) -> None:
        self.rx_count += 1
        self._last_rx_ms = now_ms
        if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id or msg.is_fd:
            reason = (
                "error_frame"
                if msg.is_error_frame
                else "remote"
                if msg.is_remote_frame
                else "not_standard_id"
                if msg.is_extended_id
                else "fd"
            )
            self.rx_errors[reason] += 1
            return
        try:
            frame = nr.decode_frame_cached(
                msg.arbitration_id, bytes(msg.data), nr.Direction.NEURON_TO_SPINAL
            )
        except nr.NeuronFrameError as exc:
            self.rx_errors[exc.reason] += 1
            return
        self.rx_kinds[frame.KIND] += 1
        if type(frame) is _SERVO_STATE:
            # The common frame (a servo state report): the steps of the general path below
            # that apply to it, in the same order, without the isinstance chain.
            slave = frame.slave
            for neuron in self.neurons:
                if neuron.slave == slave:
                    break
            else:
                self.rx_errors["unknown_slave"] += 1
                return
            index = frame.index
            if index >= len(neuron.servos):
                self.rx_errors["servo_index"] += 1
                return
            self._servo_state(neuron.servos[index], frame, now_ms)
            return
        if isinstance(frame, nr.EnumResponse):
            if self.state is MasterState.ENUMERATING:
                self._enumerated.add(frame.slave)
            return
        neuron = next((n for n in self.neurons if n.slave == frame.slave), None)  # type: ignore[attr-defined]
        if neuron is None:
            self.rx_errors["unknown_slave"] += 1
            return
        if isinstance(frame, nr.InitialConfig0):
            neuron.servo_num = frame.servo_num
            neuron.imu_send_flag = frame.imu_send_flag
            neuron.ttl_rs485_mixed = frame.ttl_rs485_mixed
            neuron.pulley_skip_thresh = frame.pulley_skip_thresh
            neuron.configured = True
            old = {s.index: s for s in neuron.servos}
            neuron.servos = [
                old.get(i) or ServoEntry(neuron.slave, i) for i in range(frame.servo_num)
            ]
            return
        index = getattr(frame, "index", None)
        if isinstance(frame, nr.ImuFrame):
            self._imu(frame, now_ms)
            return
        if index is None or index >= len(neuron.servos):
            self.rx_errors["servo_index"] += 1
            return
        entry = neuron.servos[index]
        if isinstance(frame, nr.ServoState):
            self._servo_state(entry, frame, now_ms)
        elif isinstance(frame, nr.InitialConfig1):
            entry.dynamixel_id = frame.dynamixel_id
            entry.p_gain, entry.i_gain, entry.d_gain = frame.p_gain, frame.i_gain, frame.d_gain
        elif isinstance(frame, nr.InitialConfig2):
            entry.angle = frame.present_position
            entry.goal_position = max(WORD_VALUE_MIN, min(WORD_VALUE_MAX, frame.present_position))
            entry.profile_velocity = frame.profile_velocity
            entry.current_limit = frame.current_limit
            entry.send_data_flag = frame.send_data_flag
            entry.external_encoder_flag = frame.external_encoder_flag
        elif isinstance(frame, nr.InitialConfig3):
            entry.hardware_error_status = frame.hardware_error_status
            entry.joint_resolution = frame.joint_resolution
            entry.servo_resolution = frame.servo_resolution

    @staticmethod
    def _servo_state(entry: ServoEntry, frame: nr.ServoState, now_ms: int) -> None:
        entry.temperature = frame.temperature
        entry.moving = frame.moving
        entry.force_servo_off = frame.force_servo_off
        entry.current = frame.current
        entry.error = frame.servo_error
        entry.stamp_ms = now_ms
        if frame.force_servo_off:
            entry.torque_enable = False
            entry.goal_valid = False
        if frame.goal_reported:
            # Handshake step 2: take the Neuron's goal and acknowledge it with bit 15.
            entry.goal_position = max(WORD_VALUE_MIN, min(WORD_VALUE_MAX, frame.angle))
            entry.goal_valid = True
        else:
            entry.angle = frame.angle

    def _imu(self, frame: nr.ImuFrame, now_ms: int) -> None:
        old = self.imu.get(frame.slave, ImuReading())
        value = frame.spinal_frame()
        key = {nr.ImuMessage.GYRO: "gyro", nr.ImuMessage.ACC: "acc", nr.ImuMessage.MAG: "mag"}
        fields = {"gyro": old.gyro, "acc": old.acc, "mag": old.mag, key[frame.sensor]: value}
        self.imu[frame.slave] = ImuReading(**fields, stamp_ms=now_ms)

    # ------------------------------------------------------------------ transmit
    def _send(self, frame: nr.NeuronFrame) -> None:
        self._send_raw(frame.can_id, frame.encode())

    def _send_raw(self, can_id: int, payload: bytes) -> None:
        if send_neuron_payload_via(self._bus, self._send_standard, can_id, payload):
            self.tx_count += 1
        else:
            self.tx_errors += 1

    def _log(self, t: int, level: str, text: str) -> None:
        self.events.append(LogEvent(t, level, text))

    def close(self) -> None:
        self.bus.shutdown()
