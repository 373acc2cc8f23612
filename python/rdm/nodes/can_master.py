"""Spinal's CAN-master role (fact sheet sec. 2.5-2.7), run by the Rust core
(``rdm._rdm.CanMaster``, ``rdm_core::firmware::can_master``), as a component the Spinal mirror
composes.

Time is Spinal's ``HAL_GetTick()``: whole milliseconds passed to :meth:`CanMaster.tick_ms`
(:meth:`CanMaster.tick` takes seconds, as every node does). Call it once per millisecond.

Start-up (simulated time, no sleeping): wait ``boot_delay_ms`` (5000), broadcast ENUM_REQUEST
and collect ENUM_RESPONSEs for 200 ms, sort the Neurons by slave id, then per Neuron
INITIAL_CONFIG_REQUEST and a 200 ms wait, then 100 ms of IMU init per Neuron (no CAN traffic
in this mirror), then infer the robot model. No Neuron: ``DISABLED``.

Run time, at the start of each 1 ms tick: even ms: PWM broadcast (message 0, plus message 1
with more than 6 motors); odd ms: servo target angle then target current to ONE Neuron,
round-robin. Servo states and IMU frames fill ``servo_states`` / ``imu``. No frame for more than
100 ms: a ``"CAN disconnected!!"`` log event, at most once per second. A BOARD_CONFIG request
pauses transmission for 2000 ms (``CAN_TX_PAUSE_TIME``); after a REBOOT request the Neuron's
config is requested again 5000 ms later. In real time a late tick replays at most 10 missed
milliseconds of the schedule.

Frames go to and from a python-can bus (``send_standard`` when the bus has it), or, given a
:class:`rdm.link.can_wire.CanWireLink` instead of a bus, straight to the Rust Neuron bank on the
same wire. Servo and Neuron entries are live read-only views of the core's tables.
"""

from __future__ import annotations

import enum
import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import can

from rdm import _rdm
from rdm.link.can import send_neuron_payload_via
from rdm.link.can_wire import DRAIN_AT, CanWireLink
from rdm.protocol import neuron as nr
from rdm.protocol.neuron.servo import WORD_VALUE_MAX, WORD_VALUE_MIN

from .base import drain, to_ms

BOOT_DELAY_MS = 5000
#: The duty of a stopped motor (a 1000 us pulse of the 2000 us period).
IDLE_DUTY = 0.5


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


@dataclass(frozen=True)
class ImuReading:
    """One Neuron's latest IMU samples, scaled and axis-remapped as Spinal does."""

    gyro: tuple[float, float, float] | None = None
    acc: tuple[float, float, float] | None = None
    mag: tuple[float, float, float] | None = None
    stamp_ms: int | None = None


_STATES = (
    MasterState.BOOTING,
    MasterState.ENUMERATING,
    MasterState.CONFIGURING,
    MasterState.RUNNING,
    MasterState.DISABLED,
)
_SERVO_FIELDS = (
    "slave",
    "index",
    "dynamixel_id",
    "p_gain",
    "i_gain",
    "d_gain",
    "profile_velocity",
    "current_limit",
    "send_data_flag",
    "external_encoder_flag",
    "hardware_error_status",
    "joint_resolution",
    "servo_resolution",
    "goal_position",
    "goal_valid",
    "torque_enable",
    "goal_current",
    "angle",
    "temperature",
    "moving",
    "force_servo_off",
    "current",
    "error",
    "stamp_ms",
)
_SENSOR_KEYS = ("gyro", "acc", "mag")
_SENSORS = (nr.ImuMessage.GYRO, nr.ImuMessage.ACC, nr.ImuMessage.MAG)


class ServoEntryView:
    """Spinal's record of one servo: config (INITIAL_CONFIG_1/2/3), command, last state
    (read-only; commands go through the master's ``set_servo_*``)."""

    __slots__ = ("_i", "_k", "_master")

    def __init__(self, master: CanMaster, k: int, i: int) -> None:
        self._master = master
        self._k = k
        self._i = i

    def as_tuple(self) -> tuple:
        """Every field, in :data:`SERVO_FIELDS` order."""
        return self._master._core.servo(self._k, self._i)

    def as_dict(self) -> dict:
        return dict(zip(_SERVO_FIELDS, self.as_tuple(), strict=True))

    def __repr__(self) -> str:
        return f"ServoEntryView({self.as_dict()})"


def _field(pos: int) -> property:
    return property(lambda self: self._master._core.servo(self._k, self._i)[pos])


for _pos, _name in enumerate(_SERVO_FIELDS):
    setattr(ServoEntryView, _name, _field(_pos))

#: The field order of :meth:`ServoEntryView.as_tuple`.
SERVO_FIELDS = _SERVO_FIELDS


class NeuronEntryView:
    """One Neuron of the core's table: slave id, servo count, flags, configured."""

    __slots__ = ("_k", "_master")

    def __init__(self, master: CanMaster, k: int) -> None:
        self._master = master
        self._k = k

    def _row(self) -> tuple:
        return self._master._core.neurons()[self._k]

    slave = property(lambda self: self._row()[0])
    servo_num = property(lambda self: self._row()[1])
    imu_send_flag = property(lambda self: self._row()[2])
    ttl_rs485_mixed = property(lambda self: self._row()[3])
    pulley_skip_thresh = property(lambda self: self._row()[4])
    configured = property(lambda self: self._row()[5])

    @property
    def servos(self) -> list[ServoEntryView]:
        return [ServoEntryView(self._master, self._k, i) for i in range(self._row()[6])]


class CanMaster:
    """Spinal's side of the Neuron bus in Rust. Owns ``bus``; never blocks; reads no clock."""

    def __init__(
        self,
        bus: can.BusABC,
        *,
        name: str = "can_master",
        boot_delay_ms: int = BOOT_DELAY_MS,
        start_ms: int = 0,
    ) -> None:
        self._core = _rdm.CanMaster(boot_delay_ms, start_ms)
        self.bus = bus
        self.name = name
        self.period = 0.001
        self.boot_delay_ms = boot_delay_ms
        self.state = MasterState.BOOTING
        self.tx_errors = 0
        self._events: list[LogEvent] = []

    @property
    def bus(self) -> can.BusABC:
        """The CAN bus (assignable: the send path follows it)."""
        return self._bus

    @bus.setter
    def bus(self, bus: can.BusABC | CanWireLink) -> None:
        self._bus = bus
        self._wire = bus if isinstance(bus, CanWireLink) else None
        self._send_standard = getattr(bus, "send_standard", None)

    # ------------------------------------------------------------------ node interface
    def tick(self, now: float) -> None:
        """Node interface: ``now`` in seconds; runs :meth:`tick_ms` on whole milliseconds."""
        self.tick_ms(to_ms(now))

    def tick_ms(self, now_ms: int) -> None:
        """One 1 kHz core-task tick: receive what the bus holds, then the schedule."""
        link = self._wire
        if link is not None:
            link.check_alone()
            self.apply_wire_tick(self._core.tick_wire(now_ms, link.clock(), link.wire))
            return
        messages = list(drain(self._bus))
        state, _, out = self._core.tick_ms(now_ms, messages)
        self.state = _STATES[state]
        if out:
            send_standard = self._send_standard
            sent = 0
            for can_id, payload in out:
                if send_neuron_payload_via(self._bus, send_standard, can_id, payload):
                    sent += 1
                else:
                    self.tx_errors += 1
            self._core.count_sent(sent)

    def apply_wire_tick(self, result: tuple[int, int, int, int]) -> None:
        """Take the core's ``tick_wire`` result ``(state, pending_events, sent, log_len)``:
        the phase, and the wire log drained when long (the core counts the frames sent and
        holds the events)."""
        state, _, _, logged = result
        self.state = _STATES[state]
        if logged >= DRAIN_AT:
            self._wire.drain()

    @property
    def wire(self) -> CanWireLink | None:
        """The :class:`CanWireLink` this master ticks on (None on a python-can bus)."""
        return self._wire

    @property
    def tx_count(self) -> int:
        """Frames sent (counted by the core: its wire ticks and the bus's accepted sends)."""
        return self._core.tx_count

    @property
    def _pending_events(self) -> int:
        """Log events the core holds, not yet taken."""
        return self._core.pending_events

    @property
    def core(self) -> _rdm.CanMaster:
        """The Rust master (for callers that run :meth:`tick_ms`'s wire path inline, such as
        ``SpinalMirror``'s steady-state tick; the result goes to :meth:`apply_wire_tick`)."""
        return self._core

    # ------------------------------------------------------------------ commands
    def set_motor_duties(self, duties: Sequence[float]) -> None:
        """Duties 0.5 (stop) .. 1.0 of motors 0..motor_number-1 (sent as ``duty*2000-1000``)."""
        if self.try_set_motor_duties(duties):
            return  # a valid list of floats, applied in one call; otherwise the checks below
        n = self.motor_number
        if len(duties) != n:
            raise ValueError(f"set_motor_duties: {len(duties)} duties for {n}")
        for i, d in enumerate(duties):
            if not isinstance(d, (int, float)) or not math.isfinite(d) or not 0.5 <= d <= 1.0:
                raise ValueError(f"set_motor_duties: duties[{i}]={d!r} not in 0.5..1.0")
        self._core.set_motor_duties([float(d) for d in duties])

    def try_set_motor_duties(self, duties: Sequence[float]) -> bool:
        """:meth:`set_motor_duties` in one core call when ``duties`` is a list of exactly
        :attr:`motor_number` Python floats in 0.5..1.0: True if applied; False (nothing
        applied) otherwise."""
        return type(duties) is list and self._core.try_set_motor_duties(duties)

    def _position(self, slave: int, index: int) -> tuple[int, int]:
        for k, row in enumerate(self._core.neurons()):
            if row[0] == slave and 0 <= index < row[6]:
                return k, index
        raise KeyError(f"no servo {index} on Neuron {slave}")

    def servo(self, slave: int, index: int) -> ServoEntryView:
        """The entry of servo ``index`` on Neuron ``slave`` (KeyError if unknown)."""
        return ServoEntryView(self, *self._position(slave, index))

    def set_servo_targets(self, targets: Mapping[tuple[int, int], int]) -> None:
        """Goal positions (raw ticks, 15-bit signed) keyed by ``(slave, index)``; all checked
        before any is applied."""
        checked = []
        known = set(self._core.servo_keys())  # what _position finds, in one call
        for (slave, index), value in targets.items():
            if not isinstance(value, int) or not WORD_VALUE_MIN <= value <= WORD_VALUE_MAX:
                raise ValueError(f"servo ({slave}, {index}) target {value!r} not a 15-bit int")
            if (slave, index) not in known:
                raise KeyError(f"no servo {index} on Neuron {slave}")
            checked.append((slave, index, value))
        self._core.set_servo_target_list(checked)

    def set_servo_torque(self, slave: int, index: int, enable: bool) -> None:
        """Torque enable of one servo (refused while force-off; off invalidates the goal)."""
        self._position(slave, index)
        self._core.set_servo_torque(slave, index, bool(enable))

    def set_servo_current(self, slave: int, index: int, current: int) -> None:
        if not isinstance(current, int) or not WORD_VALUE_MIN <= current <= WORD_VALUE_MAX:
            raise ValueError(f"servo ({slave}, {index}) current {current!r} not a 15-bit int")
        self._position(slave, index)
        self._core.set_servo_current(slave, index, current)

    def configure_board(self, frame: nr.BoardConfig) -> None:
        """One BOARD_CONFIG_REQUEST at the next tick, then 2000 ms without transmission;
        after REBOOT the Neuron's config is requested again 5000 ms later."""
        if not isinstance(frame, nr.BoardConfig):
            raise TypeError(f"configure_board: {type(frame).__name__} is not a BoardConfig")
        reboot = frame.slave if isinstance(frame, nr.Reboot) else None
        self._core.configure_board(frame.can_id, frame.encode(), reboot)

    # ------------------------------------------------------------------ views
    @property
    def neurons(self) -> list[NeuronEntryView]:
        return [NeuronEntryView(self, k) for k in range(len(self._core.neurons()))]

    @property
    def servo_states(self) -> dict[tuple[int, int], ServoEntryView]:
        """Every known servo keyed by ``(slave, index)``, Neurons in slave-id order."""
        out = {}
        for k, row in enumerate(self._core.neurons()):
            for i in range(row[6]):
                out[(row[0], i)] = ServoEntryView(self, k, i)
        return out

    def servo_keys(self) -> list[tuple[int, int]]:
        """The keys of :attr:`servo_states` in the same order, in one core call."""
        return self._core.servo_keys()

    def servo_reports(self) -> list[tuple[bool, int, int, int, int, bool]]:
        """``(send_data_flag, angle, temperature, current, error, torque_enable)`` of every
        servo in :attr:`servo_states` order, in one core call (the Spinal servo reports)."""
        return self._core.servo_reports()

    @property
    def slaves(self) -> list[int]:
        return [row[0] for row in self._core.neurons()]

    @property
    def connected(self) -> bool:
        return self._core.connected

    @property
    def motor_number(self) -> int:
        return self._core.motor_number

    @property
    def uav_model(self) -> int | None:
        model = self._core.uav_model
        return None if model is None else UavModel(model)

    @property
    def rx_count(self) -> int:
        return self._core.rx_count

    @property
    def goal_resyncs(self) -> int:
        """Servo goal reports after the goal-sync handshake with torque on (a Neuron that
        reset, or missed an acknowledgement)."""
        return self._core.goal_resyncs

    @property
    def rx_errors(self) -> Counter[str]:
        return Counter(dict(self._core.rx_errors()))

    @property
    def rx_kinds(self) -> Counter[str]:
        return Counter(dict(self._core.rx_kinds()))

    @property
    def imu(self) -> dict[int, ImuReading]:
        """Each Neuron's latest IMU samples, scaled and axis-remapped as Spinal does."""
        out = {}
        for slave, raws, stamp in self._core.imu():
            fields = {
                key: None if raw is None else nr.ImuFrame(slave, sensor, *raw).spinal_frame()
                for key, sensor, raw in zip(_SENSOR_KEYS, _SENSORS, raws, strict=True)
            }
            out[slave] = ImuReading(**fields, stamp_ms=stamp)
        return out

    @property
    def events(self) -> list[LogEvent]:
        """Log events not yet taken."""
        self._take_events()
        return self._events

    def pop_events(self) -> list[LogEvent]:
        """Log events not yet taken (the Spinal mirror forwards them over rosserial)."""
        if not self._pending_events and not self._events:
            return []
        self._take_events()
        out, self._events = self._events, []
        return out

    def _take_events(self) -> None:
        if not self._pending_events:
            return
        for stamp, code, arg in self._core.pop_events():
            self._events.append(self._event(stamp, code, arg))

    def _event(self, t: int, code: str, arg: int) -> LogEvent:
        if code == "disabled":
            return LogEvent(t, "error", "no Neuron answered ENUM_REQUEST: CAN master disabled")
        if code == "not_configured":
            return LogEvent(t, "warn", f"Neuron {arg} sent no INITIAL_CONFIG_0")
        if code == "gimbal_mismatch":
            return LogEvent(t, "warn", f"{arg} gimbal servos on {self.motor_number} Neurons")
        if code == "running":
            return LogEvent(
                t,
                "info",
                f"CAN: {self.motor_number} Neurons {self.slaves}, uav_model {self.uav_model}",
            )
        return LogEvent(t, "error", "CAN disconnected!!")

    def close(self) -> None:
        self.bus.shutdown()
