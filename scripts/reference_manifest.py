"""SHA-256 manifest of the reference runs: every scenario, two seeds, every byte it writes.

usage:
    python scripts/reference_manifest.py write [MANIFEST]   # run the scenarios, write it
    python scripts/reference_manifest.py check [MANIFEST]   # run again, compare (1: changed)

Each run is ``rdm sim SCENARIO --seed S --duration D`` (the whole chain: MuJoCo plant, Neuron
boards on CAN, Spinal on its UART, the onboard node, the Leptrino foot sensor) into a scratch
folder. The manifest holds the SHA-256 of the candump log, every UART capture and its time
index, the signals MCAP, and the summary with its wall-clock fields removed (``wall_s``,
``sim_s_per_wall_s``: they measure the machine, not the run). Plots are left out (their bytes
follow the matplotlib version). A change of any other byte is a change of behaviour: a
restructuring must keep the manifest; a change that means to alter bytes regenerates it once,
with the reason in its commit. ``tests/test_reference_manifest.py`` runs ``check``.

Durations are cut to what covers each experiment's phases in a few wall seconds (perching and
perching-hanging: take-off, fold, contact near 15 s, the first perched seconds).
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

DEFAULT = Path(__file__).resolve().parents[1] / "tests" / "data" / "reference_manifest.json"
SEEDS = (0, 1)
#: Scenario -> (simulated seconds, extra arguments).
RUNS: dict[str, tuple[float, tuple[str, ...]]] = {
    "hover": (4.0, ()),
    "flight": (6.0, ()),
    "perching": (18.0, ()),
    "perching-hanging": (18.0, ()),
    "push": (18.0, ()),
    "tracking": (18.0, ()),
    "drilling": (18.0, ()),
    "valve": (18.0, ()),
    "painting": (18.0, ()),
    "mission": (12.0, ("--quick",)),
}
#: Summary keys that measure the machine, not the run.
WALL_KEYS = ("wall_s", "sim_s_per_wall_s")


def _summary_digest(path: Path) -> str:
    data = json.loads(path.read_text())
    for key in WALL_KEYS:
        data.pop(key, None)
    text = json.dumps(data, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def digest_folder(folder: Path) -> dict[str, str]:
    """SHA-256 of every run file of ``folder`` but the plots, by path relative to it."""
    out: dict[str, str] = {}
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        rel = path.relative_to(folder).as_posix()
        if rel.startswith("plots/") or rel == "metrics.txt":
            continue  # drawn figures; metrics.txt repeats the summary's metrics as text
        if rel == "summary.json":
            out[rel] = _summary_digest(path)
        else:
            out[rel] = hashlib.sha256(path.read_bytes()).hexdigest()
    return out


def run_all(scratch: Path) -> dict[str, dict[str, str]]:
    """Run every reference run into ``scratch``; the digests by ``scenario-seedN``."""
    manifest: dict[str, dict[str, str]] = {}
    for scenario, (seconds, extra) in RUNS.items():
        for seed in SEEDS:
            cmd = [sys.executable, "-m", "rdm.cli", "sim", scenario, "--seed", str(seed)]
            name = f"{scenario}-seed{seed}"
            base = scratch / name
            cmd += ["--duration", str(seconds), "--out", str(base), *extra]
            done = subprocess.run(cmd, capture_output=True, text=True, check=False)
            folders = [p for p in base.iterdir() if (p / "summary.json").is_file()]
            if len(folders) != 1:
                raise RuntimeError(f"{name}: no run folder with a summary\n{done.stderr[-2000:]}")
            manifest[name] = digest_folder(folders[0])
    return manifest


def compare(expected: dict, actual: dict) -> list[str]:
    """Every difference as one line: a run or file missing, added or with other bytes."""
    lines = []
    for run in sorted(set(expected) | set(actual)):
        want, got = expected.get(run), actual.get(run)
        if want is None or got is None:
            lines.append(f"{run}: {'added' if want is None else 'missing'}")
            continue
        for rel in sorted(set(want) | set(got)):
            if want.get(rel) != got.get(rel):
                lines.append(f"{run}/{rel}: {want.get(rel)} != {got.get(rel)}")
    return lines


def main(argv: list[str]) -> int:
    if not argv or argv[0] not in ("write", "check"):
        print("usage: reference_manifest.py write|check [MANIFEST]", file=sys.stderr)
        return 2
    target = Path(argv[1]) if len(argv) > 1 else DEFAULT
    with tempfile.TemporaryDirectory(prefix="rdm-manifest-") as tmp:
        actual = run_all(Path(tmp))
    if argv[0] == "write":
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(json.dumps(actual, indent=1, sort_keys=True) + "\n")
        print(f"wrote {target}: {sum(len(v) for v in actual.values())} files in {len(actual)} runs")
        return 0
    diffs = compare(json.loads(target.read_text()), actual)
    for line in diffs:
        print(line)
    print(f"{len(diffs)} difference(s) against {target}")
    return 1 if diffs else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
