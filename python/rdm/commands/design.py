"""``rdm design``: reproduce Tables II/III (AMR, AMF) with the planner."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``design``'s options."""
    parser.add_argument("--table", type=int, choices=(2, 3), default=3)
    parser.add_argument("--resolution", type=float, default=0.1, help="grid step [m]")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument("--plot-dir", help="write reachable-set PNGs (like Figs. 3-4) here")
    parser.add_argument("--workers", type=int, default=None, help="processes (default: cores)")


def run(args: argparse.Namespace) -> int:
    """Run the sweep and print ours beside the paper's values."""
    from concurrent.futures import ProcessPoolExecutor

    from rdm.planner.design import format_table, plot_results, run_table

    if args.resolution <= 0:
        print("rdm design: --resolution must be positive")
        return 2
    with ProcessPoolExecutor(max_workers=args.workers) as ex:
        results = run_table(args.table, args.resolution, ex)
    if args.json:
        print(json.dumps({n: r.to_json() for n, r in results.items()}, indent=1))
    else:
        print(format_table(args.table, results))
    if args.plot_dir:
        d = Path(args.plot_dir)
        d.mkdir(parents=True, exist_ok=True)
        plot_results(results, str(d / f"table{args.table}_reachability.png"))
    return 0
