"""Real-time factor of the hover stack from power-on, per phase (docs/lockstep.md
"Session 11").

usage: python scripts/lockstep_phases.py
Builds the ``rdm sim hover`` stack (seed 0, in-process wires, logs written to a temporary
folder) and runs 4 simulated s from power-on, printing the wall-clock real-time factor of the
whole run, of the floor phase (0-1.5 s: the CAN boot, the robot on the floor) and of the
flight after take-off (2.5-4 s), and the simulated s per CPU s of the whole run. For an A/B
against an older tree, run that tree's copy with its ``python/`` on PYTHONPATH, alternating
with this one (single runs spread +-25 % on a shared machine: compare medians of pairs).
"""

from __future__ import annotations

import tempfile
import time

import numpy as np

from rdm.scenarios.common import sim_stack_options
from rdm.scenarios.hover import HOVER_Z, make_script
from rdm.scenarios.stack import build_stack

FLOOR_END_S, AIRBORNE_FROM_S, END_S = 1.5, 2.5, 4.0


def main() -> None:
    opts = sim_stack_options(0, "inproc", speed=None)
    with tempfile.TemporaryDirectory(prefix="rdm-phases-") as base:
        stack = build_stack("phases", base, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))
        try:
            marks = []
            wall0, cpu0 = time.perf_counter(), time.process_time()
            for t in (FLOOR_END_S, AIRBORNE_FROM_S, END_S):
                stack.loop.run_until(t)
                marks.append((time.perf_counter() - wall0, time.process_time() - cpu0))
        finally:
            stack.close()
    (floor, _), (airborne, _), (total, cpu) = marks
    print(
        f"total {END_S / total:.1f}x floor {FLOOR_END_S / floor:.1f}x "
        f"air {(END_S - AIRBORNE_FROM_S) / (total - airborne):.1f}x cpu {END_S / cpu:.1f}x"
    )


if __name__ == "__main__":
    main()
