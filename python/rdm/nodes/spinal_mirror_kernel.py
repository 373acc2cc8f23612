"""The Spinal mirror's side of the lockstep kernel (``rdm._rdm.LockstepKernel``, docs/sim.md):
the plan of the milliseconds the kernel runs itself, and the calls that finish a tick the
kernel began (docs/spinal.md "In the simulated stack").

:class:`SpinalKernelInterface` is a part of :class:`rdm.nodes.spinal_mirror.SpinalMirror`: its
methods read the mirror's state and call its tick's steps.
"""

from __future__ import annotations

from typing import Any

from rdm.control.attitude import SpinalStep
from rdm.link.inproc_can import SimClock
from rdm.nodes.can_master import IDLE_DUTY, MasterState
from rdm.nodes.spinal_mirror_publishers import (
    _NEVER,
    BATTERY_PUB_MS,
    IMU_PUB_MS,
    MOTOR_PWMS_PUB_MS,
    SERVO_STATES_PUB_MS,
    SERVO_TORQUE_PUB_MS,
)
from rdm.protocol.rosserial.timesync import ClientClock


class SpinalKernelInterface:
    """What the lockstep kernel calls on :class:`rdm.nodes.spinal_mirror.SpinalMirror` (a part
    of it)."""

    def kernel_plan(self) -> tuple | None:
        """The window in which :meth:`tick` is only the steady CAN ms, for
        ``rdm._rdm.LockstepKernel`` (docs/sim.md): (idle window lo, hi, whether
        ``_publish`` can publish, busy plan, boot phase); the kernel runs a tick at ms m
        itself when m is inside the idle window, before the battery, control and publisher
        times, and one past the CAN ms (those and the clock it reads and changes in
        ``_state``, the mirror's :class:`rdm._rdm.SpinalMirrorState`). None when no tick can
        run so: bytes waiting, the master not steady on the wire, events or output pending.
        Before the master first runs, the last item is its phase index (the kernel then runs
        the idle ms of the boot: a CAN ms that stays in that phase); else None.
        The master's ``tx_count`` and pending events are its Rust core's."""
        inbox = self.uart.inbox
        link = self._wire_link
        master = self.master
        if inbox is None or inbox or link is None:
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
        # _publish returns at once in the boot until Python code configures the session and
        # a step leaves an output
        live = not boot or (self.session.configured and self.last_output is not None)
        return (
            self._idle_lo,
            self._idle_hi,
            live,
            # In the boot a busy ms needs an output already (else the kernel's step would
            # make _publish live while ``live`` above says no).
            self._kernel_busy_plan() if not boot or self.last_output is not None else None,
            master.core.state_index if boot else None,
        )

    def _kernel_busy_plan(self) -> tuple:
        """What the kernel needs to run a routine busy ms as :meth:`tick` does (called by
        :meth:`kernel_plan` when the idle part applies):

        * ``step_core``: the :class:`SpinalStep` when a control step's routine is
          ``_step``'s one-call duty list (no pwm test, the Rust master's one-call duty
          hand-over), else None; ``period`` (``1 / rate_hz``) and the idle duty;
        * ``configured``, ``last_output``; ``imu_topic`` when the ``imu`` publication is
          :meth:`_publish_imu_frame`'s (the checked codec, a :class:`ClientClock`), the
          clock's sync state (None unless a :class:`ClientClock`: then no publication
          here); ``servo_topic``/``servo_core`` when ``servo/states`` is
          :meth:`_publish_servo_states_frame`'s Rust frame; the last publication ms of both
          and the first ms any other publisher is due;
        * the TX ring (output size, chunk size, chunks; -1 when not empty) and whether the
          UART writes any send of up to ``max_pending`` bytes whole (``UartPump.writes_whole``),
          and the UART chain (``UartPump._chain``) through which the kernel writes the
          output itself (None: no in-process chain; then the publications are the Python
          tick's).

        The kernel reads the IMU sample from the mirror, and the battery from its
        ``_state``, when it uses them (another node may set them without a re-read)."""
        core = self.core
        step_core = core if core.__class__ is SpinalStep and self.pwm_test is None else None
        session = self.session
        clock = session.clock
        # session.publisher(name) for its cache hit, inline (else the lookup itself)
        cache = session._publisher_cache
        fresh = session._cached_slots == len(session.publishers)
        imu_topic = None
        client_clock = clock.__class__ is ClientClock  # the stamps the kernel computes
        if client_clock:
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
            uart._chain,
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
        receive, nothing more: returns that plan, and the kernel runs the rest (battery,
        control, CAN ms, publishers, output) as in any ms of its plan, or calls
        :meth:`kernel_receive_rest` when that ms is not one it runs. The same calls
        in the same order as :meth:`tick` (docs/spinal.md "In the simulated stack")."""
        now_ms = self._state.tick_begin(now)
        inbox = self.uart.inbox
        if inbox is None or inbox or not self._idle_lo <= now_ms < self._idle_hi:
            self._receive(now_ms)
        plan = self.kernel_plan()
        if plan is None:
            self._tick_rest(now_ms)
        return plan

    def kernel_receive_rest(self, now: float) -> None:
        """The rest of a :meth:`kernel_receive_tick` whose plan the kernel did not run."""
        self._tick_rest(self._state.tick_begin(now))

    def kernel_finish_step(self, now_ms: int, tail: bool) -> None:
        """The rest of a kernel tick whose control step the kernel ran (``last_output``,
        ``_next_control`` and, without ``tail``, ``duties`` written back; the core counted it)
        but did not finish: with ``tail`` the step had events (``_step_tail``), else the core
        declined the duty list; then the CAN ms, publishers and output as :meth:`tick`."""
        if tail:
            self._step_tail(self.last_output)
        self._tick_tail(now_ms)

    def kernel_finish_publish(self, now_ms: int) -> None:
        """The rest of a kernel tick whose publication the kernel declined (a value its
        frame builders decline, a frame the TX ring or the UART queue would not take): the
        publishers and output as :meth:`tick`."""
        if now_ms >= self._state.next_pub_ms:
            self._publish(now_ms)
        if self.session.pending_frames or self.uart.pending:
            self.uart.send(self.session.take_output())

    def kernel_finish_wire_tick(self, now_ms: int) -> None:
        """The rest of a kernel tick whose CAN ms was not steady (``tick_wire_steady`` gave
        -1): the master takes the tick's result, then events, publishers and output as
        :meth:`tick` does."""
        master = self.master
        master.apply_wire_tick(master.core.last_wire_tick)
        self._forward_can_events()
        if now_ms >= self._state.next_pub_ms:
            self._publish(now_ms)
        if self.session.pending_frames or self.uart.pending:
            self.uart.send(self.session.take_output())
