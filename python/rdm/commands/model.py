"""``rdm model``: load a robot, print its mass properties, rotor allocation matrix and the
aerial-ZMP stability margin at a joint configuration."""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

import numpy as np

from rdm.commands.arg_types import accept_negative_values, finite_list
from rdm.commands.output import json_text
from rdm.json_values import non_finite_paths


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``rdm model``."""
    parser.add_argument(
        "--robot",
        choices=("rdm", "rcm"),
        default="rdm",
        help="shipped robot (default: rdm)",
    )
    parser.add_argument("--urdf", help="URDF file of a custom robot (needs --toml)")
    parser.add_argument("--toml", help="TOML file of a custom robot (needs --urdf)")
    parser.add_argument(
        "--q",
        type=finite_list,
        default=None,
        help="joint vector, comma-separated radians in the robot's joint order (default: "
        "zeros); finite numbers, a leading minus is fine (--q -0.5,0,...)",
    )
    parser.add_argument(
        "--degrees", action="store_true", help="read --q in degrees instead of radians"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    accept_negative_values(parser)


def _parse_q(values: list[float] | None, n: int, degrees: bool) -> list[float]:
    """The joint vector [rad] of ``--q`` (finite numbers, checked by its argparse type)."""
    if values is None:
        return [0.0] * n
    if len(values) != n:
        raise ValueError(f"--q: expected {n} values, got {len(values)}")
    return [math.radians(v) for v in values] if degrees else list(values)


def limit_warnings(robot: Any, q: list[float]) -> list[str]:
    """One line per joint of ``q`` outside the robot's joint limits (its URDF's)."""
    lines = []
    for i, (name, v, (lo, hi)) in enumerate(
        zip(robot.joint_names, q, np.asarray(robot.joint_limits).tolist(), strict=True)
    ):
        if not lo <= v <= hi:
            lines.append(
                f"--q[{i}]: joint {name} = {v:.6g} rad is outside its limits "
                f"[{lo:.6g}, {hi:.6g}] rad"
            )
    return lines


def _table(header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    line = lambda cells: "  ".join(  # noqa: E731
        c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(zip(cells, widths, strict=True))
    )
    return "\n".join([line(header), line(["-" * w for w in widths]), *map(line, rows)])


def collect(robot: Any, q: list[float]) -> dict[str, Any]:
    """Everything ``rdm model`` reports, as JSON-ready Python values."""
    out = robot.evaluate(q)
    return {
        "robot": robot.name,
        "joint_names": list(robot.joint_names),
        "q": list(q),
        "mass": float(out["mass"]),
        "cog": out["cog"].tolist(),
        "inertia": out["inertia"].tolist(),
        "rotor_names": list(robot.rotor_names),
        "rotor_positions": out["rotor_positions"].tolist(),
        "rotor_directions": out["rotor_directions"].tolist(),
        "allocation": out["allocation"].tolist(),
        "aerial_zmp": out["aerial_zmp"].tolist(),
        "zmp_margin": float(out["zmp_margin"]),
        "zmp_inside": bool(out["zmp_inside"]),
        "zmp_degenerate": bool(out["zmp_degenerate"]),
        "rho": float(out["rho"]),
    }


def _human(report: dict[str, Any]) -> str:
    f = lambda v: f"{v:+.4f}"  # noqa: E731
    lines = [
        f"robot {report['robot']}: {len(report['joint_names'])} joints, "
        f"{len(report['rotor_names'])} rotors"
    ]
    lines.append("")
    lines.append(
        _table(
            ["joint", "q [rad]", "q [deg]"],
            [
                [n, f(v), f"{math.degrees(v):+.1f}"]
                for n, v in zip(report["joint_names"], report["q"], strict=True)
            ],
        )
    )
    lines.append("")
    lines.append(f"mass     {report['mass']:.4f} kg")
    lines.append("cog      [" + ", ".join(f(v) for v in report["cog"]) + "] m (world)")
    lines.append("inertia about the CoG, CoG frame [kg m^2]:")
    lines.append(
        _table(
            ["", "x", "y", "z"],
            [
                [axis, *(f"{v:+.5f}" for v in row)]
                for axis, row in zip("xyz", report["inertia"], strict=True)
            ],
        )
    )
    lines.append("")
    lines.append("rotors (world):")
    lines.append(
        _table(
            ["rotor", "x", "y", "z", "ux", "uy", "uz"],
            [
                [n, *(f(v) for v in p), *(f(v) for v in u)]
                for n, p, u in zip(
                    report["rotor_names"],
                    report["rotor_positions"],
                    report["rotor_directions"],
                    strict=True,
                )
            ],
        )
    )
    lines.append("")
    lines.append("allocation matrix Q(q), CoG frame (eqs. 7-9):")
    alloc = np.asarray(report["allocation"])
    lines.append(
        _table(
            ["row", *report["rotor_names"]],
            [
                [name, *(f(v) for v in alloc[i])]
                for i, name in enumerate(["fx", "fy", "fz", "mx [m]", "my [m]", "mz [m]"])
            ],
        )
    )
    lines.append("")
    zx, zy = report["aerial_zmp"]
    state = (
        "degenerate polygon"
        if report["zmp_degenerate"]
        else ("inside" if report["zmp_inside"] else "OUTSIDE")
    )
    lines.append(
        f"aerial ZMP  ({zx:+.4f}, {zy:+.4f}) m, margin {report['zmp_margin']:+.4f} m "
        f"({state} the aerial support polygon)"
    )
    lines.append(f"stability  rho = {report['rho']:.5g} (eq. 65)")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """Load the robot, evaluate at ``--q`` and print; returns the exit code."""
    from rdm.model import DescriptionError, ModelError, Robot

    try:
        if args.urdf or args.toml:
            if not (args.urdf and args.toml):
                print("rdm model: --urdf and --toml go together", file=sys.stderr)
                return 2
            robot = Robot.from_files(args.urdf, args.toml)
        else:
            robot = Robot.shipped(args.robot)
        q = _parse_q(args.q, robot.n_q, args.degrees)
        warnings = limit_warnings(robot, q)
        report = collect(robot, q)
    except (DescriptionError, ModelError, ValueError) as exc:
        print(f"rdm model: {exc}", file=sys.stderr)
        return 2
    for line in warnings:
        print(f"rdm model: warning: {line}", file=sys.stderr)
    bad = non_finite_paths(report)
    if bad:
        shown = ", ".join(bad[:6]) + (f" and {len(bad) - 6} more" if len(bad) > 6 else "")
        print(
            f"rdm model: the model is not finite at this --q ({shown}); "
            "give joint angles within the limits",
            file=sys.stderr,
        )
        return 1
    print(json_text(report, indent=2) if args.json else _human(report))
    return 0
