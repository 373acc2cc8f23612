"""``rdm config``: the onboard node's configuration files (docs/onboard.md "Configuration
files").

Examples::

    rdm config example > robot.toml      # the shipped example: every field at its default
    rdm config check robot.toml          # the resolved configuration as JSON, exit 0
    rdm config check robot.toml --robot rcm
    rdm config deploy deploy/            # the systemd unit and udev rules to edit and install

``check`` reads the file as ``rdm onboard --config FILE`` does, resolves it for the robot
(the servo map from the robot's CAN wiring when the file gives none) and prints one JSON
object: ``file``, ``robot``, ``config`` (every field of ``OnboardConfig``) and ``ports``. A
file that cannot be used prints one line naming the file, the dotted field and the rule it
breaks, and exits 2.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from rdm.json_values import non_finite_paths


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Sub-commands of ``rdm config``."""
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    check = sub.add_parser(
        "check", help="check an onboard configuration file and print it resolved, as JSON"
    )
    check.add_argument("file", help="the TOML file (rdm onboard --config FILE)")
    check.add_argument(
        "--robot",
        default="rdm",
        help="shipped robot (rdm, the default, or rcm) or the path of a robot TOML (its urdf "
        "key names the URDF beside it)",
    )
    sub.add_parser("example", help="print the shipped example file (every default)")
    deploy = sub.add_parser(
        "deploy",
        help="write the shipped systemd unit and udev rules into DIR (docs/onboard.md "
        '"Deploying on the robot"); existing files are never overwritten',
    )
    deploy.add_argument("dir", help="the folder to write them into (made if missing)")


def run(args: argparse.Namespace) -> int:
    """Run ``rdm config ACTION``; exit 0, or 2 with one line on stderr."""
    from rdm.nodes.onboard_config_file import EXAMPLE_FILE

    if args.action == "example":
        sys.stdout.write(EXAMPLE_FILE.read_text(encoding="utf-8"))
        return 0
    if args.action == "deploy":
        return _deploy(Path(args.dir))
    from rdm.model import robot_source
    from rdm.nodes.onboard_config_file import (
        config_json,
        load_onboard_file,
        resolve_for_robot,
    )

    try:
        loaded = load_onboard_file(args.file)
        robot = robot_source(args.robot).robot()
        config = resolve_for_robot(loaded, robot)
    except ValueError as exc:  # ConfigFileError names the file; a robot name names itself
        print(f"rdm config: {exc}", file=sys.stderr)
        return 2
    out = {
        "file": str(loaded.path),
        "robot": args.robot,
        "config": config_json(config),
        "ports": dataclasses.asdict(loaded.ports),
    }
    bad = non_finite_paths(out)
    if bad:  # the loader refuses non-finite numbers; this guards the JSON promise
        print(f"rdm config: non-finite values at {', '.join(bad)}", file=sys.stderr)
        return 2
    print(json.dumps(out, indent=2, allow_nan=False))
    return 0


#: The shipped deployment files (``python/rdm/data/deploy``).
DEPLOY_FILES = ("rdm-onboard.service", "60-rdm-serial.rules")


def _deploy(folder: Path) -> int:
    """Copy the deployment files into ``folder``; exit 2 naming the file when one exists or
    cannot be written (nothing is overwritten)."""
    source = Path(__file__).resolve().parent.parent / "data" / "deploy"
    targets = [folder / name for name in DEPLOY_FILES]
    for target in targets:
        if target.exists() or target.is_symlink():
            print(f"rdm config deploy: {target} exists; not overwritten", file=sys.stderr)
            return 2
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for name, target in zip(DEPLOY_FILES, targets, strict=True):
            with open(target, "x", encoding="utf-8") as out:
                out.write((source / name).read_text(encoding="utf-8"))
    except OSError as exc:
        print(f"rdm config deploy: {exc.filename or folder}: {exc.strerror}", file=sys.stderr)
        return 2
    for target in targets:
        print(target)
    return 0
