"""``rdm plant``: build the MuJoCo model of a robot and export it for MuJoCo's viewer."""

from __future__ import annotations

import argparse
import sys

from rdm.commands.arg_types import finite
from rdm.commands.output import output_file
from rdm.output_files import open_output


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``rdm plant``."""
    parser.add_argument("--robot", default="rdm", help="shipped robot (rdm, rcm) or a TOML path")
    parser.add_argument(
        "--export", type=output_file, metavar="MODEL.xml", help="write the MJCF here"
    )
    parser.add_argument(
        "--ceiling-height", type=finite, default=2.0, help="ceiling plane height [m]"
    )
    parser.add_argument("--no-ceiling", action="store_true", help="omit the ceiling")
    parser.add_argument("--floor-height", type=finite, default=None, help="add a floor plane [m]")


def run(args: argparse.Namespace) -> int:
    """Build the model, print a summary, optionally export it."""
    from rdm.plant.description import DescriptionError, load_robot
    from rdm.plant.mjcf import BuildOptions, build_spec

    try:
        desc = load_robot(args.robot)
    except DescriptionError as exc:
        print(f"rdm plant: {exc}", file=sys.stderr)
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
        xml = spec.to_xml()
        try:
            with open_output(args.export, "w", encoding="utf-8") as f:
                f.write(xml)
        except OSError as exc:  # a full disk, a link planted since the check
            print(f"rdm plant: --export {str(args.export)!r}: {exc}", file=sys.stderr)
            return 2
        print(f"wrote {args.export}; view it with: python -m mujoco.viewer --mjcf {args.export}")
    return 0
