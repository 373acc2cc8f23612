"""Thread CPU time spent in ``OnboardNode.tick`` per simulated ms, hover lockstep stack.

Usage: ``python scripts/onboard_tick_cpu.py [simulated_ms]`` (after 2000 ms of warm-up).
Thread CPU time (``time.thread_time``) leaves out other processes on a shared machine and
GIL waits, which make wall-clock shares noisy.
"""

from __future__ import annotations

import sys
import tempfile
import time

from rdm.bench.lockstep import _build
from rdm.nodes.onboard import OnboardNode


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 6000
    spent = [0.0, 0]
    plain_tick = OnboardNode.tick

    def timed_tick(self: OnboardNode, now: float) -> None:
        t0 = time.thread_time()
        plain_tick(self, now)
        spent[0] += time.thread_time() - t0
        spent[1] += 1

    with tempfile.TemporaryDirectory() as base:
        stack = _build(base, profile=False)
        stack.loop.run_ticks(2000)
        OnboardNode.tick = timed_tick
        try:
            c0 = time.process_time()
            stack.loop.run_ticks(n)
            cpu = time.process_time() - c0
        finally:
            OnboardNode.tick = plain_tick
            stack.close()
    calls = max(spent[1], 1)
    print(
        f"onboard {1e6 * spent[0] / n:.1f} us/ms ({1e6 * spent[0] / calls:.0f} us/call, "
        f"{spent[1]} calls); whole {1e6 * cpu / n:.1f} us/ms"
    )


if __name__ == "__main__":
    main()
