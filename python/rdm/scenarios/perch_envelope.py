"""Perching envelope: which foot-unit geometry and perched posture can hold Table VIII.

For a candidate (foot-unit position along the root link, perched posture q1..q6) this module
answers, statically and with Table VII's parameters (eps_z = 1 N, mu = 0.9 / 0.5, H = 0.04 /
0.07 m):

* **holds**: is there a perching thrust (the perching QP's own authority: the foot rotors
  add lambda_perch >= 0 on top of the hover thrust, eqs. 39-47) that meets eqs. (39)-(42)
  with no external force?
* **ceiling effect**: the foot rotors' distance to the ceiling (along their axis), the thrust
  gain T/T0 there (:class:`rdm.plant.ceiling.ParametricCeilingEffect`, the plant's model) and
  the commanded foot thrust after contact relative to flight, ``(hover + lambda) / (gain
  hover)``: the paper's Fig. 10 B returns to 1.0;
* **push bound**: the largest force along each end-effector axis, pushed and pulled, the
  perched robot holds (:func:`rdm.scenarios.push_ceiling.ceiling`, a linear programme):
  with the perching QP's authority ("perch") and with every rotor ("all"), both with the
  ceiling gain on each rotor's thrust limit, against Table VIII's 25.1 / 8.4 / 16.8 N;
* **thrust needed**: the rotor thrust limit (all four rotors alike, before the ceiling
  gain) at which the "perch" bound reaches Table VIII's perched average on each axis;
* **binding**: for the "perch" bound, which constraint class binds, found by relaxing one at
  a time (friction, ZMP, rotor thrust maximum) and seeing which raises the bound.

Run: ``python -m rdm.scenarios.perch_envelope`` (a table) or ``--json``.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from rdm import _rdm
from rdm.descriptions import build_description
from rdm.model import Robot
from rdm.plant.ceiling import ParametricCeilingEffect

from .perching import MU, PERCH_POSTURE, leveled
from .push_ceiling import GRAVITY, ceiling

__all__ = [
    "CANDIDATES",
    "PAPER_PERCHED_FORCE_AVG",
    "PAPER_PERCHED_FORCE_PEAK",
    "TABLE_VII_EPSILON_Z",
    "Candidate",
    "candidate_robot",
    "envelope",
    "main",
]

#: Table VIII's perched end-effector forces [N], x / y / z (average and peak)
PAPER_PERCHED_FORCE_AVG = (25.1, 8.4, 16.8)
PAPER_PERCHED_FORCE_PEAK = (41.8, 15.9, 32.1)
#: Table VII's eps_z [N] (eq. 39)
TABLE_VII_EPSILON_Z = 1.0
#: a relaxed limit (friction coefficient, ZMP half-width [m], thrust gain) for the binding test
_RELAXED = 1e3
_PI = math.pi


@dataclass(frozen=True)
class Candidate:
    """A foot-unit geometry and perched posture.

    ``foot_unit_position``: fraction of the root link from the plate (1 = the far tip, the
    shipped robot); ``q6``: q1..q6 (vectoring levelled, ``perching.leveled``).
    """

    name: str
    q6: tuple[float, ...]
    foot_unit_position: float = 1.0
    reading: str = ""


CANDIDATES: tuple[Candidate, ...] = (
    Candidate(
        "hanging",
        tuple(PERCH_POSTURE),
        1.0,
        "shipped: root link hanging, foot unit at its far tip (the perching default)",
    ),
    Candidate(
        "push posture",
        (_PI / 2, -_PI / 2, 0.0, -_PI / 2, 0.0, 0.0),
        1.0,
        "shipped: the push scenario's PERCHED_POSTURE",
    ),
    Candidate(
        "straight hanging",
        (_PI / 2, 0.0, 0.0, 0.0, 0.0, 0.0),
        1.0,
        "shipped: arm straight below the plate, the end effector's x axis along the normal",
    ),
    Candidate(
        "root along ceiling",
        (0.0, 1.0, 0.0, 0.0, 0.0, 0.0),
        1.0,
        "root link flat under the ceiling (perching 'with the root unit'), foot unit at its tip",
    ),
    Candidate(
        "foot at plate, hanging",
        tuple(PERCH_POSTURE),
        0.1,
        "foot unit beside the plate ('tip' read as the root end), root link hanging",
    ),
    Candidate(
        "foot at plate, straight hanging",
        (_PI / 2, 0.0, 0.0, 0.0, 0.0, 0.0),
        0.1,
        "foot unit beside the plate, arm straight below it",
    ),
    Candidate(
        "foot at plate, root along ceiling",
        (0.0, 1.0, 0.0, 0.0, 0.0, 0.0),
        0.3,
        "foot unit 0.12 m from the plate centre, root link flat under the ceiling",
    ),
)


def candidate_robot(foot_unit_position: float) -> _rdm.Robot:
    """The shipped robot (1.0) or a generated one with the foot unit moved along the root link."""
    if foot_unit_position == 1.0:
        return Robot.default()
    d = build_description("rdm", 1.0, foot_unit_position)
    return _rdm.Robot.from_strs(d.urdf, d.toml, f"{d.name}.urdf", f"{d.name}.toml")


def _hover(o: dict[str, Any]) -> np.ndarray:
    mg = float(o["mass"]) * GRAVITY
    return np.linalg.lstsq(np.asarray(o["allocation_bar"]), [mg, 0, 0, 0], rcond=None)[0]


def _thrust_needed(
    robot: _rdm.Robot,
    q6: np.ndarray,
    gain: np.ndarray,
    tmax: float,
    target: tuple[float, float, float],
    kw: dict[str, Any],
) -> list[float]:
    """Smallest common rotor thrust limit [N] at which each axis' "perch" bound reaches
    ``target`` (log bisection in [tmax, 100 tmax]; inf beyond)."""
    out = []
    for k in range(3):
        lo, hi = 1.0, 100.0

        def ok(s: float, k=k) -> bool:
            b = ceiling(robot, q6, "perch", thrust_gain=gain * s, **kw)[k]
            return bool(math.isfinite(b) and b >= target[k])

        if ok(lo):
            out.append(float(tmax))
            continue
        if not ok(hi):
            out.append(math.inf)
            continue
        for _ in range(16):
            mid = math.sqrt(lo * hi)
            lo, hi = (lo, mid) if ok(mid) else (mid, hi)
        out.append(float(tmax * hi))
    return out


def envelope(
    cand: Candidate,
    epsilon_z: float = TABLE_VII_EPSILON_Z,
    effect: ParametricCeilingEffect | None = None,
    foot_rotors: tuple[int, ...] = (0, 1),
    thrust_needed: bool = False,
) -> dict[str, Any]:
    """Static perching envelope of one candidate (module docstring); forces in N.
    ``thrust_needed`` adds the rotor limit each axis would need (a bisection, slower)."""
    robot = candidate_robot(cand.foot_unit_position)
    q6 = np.asarray(cand.q6, dtype=float)
    o = robot.evaluate(leveled(q6, robot.n_q))
    rotors = robot.rotors
    effect = effect or ParametricCeilingEffect(radius=float(rotors[0]["diameter"]) / 2.0)
    hover = _hover(o)
    tmin = np.array([r["thrust_min"] for r in rotors], dtype=float)
    tmax = np.array([r["thrust_max"] for r in rotors], dtype=float)
    pos = np.asarray(o["rotor_positions"], dtype=float)  # foot frame, z up (ceiling at z = 0)
    axis = np.asarray(o["rotor_directions"], dtype=float)
    dist = np.array(
        [-p[2] / a[2] if a[2] > 1e-6 else math.inf for p, a in zip(pos, axis, strict=True)]
    )
    gain = np.array([effect.thrust_ratio(float(d)) for d in dist])
    cols = list(foot_rotors)
    up = axis[cols, 2]
    lam = epsilon_z / float(np.sum(up)) * np.ones(len(cols))  # symmetric press of eps_z
    commanded = (hover[cols] + lam) / (gain[cols] * hover[cols])
    kw: dict[str, Any] = {"epsilon_z": epsilon_z, "mu": MU, "perch_rotors": foot_rotors}
    perch = ceiling(robot, q6, "perch", thrust_gain=gain, **kw)
    allr = ceiling(robot, q6, "all", thrust_gain=gain, **kw)
    relaxed = {
        "friction": ceiling(robot, q6, "perch", thrust_gain=gain, **{**kw, "mu": (_RELAXED,) * 3}),
        "zmp": ceiling(robot, q6, "perch", half=(_RELAXED, _RELAXED), thrust_gain=gain, **kw),
        "thrust_max": ceiling(robot, q6, "perch", thrust_gain=gain * _RELAXED, **kw),
    }
    binding = []
    for k in range(3):
        raised = [
            name
            for name, b in relaxed.items()
            if math.isfinite(perch[k])
            and (not math.isfinite(b[k]) or b[k] > perch[k] * 1.01 + 1e-6)
        ]
        binding.append(
            "+".join(raised)
            if raised
            else ("infeasible" if not math.isfinite(perch[k]) else "none")
        )
    ee = np.asarray(o["frames"]["end_effector"], dtype=float)
    needed = (
        _thrust_needed(robot, q6, gain, float(tmax[0]), PAPER_PERCHED_FORCE_AVG, kw)
        if thrust_needed
        else None
    )
    return {
        "name": cand.name,
        "reading": cand.reading,
        "foot_unit_position": cand.foot_unit_position,
        "q6": [float(v) for v in q6],
        "epsilon_z": epsilon_z,
        "mass": float(o["mass"]),
        "rho": float(o["rho"]),
        "hover_thrust": hover.tolist(),
        "hover_in_limits": bool(np.all(hover >= tmin) and np.all(hover <= tmax)),
        "holds": bool(np.isfinite(perch).all()),
        "foot_distance_to_ceiling": dist[cols].tolist(),
        "ceiling_gain": gain.tolist(),
        "foot_commanded_after_contact_over_flight": commanded.tolist(),
        "end_effector": ee[:3, 3].tolist(),
        "push_bound_perch": perch.tolist(),
        "push_bound_all": allr.tolist(),
        "binding_perch": binding,
        "thrust_max_needed": needed,
        "paper_perched_force_avg": list(PAPER_PERCHED_FORCE_AVG),
        "paper_perched_force_peak": list(PAPER_PERCHED_FORCE_PEAK),
    }


def _fmt(v: list[float]) -> str:
    return " / ".join("-" if not math.isfinite(x) else f"{x:.1f}" for x in v)


def main(argv: list[str] | None = None) -> int:
    """Print every candidate's envelope (``--json``: a JSON list)."""
    args = sys.argv[1:] if argv is None else argv
    bad = [a for a in args if a != "--json"]
    if bad:
        print(f"perch_envelope: unknown argument {bad[0]!r} (only --json)", file=sys.stderr)
        return 2
    rows = [envelope(c, thrust_needed=True) for c in CANDIDATES]
    if "--json" in args:
        print(json.dumps(rows, indent=1))
        return 0
    print(f"Table VIII perched average {_fmt(list(PAPER_PERCHED_FORCE_AVG))} N, eps_z = 1 N")
    for r in rows:
        print(
            f"{r['name']:34s} holds={r['holds']!s:5s} hover_ok={r['hover_in_limits']!s:5s} "
            f"d_foot={r['foot_distance_to_ceiling'][0]:.3f} m gain={r['ceiling_gain'][0]:.2f} "
            f"foot cmd/flight={r['foot_commanded_after_contact_over_flight'][0]:.2f} "
            f"perch {_fmt(r['push_bound_perch'])} all {_fmt(r['push_bound_all'])} "
            f"binding {','.join(r['binding_perch'])} "
            f"rotor max needed {_fmt(r['thrust_max_needed'])}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
