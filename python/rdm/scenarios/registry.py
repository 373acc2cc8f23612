"""Scenario registry: name -> (run function, default duration, one-line description).

Only scenarios that run end to end are listed (no stubs). Each entry names its module and
imports it only when its ``run`` or ``default_duration`` is asked for: the scenario modules
pull in scipy, the planner and each other's helpers, and ``rdm sim perching`` (or
``rdm --help``) should not pay for all of them (docs/sim.md "Start-up")."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Scenario:
    """One experiment: ``run`` is ``module.function``, ``default_duration`` is
    ``module.duration`` (an attribute, or a function called with ``duration_arg``)."""

    name: str
    module: str
    function: str
    description: str
    duration: str = "DEFAULT_DURATION"
    duration_arg: str | None = None

    def _module(self) -> Any:
        return importlib.import_module(f"rdm.scenarios.{self.module}")

    @property
    def run(self) -> Callable:
        """The scenario's run function (imports its module)."""
        return getattr(self._module(), self.function)

    @property
    def default_duration(self) -> float:
        """Simulated seconds of a default run (imports the scenario's module)."""
        value = getattr(self._module(), self.duration)
        return float(value(self.duration_arg) if self.duration_arg is not None else value)


SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        Scenario("hover", "hover", "run", "take-off and hover at 0.4 m through every wire"),
        Scenario("flight", "flight", "run", "Fig. 9 configuration change in flight"),
        Scenario(
            "mission",
            "mission",
            "run",
            "operator flight: take off, go to a point, fold, perch, move the arm, unperch, "
            "land (--quick: take off, go to, land); --fault injects one fault",
        ),
        Scenario(
            "perching",
            "perching_foot_at_plate",
            "run",
            "climb, fold, perch on the ceiling, move the arm (Fig. 10) in the paper's posture: "
            "the foot unit at the plate end of the root link (rotors 6 cm under the ceiling), "
            "Table VII's eps_z = 1 N; the foot thrust returns to the flight level and the plate "
            "stays off its edges (docs/scenarios.md)",
        ),
        Scenario(
            "perching-hanging",
            "perching",
            "run",
            "climb, fold to the hanging posture (foot rotors 0.42 m under the plate, eps_z = "
            "8 N), perch on the ceiling, move the arm: the posture the tracking, push and task "
            "experiments perch in",
        ),
        Scenario(
            "wall-perching",
            "wall_perching",
            "run",
            "approach a vertical plate in the flat posture, press the foot's side face on it "
            "with the foot rotors tilted 30 deg (beta1 = -30 deg), hold perched with the "
            "plate's friction carrying 10 % of the weight, leave",
        ),
        Scenario(
            "push",
            "push",
            "run",
            "end-effector pushed and pulled in x, y, z in flight and perched (Figs. 11-12)",
        ),
        Scenario(
            "push-paper-forces",
            "push_paper",
            "run",
            "push within Table VIII's peaks: foot unit at the plate, arm straight below it",
        ),
        Scenario(
            "tracking",
            "tracking",
            "run",
            "end-effector pose errors along planned joint paths, flight and perched (Figs. 6, 13)",
        ),
        Scenario(
            "drilling",
            "tasks",
            "run_drilling",
            "perch, then drill (point contact) at three targets on a board (Fig. 14 A)",
            "duration_of",
            "drilling",
        ),
        Scenario(
            "painting",
            "tasks",
            "run_painting",
            "perch, then paint a wall: a 0.5 m vertical brush stroke in contact (Fig. 14 B)",
            "duration_of",
            "painting",
        ),
        Scenario(
            "painting-panel",
            "tasks",
            "run_painting_panel",
            "perch, then slide a compliant brush over 0.5 m in contact along a panel below",
            "duration_of",
            "painting-panel",
        ),
        Scenario(
            "valve",
            "tasks",
            "run_valve",
            "perch, then grip a hand-wheel's handle bar and turn it 69 deg with q6 (Fig. 14 C)",
            "duration_of",
            "valve",
        ),
    )
}
DEFAULT_SCENARIO = "perching"
