"""Two source trees' hover stacks run alternately in the same minutes (A/B): the machine's
speed drifts by 1.5x within an hour (hypervisor steal, neighbours), so only runs taken side
by side compare two trees.

usage: python scripts/lockstep_ab.py TREE_A TREE_B [PAIRS=10] [SECONDS=4]
Each tree must hold ``python/rdm`` with its extension built (``_rdm.abi3.so``). Every run is
a fresh process: ``build_stack`` of the hover scenario (seed 0, in-process wires, logs in a
temporary folder) and ``loop.run(SECONDS)`` from power-on, as ``rdm bench --only
lockstep``. Prints each pair and the medians of simulated s per wall s and per CPU s.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys

RUN = """
import tempfile, time
import numpy as np
from rdm.scenarios.common import sim_stack_options
from rdm.scenarios.hover import HOVER_Z, make_script
from rdm.scenarios.stack import build_stack
T = {seconds}
opts = sim_stack_options(0, "inproc", speed=None)
with tempfile.TemporaryDirectory() as base:
    st = build_stack("ab", base, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))
    c0, w0 = time.process_time(), time.perf_counter()
    st.loop.run(T)
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    st.close()
print(T / wall, T / cpu)
"""


def run(tree: str, seconds: float) -> tuple[float, float]:
    env = dict(os.environ, PYTHONPATH=os.path.join(tree, "python"), OPENBLAS_NUM_THREADS="1")
    out = subprocess.run(
        [sys.executable, "-c", RUN.format(seconds=seconds)],
        env=env,
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    return float(out[0]), float(out[1])


def main() -> None:
    a, b = sys.argv[1], sys.argv[2]
    pairs = int(sys.argv[3]) if len(sys.argv) > 3 else 10
    seconds = float(sys.argv[4]) if len(sys.argv) > 4 else 4.0
    results: dict[str, list[tuple[float, float]]] = {a: [], b: []}
    for i in range(pairs):
        for tree in (a, b):
            results[tree].append(run(tree, seconds))
        (wa, ca), (wb, cb) = results[a][-1], results[b][-1]
        print(f"pair {i + 1}: A {wa:.2f}x ({ca:.2f} per CPU s)  B {wb:.2f}x ({cb:.2f} per CPU s)")
    for name, tree in (("A", a), ("B", b)):
        wall = statistics.median(r[0] for r in results[tree])
        cpu = statistics.median(r[1] for r in results[tree])
        print(f"{name} {tree}: median {wall:.2f}x real time, {cpu:.2f} simulated s per CPU s")
    ratio = statistics.median(rb[0] / ra[0] for ra, rb in zip(results[a], results[b], strict=True))
    print(f"B / A per pair (wall), median: {ratio:.3f}")


if __name__ == "__main__":
    main()
