"""LQI synthesis per call, two builds of the extension in one process (alternating rounds).

usage: python scripts/lqi_synthesis_ab.py BASE.so NEW.so [ROUNDS=40] [SIMULATED_MS=8000]
Records the (mass, inertia, allocation) of every synthesis of a hover lockstep run (this
tree), then replays the sequence through a fresh ``LqiSynthesizer.synthesize`` of each
extension (copies of ``_rdm.abi3.so``, e.g. main's and this branch's), alternating; prints
min / median us per call and the median of the per-round ratios, and checks that both give
the same bytes (k, p, gains, report).
"""

from __future__ import annotations

import importlib.util
import statistics
import sys
import tempfile
import time

import numpy as np

from rdm.bench.lockstep import _build
from rdm.control.lqi import LqiSynthesizer


def _load(path: str):
    spec = importlib.util.spec_from_file_location("_rdm", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _record(ms: int) -> list[tuple[float, np.ndarray, np.ndarray]]:
    calls = []
    plain = LqiSynthesizer.synthesize_wire

    def recording(self, mass, inertia, allocation):
        calls.append((float(mass), np.array(inertia), np.array(allocation)))
        return plain(self, mass, inertia, allocation)

    LqiSynthesizer.synthesize_wire = recording
    try:
        with tempfile.TemporaryDirectory() as base:
            stack = _build(base, profile=False)
            stack.loop.run_ticks(ms)
            stack.close()
    finally:
        LqiSynthesizer.synthesize_wire = plain
    return calls


def _replay(module, calls) -> tuple[float, list]:
    synthesizer = module.LqiSynthesizer(None, None, True, None)
    out = []
    t0 = time.thread_time()
    for mass, inertia, allocation in calls:
        out.append(synthesizer.synthesize(mass, inertia, allocation))
    return (time.thread_time() - t0) / len(calls) * 1e6, out


def _key(d: dict) -> tuple:
    return (d["k"].tobytes(), d["p"].tobytes(), d["gains"].tobytes(), sorted(d["report"].items()))


def main() -> None:
    base, new = _load(sys.argv[1]), _load(sys.argv[2])
    rounds = int(sys.argv[3]) if len(sys.argv) > 3 else 40
    calls = _record(int(sys.argv[4]) if len(sys.argv) > 4 else 8000)
    times: dict[str, list[float]] = {"base": [], "new": []}
    for k in range(rounds):
        order = (("base", base), ("new", new)) if k % 2 == 0 else (("new", new), ("base", base))
        outs = {}
        for name, module in order:
            spent, outs[name] = _replay(module, calls)
            times[name].append(spent)
        same = [_key(a) == _key(b) for a, b in zip(outs["base"], outs["new"], strict=True)]
        if not all(same):
            raise SystemExit(f"round {k}: {same.count(False)} calls differ")
    for name, v in times.items():
        print(f"{name}: min {min(v):.1f} median {statistics.median(v):.1f} us per call")
    ratios = [b / a for a, b in zip(times["base"], times["new"], strict=True)]
    print(f"{len(calls)} calls, all equal; new/base ratio median {statistics.median(ratios):.3f}")


if __name__ == "__main__":
    main()
