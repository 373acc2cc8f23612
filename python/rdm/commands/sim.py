"""``rdm sim``: run a paper experiment on the simulated robot with every byte on its wire."""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
from contextlib import nullcontext, suppress
from pathlib import Path
from typing import TYPE_CHECKING

from rdm.commands.arg_types import positive_finite, positive_int, seed
from rdm.commands.live import add_live_arguments, open_live
from rdm.commands.output import json_text

if TYPE_CHECKING:
    from rdm.sim.run_folder import RunFolder


def _speed(text: str) -> float | None:
    if text == "fast":
        return None
    if text == "realtime":
        return 1.0
    try:
        v = float(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: fast, realtime or a factor") from exc
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"{text!r} must be finite and > 0")
    return v


def _servo_lead(text: str) -> float:
    from rdm.nodes.onboard_config import check_servo_lead

    try:
        return check_servo_lead(float(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"--servo-lead {text!r}: {exc}") from exc


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from rdm.scenarios import DEFAULT_SCENARIO, SCENARIOS

    parser.add_argument(
        "scenario",
        nargs="?",
        default=DEFAULT_SCENARIO,
        choices=[*sorted(SCENARIOS), "all"],
        help=f"default {DEFAULT_SCENARIO}; all: every scenario (with --seeds)",
    )
    parser.add_argument("--duration", type=positive_finite, default=None, help="simulated seconds")
    parser.add_argument("--seed", type=seed, default=0)
    parser.add_argument("--speed", type=_speed, default=None, help="fast | realtime | FACTOR")
    parser.add_argument("--uart", choices=("inproc", "pty"), default="inproc")
    parser.add_argument(
        "--servo-lead",
        type=_servo_lead,
        default=None,
        help="send planned servo goals S s ahead (default: the scenario's, 0.05 s identified "
        "on the simulated servos; 0 = the paper's feed-forward; docs/scenarios.md)",
    )
    parser.add_argument("--out", default="runs", help="base folder of the run folder")
    parser.add_argument(
        "--replace",
        action="store_true",
        help="remove the content of an existing run folder first (else a non-empty run "
        "folder is refused); symbolic links in it are removed, never followed",
    )
    parser.add_argument(
        "--robot",
        default=None,
        help="hover only: the robot, a shipped name or the path of a robot TOML (any rotor "
        "count 1..8; docs/onboard.md)",
    )
    parser.add_argument(
        "--fault",
        default=None,
        help="mission only: inject one fault once the robot hovers (heartbeat-loss, "
        "mocap-loss, uart-cut, low-battery, bad-adc-scale, uart-noise-1e-4, uart-noise-1e-3, "
        "battery-sag, battery-sag-0.5, battery-sag-0.3, imu-spikes, dead-esc, "
        "can-loss-1e-2, can-loss-1e-1, can-bus-off, "
        "neuron-reset) or "
        "once perched (foot-sensor-loss, stuck-servo, "
        "infeasible-qp); with --seeds "
        "also all: the fault campaign; docs/flying.md",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="mission only: take off, go to a point and land (no perch); 22 s by default",
    )
    parser.add_argument(
        "--seeds",
        type=positive_int,
        default=None,
        help="run seeds SEED..SEED+N-1 and report every metric as a distribution (median, "
        "p10..p90, passed runs); writes OUT/sweep-SCENARIO.json (docs/scenarios.md)",
    )
    parser.add_argument(
        "--randomize",
        type=positive_int,
        default=None,
        metavar="N",
        help="perching-hanging only: N runs over randomized conditions (friction, mass, CoG, "
        "servo stiffness, mocap latency and noise, battery; seeds SEED..SEED+N-1): success rate, "
        "margins, OUT/robustness-perching.json and .png (docs/scenarios.md)",
    )
    parser.add_argument(
        "--workers",
        type=positive_int,
        default=None,
        help="with --seeds: processes running seeds at once (default: cores)",
    )
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.add_argument(
        "--record-onboard",
        action="store_true",
        help="record the onboard node into the run folder's onboard/ (its port bytes and "
        "inputs, as rdm onboard --record does): rdm replay RUN reproduces its output bytes",
    )
    add_live_arguments(parser, "rdm sim")
    parser.add_argument(
        "--wire-mcap",
        action="store_true",
        help="also write wire.mcap: every CAN, UART and Leptrino message at the time it crossed "
        "its wire (decoded after the run, ~10 s per 40 simulated s; rdm decode RUN --mcap)",
    )


def _write_wire_mcap(folder: RunFolder) -> bool:
    """``wire.mcap`` of the run (``rdm decode RUN --mcap``); false, reported, on failure."""
    from rdm.sim.wire_mcap import WireMcapError, run_captures, write_wire_mcap

    try:
        report = write_wire_mcap(run_captures(folder.root), folder.wire_mcap)
    except (WireMcapError, OSError) as exc:
        print(f"rdm sim: wire.mcap could not be written: {exc}", file=sys.stderr)
        return False
    for line in report.warnings():
        print(f"rdm sim: wire.mcap: {line}", file=sys.stderr)
    print(report.summary(), file=sys.stderr)
    return True


#: Exit code of a run stopped by Ctrl-C: what a shell reports for SIGINT (128 + 2).
INTERRUPTED_EXIT = 130


def run(args: argparse.Namespace) -> int:
    """Run the scenario into its run folder; exit 0 when every metric passed, 1 when one
    failed, 2 on bad input, :data:`INTERRUPTED_EXIT` on Ctrl-C (the folder then keeps its
    INCOMPLETE marker with the reason)."""
    from rdm.sim.run_folder import RunFolderError, run_folders

    with run_folders(replace=args.replace) as created:
        try:
            return _run(args)
        except RunFolderError as exc:
            print(f"rdm sim: {exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            with suppress(ValueError):  # (only the main thread may set a handler)
                signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C: no traceback
            reason = "interrupted by Ctrl-C (SIGINT)"
            for folder in created:
                with suppress(OSError):
                    folder.mark_incomplete(reason)
            where = f"; {', '.join(str(f.root) for f in created)} marked INCOMPLETE"
            print(f"\nrdm sim: {reason}{where if created else ''}", file=sys.stderr)
            return INTERRUPTED_EXIT


def _run(args: argparse.Namespace) -> int:
    from rdm.scenarios import SCENARIOS
    from rdm.scenarios.common import servo_lead

    if args.scenario == "all" and args.seeds is None:
        print("rdm sim: scenario 'all' needs --seeds N", file=sys.stderr)
        return 2
    if args.workers is not None and args.seeds is None and args.randomize is None:
        print("rdm sim: --workers is for --seeds or --randomize", file=sys.stderr)
        return 2
    for flag, on in (("--live", args.live), ("--record-onboard", args.record_onboard)):
        if on and (args.seeds is not None or args.randomize is not None):
            print(f"rdm sim: {flag} is for one run (no --seeds or --randomize)", file=sys.stderr)
            return 2
    if args.randomize is not None:
        return _randomized(args)
    if args.seeds is not None:
        return _sweep(args)
    sc = SCENARIOS[args.scenario]
    duration = sc.default_duration if args.duration is None else args.duration
    if args.quick and sc.name != "mission":
        print("rdm sim: --quick is for the mission scenario", file=sys.stderr)
        return 2
    if not duration > 0:
        print("rdm sim: --duration must be > 0", file=sys.stderr)
        return 2
    try:  # the run folder's parent: a clear error now, not a traceback after the start-up
        Path(args.out).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        print(f"rdm sim: --out {args.out!r}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    extra = {}
    if args.fault is not None:
        from rdm.scenarios.mission import FAULTS

        if sc.name != "mission" or args.fault not in FAULTS:
            print(
                f"rdm sim: --fault {args.fault!r}: the mission scenario's faults are "
                f"{', '.join(FAULTS)}",
                file=sys.stderr,
            )
            return 2
        extra["fault"] = args.fault
    if args.robot is not None:
        from rdm.model import Robot

        if sc.name != "hover":
            print("rdm sim: --robot is for the hover scenario", file=sys.stderr)
            return 2
        try:  # a clear error now, not a traceback from the stack builder
            Robot.load(args.robot)
        except ValueError as exc:
            print(f"rdm sim: --robot {args.robot!r}: {exc}", file=sys.stderr)
            return 2
        extra["robot"] = args.robot
    if args.quick:
        from rdm.scenarios.mission import QUICK_DURATION

        extra["quick"] = True
        duration = QUICK_DURATION if args.duration is None else args.duration
    # no --servo-lead: each scenario's own default (docs/scenarios.md)
    lead = nullcontext() if args.servo_lead is None else servo_lead(args.servo_lead)
    live = open_live(args, "rdm sim")
    if live is False:
        return 2
    try:
        return _run_one(args, sc, duration, extra, lead, live)
    finally:
        if live is not None:
            live.close()


def _run_one(args: argparse.Namespace, sc, duration: float, extra: dict, lead, live) -> int:
    """One scenario run (``live``: the Foxglove publisher of ``--live``, or None)."""
    from rdm.scenarios.common import progress_to, record_onboard
    from rdm.sim import format_metrics_table
    from rdm.sim.live import live_to
    from rdm.sim.plot_worker import plots_in_background

    print(f"rdm sim {sc.name}: {sc.description}", file=sys.stderr)
    # the PNG figures are drawn by a worker process on the other core (docs/sim.md
    # "Start-up and figures"), waited for before the run folder is named
    with plots_in_background() as worker:
        with (
            lead,
            progress_to(sys.stderr, duration),
            nullcontext() if live is None else live_to(live),
            record_onboard() if args.record_onboard else nullcontext(),
        ):
            result = sc.run(
                args.out,
                duration=duration,
                seed=args.seed,
                uart=args.uart,
                speed=args.speed,
                **extra,
            )
        if args.json:
            print(json_text(json.loads(result.stack.folder.summary_json.read_text())))
        else:
            print(format_metrics_table(result.metrics), flush=True)
        # while the worker draws: the wire log on this core
        if args.wire_mcap and not _write_wire_mcap(result.stack.folder):
            return 1
        try:
            if worker is not None:
                worker.wait()
        except Exception as exc:  # reported; the run folder's data is already written
            print(f"rdm sim: a figure could not be drawn: {exc!r}", file=sys.stderr)
            return 1
    if not args.json:
        f = result.facts
        print(f"run folder: {result.folder}")
        if args.record_onboard:
            print(f"onboard recording: {result.folder / 'onboard'} (rdm replay {result.folder})")
        print(
            f"{f['simulated_s']:g} simulated s in {f['wall_s']:.1f} wall s "
            f"({f['sim_s_per_wall_s']:.2f} simulated s per wall s)"
        )
    return 0 if result.all_passed else 1


def _sweep(args: argparse.Namespace) -> int:
    """``--seeds N``: each scenario over seeds SEED..SEED+N-1 on a process pool; the
    distribution table (or JSON) and ``OUT/sweep-SCENARIO.json``; with ``--fault KIND|all``
    (mission) the fault campaign and ``OUT/faults-mission.json``. Exit 0 when every run
    completed with every metric passing (campaign: every run safe), 1 otherwise, 2 on bad
    input."""
    from concurrent.futures import ProcessPoolExecutor

    from rdm.scenarios import SCENARIOS

    if args.wire_mcap or args.servo_lead is not None:
        print("rdm sim: --seeds takes no --wire-mcap or --servo-lead", file=sys.stderr)
        return 2
    if (args.fault is not None or args.quick) and args.scenario != "mission":
        print("rdm sim: --fault and --quick are for the mission scenario", file=sys.stderr)
        return 2
    faults = None
    if args.fault is not None:
        from rdm.scenarios.mission import FAULTS

        if args.fault != "all" and args.fault not in FAULTS:
            print(
                f"rdm sim: --fault {args.fault!r}: all or one of {', '.join(FAULTS)}",
                file=sys.stderr,
            )
            return 2
        faults = list(FAULTS) if args.fault == "all" else [args.fault]
    names = sorted(SCENARIOS) if args.scenario == "all" else [args.scenario]
    seeds = list(range(args.seed, args.seed + args.seeds))
    try:
        Path(args.out).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        print(f"rdm sim: --out {args.out!r}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    with ProcessPoolExecutor(max_workers=args.workers) as ex:
        if faults is not None:
            return _campaign(args, faults, seeds, ex)
        return _distributions(args, names, seeds, ex)


def _progress(label: str):
    def report(o) -> None:
        state = "done" if o.summary is not None else f"FAILED ({o.error})"
        print(f"rdm sim {label}: seed {o.seed} {state}", file=sys.stderr, flush=True)

    return report


def _distributions(args: argparse.Namespace, names: list[str], seeds: list[int], ex) -> int:
    from rdm.output_files import write_atomic
    from rdm.scenarios.seed_sweep import format_report, report, sweep

    extra = {"quick": True} if args.quick else {}
    docs = []
    for name in names:
        outcomes = sweep(
            name, args.out, seeds, args.duration, extra, ex, _progress(name), args.replace
        )
        doc = report(name, outcomes)
        target = Path(args.out) / f"sweep-{name}.json"
        write_atomic(target, json.dumps(doc, indent=1, allow_nan=False) + "\n")
        docs.append(doc)
        if not args.json:
            print(format_report(doc), flush=True)
            print(f"sweep: {target}", flush=True)
    if args.json:
        print(json_text(docs[0] if len(docs) == 1 else {"sweeps": docs}))
    ok = all(d["runs_all_passed"] == len(d["seeds"]) for d in docs)
    return 0 if ok else 1


def _campaign(args: argparse.Namespace, faults: list[str], seeds: list[int], ex) -> int:
    from rdm.output_files import write_atomic
    from rdm.scenarios.fault_campaign import fault_row, fault_runs, format_campaign

    rows = []
    for fault in faults:
        outcomes = fault_runs(
            fault, args.out, seeds, ex, _progress(f"mission {fault}"), args.replace
        )
        rows.append(fault_row(fault, outcomes))
    doc = {"scenario": "mission", "seeds": seeds, "faults": rows}
    target = Path(args.out) / "faults-mission.json"
    write_atomic(target, json.dumps(doc, indent=1, allow_nan=False) + "\n")
    if args.json:
        print(json_text(doc))
    else:
        print(format_campaign(rows), flush=True)
        print(f"campaign: {target}", flush=True)
    return 0 if all(r["safe"] == r["runs"] for r in rows) else 1


def _randomized(args: argparse.Namespace) -> int:
    """``--randomize N``: the hanging-posture perching experiment (``perching-hanging``, the
    posture the robustness campaign flies) over randomized conditions; exit 0 when
    every run succeeded, 1 otherwise, 2 on bad input."""
    from concurrent.futures import ProcessPoolExecutor

    from rdm.output_files import write_atomic
    from rdm.scenarios.robustness import plot, randomized, summarize

    others = args.seeds, args.fault, args.wire_mcap or None, args.servo_lead, args.quick or None
    if args.scenario != "perching-hanging" or any(v is not None for v in others):
        print(
            "rdm sim: --randomize is for the perching-hanging scenario and takes --duration, "
            "--seed, --out, --replace, --workers, --json",
            file=sys.stderr,
        )
        return 2
    out = Path(args.out)
    try:
        (out / "robustness-perching").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        print(f"rdm sim: --out {args.out!r}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    seeds = list(range(args.seed, args.seed + args.randomize))

    def progress(run: dict) -> None:
        state = "succeeded" if run["success"] else f"failed {run.get('error') or ''}".rstrip()
        print(f"rdm sim perching-hanging --randomize: seed {run['seed']} {state}", file=sys.stderr)

    with ProcessPoolExecutor(max_workers=args.workers) as ex:
        runs = randomized(
            out / "robustness-perching", seeds, args.duration, ex, progress, args.replace
        )
    doc = summarize(runs)
    target = out / "robustness-perching.json"
    write_atomic(target, json.dumps(doc, indent=1, allow_nan=False) + "\n")
    plot(doc, out / "robustness-perching.png")
    if args.json:
        print(json_text(doc))
    else:
        print(f"perching over randomized conditions: {doc['succeeded']}/{doc['runs']} succeeded")
        for name, m in doc["margins"].items():
            if m["n"]:
                print(
                    f"  {name}: median {m['median']:.4g} (p10 {m['p10']:.4g}, p90 "
                    f"{m['p90']:.4g}, min {m['min']:.4g}, n {m['n']})"
                )
        for f in doc["failed"]:
            why = f["error"] or ", ".join(f["failed_metrics"])
            print(f"  seed {f['seed']} failed: {why}")
        print(f"robustness: {target}")
    return 0 if doc["succeeded"] == doc["runs"] else 1
