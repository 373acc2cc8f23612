"""``rdm plant``: build the MuJoCo model of a robot and export it for MuJoCo's viewer."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``rdm plant``."""
    parser.add_argument("--robot", default="rdm", help="shipped robot (rdm, rcm) or a TOML path")
    parser.add_argument("--export", type=Path, metavar="MODEL.xml", help="write the MJCF here")
    parser.add_argument(
        "--ceiling-height", type=float, default=2.0, help="ceiling plane height [m]"
    )
    parser.add_argument("--no-ceiling", action="store_true", help="omit the ceiling")
    parser.add_argument("--floor-height", type=float, default=None, help="add a floor plane [m]")


def run(args: argparse.Namespace) -> int:
    """Build the model, print a summary, optionally export it."""
    from rdm.plant.description import DescriptionError, load_robot
    from rdm.plant.mjcf import BuildOptions, build_spec

    try:
        desc = load_robot(args.robot)
    except DescriptionError as exc:
        print(f"rdm plant: {exc}")
        return 2
    options = BuildOptions(
        ceiling_height=None if args.no_ceiling else args.ceiling_height,
        floor_height=args.floor_height,
    )
    spec = build_spec(desc, options)
    model = spec.compile()
    mass = float(model.body_subtreemass[1])
    print(
        f"{desc.name}: {model.nbody - 1} bodies, {model.njnt} joints, {model.nu} actuators "
        f"({len(desc.rotors)} rotors), {model.nsensor} sensors, mass {mass:.3f} kg, "
        f"timestep {model.opt.timestep * 1e3:g} ms"
    )
    if args.export is not None:
        args.export.parent.mkdir(parents=True, exist_ok=True)
        args.export.write_text(spec.to_xml())
        print(f"wrote {args.export}; view it with: python -m mujoco.viewer --mjcf {args.export}")
    return 0
