"""Scenario registry: name -> (run function, default duration, one-line description).

Only scenarios that run end to end are listed (no stubs)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from . import flight, hover, perching, push, tasks, tracking


@dataclass(frozen=True)
class Scenario:
    name: str
    run: Callable
    default_duration: float
    description: str


SCENARIOS: dict[str, Scenario] = {
    "hover": Scenario(
        "hover", hover.run, hover.DEFAULT_DURATION, "take-off and hover at 0.4 m through every wire"
    ),
    "flight": Scenario(
        "flight", flight.run, flight.DEFAULT_DURATION, "Fig. 9 configuration change in flight"
    ),
    "perching": Scenario(
        "perching",
        perching.run,
        perching.DEFAULT_DURATION,
        "climb, fold to the hanging posture, perch on the ceiling, move the arm (Fig. 10)",
    ),
    "push": Scenario(
        "push",
        push.run,
        push.DEFAULT_DURATION,
        "end-effector pushed and pulled in x, y, z in flight and perched (Figs. 11-12)",
    ),
    "tracking": Scenario(
        "tracking",
        tracking.run,
        tracking.DEFAULT_DURATION,
        "end-effector pose errors under the same joint motion in flight and perched (Fig. 13)",
    ),
    "drilling": Scenario(
        "drilling",
        tasks.run_drilling,
        tasks.duration_of("drilling"),
        "perch, then drill (point contact) at three targets on a board (Fig. 14 A)",
    ),
    "painting": Scenario(
        "painting",
        tasks.run_painting,
        tasks.duration_of("painting"),
        "perch, then slide a compliant brush over 0.5 m in contact along a panel (Fig. 14 B)",
    ),
    "valve": Scenario(
        "valve",
        tasks.run_valve,
        tasks.duration_of("valve"),
        "perch, then grip a hand-wheel's handle bar and turn it 69 deg with q6 (Fig. 14 C)",
    ),
}
DEFAULT_SCENARIO = "perching"
