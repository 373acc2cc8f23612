"""CPU per simulated ms of the hover stack with the lockstep kernel, Spinal's busy ms in the
kernel (``SpinalMirror.kernel_busy``) off and on, alternating (docs/spinalkernel.md).

usage: python scripts/spinal_kernel_busy_ab.py [PAIRS=6] [SECONDS=6]
Each run builds the ``rdm sim hover`` stack (seed 0, in-process wires, logs to a temporary
folder), runs 1.5 simulated s (past the CAN boot), then measures ``SECONDS`` with
``time.process_time``. Prints each pair and the medians.
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time

import numpy as np

from rdm.scenarios.common import sim_stack_options
from rdm.scenarios.hover import HOVER_Z, make_script
from rdm.scenarios.stack import build_stack


def once(busy: bool, seconds: float) -> float:
    """us of CPU per simulated ms."""
    opts = sim_stack_options(0, "inproc", speed=None)
    with tempfile.TemporaryDirectory(prefix="rdm-spinal-kernel-ab-") as base:
        stack = build_stack("ab", base, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))
        try:
            stack.spinal.kernel_busy = busy
            stack.loop.run(1.5)
            cpu0 = time.process_time()
            stack.loop.run(seconds)
            return (time.process_time() - cpu0) / seconds * 1e3
        finally:
            stack.close()


def main() -> None:
    pairs = int(sys.argv[1]) if len(sys.argv) > 1 else 6
    seconds = float(sys.argv[2]) if len(sys.argv) > 2 else 6.0
    on: list[float] = []
    off: list[float] = []
    for i in range(pairs):
        off.append(once(False, seconds))
        on.append(once(True, seconds))
        print(f"pair {i}: off {off[-1]:.1f}  on {on[-1]:.1f} us per ms", flush=True)
    ratios = sorted(a / b for a, b in zip(on, off, strict=True))
    print(
        f"median off {statistics.median(off):.1f}  on {statistics.median(on):.1f} us per ms; "
        f"on/off ratio median {statistics.median(ratios):.3f} "
        f"(min {ratios[0]:.3f}, max {ratios[-1]:.3f})"
    )


if __name__ == "__main__":
    main()
