"""Fuzzing campaign of the Python targets (``docs/fuzzing.md``).

    python fuzz/python/fuzz.py list
    python fuzz/python/fuzz.py seed [TARGET ...]      # write golden-vector seeds to the corpus
    python fuzz/python/fuzz.py replay [TARGET ...]    # the committed corpus through the checks
    python fuzz/python/fuzz.py run TARGET --runs N [--engine auto|atheris|mutate]
    python fuzz/python/fuzz.py minimize TARGET        # seeds + the inputs a run kept, capped

``run`` prints one JSON object: inputs run, coverage (atheris: libFuzzer's ``cov``/``ft``),
crashes, hangs, findings by kind (``bad_frame_accepted``, ``not_canonical``,
``non_finite``, ...), known open findings, peak RSS, wall time. Exit status 1 when
anything new was found. The corpus lives in ``fuzz/corpus/<target>/`` (file name: sha1 of
the content); new inputs and crash artifacts go to ``fuzz/out/<target>/`` (not kept).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
FUZZ = HERE.parent
CORPUS = FUZZ / "corpus"
WORK = FUZZ / "out"

import engines  # noqa: E402  (after the path set-up above)

#: The longest input each target's engines make (bytes); libFuzzer's -max_len.
MAX_LEN = {"description": 16384, "candump_asc": 4096, "candump_log": 4096}
DEFAULT_MAX_LEN = 2048


def corpus_of(name: str) -> list[bytes]:
    """The committed corpus of ``name`` (sorted by file name)."""
    folder = CORPUS / name
    return [p.read_bytes() for p in sorted(folder.iterdir())] if folder.is_dir() else []


def write_corpus(name: str, items: list[bytes]) -> int:
    """Add ``items`` to ``fuzz/corpus/<name>/`` (content-named files); returns how many
    were new."""
    folder = CORPUS / name
    folder.mkdir(parents=True, exist_ok=True)
    new = 0
    for data in items:
        path = folder / hashlib.sha1(data).hexdigest()
        if not path.exists():
            path.write_bytes(data)
            new += 1
    return new


def cmd_seed(names: list[str]) -> int:
    import rust_targets
    from fuzz_targets import TARGETS

    for name in names or [*TARGETS, *rust_targets.RUST_TARGETS]:
        items = list(TARGETS[name].seeds()) if name in TARGETS else rust_targets.seeds(name)
        new = write_corpus(name, items)
        print(f"{name}: {new} new seeds, {len(corpus_of(name))} in the corpus")
    return 0


def cmd_replay(names: list[str], timeout: float) -> int:
    from fuzz_targets import TARGETS

    bad = 0
    for name in names or TARGETS:
        target = TARGETS[name]
        items = corpus_of(name)
        out = engines.Outcome()
        worker = engines._Worker(name, timeout) if target.isolated else None
        for data in items:
            kind, message = worker.run(data) if worker else engines.run_one(target, data, timeout)
            out.runs += 1
            if kind and not kind.startswith("known:"):
                out.record(kind, message, data)
        if worker is not None:
            worker.close()
        failed = len(out.crashes) + out.hangs + sum(out.findings.values())
        bad += failed
        print(f"{name}: {out.runs} corpus inputs, {failed} failing {out.crashes[:1]}")
    return 1 if bad else 0


_COV = re.compile(rb"cov: (\d+) ft: (\d+)")
_DONE = re.compile(rb"Done (\d+) runs in (\d+) second")


def _atheris_once(name: str, runs: int, timeout: float, max_len: int, seed: int) -> dict:
    """One atheris process: until ``runs`` inputs are done or it stops on a finding."""
    work = WORK / name
    (work / "corpus").mkdir(parents=True, exist_ok=True)
    (work / "artifacts").mkdir(parents=True, exist_ok=True)
    stats = work / "stats.json"
    stats.unlink(missing_ok=True)
    argv = [
        f"-runs={runs}", f"-max_len={max_len}", "-rss_limit_mb=2048", "-print_final_stats=1",
        f"-seed={seed}", f"-artifact_prefix={work / 'artifacts'}/", str(work / "corpus"),
        str(CORPUS / name),
    ]  # fmt: skip
    proc = subprocess.run(
        [sys.executable, str(HERE / "fuzz.py"), "_atheris", name, str(stats), str(timeout),
         "--", *argv],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, check=False,
    )  # fmt: skip
    err = proc.stdout
    (work / "last.log").write_bytes(err[-200_000:])
    counted = json.loads(stats.read_text()) if stats.exists() else {"runs": 0, "known": {}}
    done = _DONE.search(err)
    cov = _COV.findall(err)
    rss = re.search(rb"stat::peak_rss_mb:\s*(\d+)", err)
    result: dict[str, Any] = {
        "runs": int(done.group(1)) if done else counted["runs"],
        "cov": int(cov[-1][0]) if cov else None,
        "ft": int(cov[-1][1]) if cov else None,
        "known": counted["known"],
        "peak_rss_mb": int(rss.group(1)) if rss else None,
        "stopped": None,
    }
    if proc.returncode != 0 or not done:
        artifact = re.search(rb"Test unit written to (\S+)", err)
        text = err.decode("utf-8", "replace")
        if "ALARM: working on the last Unit" in text or "timeout-" in text:
            kind = "hang"
        elif "out-of-memory" in text:
            kind = "oom"
        else:
            m = re.search(r"^(BadFrameAccepted|NotCanonical|NonFinite|WrongCount): ", text, re.M)
            kind = {"BadFrameAccepted": "bad_frame_accepted", "NotCanonical": "not_canonical",
                    "NonFinite": "non_finite", "WrongCount": "wrong_count"}.get(
                m.group(1) if m else "", "crash")  # fmt: skip
        tail = text[text.find("=== Uncaught") :][:1500] if "=== Uncaught" in text else text[-1500:]
        result["stopped"] = {
            "kind": kind,
            "artifact": artifact.group(1).decode() if artifact else None,
            "message": tail,
        }
    return result


def run_atheris(name: str, runs: int, timeout: float, max_len: int, seed: int,
                keep_going: bool) -> dict:  # fmt: skip
    """Run ``runs`` inputs under atheris, restarting after a finding when ``keep_going``."""
    total: dict[str, Any] = {"runs": 0, "cov": None, "ft": None, "known": {}, "stopped": [],
                             "peak_rss_mb": None}  # fmt: skip
    restarts = 0
    while total["runs"] < runs and restarts < 20:
        part = _atheris_once(name, runs - total["runs"], timeout, max_len, seed + restarts)
        total["runs"] += part["runs"]
        for key in ("cov", "ft", "peak_rss_mb"):
            if part[key] is not None:
                total[key] = max(total[key] or 0, part[key])
        for k, v in part["known"].items():
            total["known"][k] = total["known"].get(k, 0) + v
        if part["stopped"] is None:
            break
        total["stopped"].append(part["stopped"])
        restarts += 1
        if not keep_going or part["runs"] == 0:
            break
    return total


def cmd_run(args: argparse.Namespace) -> int:
    from fuzz_targets import TARGETS

    name = args.target
    target = TARGETS[name]
    engine = args.engine
    if engine == "auto":
        engine = "mutate" if target.isolated else "atheris"
    max_len = args.max_len or MAX_LEN.get(name, DEFAULT_MAX_LEN)
    start = time.monotonic()
    report: dict[str, Any] = {"target": name, "engine": engine, "requested": args.runs}
    if engine == "atheris":
        got = run_atheris(name, args.runs, args.timeout, max_len, args.seed, args.keep_going)
        stops = got.pop("stopped")
        report.update(got)
        report["crashes"] = [s for s in stops if s["kind"] == "crash"]
        report["hangs"] = sum(s["kind"] == "hang" for s in stops)
        report["findings"] = {}
        for s in stops:
            if s["kind"] not in ("crash", "hang"):
                report["findings"][s["kind"]] = report["findings"].get(s["kind"], 0) + 1
    else:

        def progress(k: int) -> None:
            print(f"{name}: {k} inputs", file=sys.stderr, flush=True)

        out = engines.run_mutations(target, corpus_of(name), args.runs, seed=args.seed,
                                    timeout=args.timeout, max_len=max_len,
                                    progress=progress)  # fmt: skip
        report.update(runs=out.runs, cov=None, ft=None, known=dict(out.known),
                      crashes=out.crashes[:20], hangs=out.hangs, findings=dict(out.findings),
                      peak_rss_mb=resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss // 1024
                      if target.isolated else
                      resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024)  # fmt: skip
        work = WORK / name / "artifacts"
        for data in out.reproducers:
            work.mkdir(parents=True, exist_ok=True)
            (work / f"input-{hashlib.sha1(data).hexdigest()}").write_bytes(data)
    report["wall_s"] = round(time.monotonic() - start, 1)
    print(json.dumps(report))
    new = len(report["crashes"]) + report["hangs"] + sum(report["findings"].values())
    return 1 if new else 0


def cmd_minimize(name: str, most: int = 300) -> int:
    """Fold the inputs a campaign kept into the committed corpus: the golden-vector seeds,
    plus the inputs libFuzzer wrote to ``fuzz/out/<name>/corpus`` (each added a coverage
    feature when it was found), smallest first, up to ``most`` files in all."""
    from fuzz_targets import TARGETS

    seeds = list(TARGETS[name].seeds())
    found = sorted(
        (p.read_bytes() for p in (WORK / name / "corpus").glob("*")), key=lambda d: (len(d), d)
    )
    keep = seeds + found[: max(0, most - len(seeds))]
    folder = CORPUS / name
    for p in folder.iterdir():
        p.unlink()
    write_corpus(name, keep)
    items = corpus_of(name)
    print(f"{name}: {len(items)} inputs ({len(found)} found), {sum(map(len, items))} bytes")
    return 0


def cmd_table(paths: list[str]) -> int:
    """A Markdown table of the JSON lines in ``paths`` (one line per target run)."""
    print(
        "| target | engine | inputs run | coverage (cov / ft) | crashes | hangs | "
        "bad frames accepted | other findings | known open | peak RSS MB | wall s |"
    )
    print("|---|---|---:|---|---:|---:|---:|---|---|---:|---:|")
    lines = [line for path in paths for line in Path(path).read_text().splitlines()]
    for line in lines:
        r = json.loads(line)
        cov = f"{r['cov']} / {r['ft']}" if r.get("cov") is not None else "n/a"
        findings = dict(r["findings"])
        bad = findings.pop("bad_frame_accepted", 0)
        other = ", ".join(f"{k} {v}" for k, v in findings.items()) or "0"
        known = ", ".join(f"{k} {v}" for k, v in r["known"].items()) or "-"
        print(
            f"| {r['target']} | {r['engine']} | {r['runs']:,} | {cov} | {len(r['crashes'])} | "
            f"{r['hangs']} | {bad} | {other} | {known} | {r['peak_rss_mb']} | {r['wall_s']} |"
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["_worker"]:
        engines.worker_main(argv[1], float(argv[2]))
        return 0
    if argv[:1] == ["_atheris"]:
        engines.atheris_main(argv[1], argv[2], float(argv[3]), argv[5:])
        return 0
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    sub.add_parser("list")
    for cmd in ("seed", "replay"):
        p = sub.add_parser(cmd)
        p.add_argument("targets", nargs="*")
        p.add_argument("--timeout", type=float, default=10.0)
    p = sub.add_parser("run")
    p.add_argument("target")
    p.add_argument("--runs", type=int, default=1_000_000)
    p.add_argument("--engine", choices=("auto", "atheris", "mutate"), default="auto")
    p.add_argument("--timeout", type=float, default=10.0, help="per input [s]")
    p.add_argument("--max-len", type=int, default=0)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--keep-going", action="store_true", help="restart after a finding")
    p = sub.add_parser("rust", help="run a Rust target (cargo +nightly fuzz)")
    p.add_argument("target")
    p.add_argument("--runs", type=int, default=1_000_000)
    p.add_argument("--timeout", type=float, default=10.0, help="per input [s]")
    p.add_argument("--seed", type=int, default=1)
    p = sub.add_parser("minimize")
    p.add_argument("target")
    p = sub.add_parser("table", help="the results of a campaign (JSON lines) as a table")
    p.add_argument("results", nargs="+")
    args = parser.parse_args(argv)
    if args.cmd == "rust":
        import rust_targets

        start = time.monotonic()
        report = rust_targets.run(args.target, args.runs, args.timeout, args.seed)
        report["wall_s"] = round(time.monotonic() - start, 1)
        print(json.dumps(report))
        return 1 if report["crashes"] or report["hangs"] or report["findings"] else 0
    if args.cmd == "table":
        return cmd_table(args.results)
    if args.cmd == "list":
        from fuzz_targets import TARGETS

        for name, t in TARGETS.items():
            print(f"{name:18} {'isolated ' if t.isolated else ''}{t.about}")
        return 0
    if args.cmd == "seed":
        return cmd_seed(args.targets)
    if args.cmd == "replay":
        return cmd_replay(args.targets, args.timeout)
    if args.cmd == "minimize":
        return cmd_minimize(args.target)
    return cmd_run(args)


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    sys.exit(main())
