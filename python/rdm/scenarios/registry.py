"""Scenario registry: name -> (run function, default duration, one-line description).

Only scenarios that run end to end are listed (no stubs). ``perching``, ``flight`` and
``push`` are not here yet: the simulated robot does not hover stably (docs/sim.md)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from . import flight, hover


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
}
DEFAULT_SCENARIO = "hover"
