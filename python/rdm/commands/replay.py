"""``rdm replay RUN``: feed a flight recording through a fresh onboard node and compare the
bytes it writes with the recorded ones (docs/onboard.md, "Flight recorder and replay").

Examples::

    rdm replay runs/onboard-20260101T120000Z
    rdm replay runs/hover-seed0 --json      # a run folder that holds onboard/

Exit 0 when every written byte is the same, 1 at the first difference (its link, byte
offset and time are printed), 2 when the recording cannot be read or cannot be replayed
exactly (one line: a rotated recording names its first segment kept). The node is built from
the robot description and configuration copies inside the recording; a note on stderr says
when the files they were copied from changed or moved since (the copies are used).
"""

from __future__ import annotations

import argparse
import json
import sys


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", help="the recording folder (rdm onboard --record DIR)")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")


def _line(report: dict) -> str:
    if report["identical"]:
        sizes = ", ".join(f"{n} {s['recorded_bytes']} B" for n, s in report["streams"].items())
        head = "identical"
    else:
        parts = []
        for n, s in report["streams"].items():
            d = s["first_difference"]
            if d is None:
                continue
            t = d["recorded_time_s"] if d["recorded_time_s"] is not None else d["replayed_time_s"]
            when = "past the end" if t is None else f"at {t:.6f} s"
            parts.append(
                f"{n} byte {d['offset']} {when} (recorded {d['recorded']}, replayed "
                f"{d['replayed']}; {s['recorded_bytes']} B recorded, {s['replayed_bytes']} B "
                "replayed)"
            )
        head, sizes = "DIFFERENT", "; ".join(parts)
    cut = " (the recording ends early: compared up to its end)" if report["truncated"] else ""
    return (
        f"rdm replay: {head}: {report['ticks']} ticks, {report['calls']} inputs, "
        f"{report['segments']} segment(s); {sizes}{cut}"
    )


def run(args: argparse.Namespace) -> int:
    from rdm.nodes.flight_replay import ReplayError, replay

    try:
        report = replay(args.run)
    except (ReplayError, OSError, ValueError) as exc:
        print(f"rdm replay: {exc}", file=sys.stderr)
        return 2
    for note in report["notes"]:
        print(f"rdm replay: note: {note}", file=sys.stderr, flush=True)
    print(json.dumps(report, indent=2) if args.json else _line(report), flush=True)
    return 0 if report["identical"] else 1
