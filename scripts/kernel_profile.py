"""Where the time of the hover stack goes with the lockstep kernel (docs/sim.md).

usage: python scripts/kernel_profile.py [SECONDS=6] [perching FROM_S]
Builds the ``rdm sim hover`` stack (seed 0, in-process wires, logs to a temporary folder),
runs 1 simulated s, then ``SECONDS`` more with the kernel's profile mode: wall us per
simulated ms of every node on its fast path ("fast") and in Python ("py", the flush and plan
re-reads around it included), and of the physics steps, with the tick counts.
With ``perching FROM_S``: the ``rdm sim perching-hanging`` stack instead, profiled from ``FROM_S``
(e.g. ``6 perching 16``: the perched joint motion, docs/sim.md "Speed").
"""

from __future__ import annotations

import sys
import tempfile
import time

import numpy as np

from rdm.scenarios.common import sim_stack_options
from rdm.scenarios.hover import HOVER_Z, make_script
from rdm.scenarios.stack import build_stack


def main() -> None:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 6.0
    warm_up = 1.0
    if len(sys.argv) > 2 and sys.argv[2] == "perching":
        from rdm.scenarios import perching

        warm_up = float(sys.argv[3]) if len(sys.argv) > 3 else 16.0
        opts = sim_stack_options(0, "inproc", log=True, onboard=perching.onboard_config())
        script = perching.PerchingScript(perching.PERCHED_MOTION)
    else:
        opts = sim_stack_options(0, "inproc", speed=None)
        script = make_script(np.array([0.483, 0.0, HOVER_Z]))
    with tempfile.TemporaryDirectory(prefix="rdm-kernel-profile-") as base:
        stack = build_stack("profile", base, opts, script)
        try:
            stack.loop.run(warm_up)
            kernel = stack.loop.kernel
            kernel.profile = True
            before = kernel.stats()
            cpu0, wall0 = time.process_time(), time.perf_counter()
            stack.loop.run(seconds)
            cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
            stats = kernel.stats()
            names = [node.name for node in stack.loop.nodes]
        finally:
            stack.close()
    ms = seconds * 1000.0
    rows = [("physics", stats["physics_ns"] / ms / 1e3, round(ms))]
    for i, name in enumerate(names):
        for path, ns, count in (("fast", "fast_ns", "fast"), ("py", "python_ns", "python")):
            ticks = stats[count][i] - before[count][i]
            rows.append((f"{name} {path}", stats[ns][i] / ms / 1e3, ticks))
    print(
        f"{seconds / wall:.1f}x real time, {seconds / cpu:.2f} simulated s per CPU s "
        f"({cpu / seconds * 1e3:.0f} us per ms)"
    )
    for name, us, ticks in sorted(rows, key=lambda r: -r[1]):
        if ticks:
            print(f"  {name:24s} {us:6.1f} us/ms  ({ticks} ticks)")
    print(f"  {'total':24s} {sum(r[1] for r in rows):6.1f} us/ms")


if __name__ == "__main__":
    main()
