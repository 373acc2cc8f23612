"""``rdm design``: reproduce Tables II/III (AMR [m^3], AMF) on a 3-D grid beside the
paper's values."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rdm.commands.arg_types import positive_finite, positive_int
from rdm.commands.output import check_output_path, json_text
from rdm.json_values import nulled


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``design``'s options."""
    parser.add_argument("--table", type=int, choices=(2, 3), default=3)
    parser.add_argument(
        "--resolution", type=positive_finite, default=0.1, help="voxel side [m] (finite, > 0)"
    )
    parser.add_argument(
        "--joint-step",
        type=positive_finite,
        default=0.12,
        help="joint grid step [rad] (finite, > 0)",
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument("--plot-dir", help="write reachable-set PNGs (like Figs. 3-4) here")
    parser.add_argument(
        "--workers", type=positive_int, default=None, help="processes (default: cores)"
    )


def run(args: argparse.Namespace) -> int:
    """Run the sweep and print ours beside the paper's values."""
    from concurrent.futures import ProcessPoolExecutor

    from rdm.planner.design import format_table, plot_results, run_table, table_json

    if args.joint_step < 0.03 or args.resolution < 0.02:
        print(
            "rdm design: --joint-step must be >= 0.03 rad and --resolution >= 0.02 m "
            "(finer grids do not fit in memory)",
            file=sys.stderr,
        )
        return 2
    png = None
    if args.plot_dir:  # the figure's folder and file checked before the sweep, not after it
        try:
            Path(args.plot_dir).mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            print(f"rdm design: --plot-dir {args.plot_dir!r}: {exc.strerror}", file=sys.stderr)
            return 2
        try:
            png = check_output_path(
                Path(args.plot_dir) / f"table{args.table}_reachability.png", "--plot-dir"
            )
        except ValueError as exc:
            print(f"rdm design: {exc}", file=sys.stderr)
            return 2
    with ProcessPoolExecutor(max_workers=args.workers) as ex:
        results = run_table(args.table, args.resolution, ex, joint_step=args.joint_step)
    if args.json:
        # valid JSON: a figure that is not finite is null
        print(json_text(nulled(table_json(args.table, results)), indent=1))
    else:
        print(format_table(args.table, results))
    if png is not None:
        try:
            plot_results(results, str(png))
        except OSError as exc:  # a full disk, a link planted since the check
            print(f"rdm design: --plot-dir: {png}: {exc}", file=sys.stderr)
            return 2
    return 0
