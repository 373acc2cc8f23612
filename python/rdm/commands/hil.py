"""``rdm hil [hover|perching]``: a scenario with the nodes as separate processes on real ports.

Examples::

    rdm hil --can socketcan:vcan0                  # kernel CAN (a vcan0, or can0 on a bench)
    rdm hil --can udp                              # no SocketCAN: UDP multicast between processes
    rdm hil --can socketcan:vcan0 --scale 0.05 --duration 5 --out runs/hil
    rdm hil perching --can udp                     # the perching scenario (contact ~14.8 s)
    rdm hil perching --quick --can udp             # 4 s fold: contact ~9 s, 11 s by default

Three processes (robot = plant + Neurons + Leptrino + mocap, Spinal, onboard PC) on a shared
scaled clock (``--scale`` simulated s per wall s), the Spinal and Leptrino UARTs on ptys. Prints
the outcome, the per-process deadline figures and the run folder; exit 0 when the outcome
passes (hover: the robot took off and holds the target; perching: perched and held the ceiling
without slip; docs/processes.md), 1 otherwise, 2 on a failed run.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from rdm.commands.arg_types import positive_finite, seed
from rdm.commands.output import json_text
from rdm.json_values import nulled

#: The pass criteria of the outcome over the last simulated second: x, y 3 cm and 5 deg (the
#: lockstep hover test's); z 12 cm (lockstep overshoots to 0.495 m around 4 s and settles
#: slowly on the Table V altitude integral: 0.095 m worst over 4-5 s).
LIMITS = {
    "max_abs_err_x_last1s": 0.03,
    "max_abs_err_y_last1s": 0.03,
    "max_abs_err_z_last1s": 0.12,
    "max_roll_pitch_deg_after_arm": 5.0,
}
#: Perching: perched, held >= 1 s after the contact transient, contact kept on every sample,
#: slip < 1 mm and the foot at the ceiling within 1 cm (tests/test_scenario_perching.py's
#: limits), the ZMP never outside the plate (margin >= 0, it touches the edge in the
#: transient), < 20 deg (the scenario's attitude limit).
PERCHING_LIMITS = {
    "slip_mm": 1.0,
    "foot_height_err_mm": 10.0,
    "max_roll_pitch_deg_perched": 20.0,
}
#: Simulated seconds of a run when --duration is not given: 2 s after the perch switch.
DEFAULT_DURATION = {"hover": 5.0, "perching": 17.0, "perching-quick": 11.0}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "scenario",
        nargs="?",
        default="hover",
        choices=("hover", "perching", "mission"),
        help="default hover; mission: rdm onboard as its own process, operated by rdm ctl "
        "(docs/flying.md)",
    )
    parser.add_argument(
        "--fault",
        default="none",
        help="mission: one fault once the robot hovers (none, heartbeat-loss, mocap-loss, "
        "uart-cut, low-battery, replayed-command, garbage-datagram) or once perched "
        "(foot-sensor-loss)",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="perching: fold in 4 s and approach from 5 cm (contact ~9 s instead of ~14.8 s); "
        "mission: take off, go to, land (no perch)",
    )
    parser.add_argument(
        "--can",
        default="socketcan:vcan0",
        help="socketcan:IFACE | udp (a fresh UDP multicast group) | udp_multicast:GROUP,port=N",
    )
    parser.add_argument(
        "--duration",
        type=positive_finite,
        default=None,
        help="simulated s (default hover 5, perching 17, perching --quick 11, mission 60, "
        "mission --quick 24)",
    )
    parser.add_argument(
        "--scale", type=positive_finite, default=0.05, help="simulated s per wall s (default 0.05)"
    )
    parser.add_argument(
        "--free-running",
        action="store_true",
        help="pure scaled wall clock: the controllers do not wait for a slow physics process",
    )
    parser.add_argument("--seed", type=seed, default=0)
    parser.add_argument("--out", default=None, help="run folder (default runs/hil-<time>)")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")


def passed(metrics: dict[str, float]) -> bool:
    """The hover outcome criteria (:data:`LIMITS`, and the robot climbed at least 20 cm)."""
    ok = all(metrics[k] < v for k, v in LIMITS.items())
    return ok and metrics["climb_m"] > 0.2


def perching_passed(metrics: dict[str, float]) -> bool:
    """The perching outcome criteria (:data:`PERCHING_LIMITS` and the comment above it);
    NaN fails."""
    ok = all(metrics[k] < v for k, v in PERCHING_LIMITS.items())
    return (
        ok
        and metrics["perched"] == 1.0
        and metrics["held_s"] >= 1.0
        and metrics["contact_kept"] == 1.0
        and metrics["min_zmp_margin_mm"] >= 0.0
    )


def run_mission(args: argparse.Namespace) -> int:
    """``rdm hil mission``: one JSON record (``--json``) or a summary; exit 0 when safe and
    the fault (if any) was detected."""
    from rdm.scenarios import hil_mission

    if args.fault not in hil_mission.FAULTS:
        print(
            f"rdm hil mission: --fault {args.fault!r}: one of {', '.join(hil_mission.FAULTS)}",
            file=sys.stderr,
        )
        return 2
    if args.duration is not None and not (args.duration > 0 and math.isfinite(args.duration)):
        print("rdm hil mission: --duration must be > 0", file=sys.stderr)
        return 2
    out = Path(args.out or "runs")
    try:
        record = hil_mission.run(
            out, fault=args.fault, seed=args.seed, duration=args.duration, quick=args.quick
        )
    except (OSError, RuntimeError, ValueError) as exc:
        print(f"rdm hil mission: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json_text(nulled(record)))
    else:
        for key in ("outcome", "safe", "fault", "fault_detected", "final_state"):
            print(f"{key}: {record[key]}")
        print(f"max tilt {record['max_tilt_deg']:.1f} deg, max duty {record['max_duty']:.4f}")
        print(f"run folder: {record['run_folder']}")
    ok = record["safe"] and record["fault_detected"] is not False
    return 0 if ok else 1


def run(args: argparse.Namespace) -> int:
    from rdm.scenarios.processes import ProcessRunError, ProcessRunOptions, run_processes
    from rdm.sim.udp_can import random_udp_spec

    if args.scenario == "mission":
        return run_mission(args)

    if args.quick and args.scenario != "perching":
        print("rdm hil: --quick is for perching", file=sys.stderr)
        return 2
    if args.duration is None:
        key = "perching-quick" if args.quick else args.scenario
        args.duration = DEFAULT_DURATION[key]
    if not (args.scale > 0 and args.duration > 0 and math.isfinite(args.duration)):
        print("rdm hil: --scale and --duration must be > 0", file=sys.stderr)
        return 2
    spec = random_udp_spec() if args.can == "udp" else args.can
    out = Path(args.out or f"runs/hil-{time.strftime('%Y%m%d-%H%M%S')}")
    opts = ProcessRunOptions(
        can=spec,
        scenario=args.scenario,
        quick=args.quick,
        duration=args.duration,
        scale=args.scale,
        seed=args.seed,
        gate=not args.free_running,
    )
    print(
        f"rdm hil {args.scenario}{' --quick' if args.quick else ''}: 3 processes on {spec}, "
        f"{args.duration:g} simulated s at scale "
        f"{args.scale:g} (~{args.duration / args.scale:.0f} wall s) -> {out}",
        file=sys.stderr,
    )
    try:
        res = run_processes(out, opts)
    except (ProcessRunError, OSError, ValueError) as exc:
        print(f"rdm hil: {exc}", file=sys.stderr)
        return 2
    ok = perching_passed(res.metrics) if args.scenario == "perching" else passed(res.metrics)
    summary = json.loads((out / "summary.json").read_text())
    summary["passed"] = ok
    if args.json:
        print(json_text(nulled(summary)))  # valid JSON: a metric that is no number is null
    else:
        for k, v in res.metrics.items():
            print(f"{k:<32} {v:9.4f}")
        for role, d in summary["deadlines"].items():
            for node, s in d.items():
                print(
                    f"{role:>8}/{node:<14} ticks {s['ticks']:6d} overruns {s['overruns']:5d} "
                    f"late max {s['max_late_ms']:8.2f} ms mean {s['mean_late_ms']:6.2f} ms"
                )
        print(
            f"achieved scale {args.duration / res.wall_s:.4f}; "
            f"wall {res.wall_s:.1f} s (+{res.startup_wall_s:.1f} s start-up); "
            f"{'PASS' if ok else 'FAIL'}; folder {out}"
        )
    return 0 if ok else 1
