"""ESC + motor model: PWM duty -> steady thrust, then a first-order lag.

The flight firmware (Spinal ``pwmConversion``, SQRT mode; jsk-wire-protocols.md sec. 3.6)
turns a thrust command f [N] into a duty by solving

    v_factor * f = 0.1 p2 x^2 + 0.1 p1 x + p0,   x = duty * 100 [%],  v_factor = (V_ref/V)^2

for x. The plant's ESC is the inverse: a duty gives the steady thrust
``(0.1 p2 x^2 + 0.1 p1 x + p0) / v_factor``, clamped to [0, thrust_max]; duty <= 0.5
(a 1000 us pulse, ``IDLE_DUTY``) stops the motor. The rotor then follows that steady thrust
with a first-order lag of time constant ``tau`` (ASSUMPTION 0.05 s: motor + prop spin-up).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

IDLE_DUTY = 0.5


@dataclass(frozen=True)
class EscParams:
    """SQRT-mode conversion coefficients and motor lag.

    Defaults: the Hydrus quad ``MotorInfo.yaml`` reference at 25.2 V (p2, p1, p0 "x10" as
    the firmware stores them), thrust_max 20 N (Sec. VI-B), tau 0.05 s (ASSUMPTION).
    """

    p2: float = 0.07983707
    p1: float = -6.627443098
    p0: float = 12.3593793002
    v_ref: float = 25.2
    thrust_max: float = 20.0
    tau: float = 0.05

    def __post_init__(self) -> None:
        if not self.p2 > 0:
            raise ValueError("EscParams.p2: must be > 0 (the SQRT mode needs an upward parabola)")
        if not (self.v_ref > 0 and self.thrust_max > 0 and self.tau > 0):
            raise ValueError("EscParams: v_ref, thrust_max and tau must be > 0")

    def v_factor(self, voltage: float) -> float:
        """SQRT-mode voltage factor (V_ref / V)^2."""
        return (self.v_ref / voltage) ** 2

    def steady_thrust(self, duty: float, voltage: float) -> float:
        """Steady thrust [N] for a duty at battery ``voltage`` (inverse of the firmware)."""
        if not math.isfinite(duty) or duty <= IDLE_DUTY:
            return 0.0
        x = 100.0 * min(duty, 1.0)
        # v_factor(voltage) inline (the same expression; this runs per rotor every ms)
        f = (0.1 * self.p2 * x * x + 0.1 * self.p1 * x + self.p0) / (self.v_ref / voltage) ** 2
        return min(max(f, 0.0), self.thrust_max)

    def duty_for_thrust(self, thrust: float, voltage: float) -> float:
        """The firmware's SQRT-mode duty for ``thrust`` [N] (no min/max-duty clamp)."""
        f = max(self.v_factor(voltage) * thrust, 0.0) if math.isfinite(thrust) else 0.0
        disc = self.p1 * self.p1 - 40.0 * self.p2 * (self.p0 - f)
        x = (-self.p1 + math.sqrt(max(disc, 0.0))) / (2.0 * self.p2)
        return min(max(x / 100.0, IDLE_DUTY), 1.0)


class _ThrustStore(Protocol):
    """Where an attached ESC keeps its state (``RotorPlantCore``): present and target thrust,
    the duty map and last duty, the rejected count."""

    def thrust(self, i: int) -> float: ...
    def target(self, i: int) -> float: ...
    def set_thrust(self, i: int, value: float) -> None: ...
    def set_target(self, i: int, value: float) -> None: ...
    def set_esc_map(
        self, i: int, p2: float, p1: float, p0: float, thrust_max: float, v_factor: float
    ) -> None: ...
    def duty(self, i: int) -> float: ...
    def set_duty(self, i: int, value: float) -> None: ...
    def rejected(self, i: int) -> int: ...
    def set_rejected(self, i: int, value: int) -> None: ...


def _checked_v_factor(params: EscParams, voltage: float) -> float:
    """``params.v_factor(voltage)``, or ValueError naming ``voltage`` where it is not a
    positive finite number (0 V, a voltage whose factor overflows or rounds to 0): every
    ESC map then divides by a usable factor, in Rust and in :meth:`EscParams.steady_thrust`."""
    if not (math.isfinite(voltage) and voltage > 0):
        raise ValueError(f"voltage: must be a positive number, got {voltage}")
    try:
        factor = params.v_factor(voltage)
    except OverflowError:
        factor = math.inf
    if not (math.isfinite(factor) and factor > 0):
        raise ValueError(
            f"voltage: (v_ref / voltage) ** 2 must be a positive finite number, got {voltage}"
            f" (v_ref {params.v_ref})"
        )
    return factor


class Esc:
    """One ESC + motor + propeller: duty or thrust in, lagged thrust out."""

    def __init__(self, params: EscParams | None = None, voltage: float | None = None) -> None:
        # The state lives in a store: the Esc's own slots, or a plant's rotor core (one
        # source of truth for the plant's per-step work, its one-call duty commands and
        # Python readers/writers).
        self._store: _ThrustStore | None = None
        self._slot = 0
        self._own_target = 0.0
        self._own_thrust = 0.0
        self._own_duty = IDLE_DUTY
        self._own_rejected = 0
        self._params = params or EscParams()
        self._voltage = self._params.v_ref if voltage is None else voltage
        #: (v_ref / voltage) ** 2 (a positive finite number, see :func:`_checked_v_factor`).
        self._v_factor = _checked_v_factor(self._params, self._voltage)
        self.duty = IDLE_DUTY
        self.rejected = 0  # count of non-finite commands replaced by a stop

    def attach(self, store: _ThrustStore, slot: int) -> None:
        """Keep the state in ``store`` at ``slot`` from now on (the present values move)."""
        thrust, target, duty, rejected = self._thrust, self._target, self.duty, self.rejected
        self._store, self._slot = store, slot
        self._thrust, self._target, self.duty, self.rejected = thrust, target, duty, rejected
        self._push_map()

    def _push_map(self) -> None:
        store = self._store
        if store is not None:
            p = self._params
            store.set_esc_map(self._slot, p.p2, p.p1, p.p0, p.thrust_max, self._v_factor)

    @property
    def params(self) -> EscParams:
        """The duty map and lag parameters."""
        return self._params

    @params.setter
    def params(self, value: EscParams) -> None:
        self._v_factor = _checked_v_factor(value, self._voltage)
        self._params = value
        self._push_map()

    @property
    def voltage(self) -> float:
        """Battery voltage [V] of the duty -> thrust map."""
        return self._voltage

    @voltage.setter
    def voltage(self, value: float) -> None:
        self._v_factor = _checked_v_factor(self._params, value)
        self._voltage = value
        self._push_map()

    @property
    def duty(self) -> float:
        """The last commanded duty (after the clamp)."""
        store = self._store
        return self._own_duty if store is None else store.duty(self._slot)

    @duty.setter
    def duty(self, value: float) -> None:
        if self._store is None:
            self._own_duty = value
        else:
            self._store.set_duty(self._slot, value)

    @property
    def rejected(self) -> int:
        """Non-finite commands replaced by a stop."""
        store = self._store
        return self._own_rejected if store is None else store.rejected(self._slot)

    @rejected.setter
    def rejected(self, value: int) -> None:
        if self._store is None:
            self._own_rejected = value
        else:
            self._store.set_rejected(self._slot, value)

    @property
    def _thrust(self) -> float:
        store = self._store
        return self._own_thrust if store is None else store.thrust(self._slot)

    @_thrust.setter
    def _thrust(self, value: float) -> None:
        if self._store is None:
            self._own_thrust = value
        else:
            self._store.set_thrust(self._slot, value)

    @property
    def _target(self) -> float:
        store = self._store
        return self._own_target if store is None else store.target(self._slot)

    @_target.setter
    def _target(self, value: float) -> None:
        if self._store is None:
            self._own_target = value
        else:
            self._store.set_target(self._slot, value)

    def set_voltage(self, voltage: float) -> None:
        """Battery voltage [V] (changes the duty -> thrust map of later duty commands)."""
        self.voltage = voltage

    def command_duty(self, duty: float) -> None:
        """Command a PWM duty in [0.5, 1] (0.5 = stop); the thrust settles to its steady value."""
        if not math.isfinite(duty):
            self.rejected += 1
            duty = IDLE_DUTY
        self.duty = d = min(max(duty, IDLE_DUTY), 1.0)
        target = self.params.steady_thrust(d, self.voltage)
        store = self._store  # the ``_target`` setter, inline (per rotor every ms)
        if store is None:
            self._own_target = target
        else:
            store.set_target(self._slot, target)

    def command_thrust(self, thrust: float) -> None:
        """Command a steady thrust [N] directly (clamped to [0, thrust_max]), bypassing PWM."""
        if not math.isfinite(thrust):
            self.rejected += 1
            thrust = 0.0
        self._target = min(max(thrust, 0.0), self.params.thrust_max)
        self.duty = self.params.duty_for_thrust(self._target, self.voltage)

    def reset(self, thrust: float = 0.0) -> None:
        """Set both the command and the present thrust (a spun-up rotor at ``thrust``)."""
        self.command_thrust(thrust)
        self._thrust = self._target

    @property
    def target_thrust(self) -> float:
        """Steady thrust the rotor is heading to [N]."""
        return self._target

    @property
    def thrust(self) -> float:
        """Present (lagged) thrust [N], before the ceiling effect."""
        return self._thrust

    def lag_factor(self, dt: float) -> float:
        """The fraction of the remaining gap the lag closes in ``dt``: ``1 - exp(-dt/tau)``
        (the plant caches it per physics step; :meth:`update` uses the same expression)."""
        return (1.0 - math.exp(-dt / self.params.tau)) if dt > 0 else 0.0

    def update(self, dt: float) -> float:
        """Advance the lag by ``dt`` seconds (exact discretisation) and return the thrust."""
        if dt > 0:
            self._thrust += (1.0 - math.exp(-dt / self.params.tau)) * (self._target - self._thrust)
        return self._thrust
