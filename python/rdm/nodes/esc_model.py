"""The one ESC a Neuron drives: the PWM value it holds and the pulse it outputs (fact sheet
sec. 2.4 "Motor PWM", 2.6 watchdog, 3.6).

The Neuron holds the last value ``v`` it read from its PWM slot and outputs a ``v + 1000`` us
pulse at 500 Hz; while its CAN watchdog is tripped it outputs ``v = 0`` (1000 us, stopped).
"""

from __future__ import annotations

#: ESC PWM frame period of the Neuron timer (500 Hz).
ESC_PERIOD_US = 2000


class EscOutputs:
    """What an ESC outputs, derived from ``value`` (0..1000, the timer's value now); the Neuron
    bank's ESC view (:class:`rdm.nodes.neuron_bank.EscView`) reads ``value`` from the core."""

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
