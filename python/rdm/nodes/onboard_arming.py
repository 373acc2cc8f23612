"""PC-side arming sequence of the onboard node (``flight_navigation.cpp``, fact sheet sec. 3.7).

* ``arm()``: STARTING. ``uav_info`` and ``motor_info`` go out every ``info_period`` (0.1 s).
  ARM_ON is sent only once both infos have been sent (Spinal ignores ARM_ON without them and
  sends no ack), then re-sent every ``retry`` until ``flight_config_ack`` 0 -> ARMED.
* ``disarm()``: DISARMING, ARM_OFF until ack 1 -> IDLE.
* ``force_landing()``: FORCE_LANDING sent until ack 2 -> LANDING (stays armed on Spinal).
* An unsolicited ack 2 (a Spinal fail-safe) -> LANDING, counted ``spinal_force_landing``.

Sans-IO: :meth:`ArmingSequencer.due` returns what to publish at ``now``; :meth:`on_ack` feeds
acks. Nothing here knows the transport.
"""

from __future__ import annotations

import enum
from collections import Counter

ARM_ON, ARM_OFF, FORCE_LANDING = 0, 1, 2


class FlightState(enum.Enum):
    IDLE = "idle"
    STARTING = "starting"
    ARMED = "armed"
    LANDING = "landing"
    DISARMING = "disarming"


class ArmingSequencer:
    """Which flight-config messages to send, and when."""

    def __init__(self, info_period: float = 0.1, retry: float = 0.5) -> None:
        self.info_period = info_period
        self.retry = retry
        self.state = FlightState.IDLE
        self.counts: Counter[str] = Counter()
        self._infos_sent = {"uav_info": False, "motor_info": False}
        self._next_info = 0.0
        self._pending: int | None = None  # command awaiting its ack
        self._next_cmd = 0.0
        self.acks: list[int] = []

    # -- requests ------------------------------------------------------------------------
    def arm(self, now: float) -> None:
        if self.state in (FlightState.ARMED, FlightState.STARTING):
            return
        self.state = FlightState.STARTING
        self._infos_sent = {"uav_info": False, "motor_info": False}
        self._next_info = now
        self._pending = ARM_ON
        self._next_cmd = now

    def disarm(self, now: float) -> None:
        self.state = FlightState.DISARMING
        self._pending = ARM_OFF
        self._next_cmd = now

    def force_landing(self, now: float) -> None:
        if self.state not in (FlightState.ARMED, FlightState.LANDING, FlightState.STARTING):
            self.counts["force_landing_not_armed"] += 1
            return
        self.state = FlightState.LANDING
        self._pending = FORCE_LANDING
        self._next_cmd = now

    def link_lost(self) -> None:
        """The rosserial session was lost: Spinal's command timeout takes over; start over."""
        if self.state is not FlightState.IDLE:
            self.counts["link_lost"] += 1
        self.state = FlightState.IDLE
        self._pending = None

    # -- wire ----------------------------------------------------------------------------
    def due(self, now: float) -> list[tuple[str, int | None]]:
        """Messages to publish now: ``("uav_info"|"motor_info", None)`` or
        ``("flight_config_cmd", cmd)``. Call :meth:`sent` for each one actually published."""
        out: list[tuple[str, int | None]] = []
        if self.state is FlightState.STARTING and now >= self._next_info - 1e-9:
            out += [("uav_info", None), ("motor_info", None)]
        infos_done = all(self._infos_sent.values())
        if (
            self._pending is not None
            and now >= self._next_cmd - 1e-9
            and (self._pending != ARM_ON or infos_done)
        ):
            out.append(("flight_config_cmd", self._pending))
        return out

    def sent(self, topic: str, now: float) -> None:
        if topic in self._infos_sent:
            self._infos_sent[topic] = True
            self._next_info = now + self.info_period
        else:
            self._next_cmd = now + self.retry
            self.counts["commands_sent"] += 1

    def on_ack(self, ack: int) -> None:
        self.acks.append(ack)
        if ack == ARM_ON and self._pending == ARM_ON:
            self.state, self._pending = FlightState.ARMED, None
        elif ack == ARM_OFF and self._pending == ARM_OFF:
            self.state, self._pending = FlightState.IDLE, None
        elif ack == FORCE_LANDING:
            if self._pending != FORCE_LANDING:
                self.counts["spinal_force_landing"] += 1
            self.state, self._pending = FlightState.LANDING, None
        else:
            self.counts["unexpected_ack"] += 1

    @property
    def flying(self) -> bool:
        """Spinal is armed (commands are meaningful)."""
        return self.state in (FlightState.ARMED, FlightState.LANDING)
