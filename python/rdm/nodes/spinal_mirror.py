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

The node's parts, one module each: what arrives on the UART
(:mod:`rdm.nodes.spinal_mirror_commands`), the battery and control steps
(:mod:`rdm.nodes.spinal_mirror_control`), the publications
(:mod:`rdm.nodes.spinal_mirror_publishers`) and the lockstep kernel's calls
(:mod:`rdm.nodes.spinal_mirror_kernel`). This module holds the node itself: its state, the
tick and the CAN milliseconds.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any, ClassVar

import can
import numpy as np

from rdm._rdm import SpinalMirrorState
from rdm.control.attitude import CommandRejectedError, SpinalStep
from rdm.link.can_wire import DRAIN_AT
from rdm.link.inproc_can import SimClock
from rdm.nodes.can_master import BOOT_DELAY_MS, IDLE_DUTY, CanMaster, MasterState
from rdm.nodes.spinal_mirror_commands import (
    _COMMAND_KINDS,
    _COMMAND_TYPES,
    SpinalCommands,
    rejection_reason,
)
from rdm.nodes.spinal_mirror_control import SpinalControl
from rdm.nodes.spinal_mirror_kernel import SpinalKernelInterface
from rdm.nodes.spinal_mirror_publishers import SpinalPublishers
from rdm.nodes.spinal_servo_bridge import ServoBridge
from rdm.nodes.spinal_uart import UartPump
from rdm.protocol.rosserial import constants as C
from rdm.protocol.rosserial.client import ClientSession
from rdm.protocol.rosserial.registry import TypeRegistry, spinal_registry

#: A tick that skips more milliseconds than this replays only the last ones on CAN (as
#: ``CanMaster``'s own cap): on a starved host a bigger replay makes every tick slower still.
MAX_CAN_CATCH_UP_MS = 10
#: A level, still IMU: no rotation, gravity on +z (m/s^2), an Earth-like field (uT).
LEVEL_GYRO = (0.0, 0.0, 0.0)
LEVEL_ACC = (0.0, 0.0, 9.80665)
LEVEL_MAG = (30.0, 0.0, -40.0)
DEFAULT_BATTERY_V = 25.2
MAX_RATE_HZ = 1000.0
_LOG_LEVELS = {
    "debug": C.LogLevel.DEBUG,
    "info": C.LogLevel.INFO,
    "warn": C.LogLevel.WARN,
    "error": C.LogLevel.ERROR,
    "fatal": C.LogLevel.FATAL,
}


def _floats(values: Sequence[float]) -> tuple[float, ...]:
    """``tuple(float(v) for v in values)``; a float64 array in one ``tolist`` call."""
    if isinstance(values, np.ndarray) and values.dtype == np.float64:
        return tuple(values.tolist())
    return tuple(float(v) for v in values)


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
    control_overruns: int = 0
    configured: int = 0
    sync_lost: int = 0
    #: The control step core whose own count is :attr:`control_steps` (None: no steps).
    step_core: SpinalStep | None = field(default=None, repr=False, compare=False)

    @property
    def control_steps(self) -> int:
        """Control steps run (``SpinalStep.steps``: the Python tick's and the kernel's)."""
        core = self.step_core
        return 0 if core is None else core.steps


class SpinalMirror(SpinalCommands, SpinalControl, SpinalPublishers, SpinalKernelInterface):
    """Spinal on a UART (rosserial client) and a CAN bus (Neuron master).

    ``uart`` is a :class:`rdm.link.serial.SerialLink` (anything with ``read_available`` and a
    pyserial ``port``); ``can_bus`` a python-can bus. Both are owned (closed by :meth:`close`).
    ``spinal_options`` go to :class:`SpinalStep` (``time_matched``, ``anti_windup``,
    ``command_timeout_s``, estimator overrides such as ``gyro_calib_duration_s`` ...).
    """

    #: Its part of the lockstep kernel (``rdm.nodes.lockstep_kernel.kind_of``); read from
    #: this class itself, so a subclass has only its Python tick unless it sets its own.
    lockstep_part: ClassVar[str] = "spinal"

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
        #: The clock, CAN ms, control time, IMU sample and battery (one Rust state: the
        #: Python tick and the lockstep kernel both read and change it).
        self._state = SpinalMirrorState(DEFAULT_BATTERY_V, LEVEL_GYRO, LEVEL_ACC, LEVEL_MAG)
        self.uart = UartPump(uart)
        self.master = CanMaster(can_bus, boot_delay_ms=boot_delay_ms)
        self.core = SpinalStep(self.rate_hz, **spinal_options)
        self.servos = ServoBridge(self.master)
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
        #: The subscribers whose frames ``rdm._rdm.spinal_apply_commands`` decodes: a plain
        #: slot of the type it reads, with that type's wire layout and a message handler.
        builtin = spinal_registry()
        applied = set()
        for slot in self.session.subscribers:
            type_ = _COMMAND_TYPES.get(slot.name)
            if (
                type_ is not None
                and slot.service is None
                and slot.codec.full_name == type_
                and slot.codec.field_tree() == builtin.msg(type_).field_tree()
                and self._routes.get(slot.name) is not None
            ):
                applied.add(slot.name)
        self._runs_armed = False  # whether the session hands command runs to the call
        #: Per subscriber index: the ``rdm._rdm.spinal_apply_commands`` kind of its frames
        #: (0: not one it applies) and its topic, for :meth:`_apply_command_run`.
        self._command_kinds = bytes(
            _COMMAND_KINDS[slot.name] if slot.name in applied else 0
            for slot in self.session.subscribers
        )
        self._command_topics = tuple(slot.name for slot in self.session.subscribers)
        self._imu_codec: Any = None  # the imu publisher's codec, checked for _imu_frame
        self.counters = MirrorCounters(step_core=self.core)
        #: ``set_adc_scale`` as the firmware takes it (any positive scale); False: a scale
        #: giving an implausible battery reading is rejected (see :meth:`_on_adc_scale`)
        self.firmware_adc_scale = False
        #: the highest reference voltage of the last accepted ``motor_info`` (the full battery)
        self.reference_voltage = DEFAULT_BATTERY_V
        self.mag_declination = 0.0
        self.last_output: Any = None
        self.duties: list[float] = []
        self.pwm_test: list[float] | None = None
        self._master_was_running = False
        self._last_pub: dict[str, int] = {}
        self._duties_to_master: list[float] | None = None
        self._idle_lo = self._idle_hi = 0  # ClientSession.idle_window after the last spin
        # The Rust master on a CanWireLink: tick's steady-state CAN ms in one core call.
        wire = self.master.wire
        self._wire_link = wire
        self._wire_channel = None if wire is None else wire._ch
        self._tick_wire_steady = None if wire is None else self.master.core.tick_wire_steady
        self._core_try_duties = None if wire is None else self.master.core.try_set_motor_duties

    # ---------------------------------------------------------------- inputs from outside
    def set_imu_sample(
        self, gyro: Sequence[float], acc: Sequence[float], mag: Sequence[float]
    ) -> None:
        """The IMU sample the next control steps use: gyro rad/s, acc m/s^2, mag uT (body)."""
        self._state.set_imu_sample(_floats(gyro), _floats(acc), _floats(mag))

    def set_battery_voltage(self, volts: float) -> None:
        """The raw battery reading (V), sampled every 20 ms and low-passed as the firmware does."""
        self._state.battery_input = float(volts)

    # ---------------------------------------------------------------- clock, IMU, battery
    @property
    def gyro(self) -> tuple[float, float, float]:
        """The IMU sample's gyro (rad/s, body frame)."""
        return self._state.gyro

    @property
    def acc(self) -> tuple[float, float, float]:
        """The IMU sample's accelerometer (m/s^2, body frame)."""
        return self._state.acc

    @property
    def mag(self) -> tuple[float, float, float]:
        """The IMU sample's magnetometer (uT, body frame)."""
        return self._state.mag

    @property
    def now_ms(self) -> int | None:
        """The ms of the last tick (None: no tick yet)."""
        return self._state.now_ms

    @property
    def battery_input(self) -> float:
        """The raw battery reading (V) before the ADC scale."""
        return self._state.battery_input

    @battery_input.setter
    def battery_input(self, volts: float) -> None:
        self._state.battery_input = volts

    @property
    def adc_scale(self) -> float:
        """The ADC scale of the battery reading (``set_adc_scale``)."""
        return self._state.adc_scale

    @adc_scale.setter
    def adc_scale(self, scale: float) -> None:
        self._state.adc_scale = scale

    @property
    def battery_voltage(self) -> float | None:
        """The low-passed battery voltage the firmware uses (None: no sample yet)."""
        return self._state.battery_voltage

    @property
    def _now_s(self) -> float:
        """The latest tick time (s)."""
        return self._state.now_s

    @property
    def _can_ms(self) -> int | None:
        """The last ms the CAN master ran (None: not yet)."""
        return self._state.can_ms

    @property
    def _next_control(self) -> float | None:
        """When the next control step is due (s; None: at the next tick)."""
        return self._state.next_control

    @property
    def _next_pub_ms(self) -> int:
        """The earliest ms a periodic publisher can be due (see ``_publish``)."""
        return self._state.next_pub_ms

    @property
    def _battery_due_ms(self) -> int:
        """The first ms the battery task samples again."""
        return self._state.battery_due_ms

    # ---------------------------------------------------------------- node interface
    def tick(self, now: float) -> None:
        """Advance to ``now`` (s): UART in, due control steps, CAN ms ticks, publish, UART out."""
        # Every step's own "nothing to do" check is inline, so that an idle ms (no UART
        # byte, no control step or publisher due, one steady CAN ms) costs one Rust call and
        # a few comparisons. Each skip is exactly the guarded step's no-op.
        now_ms = self._state.tick_begin(now)
        inbox = self.uart.inbox
        if inbox is None or inbox or not self._idle_lo <= now_ms < self._idle_hi:
            self._receive(now_ms)  # else: no byte to read and spin(b"") would do nothing
        self._tick_rest(now_ms)

    def _tick_rest(self, now_ms: int) -> None:
        """:meth:`tick` after the UART receive: battery, due control steps, the tail."""
        state = self._state
        if now_ms >= state.battery_due_ms:
            self._battery(now_ms)
        if state.control_due():
            self._control(state.now_s)
        self._tick_tail(now_ms)

    def _tick_tail(self, now_ms: int) -> None:
        """:meth:`tick` after the control steps: the CAN ms, publishers and UART output (also
        the lockstep kernel's continuation of a ms whose control step it ran)."""
        state = self._state
        can_ms = state.can_ms
        link = self._wire_link
        master = self.master
        if (
            link is not None
            and can_ms is not None
            and now_ms == can_ms + 1
            and self._master_was_running
            and master.state is MasterState.RUNNING
            and master._wire is link
            and (self.duties is self._duties_to_master or self._try_wire_duties(self.duties))
        ):
            # _can's steady state with no new duties, and CanMaster.tick_ms's wire path,
            # in one core call: the same checks, stamp, frames, counters and log drain.
            ch = self._wire_channel
            if len(ch.buses) != 1 or ch.taps:
                link.check_alone()  # raises CanWireError
            clock = ch.clock
            stamp = clock.now if clock.__class__ is SimClock else clock()
            sent = self._tick_wire_steady(now_ms, stamp, link.wire, DRAIN_AT)
            state.can_ms = now_ms
            if sent >= 0:  # still running, no event pending, the log short (core counted)
                if master._events:
                    self._forward_can_events()
            else:
                master.apply_wire_tick(master.core.last_wire_tick)
                self._forward_can_events()
        else:
            self._can(now_ms)
            self._forward_can_events()
        if now_ms >= self._state.next_pub_ms:
            self._publish(now_ms)
        if self.session.pending_frames or self.uart.pending:  # else send has nothing to do
            self.uart.send(self.session.take_output())

    def _try_wire_duties(self, duties: list[float]) -> bool:
        """_can's steady-state hand-over of a new duty list when the core takes it in one
        call (``CanMaster.try_set_motor_duties``); False: nothing applied, _can decides."""
        if duties.__class__ is list and self._core_try_duties(duties):
            self._duties_to_master = duties
            return True
        return False

    def close(self) -> None:
        """Close the UART and the CAN bus."""
        try:
            self.uart.link.close()
        finally:
            self.master.close()

    # ---------------------------------------------------------------- CAN
    def _can(self, now_ms: int) -> None:
        state = self._state
        can_ms = state.can_ms
        if self._master_was_running and can_ms is not None and now_ms == can_ms + 1:
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
            state.can_ms = now_ms
            return
        start = now_ms if can_ms is None else can_ms + 1
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
        state.can_ms = now_ms

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
