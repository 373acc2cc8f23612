"""``rdm plan``: plan an end-effector motion with the differential-kinematics planner."""

from __future__ import annotations

import argparse
import math
import sys

from rdm.commands.arg_types import accept_negative_values
from rdm.commands.output import json_text, output_file
from rdm.json_values import non_finite_paths


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``plan``'s options."""
    parser.add_argument("--robot", default="rdm", help="shipped name or TOML path (default rdm)")
    parser.add_argument(
        "--target", required=True, help="x,y,z[,roll,pitch,yaw] in the world/foot frame [m, rad]"
    )
    parser.add_argument("--mode", choices=("perched", "flight"), default="perched")
    parser.add_argument("--out", type=output_file, help="write the trajectory (.csv or .json)")
    parser.add_argument("--plot", type=output_file, help="write a PNG of the trajectory")
    accept_negative_values(parser)  # --target -0.2,0,0.5


def run(args: argparse.Namespace) -> int:
    """Plan; exit 0 if reached, 1 if unreachable, 2 on bad input."""
    from rdm.planner import plan

    try:
        target = [float(v) for v in args.target.split(",")]
        if len(target) not in (3, 6):
            raise ValueError("expected 3 or 6 comma-separated numbers")
        if not all(math.isfinite(v) for v in target):
            raise ValueError(f"{args.target!r}: every number must be finite")
    except ValueError as e:
        print(f"rdm plan: --target: {e}", file=sys.stderr)
        return 2
    try:
        traj = plan(args.robot, target, mode=args.mode)
    except (ValueError, OSError) as e:  # a robot file or setup refused (RdmError: a ValueError)
        print(f"rdm plan: {e}", file=sys.stderr)
        return 2
    summary = {
        "reached": traj.reached,
        "blocking": traj.blocking,
        "steps": traj.steps,
        "final_error_m": traj.final_error,
        "final_q": [round(v, 4) for v in traj.zeta[-1][6:]],
    }
    bad = non_finite_paths(summary)
    if bad:
        print(
            f"rdm plan: the plan to --target {args.target} is not finite ({', '.join(bad)}); "
            "is the target within reach of the robot?",
            file=sys.stderr,
        )
        return 1
    for option, path, write in (("--out", args.out, traj.save), ("--plot", args.plot, traj.plot)):
        if path is None:
            continue
        try:
            write(path)
        except (OSError, ValueError) as e:  # a full disk, a link planted since the check
            print(f"rdm plan: {option} {str(path)!r}: {e}", file=sys.stderr)
            return 2
    print(json_text(summary))
    return 0 if traj.reached else 1
