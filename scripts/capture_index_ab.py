"""A/B of the captures' time index: the hover stack from power-on, 4 simulated s, with and
without the index (docs/lockstep.md "Session 13").

usage: python scripts/capture_index_ab.py [PAIRS=8]
Alternates the two builds of the stack PAIRS times and prints the wall us per simulated ms of
each, with the medians. "plain" opens the in-process UARTs without a clock (no .idx files).
"""

from __future__ import annotations

import sys
import tempfile
import time

import numpy as np

import rdm.scenarios.stack as stack_module
from rdm.scenarios.common import sim_stack_options
from rdm.scenarios.hover import HOVER_Z, make_script

_INDEXED = stack_module.open_inproc_uart


def _plain(capture_dir, stem, ext, clock=None):
    return _INDEXED(capture_dir, stem, ext, None)


def run(indexed: bool, seconds: float = 4.0) -> float:
    """Wall us per simulated ms of ``seconds`` from power-on."""
    stack_module.open_inproc_uart = _INDEXED if indexed else _plain
    try:
        opts = sim_stack_options(0, "inproc", speed=None)
        with tempfile.TemporaryDirectory(prefix="rdm-index-ab-") as base:
            script = make_script(np.array([0.483, 0.0, HOVER_Z]))
            stack = stack_module.build_stack("ab", base, opts, script)
            try:
                t = time.perf_counter()
                stack.loop.run(seconds)
                wall = time.perf_counter() - t
            finally:
                stack.close()
    finally:
        stack_module.open_inproc_uart = _INDEXED
    return wall / (seconds * 1000.0) * 1e6


def main() -> None:
    pairs = int(sys.argv[1]) if len(sys.argv) > 1 else 8
    results: dict[bool, list[float]] = {True: [], False: []}
    for k in range(pairs):
        for indexed in (True, False) if k % 2 else (False, True):
            results[indexed].append(run(indexed))
    for indexed in (False, True):
        values = sorted(results[indexed])
        label = "indexed" if indexed else "plain"
        print(f"{label:8s} median {np.median(values):.1f} us/ms  {[round(v, 1) for v in values]}")


if __name__ == "__main__":
    main()
