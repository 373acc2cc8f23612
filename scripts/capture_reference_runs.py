"""Run folders to compare byte for byte: perching (shortened, log=True) and hover, seed 0.

usage: python scripts/capture_reference_runs.py OUT [PERCHING_S=24] [HOVER_S=5]
then e.g. ``cmp`` every file of OUT_A and OUT_B (signals.mcap, can.log, uart/*). The perching
run perches at 14.83 s, so 24 s covers flight, the transition and the perched joint motion.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from rdm.scenarios import perching
from rdm.scenarios.common import run_stack, sim_stack_options
from rdm.scenarios.hover import HOVER_Z, make_script
from rdm.scenarios.stack import build_stack


def main() -> None:
    out = sys.argv[1]
    perch_s = float(sys.argv[2]) if len(sys.argv) > 2 else 24.0
    hover_s = float(sys.argv[3]) if len(sys.argv) > 3 else 5.0
    opts = sim_stack_options(0, "inproc", log=True, onboard=perching.onboard_config())
    script = perching.PerchingScript(perching.PERCHED_MOTION)
    stack = build_stack("perching", out + "/perching", opts, script)
    t = time.process_time()
    run_stack(stack, perch_s)
    cpu = time.process_time() - t
    print(f"perching {perch_s} s: sim/cpu {perch_s / cpu:.2f}, perched at {script.t_perch}")
    stack = build_stack(
        "hover",
        out + "/hover",
        sim_stack_options(0, "inproc"),
        make_script(np.array([0.483, 0.0, HOVER_Z])),
    )
    t = time.process_time()
    run_stack(stack, hover_s)
    print(f"hover {hover_s} s: sim/cpu {hover_s / (time.process_time() - t):.2f}")


if __name__ == "__main__":
    main()
