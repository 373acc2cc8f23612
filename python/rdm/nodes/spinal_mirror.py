"""The Spinal flight-controller mirror: rosserial client on a UART + Neuron CAN master + the
on-board estimator / attitude controller / PWM (``jsk-wire-protocols.md`` sec. 1.3-1.7,
2.5-2.7, 3).

It composes the existing parts and re-implements none of them:

* :class:`rdm.protocol.rosserial.ClientSession` (Spinal is the rosserial *client*) with the
  stm32H7_v2 slot layout; subscribers are routed into the core and the CAN master;
* :class:`rdm._rdm.SpinalStep` (estimator + attitude controller with the arming / fail-safe
  state machine + thrust -> PWM) stepped at ``rate_hz`` (200 Hz default, up to 1 kHz);
* :class:`rdm.nodes.can_master.CanMaster` ticked for every elapsed millisecond, fed the duties.

Node pattern (``rdm.nodes.base``): ``tick(now)`` with the time passed in, never a wall clock,
never blocking. IMU samples and the battery voltage come from outside
(:meth:`SpinalMirror.set_imu_sample`, :meth:`SpinalMirror.set_battery_voltage`); the default
is a level, still IMU so that a stand-alone process works. See ``docs/spinal.md``.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from math import floor as _floor
from types import SimpleNamespace
from typing import Any

import can
import numpy as np

from rdm import _rdm
from rdm._rdm import RdmError
from rdm.control.attitude import ARM_OFF, N_ROTORS, CommandRejectedError, SpinalStep
from rdm.link.can_wire import DRAIN_AT
from rdm.link.capture_index import timed_capture_of
from rdm.link.inproc_can import SimClock
from rdm.nodes.base import to_ms
from rdm.nodes.can_master import BOOT_DELAY_MS, IDLE_DUTY, CanMaster, MasterState
from rdm.nodes.onboard_monitors import MonitorLimits, battery_cells
from rdm.nodes.spinal_servo_bridge import MirrorRejection, ServoBridge, target_rejection
from rdm.nodes.spinal_uart import UartPump
from rdm.protocol.rosserial import constants as C
from rdm.protocol.rosserial.client import ClientSession
from rdm.protocol.rosserial.events import (
    Configured,
    DroppedMessage,
    FrameRejected,
    MessageReceived,
    ServiceHandled,
    SyncLost,
)
from rdm.protocol.rosserial.registry import TypeRegistry, spinal_registry
from rdm.protocol.rosserial.timesync import ClientClock

try:  # the busy-ms helpers (crates/rdm_py/src/spinal_mirror.rs); without them: Python only
    from rdm._rdm import spinal_duty_list as _duty_list
    from rdm._rdm import spinal_imu_frame as _imu_frame
except ImportError:
    _duty_list = _imu_frame = None

#: Publication periods in HAL ms and whether the firmware compares with ``>`` (strict).
IMU_PUB_MS = 5  # >= 5 ms (200 Hz), attitude_estimate.h
BATTERY_PUB_MS = 100  # > 100 ms, battery_status.h
BATTERY_SAMPLE_MS = 20  # the battery task runs every 20 ms
MOTOR_PWMS_PUB_MS = 100  # > 100 ms, attitude_control.cpp
SERVO_STATES_PUB_MS = 20  # >= 20 ms (50 Hz), spine.cpp
SERVO_TORQUE_PUB_MS = 1000  # >= 1000 ms
#: Battery low-pass ``v = 0.99 v + 0.01 new`` per 20 ms sample.
BATTERY_FILTER = 0.99
#: A tick that skips more milliseconds than this replays only the last ones on CAN (as
#: ``CanMaster``'s own cap): on a starved host a bigger replay makes every tick slower still.
MAX_CAN_CATCH_UP_MS = 10
#: Control steps replayed at most per tick when the loop runs late; then re-phased.
MAX_CONTROL_CATCH_UP = 5
#: A level, still IMU: no rotation, gravity on +z (m/s^2), an Earth-like field (uT).
LEVEL_GYRO = (0.0, 0.0, 0.0)
LEVEL_ACC = (0.0, 0.0, 9.80665)
LEVEL_MAG = (30.0, 0.0, -40.0)
DEFAULT_BATTERY_V = 25.2
MAX_RATE_HZ = 1000.0

#: (key, period ms, strict) of every periodic publisher, as ``_publish_due`` checks them.
_PUBLISHERS = (
    ("imu", IMU_PUB_MS, False),
    ("battery_voltage_status", BATTERY_PUB_MS, True),
    ("motor_pwms", MOTOR_PWMS_PUB_MS, True),
    ("servo/states", SERVO_STATES_PUB_MS, False),
    ("servo/torque_states", SERVO_TORQUE_PUB_MS, False),
)


#: ``_next_due`` of a publisher that never published (due at once).
_NEVER = -(2**62)


def _next_due(last_pub: dict[str, int], key: str, period_ms: int, strict: bool) -> int:
    """First ms at which ``SpinalMirror._due(key, ...)`` returns True again."""
    last = last_pub.get(key)
    if last is None:
        return _NEVER
    return last + period_ms + (1 if strict else 0)


_FAILSAFE_TEXT = {
    "failsafe_timeout": "failsafe: cannot connect with ROS",
    "failsafe_tilt": "failsafe: the roll pitch angles are too large",
    "failsafe_command_tilt": "failsafe: target angles are too large",
}
#: The controller's guards (docs/spinal.md "Guards on the actuator path"): the first of a run
#: is logged as a warning; every trip is counted by the core (``core.counters``).
_GUARD_TEXT = {
    "voltage_rejected": "guard: implausible battery voltage, the last good one is used",
    "command_saturated": "guard: four_axes/command thrust saturated",
    "non_finite_output": "guard: non-finite thrust, every motor at min duty",
}
_LOG_LEVELS = {
    "debug": C.LogLevel.DEBUG,
    "info": C.LogLevel.INFO,
    "warn": C.LogLevel.WARN,
    "error": C.LogLevel.ERROR,
    "fatal": C.LogLevel.FATAL,
}
#: The commands the fast path applies from their field values (``_route_values``), with
#: the message type whose layout those handlers read (a slot of another type or layout is
#: routed as a message).
_VALUE_ROUTE_TYPES = {
    "four_axes/command": "spinal/FourAxisCommand",
    "rpy/gain": "spinal/RollPitchYawTerms",
    "p_matrix_pseudo_inverse_inertia": "spinal/PMatrixPseudoInverseWithInertia",
    "desire_coordinate": "spinal/DesireCoord",
    "servo/target_states": "spinal/ServoControlCmd",
}
#: ``rdm._rdm.spinal_apply_commands``' kind codes of the value-route topics.
_COMMAND_KINDS = {
    "four_axes/command": 1,
    "rpy/gain": 2,
    "p_matrix_pseudo_inverse_inertia": 3,
    "desire_coordinate": 4,
    "servo/target_states": 5,
}
_apply_commands = getattr(_rdm, "spinal_apply_commands", None)
#: The ``spinal/Imu`` layout ``rdm._rdm.spinal_imu_frame`` writes (``codec._FlatLayout``).
_IMU_PARTS = [
    ("stamp", "t", None),
    ("acc", "a", 3),
    ("gyro", "a", 3),
    ("mag", "a", 3),
    ("quaternion", "a", 4),
]
_IMU_FORMAT = "<II3f3f3f4f"
_IMU_CALIB_GET = 0  # spinal/ImuCalib GET_CALIB_DATA
_IMU_CALIB_GYRO = 2  # spinal/ImuCalib CALIB_GYRO
_MAG_SET = 1  # spinal/MagDeclination SET


def _floats(values: Sequence[float]) -> tuple[float, ...]:
    """``tuple(float(v) for v in values)``; a float64 array in one ``tolist`` call."""
    if isinstance(values, np.ndarray) and values.dtype == np.float64:
        return tuple(values.tolist())
    return tuple(float(v) for v in values)


def _applied(setter: Any, *args: Any) -> bool:
    """Call a core ``*_rows`` setter (plain Python ints, no numpy array); False when its
    arguments do not convert (floats, out-of-range ints, wrong lengths: nothing applied), so
    that the caller's array path runs and decides as the reference does. The core's own
    rejections (:class:`RdmError`) are the reference's and propagate."""
    try:
        setter(*args)
    except RdmError:
        raise
    except (TypeError, OverflowError, ValueError):
        return False
    return True


def _wire_layout(codec: Any) -> tuple[Any, ...]:
    """``(name, base type, array length, nested layout)`` of every field of ``codec``,
    nested types expanded: two codecs with equal layouts decode a payload to the same
    values."""
    out = []
    for f in codec.spec.fields:
        nested = None if f.is_primitive else _wire_layout(codec._resolve(f.base_type))
        out.append((f.name, f.base_type, f.array_len, nested))
    return tuple(out)


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


@dataclass
class MirrorCounters:
    """Diagnostics of a :class:`SpinalMirror` (all monotonic)."""

    #: Messages accepted per topic (subscribers) and sent per topic (publishers).
    received: Counter[str] = field(default_factory=Counter)
    published: Counter[str] = field(default_factory=Counter)
    #: Messages not applied, by reason (``wrong_length``, ``not_armed``, ``servo_index`` ...).
    rejected: Counter[str] = field(default_factory=Counter)
    #: Fail-safe events by kind (``failsafe_timeout``, ``failsafe_tilt`` ...) and acks by value.
    failsafes: Counter[str] = field(default_factory=Counter)
    acks: Counter[int] = field(default_factory=Counter)
    #: rosserial frames the parser delivered / rejected, undeliverable frames.
    frames_rejected: Counter[str] = field(default_factory=Counter)
    dropped: int = 0
    logs: Counter[str] = field(default_factory=Counter)
    control_steps: int = 0
    control_overruns: int = 0
    configured: int = 0
    sync_lost: int = 0


class SpinalMirror:
    """Spinal on a UART (rosserial client) and a CAN bus (Neuron master).

    ``uart`` is a :class:`rdm.link.serial.SerialLink` (anything with ``read_available`` and a
    pyserial ``port``); ``can_bus`` a python-can bus. Both are owned (closed by :meth:`close`).
    ``spinal_options`` go to :class:`SpinalStep` (``time_matched``, ``anti_windup``,
    ``command_timeout_s``, estimator overrides such as ``gyro_calib_duration_s`` ...).
    """

    def __init__(
        self,
        uart: Any,
        can_bus: can.BusABC,
        rate_hz: float = 200.0,
        *,
        name: str = "spinal",
        period: float = 0.001,
        boot_delay_ms: int = BOOT_DELAY_MS,
        registry: TypeRegistry | None = None,
        layout: Any = None,
        master_backend: str = "python",
        fast_paths: bool = True,
        **spinal_options: Any,
    ) -> None:
        if not (isinstance(rate_hz, (int, float)) and 0 < rate_hz <= MAX_RATE_HZ):
            raise ValueError(f"SpinalMirror: rate_hz {rate_hz!r} not in (0, {MAX_RATE_HZ:g}]")
        if not (isinstance(period, (int, float)) and 0 < period <= 0.1):
            raise ValueError(f"SpinalMirror: period {period!r} not in (0, 0.1] s")
        self.name = name
        # Wanted tick period: 1 ms is the firmware's core task. A longer one (slow hosts) still
        # runs the CAN schedule for every elapsed ms and the control at rate_hz.
        self.period = float(period)
        self.rate_hz = float(rate_hz)
        self.uart = UartPump(uart)
        if master_backend == "rust":  # the Rust core (docs/canbus.md); "python" = reference
            from rdm.nodes.can_master_rust import RustCanMaster

            self.master = RustCanMaster(can_bus, boot_delay_ms=boot_delay_ms)
        elif master_backend == "python":
            self.master = CanMaster(can_bus, boot_delay_ms=boot_delay_ms)
        else:
            raise ValueError(f"SpinalMirror: master_backend {master_backend!r}: 'python' or 'rust'")
        self.core = SpinalStep(self.rate_hz, **spinal_options)
        # fast_paths=False keeps the plain per-ms path (the reference of the fast one).
        self._fast = bool(fast_paths)
        #: The lockstep kernel may run the routine busy ms (control step, battery sample,
        #: ``imu`` / ``servo/states`` publications) itself (:meth:`kernel_plan`'s busy part);
        #: False: only the idle ms (the plain kernel path, docs/spinal.md).
        self.kernel_busy = True
        #: A ms with bytes to read: this mirror receives them (:meth:`kernel_receive_tick`)
        #: and the kernel runs the rest of the ms from its plan; False: the whole tick here.
        self.kernel_receive = True
        #: The kernel writes its deferred output and the TX counters itself, through the
        #: UART chain (as :meth:`kernel_commit_tx` does); False: it calls that method.
        self.kernel_tx_direct = True
        self.servos = ServoBridge(self.master, fast=self._fast)
        #: The Rust master's one-call duty hand-over (None: the Python master).
        self._try_duties = getattr(self.master, "try_set_motor_duties", None)
        reg = registry or spinal_registry()
        self.session = ClientSession.from_layout(
            layout,
            handlers={
                "imu_calib": self._srv_imu_calib,
                "set_attitude_control": self._srv_set_attitude_control,
                "get_board_info": self._srv_get_board_info,
                "mag_declination": self._srv_mag_declination,
            },
            registry=reg,
        )
        self._msg = SimpleNamespace(
            imu=reg.msg("spinal/Imu"),
            uint8=reg.msg("std_msgs/UInt8"),
            float32=reg.msg("std_msgs/Float32"),
            pwms=reg.msg("spinal/Pwms"),
            servo_state=reg.msg("spinal/ServoState"),
            servo_states=reg.msg("spinal/ServoStates"),
            torque_states=reg.msg("spinal/ServoTorqueStates"),
            board_info=reg.msg("spinal/BoardInfo"),
            servo_info=reg.msg("spinal/ServoInfo"),
        )
        self._srv = SimpleNamespace(
            imu_calib=reg.srv("spinal/ImuCalib").response,
            set_bool=reg.srv("std_srvs/SetBool").response,
            board_info=reg.srv("spinal/GetBoardInfo").response,
            mag=reg.srv("spinal/MagDeclination").response,
        )
        self._routes = {
            "four_axes/command": self._on_four_axis_command,
            "rpy/gain": self._on_gain,
            "p_matrix_pseudo_inverse_inertia": self._on_pinv_inertia,
            "torque_allocation_matrix_inv": self._on_torque_allocation_inv,
            "motor_info": self._on_motor_info,
            "uav_info": self._on_uav_info,
            "flight_config_cmd": self._on_flight_config,
            "desire_coordinate": self._on_desire_coordinate,
            "pwm_test": self._on_pwm_test,
            "servo/target_states": self.servos.target_states,
            "servo/target_current": self.servos.target_current,
            "servo/torque_enable": self.servos.torque_enable,
            "set_adc_scale": self._on_adc_scale,
        }
        #: The fast path's command handlers taking ``decode_values`` field values instead of
        #: a message (``_route_values``); each returns False, having applied nothing, when
        #: the values do not convert (then the message path runs and decides).
        #: Armed on the session while ``_fast`` is on (``_receive`` follows a change).
        self._value_routes: dict[str, Any] = {}
        handlers = {
            "four_axes/command": self._four_axis_values,
            "rpy/gain": self._gain_values,
            "p_matrix_pseudo_inverse_inertia": self._pinv_values,
            "desire_coordinate": self._desire_values,
            "servo/target_states": self._servo_targets_values,
        }
        builtin = spinal_registry()
        for slot in self.session.subscribers:
            type_ = _VALUE_ROUTE_TYPES.get(slot.name)
            if (
                type_ is not None
                and slot.service is None
                and slot.codec.full_name == type_
                and _wire_layout(slot.codec) == _wire_layout(builtin.msg(type_))
                and self._routes.get(slot.name) is not None
            ):
                self._value_routes[slot.name] = handlers[slot.name]
        self._values_armed = False  # whether the session delivers _value_routes as values
        #: Per subscriber index: the ``rdm._rdm.spinal_apply_commands`` kind of its frames
        #: (0: not one it applies) and its topic, for :meth:`_apply_command_run`.
        self._command_kinds = bytes(
            _COMMAND_KINDS[slot.name] if slot.name in self._value_routes else 0
            for slot in self.session.subscribers
        )
        self._command_topics = tuple(slot.name for slot in self.session.subscribers)
        self._imu_codec: Any = None  # the imu publisher's codec, checked for _imu_frame
        self.counters = MirrorCounters()
        self.gyro = LEVEL_GYRO
        self.acc = LEVEL_ACC
        self.mag = LEVEL_MAG
        self.battery_input = DEFAULT_BATTERY_V
        self.adc_scale = 1.0
        #: ``set_adc_scale`` as the firmware takes it (any positive scale); False: a scale
        #: giving an implausible battery reading is rejected (see :meth:`_on_adc_scale`)
        self.firmware_adc_scale = False
        #: the highest reference voltage of the last accepted ``motor_info`` (the full battery)
        self.reference_voltage = DEFAULT_BATTERY_V
        self.battery_voltage: float | None = None  # the low-passed value the firmware uses
        self.mag_declination = 0.0
        self.last_output: Any = None
        self.duties: list[float] = []
        self.pwm_test: list[float] | None = None
        self.now_ms: int | None = None
        self._now_s = 0.0
        self._next_control: float | None = None
        self._can_ms: int | None = None
        self._master_was_running = False
        self._last_pub: dict[str, int] = {}
        self._next_pub_ms = -(2**62)  # earliest ms a publisher can be due (see _publish)
        self._duties_to_master: list[float] | None = None
        self._battery_due_ms = -(2**62)  # first ms _battery samples again
        self._idle_lo = self._idle_hi = 0  # ClientSession.idle_window after the last spin
        # The Rust master on a CanWireLink: tick's steady-state CAN ms in one core call.
        wire = getattr(self.master, "wire", None) if master_backend == "rust" else None
        self._wire_link = wire if self._fast else None
        self._wire_channel = None if wire is None else wire._ch
        self._tick_wire_steady = None if wire is None else self.master.core.tick_wire_steady
        self._core_try_duties = None if wire is None else self.master.core.try_set_motor_duties

    # ---------------------------------------------------------------- inputs from outside
    def set_imu_sample(
        self, gyro: Sequence[float], acc: Sequence[float], mag: Sequence[float]
    ) -> None:
        """The IMU sample the next control steps use: gyro rad/s, acc m/s^2, mag uT (body)."""
        self.gyro = _floats(gyro)
        self.acc = _floats(acc)
        self.mag = _floats(mag)

    def set_battery_voltage(self, volts: float) -> None:
        """The raw battery reading (V), sampled every 20 ms and low-passed as the firmware does."""
        self.battery_input = float(volts)

    # ---------------------------------------------------------------- node interface
    def tick(self, now: float) -> None:
        """Advance to ``now`` (s): UART in, due control steps, CAN ms ticks, publish, UART out."""
        if not self._fast:
            self._tick_plain(now)
            return
        # The plain tick with every step's own "nothing to do" check inline, so that an idle
        # ms (no UART byte, no control step or publisher due, one steady CAN ms) costs one
        # Rust call and a few comparisons. Each skip is exactly the guarded step's no-op.
        now_ms = self._tick_begin(now)
        inbox = self.uart.inbox
        if inbox is None or inbox or not self._idle_lo <= now_ms < self._idle_hi:
            self._receive(now_ms)  # else: no byte to read and spin(b"") would do nothing
        self._tick_rest(now_ms)

    def _tick_begin(self, now: float) -> int:
        """:meth:`tick`'s clock: the ms of ``now`` (never before the last one) and ``_now_s``.
        Calling it again with the same ``now`` changes nothing."""
        now_ms = _floor(now * 1000.0 + 1e-6)  # to_ms(now)
        last_ms = self.now_ms
        if last_ms is not None and now_ms < last_ms:
            now_ms = last_ms  # time never goes back
        if now.__class__ is not float:
            now = float(now)
        if now > self._now_s:  # max(self._now_s, now)
            self._now_s = now
        self.now_ms = now_ms
        return now_ms

    def _tick_rest(self, now_ms: int) -> None:
        """:meth:`tick` after the UART receive: battery, due control steps, the tail."""
        if now_ms >= self._battery_due_ms:
            self._battery(now_ms)
        next_control = self._next_control
        if next_control is None or self._now_s >= next_control - 1e-9:
            self._control(self._now_s)
        self._tick_tail(now_ms)

    def _tick_tail(self, now_ms: int) -> None:
        """:meth:`tick` after the control steps: the CAN ms, publishers and UART output (also
        the lockstep kernel's continuation of a ms whose control step it ran)."""
        can_ms = self._can_ms
        link = self._wire_link
        master = self.master
        if (
            link is not None
            and can_ms is not None
            and now_ms == can_ms + 1
            and self._master_was_running
            and master.state is MasterState.RUNNING
            and master._wire is link
            and (
                self.duties is self._duties_to_master
                or (master.fast and self._try_wire_duties(self.duties))
            )
        ):
            # _can's steady state with no new duties, and RustCanMaster.tick_ms's wire path,
            # in one core call: the same checks, stamp, frames, counters and log drain.
            ch = self._wire_channel
            if len(ch.buses) != 1 or ch.taps:
                link.check_alone()  # raises CanWireError
            clock = ch.clock
            stamp = clock.now if clock.__class__ is SimClock else clock()
            sent = self._tick_wire_steady(now_ms, stamp, link.wire, DRAIN_AT)
            self._can_ms = now_ms
            if sent >= 0:  # still running, no event pending, the log short
                master.tx_count += sent
                master._pending_events = 0
                if master._events:
                    self._forward_can_events()
            else:
                master.apply_wire_tick(master.core.last_wire_tick)
                self._forward_can_events()
        else:
            self._can(now_ms)
            self._forward_can_events()
        if now_ms >= self._next_pub_ms:
            self._publish(now_ms)
        if self.session.pending_frames or self.uart.pending:  # else send has nothing to do
            self.uart.send(self.session.take_output())

    def _try_wire_duties(self, duties: list[float]) -> bool:
        """_can's steady-state hand-over of a new duty list when the core takes it in one
        call (``RustCanMaster.try_set_motor_duties``); False: nothing applied, _can decides."""
        if duties.__class__ is list and self._core_try_duties(duties):
            self._duties_to_master = duties
            return True
        return False

    def _tick_plain(self, now: float) -> None:
        """The reference tick: every step every ms (``fast_paths=False``)."""
        now_ms = to_ms(now)
        if self.now_ms is not None and now_ms < self.now_ms:
            now_ms = self.now_ms  # time never goes back
        self._now_s = max(self._now_s, float(now))
        self.now_ms = now_ms
        self._receive(now_ms)
        self._battery(now_ms)
        self._control(self._now_s)
        self._can(now_ms)
        self._forward_can_events()
        self._publish(now_ms)
        self.uart.send(self.session.take_output())

    def close(self) -> None:
        """Close the UART and the CAN bus."""
        try:
            self.uart.link.close()
        finally:
            self.master.close()

    # ---------------------------------------------------------------- UART receive
    def _receive(self, now_ms: int) -> None:
        if self._values_armed is not self._fast:  # the value routes follow fast_paths
            self.session.deliver_values(self._value_routes if self._fast else ())
            runs = self._fast and _apply_commands is not None and any(self._command_kinds)
            self.session.command_run = self._apply_command_run if runs else None
            self._values_armed = self._fast
        data = self.uart.read()
        for event in self.session.spin(data, now_ms):
            if event.__class__ is tuple:  # (slot, values, payload): see _route_values
                self._route_values(*event)
            elif isinstance(event, MessageReceived):
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
        # the ms from here up to hi need no spin while no byte comes (the fast tick's skip)
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

    def _route_values(self, slot: Any, values: tuple[Any, ...], payload: bytes) -> None:
        """:meth:`_route` of ``slot.codec.decode(payload)`` from its field ``values``
        (``ClientSession.deliver_values``): the same calls into the core, the same counters
        and rejections. A handler that declines (False, nothing applied) hands over to the
        message path."""
        topic = slot.name
        try:
            done = self._value_routes[topic](values)
        except ValueError as exc:
            self._route_failed(topic, exc)
            return
        if done:
            self.counters.received[topic] += 1
        else:
            self._route(topic, slot.codec.decode(payload))

    def _apply_command_run(self, items: list) -> int:
        """``ClientSession.command_run``: the leading steady command frames of ``items``
        (the parser's good frames) applied in one call, ``rdm._rdm.spinal_apply_commands``:
        the core calls of :meth:`_route_values` for each, with its counters and rejections.
        Returns how many frames are done; the session hands the rest to the usual path."""
        assert _apply_commands is not None
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
        if exc is not None:  # item n's core call raised: routed as _route_values does
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
    # The *_values handlers are the fast forms of the _on_* handlers below, from the field
    # values of ``MessageCodec.decode_values`` (nested messages as tuples); same core calls.
    def _four_axis_values(self, values: tuple[Any, ...]) -> bool:
        angles, base = values  # list of 3 floats, list of floats: _on_four_axis_command's
        return _applied(self.core.four_axis_command_list, angles, base, self._now_s)

    def _gain_values(self, values: tuple[Any, ...]) -> bool:
        return _applied(self.core.set_gains_wire_rows, values[0])  # the 7-int rows

    def _pinv_values(self, values: tuple[Any, ...]) -> bool:
        return _applied(self.core.set_pinv_inertia_wire_rows, values[0], values[1])

    def _desire_values(self, values: tuple[Any, ...]) -> bool:
        self.core.set_desire_coordinate(*values)  # three floats
        return True

    def _servo_targets_values(self, values: tuple[Any, ...]) -> bool:
        self.servos.target_states_values(values[0], values[1])
        return True

    def _on_four_axis_command(self, msg: Any) -> None:
        if self._fast:
            try:
                angles = [float(a) for a in msg.angles]
            except (TypeError, ValueError):
                angles = None  # the array path below raises as the reference does
            if angles is not None and _applied(
                self.core.four_axis_command_list, angles, msg.base_thrust, self._now_s
            ):
                return
        base = np.asarray(msg.base_thrust, dtype=np.float64)
        self.core.four_axis_command([float(a) for a in msg.angles], base, self._now_s)

    def _on_gain(self, msg: Any) -> None:
        if self._fast:
            rows = [
                (m.roll_p, m.roll_i, m.roll_d, m.pitch_p, m.pitch_i, m.pitch_d, m.yaw_d)
                for m in msg.motors
            ]
            if _applied(self.core.set_gains_wire_rows, rows):
                return
        terms = np.array(
            [
                [m.roll_p, m.roll_i, m.roll_d, m.pitch_p, m.pitch_i, m.pitch_d, m.yaw_d]
                for m in msg.motors
            ],
            dtype=np.int64,
        ).reshape(-1, 7)
        self.core.set_gains_wire(terms)

    def _on_pinv_inertia(self, msg: Any) -> None:
        if self._fast:
            pinv = [(u.r, u.p, u.y) for u in msg.pseudo_inverse]
            inertia = [int(v) for v in msg.inertia]
            if _applied(self.core.set_pinv_inertia_wire_rows, pinv, inertia):
                return
        rows = np.array([[u.r, u.p, u.y] for u in msg.pseudo_inverse], dtype=np.int16).reshape(
            -1, 3
        )
        self.core.set_pinv_inertia_wire(rows, [int(v) for v in msg.inertia])

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

    # ---------------------------------------------------------------- battery, control, CAN
    def _battery(self, now_ms: int) -> None:
        last = self._last_pub.get("_battery_sample")
        if last is not None and now_ms - last < BATTERY_SAMPLE_MS:
            return
        self._last_pub["_battery_sample"] = now_ms
        self._battery_due_ms = now_ms + BATTERY_SAMPLE_MS
        sample = self.battery_input * self.adc_scale
        if not math.isfinite(sample):
            self.counters.rejected["battery_non_finite"] += 1
            return
        v = self.battery_voltage
        self.battery_voltage = (
            sample if v is None else BATTERY_FILTER * v + (1 - BATTERY_FILTER) * sample
        )

    def _control(self, now: float) -> None:
        period = 1.0 / self.rate_hz
        if self._next_control is None:
            self._next_control = now
        steps = 0
        while now >= self._next_control - 1e-9:
            if steps == MAX_CONTROL_CATCH_UP:
                self.counters.control_overruns += 1
                self._next_control = now + period
                break
            self._step(now)
            steps += 1
            self._next_control += period

    def _step(self, now: float) -> None:
        voltage = self.battery_voltage if self.battery_voltage is not None else self.battery_input
        out = self.core.step(now, self.gyro, self.acc, self.mag, voltage)
        self.last_output = out
        self.counters.control_steps += 1
        if self._fast and _duty_list is not None and self.pwm_test is None:
            # No event and the controller's own duties: the list _step_tail builds, from
            # the core's output in one call (None: an event or another case, below).
            n = self.master.motor_number
            if n == self.core.motor_number:
                duties = _duty_list(out, n, IDLE_DUTY)
                if duties is not None:
                    self.duties = duties
                    return
        self._step_tail(out)

    def _step_tail(self, out: Any) -> None:
        """The events of a control step, then the duty list for the CAN master."""
        for kind, value in out.events:
            if kind == "ack":
                self.counters.acks[int(value)] += 1
                self._publish_topic("flight_config_ack", self._msg.uint8.new(data=int(value)))
            elif kind == "rejected":
                self._log(C.LogLevel.ERROR, str(value))
            elif kind in _FAILSAFE_TEXT:
                self.counters.failsafes[kind] += 1
                self._log(C.LogLevel.ERROR, _FAILSAFE_TEXT[kind])
            elif kind in _GUARD_TEXT:
                self._log(C.LogLevel.WARN, _GUARD_TEXT[kind])
            elif kind == "events_dropped":
                self.counters.failsafes["events_dropped"] += int(value)
        n = self.master.motor_number
        if self.pwm_test is not None:
            duties = (self.pwm_test + [IDLE_DUTY] * n)[:n]
        elif n and n == self.core.motor_number and n <= N_ROTORS:
            # tolist: the same Python floats as float() of each element, in one call
            duties = [min(1.0, max(IDLE_DUTY, d)) for d in out.duty.tolist()[:n]]
        else:
            duties = [IDLE_DUTY] * n
        self.duties = duties

    def _can(self, now_ms: int) -> None:
        can_ms = self._can_ms
        if self._fast and self._master_was_running and can_ms is not None and now_ms == can_ms + 1:
            # The steady state: one new ms, the model adopted; the loop below for t = now_ms.
            master = self.master
            if master.state is MasterState.RUNNING:
                duties = self.duties
                if duties is not self._duties_to_master:
                    if self._try_duties is not None and self._try_duties(duties):
                        self._duties_to_master = duties  # valid floats, applied in one call
                    elif len(duties) == master.motor_number:
                        master.set_motor_duties(duties)
                        self._duties_to_master = duties
            master.tick_ms(now_ms)
            self._can_ms = now_ms
            return
        start = now_ms if self._can_ms is None else self._can_ms + 1
        start = max(start, now_ms - MAX_CAN_CATCH_UP_MS + 1)
        for t in range(start, now_ms + 1):
            if self.master.state is MasterState.RUNNING:
                if not self._master_was_running:
                    self._master_was_running = True
                    self._adopt_can_model()
                if len(self.duties) == self.master.motor_number and (
                    self.duties is not self._duties_to_master
                ):
                    # Only a new duty list is handed over (the master keeps the last one;
                    # _step always builds a new list, so the same object = the same values).
                    self.master.set_motor_duties(self.duties)
                    self._duties_to_master = self.duties
            self.master.tick_ms(t)
        self._can_ms = now_ms

    def _adopt_can_model(self) -> None:
        """Spine::init: motor number and model inferred from CAN go to the controller."""
        model = self.master.uav_model
        n = self.master.motor_number
        if model is None or n == 0:
            return
        try:
            self.core.set_uav_info(n, int(model))
        except (CommandRejectedError, ValueError) as exc:
            self._reject(rejection_reason(str(exc)), f"CAN model: {exc}", log=True)
        self.duties = [IDLE_DUTY] * n

    def _forward_can_events(self) -> None:
        for event in self.master.pop_events():
            self._log(_LOG_LEVELS.get(event.level, C.LogLevel.INFO), event.text)

    # ---------------------------------------------------------------- publishers
    def _due(self, key: str, now_ms: int, period_ms: int, strict: bool) -> bool:
        last = self._last_pub.get(key)
        if last is not None:
            elapsed = now_ms - last
            if (elapsed <= period_ms) if strict else (elapsed < period_ms):
                return False
        self._last_pub[key] = now_ms
        return True

    def _publish(self, now_ms: int) -> None:
        if not self.session.configured or self.last_output is None:
            return
        if now_ms < self._next_pub_ms:
            return  # no publisher due (exact: the earliest time any _due below fires)
        if self._fast:
            self._next_pub_ms = self._publish_due_fast(now_ms)
            return
        self._publish_due(now_ms)
        last = self._last_pub
        self._next_pub_ms = min(
            _next_due(last, key, period, strict) for key, period, strict in _PUBLISHERS
        )

    def _publish_due_fast(self, now_ms: int) -> int:
        """:meth:`_publish_due` with the five ``_due`` checks inline (same order, same
        ``_last_pub`` updates); returns the first ms a publisher is due again."""
        last = self._last_pub
        get = last.get
        stamp = None
        t = get("imu")
        if t is None or now_ms - t >= IMU_PUB_MS:
            last["imu"] = t = now_ms
            if not self._publish_imu_frame(now_ms):
                stamp = self.session.now(now_ms)
                self._publish_topic("imu", self._imu_message(stamp))
        next_ms = t + IMU_PUB_MS
        t = get("battery_voltage_status")
        if t is None or now_ms - t > BATTERY_PUB_MS:
            last["battery_voltage_status"] = t = now_ms
            if self.battery_voltage is not None:
                self._publish_topic(
                    "battery_voltage_status", self._msg.float32.new(data=self.battery_voltage)
                )
        next_ms = min(next_ms, t + BATTERY_PUB_MS + 1)
        t = get("motor_pwms")
        if t is None or now_ms - t > MOTOR_PWMS_PUB_MS:
            last["motor_pwms"] = t = now_ms
            values = [int(d * 2000.0) for d in self.duties]
            self._publish_topic("motor_pwms", self._msg.pwms.new(motor_value=values))
        next_ms = min(next_ms, t + MOTOR_PWMS_PUB_MS + 1)
        t = get("servo/states")
        if t is None or now_ms - t >= SERVO_STATES_PUB_MS:
            last["servo/states"] = t = now_ms
            if stamp is None:
                stamp = self.session.now(now_ms)
            if not self._publish_servo_states_frame(stamp):
                msg = self.servos.states(self._msg, stamp)
                if msg is not None:
                    self._publish_topic("servo/states", msg)
        next_ms = min(next_ms, t + SERVO_STATES_PUB_MS)
        t = get("servo/torque_states")
        if t is None or now_ms - t >= SERVO_TORQUE_PUB_MS:
            last["servo/torque_states"] = t = now_ms
            msg = self.servos.torque_states(self._msg)
            if msg is not None:
                self._publish_topic("servo/torque_states", msg)
        return min(next_ms, t + SERVO_TORQUE_PUB_MS)

    def _publish_imu_frame(self, now_ms: int) -> bool:
        """The ``imu`` publication of :meth:`_publish_due` as one frame built in Rust
        (``rdm._rdm.spinal_imu_frame``: stamp, message, frame and checksums): the same bytes,
        TX ring and counters. False, having done nothing, when that path does not apply (no
        extension function, another publisher codec or clock class, values it declines)."""
        session = self.session
        clock = session.clock
        if _imu_frame is None or clock.__class__ is not ClientClock:
            return False
        try:
            slot = session.publisher("imu")
        except KeyError:
            return False  # the message path raises it
        codec = slot.codec
        if codec is not self._imu_codec:
            flat = codec._flat
            if flat is None or flat.parts != _IMU_PARTS or flat.struct.format != _IMU_FORMAT:
                return False
            self._imu_codec = codec
        topic_id = slot.topic_id
        frame = _imu_frame(
            topic_id,
            now_ms,
            clock.synced,
            clock._sync_tick,
            clock._sync_ns,
            self.acc,
            self.last_output,
            self.mag,
        )
        if frame is None:
            return False
        if session.send_frame(topic_id, frame) > 0:
            self.counters.published["imu"] += 1
        return True

    def _publish_servo_states_frame(self, stamp: Any) -> bool:
        """The ``servo/states`` publication built from the servo table without message
        objects (``ServoBridge.states_frame``): the same frame and counters. False, having
        done nothing, when that path does not apply."""
        session = self.session
        try:
            slot = session.publisher("servo/states")
        except KeyError:
            return False  # the message path raises it (if a servo reports)
        codec = slot.codec
        if codec is not self._msg.servo_states:
            return False
        topic_id = slot.topic_id
        frame = self.servos.states_frame(codec, stamp, topic_id)
        if frame is False:
            return False
        if frame is not None and session.send_frame(topic_id, frame) > 0:
            self.counters.published["servo/states"] += 1
        return True

    def _imu_message(self, stamp: Any) -> Any:
        """The ``spinal/Imu`` message of the present sample and estimate."""
        out = self.last_output
        return self._msg.imu.new(
            stamp=stamp,
            acc=list(self.acc),
            gyro=out.angular_velocity.tolist(),
            mag=list(self.mag),
            quaternion=out.quaternion.tolist(),
        )

    def _publish_due(self, now_ms: int) -> None:
        stamp = self.session.now(now_ms)
        if self._due("imu", now_ms, IMU_PUB_MS, strict=False):
            self._publish_topic("imu", self._imu_message(stamp))
        if (
            self._due("battery_voltage_status", now_ms, BATTERY_PUB_MS, strict=True)
            and self.battery_voltage is not None
        ):
            self._publish_topic(
                "battery_voltage_status", self._msg.float32.new(data=self.battery_voltage)
            )
        if self._due("motor_pwms", now_ms, MOTOR_PWMS_PUB_MS, strict=True):
            values = [int(d * 2000.0) for d in self.duties]
            self._publish_topic("motor_pwms", self._msg.pwms.new(motor_value=values))
        if self._due("servo/states", now_ms, SERVO_STATES_PUB_MS, strict=False):
            msg = self.servos.states(self._msg, stamp)
            if msg is not None:
                self._publish_topic("servo/states", msg)
        if self._due("servo/torque_states", now_ms, SERVO_TORQUE_PUB_MS, strict=False):
            msg = self.servos.torque_states(self._msg)
            if msg is not None:
                self._publish_topic("servo/torque_states", msg)

    def _publish_topic(self, topic: str, msg: Any) -> None:
        if self.session.publish(topic, msg) > 0:
            self.counters.published[topic] += 1

    def _log(self, level: int, text: str) -> None:
        self.counters.logs[C.LogLevel(level).name.lower()] += 1
        self.session.log(level, text)

    # ---------------------------------------------------------------- lockstep kernel
    def kernel_plan(self) -> tuple | None:
        """The window in which :meth:`tick` is only the steady CAN ms, for
        ``rdm._rdm.LockstepKernel`` (docs/sim.md): (now_ms, _now_s, idle window lo, hi,
        battery due ms, next control time, CAN ms, next publisher ms); the kernel runs a
        tick at ms m itself when m is inside the idle window, before the battery, control and
        publisher times, and one past the CAN ms. None when no tick can run so: the plain
        tick, bytes waiting, the master not steady on the wire, events or output pending.
        Before the master first runs, the last item is its phase index (the kernel then runs
        the idle ms of the boot: a CAN ms that stays in that phase); else None.
        The kernel writes ``now_ms``, ``_now_s``, ``_can_ms`` and the master's ``tx_count``
        and ``_pending_events`` back itself, as the steady tick leaves them."""
        if not self._fast or self.now_ms is None or self._next_control is None:
            return None
        inbox = self.uart.inbox
        link = self._wire_link
        master = self.master
        if inbox is None or inbox or link is None or self._can_ms is None:
            return None
        # Before the master first runs (boot, enumeration, configuration) the tick's CAN ms
        # is the master's plain tick_ms, with no duty hand-over.
        boot = not self._master_was_running and master.state is not MasterState.RUNNING
        if not boot and (not self._master_was_running or master.state is not MasterState.RUNNING):
            return None
        if master._wire is not link or (not boot and self.duties is not self._duties_to_master):
            return None
        ch = self._wire_channel
        if len(ch.buses) != 1 or ch.taps or ch.clock.__class__ is not SimClock:
            return None
        if master._events or self.session.pending_frames or self.uart.pending:
            return None
        next_pub = self._next_pub_ms
        if boot and (not self.session.configured or self.last_output is None):
            next_pub = 2**62  # _publish returns at once until Python code changes that
        return (
            self.now_ms,
            self._now_s,
            self._idle_lo,
            self._idle_hi,
            self._battery_due_ms,
            self._next_control,
            self._can_ms,
            next_pub,
            # In the boot a busy ms needs an output already (else the kernel's step would
            # make _publish live while next_pub above says never).
            self._kernel_busy_plan()
            if self.kernel_busy and (not boot or self.last_output is not None)
            else None,
            master.core.state_index if boot else None,
        )

    def _kernel_busy_plan(self) -> tuple:
        """What the kernel needs to run a routine busy ms as :meth:`tick` does (called by
        :meth:`kernel_plan` when the idle part applies):

        * ``step_core``: the :class:`SpinalStep` when a control step's routine is
          ``_step``'s fast path (no pwm test, the Rust master's one-call duty hand-over), else
          None; ``period`` (``1 / rate_hz``) and the idle duty;
        * the battery filter and sample period;
        * ``configured``, ``last_output``; ``imu_topic`` when the ``imu`` publication is
          :meth:`_publish_imu_frame`'s (the checked codec, a :class:`ClientClock`), the
          clock's sync state (None unless a :class:`ClientClock`: then no publication
          here); ``servo_topic``/``servo_core`` when ``servo/states`` is
          :meth:`_publish_servo_states_frame`'s Rust frame; the last publication ms of both
          and the first ms any other publisher is due;
        * the TX ring (output size, chunk size, chunks; -1 when not empty) and whether the
          UART writes any send of up to ``max_pending`` bytes whole (``UartPump.writes_whole``),
          and the UART chain (``UartPump._chain``) when the kernel writes the output itself
          (:attr:`kernel_tx_direct`), else None (it calls :meth:`kernel_commit_tx`).

        The kernel reads the IMU sample, battery input, ADC scale and battery voltage from
        the mirror itself when it uses them (another node may set them without a re-read)."""
        core = self.core
        master = self.master
        step_core = (
            core
            if core.__class__ is SpinalStep
            and self.pwm_test is None
            and _duty_list is not None
            and getattr(master, "fast", False) is True
            else None
        )
        session = self.session
        clock = session.clock
        # session.publisher(name) for its cache hit, inline (else the lookup itself)
        cache = session._publisher_cache
        fresh = session._cached_slots == len(session.publishers)
        imu_topic = None
        client_clock = clock.__class__ is ClientClock  # the stamps the kernel computes
        if _imu_frame is not None and client_clock:
            slot = cache.get("imu") if fresh else None
            if slot is None or slot.service is not None:
                slot = self._kernel_publisher("imu")
            if slot is not None and slot.codec is self._imu_codec:
                imu_topic = slot.topic_id
        servo_topic = servo_core = None
        slot = cache.get("servo/states") if fresh else None
        if slot is None or slot.service is not None:
            slot = self._kernel_publisher("servo/states")
        if slot is not None and slot.codec is self._msg.servo_states:
            servo_core = self.servos.kernel_frame_core(slot.codec)
            if servo_core is not None:
                servo_topic = slot.topic_id
        # min(_next_due(...)) of the other publishers, inline
        get = self._last_pub.get
        t = get("battery_voltage_status")
        others = _NEVER if t is None else t + BATTERY_PUB_MS + 1
        t = get("motor_pwms")
        others = _NEVER if t is None else min(others, t + MOTOR_PWMS_PUB_MS + 1)
        t = get("servo/torque_states")
        others = _NEVER if t is None else min(others, t + SERVO_TORQUE_PUB_MS)
        uart = self.uart
        return (
            step_core,
            1.0 / self.rate_hz,
            IDLE_DUTY,
            BATTERY_FILTER,
            BATTERY_SAMPLE_MS,
            session.configured,
            self.last_output,
            imu_topic,
            clock.synced if client_clock else None,
            clock._sync_tick if client_clock else None,
            clock._sync_ns if client_clock else None,
            get("imu"),
            IMU_PUB_MS,
            servo_topic,
            servo_core,
            get("servo/states"),
            SERVO_STATES_PUB_MS,
            others,
            session.output_size,
            session._tx_chunk_bytes,
            session._tx_chunks if session._tx_used == 0 else -1,
            uart.writes_whole(),
            uart.max_pending,
            uart._chain if self.kernel_tx_direct else None,
        )

    def _kernel_publisher(self, name: str) -> Any:
        """``session.publisher(name)``, None for no such publisher."""
        try:
            return self.session.publisher(name)
        except KeyError:
            return None

    def kernel_receive_tick(self, now: float) -> tuple | None:
        """The lockstep kernel's tick of a ms it cannot run from its plan (bytes to read, the
        idle window over): :meth:`tick` up to and with its UART receive, then either the rest
        here (returns None: the whole tick ran) or, when :meth:`kernel_plan` applies after the
        receive and ``kernel_receive`` is on, nothing more: returns that plan, and the kernel
        runs the rest (battery, control, CAN ms, publishers, output) as in any ms of its plan,
        or calls :meth:`kernel_receive_rest` when that ms is not one it runs. The same calls
        in the same order as :meth:`tick` (docs/spinal.md "In the simulated stack")."""
        if not self._fast:
            self._tick_plain(now)
            return None
        now_ms = self._tick_begin(now)
        inbox = self.uart.inbox
        if inbox is None or inbox or not self._idle_lo <= now_ms < self._idle_hi:
            self._receive(now_ms)
        plan = self.kernel_plan() if self.kernel_receive else None
        if plan is None:
            self._tick_rest(now_ms)
        return plan

    def kernel_receive_rest(self, now: float) -> None:
        """The rest of a :meth:`kernel_receive_tick` whose plan the kernel did not run."""
        self._tick_rest(self._tick_begin(now))

    def kernel_finish_step(self, now_ms: int, tail: bool) -> None:
        """The rest of a kernel tick whose control step the kernel ran (``last_output``,
        ``control_steps``, ``_next_control`` and, without ``tail``, ``duties`` written back)
        but did not finish: with ``tail`` the step had events (``_step_tail``), else the core
        declined the duty list; then the CAN ms, publishers and output as :meth:`tick`."""
        if tail:
            self._step_tail(self.last_output)
        self._tick_tail(now_ms)

    def kernel_finish_publish(self, now_ms: int) -> None:
        """The rest of a kernel tick whose publication the kernel declined (a value its
        frame builders decline, a frame the TX ring or the UART queue would not take): the
        publishers and output as :meth:`tick`."""
        if now_ms >= self._next_pub_ms:
            self._publish(now_ms)
        if self.session.pending_frames or self.uart.pending:
            self.uart.send(self.session.take_output())

    def kernel_commit_tx(
        self,
        data: bytes,
        frames: int,
        imu: int,
        servo: int,
        marks: Sequence[tuple[float, int]] = (),
    ) -> None:
        """The kernel's publications since the last write back: ``frames`` frames queued
        and taken by ``take_output`` (``imu`` on ``imu``, ``servo`` on ``servo/states``),
        ``data`` their bytes in order, written in one :meth:`UartPump.send` (whole, as the
        plan's ``writes_whole`` said: the same bytes and counters as one send per tick);
        ``marks`` each tick's ``(time s, end)`` in ``data`` for the capture's time index.
        With :attr:`kernel_tx_direct` the kernel does the same without this call: the
        counters, then ``UartPump._write_chain``'s effect of a whole write and ``bytes_out``."""
        self.session.counts["tx_frames"] += frames
        published = self.counters.published
        if imu:
            published["imu"] += imu
        if servo:
            published["servo/states"] += servo
        capture = timed_capture_of(self.uart.link) if marks else None
        if capture is None or self.uart.pending:  # queued bytes first: those take the clock
            self.uart.send(data)
        else:
            with capture.marked(marks):
                self.uart.send(data)

    def kernel_finish_wire_tick(self, now_ms: int) -> None:
        """The rest of a kernel tick whose CAN ms was not steady (``tick_wire_steady`` gave
        -1): the master takes the tick's result, then events, publishers and output as
        :meth:`tick` does."""
        master = self.master
        master.apply_wire_tick(master.core.last_wire_tick)
        self._forward_can_events()
        if now_ms >= self._next_pub_ms:
            self._publish(now_ms)
        if self.session.pending_frames or self.uart.pending:
            self.uart.send(self.session.take_output())

    # ---------------------------------------------------------------- diagnostics
    def diagnostics(self) -> dict[str, Any]:
        """A snapshot of every counter (UART, rosserial, control, CAN) as plain data."""
        c = self.counters
        return {
            "uart": {
                "bytes_in": self.uart.bytes_in,
                "bytes_out": self.uart.bytes_out,
                "bytes_discarded": self.uart.bytes_discarded,
                "write_errors": self.uart.write_errors,
                "read_errors": self.uart.read_errors,
            },
            "rosserial": {
                "configured": self.session.configured,
                "frames_in": self.session.parser.counts.get("frames", 0),
                "frames_out": self.session.counts.get("tx_frames", 0),
                "frames_rejected": dict(c.frames_rejected),
                "dropped": c.dropped,
                "session": dict(self.session.counts),
            },
            "received": dict(c.received),
            "published": dict(c.published),
            "rejected": dict(c.rejected),
            "failsafes": dict(c.failsafes),
            "acks": dict(c.acks),
            "logs": dict(c.logs),
            "control": {
                "steps": c.control_steps,
                "overruns": c.control_overruns,
                "armed": self.core.armed,
                "force_landing": self.core.force_landing,
                "motor_number": self.core.motor_number,
                "core": dict(self.core.counters),
            },
            "can": {
                "state": self.master.state.value,
                "slaves": self.master.slaves,
                "connected": self.master.connected,
                "rx": self.master.rx_count,
                "tx": self.master.tx_count,
                "rx_errors": dict(self.master.rx_errors),
                "tx_errors": self.master.tx_errors,
            },
        }
