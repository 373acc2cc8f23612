"""The one ESC a Neuron drives: the PWM value it holds and the pulse it outputs (fact sheet
sec. 2.4 "Motor PWM", 2.6 watchdog, 3.6).

The Neuron holds the last value ``v`` it read from its PWM slot and outputs a ``v + 1000`` us
pulse at 500 Hz; while its CAN watchdog is tripped it outputs ``v = 0`` (1000 us, stopped).
"""

from __future__ import annotations

from rdm.protocol.neuron.pwm import PWM_STOP_VALUE

#: ESC PWM frame period of the Neuron timer (500 Hz).
ESC_PERIOD_US = 2000


class EscOutputs:
    """What an ESC outputs, derived from ``value`` (0..1000, the timer's value now): shared by
    :class:`EscModel` and the Rust Neuron bank's ESC view."""

    __slots__ = ()
    value: int

    @property
    def pulse_us(self) -> int:
        return self.value + 1000

    @property
    def duty(self) -> float:
        """Spinal's duty convention: pulse / 2000 us, 0.5 (stop) .. 1.0 (full)."""
        return self.pulse_us / ESC_PERIOD_US

    @property
    def throttle(self) -> float:
        """0 (stop) .. 1 (full) for a plant's rotor model."""
        return self.value / 1000.0


class EscModel(EscOutputs):
    """``held_value`` is the last slot value received; ``stopped`` is the watchdog's verdict.

    Every change of either bumps ``changes[0]`` (a counter the owning Neuron shares with its
    servos), so a plant bridge can skip unchanged boards without reading each output.
    """

    __slots__ = ("_held_value", "_stopped", "changes")

    def __init__(self, held_value: int = PWM_STOP_VALUE, stopped: bool = True) -> None:
        self._held_value = held_value
        self._stopped = stopped
        self.changes = [0]

    def __repr__(self) -> str:
        return f"EscModel(held_value={self._held_value!r}, stopped={self._stopped!r})"

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, EscModel):
            return NotImplemented
        return (self._held_value, self._stopped) == (other._held_value, other._stopped)

    __hash__ = None  # type: ignore[assignment]  # mutable, as the dataclass it replaces

    @property
    def held_value(self) -> int:
        return self._held_value

    @held_value.setter
    def held_value(self, value: int) -> None:
        if value != self._held_value:
            self._held_value = value
            self.changes[0] += 1

    @property
    def stopped(self) -> bool:
        return self._stopped

    @stopped.setter
    def stopped(self, value: bool) -> None:
        if value != self._stopped:
            self._stopped = value
            self.changes[0] += 1

    @property
    def value(self) -> int:
        """What the timer outputs now, 0..1000 (``pulse_us - 1000``)."""
        return PWM_STOP_VALUE if self.stopped else self.held_value
