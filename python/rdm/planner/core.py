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
            if not t.is_file():
                raise FileNotFoundError(
                    f"unknown robot {str(robot)!r}: shipped robots are 'rdm' and 'rcm'; "
                    "or give the path of a description's TOML file (its URDF beside it)"
                )
            urdf_path = t.with_suffix(".urdf")
            if not urdf_path.is_file():
                raise FileNotFoundError(
                    f"robot {str(robot)!r}: no URDF {str(urdf_path)!r} beside the TOML file"
                )
            urdf, toml = urdf_path.read_text(), t.read_text()
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


#: Default damper thresholds (restricted) used to score starts; they mirror
#: ``PlannerConfig::new`` in crates/rdm_core/src/planner/config.rs.
_RESTRICTED = {"state": 0.15, "rho": 3e-4, "collision": 0.1}
_FORBIDDEN_DISTANCE = 0.01


def start_margin(core: _rdm.CorePlanner, model: Robot) -> float:
    """Smallest normalised distance of the core's current state to any limit (< 0: a limit
    is violated or a damper band is entered): thrust to [min, upper] over thrust_max,
    torque to stall, joints and rho to their restricted bands, clearances and rotor spacing
    to their forbidden distance (over the restricted one)."""
    lay, v = core.layout, core.values
    t0, nt = lay["thrust"]
    thrust = v[t0 : t0 + nt]
    upper = v[lay["thrust_upper"][0] : lay["thrust_upper"][0] + nt]
    tmin = np.array([r["thrust_min"] for r in model.rotors])
    tmax = np.array([r["thrust_max"] for r in model.rotors])
    tau = v[lay["torque"][0] : lay["torque"][0] + lay["torque"][1]]
    stall = np.array(model.stall_torques)
    lo, hi = np.array(model.joint_limits).T
    q = core.zeta[6:]
    free = [i - 6 for i in core.free if i >= 6]
    c0, nc = lay["collision"]
    a0, na = lay["airflow"]
    parts = [
        ((thrust - tmin) / tmax).min(),
        ((upper - thrust) / tmax).min(),
        ((stall - np.abs(tau)) / stall).min(),
        (np.minimum(q - lo, hi - q)[free] / _RESTRICTED["state"] - 1.0).min(),
        v[lay["rho"][0]] / _RESTRICTED["rho"] - 1.0,
    ]
    # Distances only need to clear the forbidden band: rotors of two units on one link
    # (the RCM) sit a fixed 13 mm beyond a diameter apart.
    if nc:
        parts.append((v[c0 : c0 + nc].min() - _FORBIDDEN_DISTANCE) / _RESTRICTED["collision"])
    if na:
        parts.append((v[a0 : a0 + na].min() - _FORBIDDEN_DISTANCE) / _RESTRICTED["collision"])
    return float(min(parts))


def feasible_starts(
    setup: PlannerSetup, step: float = 0.2, bin_width: float = 0.3
) -> list[np.ndarray]:
    """Start states for design sweeps, found by a grid search over the planar (x-z) arm
    configurations (q1, q2, q4; yaw joints and q6 zero): in every ``bin_width`` band of
    end-effector x, the configuration with the largest ``start_margin``. Differential IK
    is local, so a sweep tries these starts in turn, nearest first. Only starts with a
    positive margin are returned (empty when the robot cannot hold any planar
    configuration, e.g. Table II's root variant)."""
    model = Robot.from_strs(setup.urdf, setup.toml)
    lo, hi = np.array(model.joint_limits).T
    base = np.zeros(6 + model.n_q)
    core = None
    best: dict[int, tuple[float, np.ndarray]] = {}
    q1s = np.arange(0.0, hi[0] - 0.15 + 1e-9, step)
    q2s = np.arange(lo[1] + 0.15, hi[1] - 0.15 + 1e-9, step)
    q4s = np.arange(lo[3] + 0.15, hi[3] - 0.15 + 1e-9, step)
    for q1 in q1s:
        for q2 in q2s:
            for q4 in q4s:
                zeta = base.copy()
                zeta[6:10] = (q1, q2, 0.0, q4)
                try:
                    if core is None:
                        core = make_core(setup, zeta)
                    else:
                        core.set_zeta(zeta)
                except (_rdm.RdmError, ValueError):
                    continue
                margin = start_margin(core, model)
                key = int(np.floor(core.end_effector_pose()[0][0] / bin_width))
                if margin > 0.0 and margin > best.get(key, (0.0, None))[0]:
                    best[key] = (margin, core.zeta.copy())
    return [best[k][1] for k in sorted(best)]
