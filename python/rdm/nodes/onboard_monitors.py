"""Health monitors of the onboard node: battery, input freshness (Spinal's ``imu``, the
servos' ``servo/states``, the foot sensor, the ground station), the geofence and the commanded
tilt. Each trip is counted under its monitor's name, logged (``logging`` logger
``rdm.onboard``, warning) and kept in a short list of events for the status line; the node
decides the reaction (``docs/flying.md`` "What the robot does on each fault").

Battery (``jsk-flight-navigation.md`` sec. 8, made stricter): the cell count comes from the
configuration or, by default, from the highest reference voltage of ``motor_info``
(``round(V / 4.2)``: the Hydrus example's 25.2 V is 6S). A reading outside
``cell_plausible`` x cells is rejected, counted (``battery_implausible``) and the last good
value kept. A plausible reading below ``cell_low`` x cells for ``low_battery_s`` trips
``battery_low`` (the node lands). Arming is refused without a plausible reading at or above
``cell_arm_min`` x cells once one has arrived. JSK instead maps a sag-compensated voltage onto
a Li-Po percentage; a per-cell threshold on Spinal's filtered voltage is the ASSUMPTION here.
"""

from __future__ import annotations

import logging
import math
from collections import Counter, deque
from dataclasses import dataclass
from typing import Any

LOG = logging.getLogger("rdm.onboard")

#: A fully charged Li-Po cell, V.
CELL_FULL_V = 4.2


@dataclass(frozen=True)
class MonitorLimits:
    """Thresholds of the monitors (every value an ASSUMPTION unless noted)."""

    #: Spinal silent (no ``imu``) for longer than this, s (Spinal publishes ``imu`` at 200 Hz).
    imu_timeout_s: float = 0.1
    #: No ``servo/states`` for longer than this, s (Spinal sends them at about 20 Hz).
    servo_timeout_s: float = 0.5
    #: Battery cells; None: from ``motor_info``'s highest reference voltage.
    battery_cells: int | None = None
    #: Plausible cell voltage range, V (the window of Spinal's voltage guard,
    #: ``rdm_core::pwm``: a Li-Po's discharge cut-off to a high-voltage cell's full charge).
    cell_plausible: tuple[float, float] = (3.0, 4.45)
    #: Land below this cell voltage (sustained ``low_battery_s``), V.
    cell_low: float = 3.5
    low_battery_s: float = 1.0
    #: Refuse to arm below this cell voltage, V.
    cell_arm_min: float = 3.6
    #: What losing the ground station does while perched: "hold" (stay perched) or "land".
    ground_loss_perched: str = "hold"
    #: Joint tracking: a joint whose present angle (``servo/states``) stays further than
    #: ``joint_tracking_rad`` from the goal last sent for ``joint_tracking_s`` trips
    #: ``joint_tracking`` (a stuck or overloaded servo). ASSUMPTION: 0.2 rad for 0.25 s; the
    #: whole mission's largest error is 0.09 rad (the 50 ms servo lead at 0.5 rad/s and the
    #: servos' lag; docs/flying.md).
    joint_tracking_rad: float = 0.2
    joint_tracking_s: float = 0.25
    #: Perching QP: no solution (``infeasible`` or another failed status; the controller then
    #: gives its safe command) in every control tick for ``perch_qp_fail_s`` trips
    #: ``perch_qp_failed``. ASSUMPTION: 2 s (80 ticks at 40 Hz): the contact transient of a
    #: normal perch gives up to 28 infeasible ticks in a row (whole mission, seeds 0-7).
    perch_qp_fail_s: float = 2.0

    def __post_init__(self) -> None:
        for name in (
            "imu_timeout_s",
            "servo_timeout_s",
            "low_battery_s",
            "joint_tracking_rad",
            "joint_tracking_s",
            "perch_qp_fail_s",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"MonitorLimits.{name}={v!r} must be finite and > 0")
        lo, hi = self.cell_plausible
        if not (0 < lo < self.cell_low < self.cell_arm_min <= hi and math.isfinite(hi)):
            raise ValueError(
                "MonitorLimits: need 0 < cell_plausible[0] < cell_low < cell_arm_min "
                "<= cell_plausible[1]"
            )
        if self.battery_cells is not None and not (
            isinstance(self.battery_cells, int) and 1 <= self.battery_cells <= 24
        ):
            raise ValueError(f"MonitorLimits.battery_cells={self.battery_cells!r}: 1..24")
        if self.ground_loss_perched not in ("hold", "land"):
            raise ValueError("MonitorLimits.ground_loss_perched: 'hold' or 'land'")


def battery_cells(voltages: list[float]) -> int:
    """The cell count of a battery whose full voltage is the highest reference voltage."""
    top = max((v for v in voltages if math.isfinite(v) and v > 0), default=CELL_FULL_V)
    return max(1, round(top / CELL_FULL_V))


#: How many of the latest monitor events the status carries.
EVENTS_KEPT = 32


class Monitors:
    """Trip counters, the event list and the battery state (see the module doc)."""

    def __init__(self, limits: MonitorLimits, cells: int) -> None:
        self.limits = limits
        self.cells = cells
        self.counts: Counter[str] = Counter()
        #: The latest trips and notes, for the status line (``counts`` counts every one and
        #: each is logged). ASSUMPTION: 32 is enough to see how a flight ended while keeping
        #: a status line short.
        self.events: deque[dict[str, Any]] = deque(maxlen=EVENTS_KEPT)
        self.voltage: float | None = None
        self._low_since: float | None = None
        self._stale: set[str] = set()
        self._since: dict[str, float] = {}

    def trip(self, name: str, reason: str, now: float) -> None:
        """Count, log and remember one trip."""
        self.counts[name] += 1
        self.events.append({"t": round(now, 4), "monitor": name, "reason": reason})
        LOG.warning("t=%.3f %s: %s", now, name, reason)

    def note(self, name: str, what: str, now: float) -> None:
        """Count, log (info) and remember one event of the flight that is not a fault."""
        self.counts[name] += 1
        self.events.append({"t": round(now, 4), "monitor": name, "reason": what})
        LOG.info("t=%.3f %s: %s", now, name, what)

    # -- battery -------------------------------------------------------------------------
    def battery(self, volts: float, now: float) -> bool:
        """A ``battery_voltage_status`` reading; False if rejected (the last good one kept)."""
        lo, hi = (c * self.cells for c in self.limits.cell_plausible)
        if not (math.isfinite(volts) and lo <= volts <= hi):
            self.trip(
                "battery_implausible",
                f"{volts!r} V outside {lo:.2f}..{hi:.2f} V ({self.cells} cells)",
                now,
            )
            return False
        self.voltage = volts
        if volts >= self.limits.cell_low * self.cells:
            self._low_since = None
        elif self._low_since is None:
            self._low_since = now
        return True

    def battery_low(self, now: float) -> bool:
        """Whether the voltage stayed below ``cell_low`` for ``low_battery_s`` (trips once)."""
        low = (
            self._low_since is not None
            and now - self._low_since >= self.limits.low_battery_s - 1e-9
        )
        return self.stale(
            "battery_low",
            low,
            now,
            f"{self.voltage} V below {self.limits.cell_low * self.cells:.2f} V",
        )

    def arm_refusal(self) -> str | None:
        """Why arming is refused now (None: allowed)."""
        if self.counts["battery_implausible"] and self.voltage is None:
            return "no plausible battery reading"
        if self.voltage is not None and self.voltage < self.limits.cell_arm_min * self.cells:
            return (
                f"battery {self.voltage:.2f} V below {self.limits.cell_arm_min * self.cells:.2f} V"
            )
        return None

    # -- freshness and limits ------------------------------------------------------------
    def stale(self, name: str, condition: bool, now: float, reason: str) -> bool:
        """True on the tick ``condition`` becomes true (one trip per episode)."""
        if not condition:
            self._stale.discard(name)
            return False
        if name in self._stale:
            return False
        self._stale.add(name)
        self.trip(name, reason, now)
        return True

    def sustained(self, name: str, condition: bool, hold_s: float, now: float, reason: str) -> bool:
        """:meth:`stale` of ``condition`` held without a break for ``hold_s`` s (one trip per
        episode; a tick without it starts the wait again)."""
        if not condition:
            self._since.pop(name, None)
        else:
            self._since.setdefault(name, now)
        held = condition and now - self._since[name] >= hold_s - 1e-9
        return self.stale(name, held, now, reason)

    def active(self, name: str) -> bool:
        """Whether the condition of ``name`` holds at the last check."""
        return name in self._stale

    def status(self) -> dict[str, Any]:
        return {
            "counts": dict(self.counts),
            "active": sorted(self._stale),
            "events": list(self.events),
            "battery_cells": self.cells,
        }
