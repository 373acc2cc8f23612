"""cProfile of one node's ticks in the hover stack (seed 0, log=False).

usage: python scripts/profile_stack_node.py NODE   (plant_bridge, spinal, neurons, onboard, ...)
Runs 2 s from power-on unprofiled, then 2 s with the profiler on around that node's ticks only.
"""

import cProfile
import pstats
import sys
import tempfile

import numpy as np

from rdm.scenarios.common import sim_stack_options
from rdm.scenarios.hover import HOVER_Z, make_script
from rdm.scenarios.stack import build_stack


def main() -> None:
    node_name = sys.argv[1]
    opts = sim_stack_options(0, "inproc", log=False)
    script = make_script(np.array([0.483, 0.0, HOVER_Z]))
    stack = build_stack("profile", tempfile.mkdtemp(), opts, script)
    try:
        stack.loop.run(2.0)
        node = next(n for n in stack.loop.nodes if n.name == node_name)
        profiler = cProfile.Profile()
        plain_tick = node.tick

        def tick(now: float) -> None:
            profiler.enable()
            plain_tick(now)
            profiler.disable()

        node.tick = tick
        stack.loop.run(2.0)
    finally:
        stack.close()
    pstats.Stats(profiler).sort_stats("tottime").print_stats(30)


if __name__ == "__main__":
    main()
