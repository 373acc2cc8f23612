"""Simulated seconds per CPU second of the lockstep hover stack (docs/sim.md "Speed").

usage: python scripts/hover_cpu_rate.py [SECONDS=6] [START=1]
Builds the ``rdm sim hover`` stack (seed 0, in-process wires, logs written to a temporary
folder), runs ``START`` simulated s (1: power-on, enumeration), then measures ``SECONDS``
more with ``time.process_time`` (``1.5 0``: the CAN boot on the floor, from power-on).
For an A/B against another tree, run that tree's copy with its
``python/`` on PYTHONPATH, alternating with this one (single runs spread +-20 % on a shared
machine: compare medians of several pairs).
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
    start = float(sys.argv[2]) if len(sys.argv) > 2 else 1.0
    opts = sim_stack_options(0, "inproc", speed=None)
    with tempfile.TemporaryDirectory(prefix="rdm-hover-rate-") as base:
        stack = build_stack("rate", base, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))
        try:
            if start > 0:
                stack.loop.run(start)
            cpu0 = time.process_time()
            stack.loop.run(seconds)
            cpu = time.process_time() - cpu0
        finally:
            stack.close()
    print(f"{seconds / cpu:.2f} simulated s per CPU s ({cpu / seconds * 1000:.0f} us per ms)")


if __name__ == "__main__":
    main()
