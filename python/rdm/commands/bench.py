"""``rdm bench``: measure the real-time core against its budgets and against peers.

Pins BLAS/OpenMP threads to 1 *before* numpy is imported (when this module is the first
to load numpy, as from the ``rdm`` console script); the report says whether that held.
"""

from __future__ import annotations

import os
import sys

_NUMPY_WAS_LOADED = "numpy" in sys.modules
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

import argparse  # noqa: E402

from rdm.bench.runner import run_benchmarks  # noqa: E402  (after the thread pinning)
from rdm.commands.arg_types import positive_int  # noqa: E402
from rdm.commands.output import output_file_or_stdout  # noqa: E402


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``rdm bench``."""
    parser.add_argument(
        "--quick", action="store_true", help="about 10x fewer iterations than the full run"
    )
    parser.add_argument(
        "--json",
        nargs="?",
        const="-",
        default=None,
        type=output_file_or_stdout,  # checked while parsing: before the benchmarks run
        metavar="FILE",
        help="also write the figures as JSON to FILE (stdout if FILE is omitted)",
    )
    parser.add_argument(
        "--iterations",
        type=positive_int,
        default=None,
        metavar="N",
        help="iterations of every measurement (peers: at most N); default per case",
    )
    parser.add_argument(
        "--only",
        action="append",
        default=None,
        metavar="CASE",
        help="run only this case (group such as 'lqi' or measurement such as "
        "'lqi_warm_rust'); repeatable",
    )


def run(args: argparse.Namespace) -> int:
    """Run the benchmarks, print the report (stdout, or stderr when JSON goes to stdout)."""
    from rdm.bench.report import format_text, write_json

    command = "rdm bench" + "".join(
        [
            " --quick" if args.quick else "",
            f" --iterations {args.iterations}" if args.iterations is not None else "",
            "".join(f" --only {c}" for c in args.only or []),
            f" --json {args.json}" if args.json not in (None, "-") else "",
            " --json" if args.json == "-" else "",
        ]
    )
    try:
        doc = run_benchmarks(
            only=args.only,
            iterations=args.iterations,
            quick=args.quick,
            command=command,
            blas_pinned=not _NUMPY_WAS_LOADED,
        )
    except ValueError as exc:
        print(f"rdm bench: {exc}", file=sys.stderr)
        return 2
    text = format_text(doc)
    print(text, file=sys.stderr if args.json == "-" else sys.stdout)
    if args.json is not None:
        try:
            write_json(doc, args.json)
        except (OSError, ValueError) as exc:  # a full disk, a link planted since the check
            print(f"rdm bench: --json {args.json!r}: {exc}", file=sys.stderr)
            return 2
    return 0
