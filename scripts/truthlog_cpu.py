"""Thread CPU per call of the ground truth, its MCAP record, the mocap and status nodes and
the bridge's 100 Hz tick in the hover stack (seed 0, logs on; docs/truthlog.md).

usage: python scripts/truthlog_cpu.py [SECONDS=4]
Runs 3 s from power-on, then ``SECONDS`` with ``time.thread_time_ns`` around: the truth
computation (``Plant._ground_truth``), the logger's ``log_truth``, the bridge's truth sink,
``MocapNode.tick``, ``StatusNode.tick``, the bridge's ticks split into those that take a
truth record and the rest, and the chunk close on the simulation thread. For an A/B against
an older tree, run that tree's copy with its ``python/`` on PYTHONPATH, alternating.
"""

from __future__ import annotations

import sys
import tempfile
import time
from dataclasses import replace

import numpy as np

from rdm.scenarios.common import sim_stack_options
from rdm.scenarios.hover import HOVER_Z, make_script
from rdm.scenarios.stack import build_stack

_clock = time.thread_time_ns


def main() -> None:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 4.0
    acc: dict[str, list[int]] = {}

    def timed(obj, attr: str, key: str) -> None:
        f = getattr(obj, attr)
        acc[key] = [0, 0]

        def wrapper(*a, **k):
            t0 = _clock()
            r = f(*a, **k)
            x = acc[key]
            x[0] += _clock() - t0
            x[1] += 1
            return r

        setattr(obj, attr, wrapper)

    # The Python loop: the lockstep kernel holds the nodes' bound ticks from the build on, so
    # timers put on them afterwards would not run (the ticks' own cost is the same).
    opts = replace(sim_stack_options(0, "inproc", speed=None), lockstep_kernel=False)
    with tempfile.TemporaryDirectory(prefix="rdm-truthlog-") as base:
        stack = build_stack("cpu", base, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))
        try:
            stack.loop.run(3.0)
            bridge = stack.bridge
            status = next(n for n in stack.loop.nodes if n.name == "status")
            timed(stack.plant, "_ground_truth", "truth computation")
            timed(stack.logger, "log_truth", "log_truth")
            timed(bridge, "_truth_sink", "truth sink")
            timed(stack.mocap, "tick", "MocapNode.tick")
            timed(status, "tick", "StatusNode.tick")
            fast = stack.logger._fast
            close = "_close_chunk" if hasattr(fast, "_close_chunk") else "_finalize"
            timed(fast, close, "chunk close")
            tick = bridge.tick
            acc["bridge, truth tick"] = [0, 0]
            acc["bridge, other ticks"] = [0, 0]

            def bridge_tick(now: float) -> None:
                due = bridge._sample_count % bridge._truth_n == 0
                t0 = _clock()
                tick(now)
                x = acc["bridge, truth tick" if due else "bridge, other ticks"]
                x[0] += _clock() - t0
                x[1] += 1

            bridge.tick = bridge_tick
            cpu0 = time.process_time()
            stack.loop.run(seconds)
            cpu = time.process_time() - cpu0
        finally:
            stack.close()
    print(f"whole stack: {cpu / seconds * 1000:.1f} us of process CPU per simulated ms")
    for key, (ns, n) in acc.items():
        if n:
            per_ms = ns / 1e3 / seconds / 1e3
            print(f"{key:20s} n={n:6d} {ns / n / 1e3:8.2f} us/call {per_ms:6.2f} us/ms")


if __name__ == "__main__":
    main()
