"""Build the Rust planner core (``rdm._rdm.CorePlanner``) for a robot and mode."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rdm import _rdm
from rdm.model import Robot, shipped_robot_files
from rdm.planner.shapes import collision_config

#: Perched start: foot on the ceiling at the origin, root link pitched down, middle link
#: folded forward, end link back down. ASSUMPTION, chosen by a grid search (docs/planner.md)
#: for the largest margin to every limit: the hover thrusts (9.0, 9.0, 11.7, 11.7) N are
#: inside [0, 20] N (the CoG lies between the two rotor pairs), |tau| <= 1.72 N m, rho = 1.5e-3.
PERCHED_START_Q = (1.2, 0.8, 0.0, -0.9, 0.0, 0.0)
#: Flight start, chosen the same way: thrusts (7.8, 7.8, 10.4, 10.4) N, rho = 1.8e-3.
FLIGHT_START_Q = (1.0, 1.1, 0.0, -0.9, 0.0, 0.0)


@dataclass(frozen=True)
class PlannerSetup:
    """Everything needed to build a core in any process: description texts, mode, config."""

    urdf: str
    toml: str
    mode: str = "perched"
    config: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def for_robot(
        cls, robot: str | Path | tuple[str, str], mode: str = "perched", **config: Any
    ) -> PlannerSetup:
        """``robot``: a shipped name ("rdm", "rcm"), a TOML path next to its URDF, or a
        (urdf_text, toml_text) pair (e.g. from ``rdm.descriptions.build_description``)."""
        if isinstance(robot, tuple):
            urdf, toml = robot
        elif isinstance(robot, str) and robot in ("rdm", "rcm"):
            with shipped_robot_files(robot) as (u, t):
                urdf, toml = u.read_text(), t.read_text()
        else:
            t = Path(robot)
            urdf, toml = t.with_suffix(".urdf").read_text(), t.read_text()
        model = Robot.from_strs(urdf, toml)
        units = {}
        for unit in model.vectoring_units:
            key = "foot_unit" if unit["name"].startswith("foot") else "arm_unit"
            units[key] = unit.get("parent_link", unit["name"])
        merged = collision_config(model.link_names, units)
        merged.update(config)
        return cls(urdf=urdf, toml=toml, mode=mode, config=merged)


def default_start(setup: PlannerSetup) -> np.ndarray:
    """A start state zeta = [p, eta, q] for the setup's mode (unit angles are re-solved)."""
    model = Robot.from_strs(setup.urdf, setup.toml)
    zeta = np.zeros(6 + model.n_q)
    q6 = PERCHED_START_Q if setup.mode == "perched" else FLIGHT_START_Q
    zeta[6:12] = q6
    return zeta


def make_core(setup: PlannerSetup, zeta0: np.ndarray | None = None) -> _rdm.CorePlanner:
    """Build the Rust planner for ``setup`` starting at ``zeta0`` (default start if None)."""
    start = default_start(setup) if zeta0 is None else np.asarray(zeta0, dtype=float)
    return _rdm.CorePlanner(setup.urdf, setup.toml, setup.mode, start, dict(setup.config))
