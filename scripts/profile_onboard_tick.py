"""Onboard node's 40 Hz tick: CPU time per call by phase, per-section timers or cProfile.

usage: python scripts/profile_onboard_tick.py perching|hover SECONDS [--plain | --cprofile]
  (default) per-call tick time + section timers (they add ~10 %);
  --plain    per-call tick time only;  --cprofile  cProfile around the onboard ticks only.
Times are ``time.thread_time`` (CPU of this thread). See docs/lockstep.md.
"""

from __future__ import annotations

import collections
import cProfile
import pstats
import sys
import tempfile
import time

import numpy as np

from rdm.scenarios import perching
from rdm.scenarios.common import sim_stack_options
from rdm.scenarios.hover import HOVER_Z, make_script
from rdm.scenarios.stack import build_stack

clock = time.thread_time


def main() -> None:
    scen, seconds = sys.argv[1], float(sys.argv[2])
    mode = sys.argv[3] if len(sys.argv) > 3 else "--sections"
    if scen == "perching":
        opts = sim_stack_options(0, "inproc", log=True, onboard=perching.onboard_config())
        script = perching.PerchingScript(perching.PERCHED_MOTION)
    else:
        opts = sim_stack_options(0, "inproc")
        script = make_script(np.array([0.483, 0.0, HOVER_Z]))
    stack = build_stack(scen, tempfile.mkdtemp(), opts, script)
    node = stack.onboard
    total: dict[str, float] = collections.defaultdict(float)
    calls: collections.Counter[str] = collections.Counter()

    def wrap(obj, name: str, key: str) -> None:
        f = getattr(obj, name)

        def timed(*a, **k):
            t = clock()
            try:
                return f(*a, **k)
            finally:
                total[key] += clock() - t
                calls[key] += 1

        setattr(obj, name, timed)

    if mode == "--sections":
        ctl = node.control
        for name in ("update_model", "synthesize", "p_matrix_wire", "step"):
            wrap(ctl, name, name)
        wrap(ctl.position, "step", "  position.step")
        wrap(ctl.perch, "tick", "  perch.tick")
        wrap(ctl.lqi, "synthesize", "  lqi.synthesize (core)")
        for name in ("_control", "_send_servo_targets", "_send_gains", "_publish", "_on_event"):
            wrap(node, name, name)
        for name in ("feed", "poll", "take_output"):
            wrap(node.session, name, f"session.{name}")
        if node.foot is not None:
            wrap(node.foot, "poll", "foot.poll")
    prof = cProfile.Profile()
    tick = node.tick
    per_phase: dict[str, list[float]] = collections.defaultdict(list)

    def timed_tick(now: float) -> None:
        if mode == "--cprofile":
            prof.enable()
        t = clock()
        tick(now)
        dt = clock() - t
        if mode == "--cprofile":
            prof.disable()
        flying = node.arming.flying
        phase = "perched" if node.control.perching else ("flight" if flying else "ground")
        per_phase[phase].append(dt)

    node.tick = timed_tick  # the loop looks tick up on every call
    t0 = time.process_time()
    stack.loop.run(seconds)
    cpu = time.process_time() - t0
    stack.close()
    print(f"{scen} {seconds}s: cpu {cpu:.2f} sim/cpu {seconds / cpu:.2f}")
    for phase, v in per_phase.items():
        a = np.array(v) * 1e6
        print(f"  {phase}: {a.size} ticks, mean {a.mean():.1f} us, median {np.median(a):.0f} us")
    for key in sorted(total, key=lambda k: -total[k]):
        n = calls[key]
        print(f"  {key:28s} {n:7d} calls {total[key] * 1e6 / n:8.1f} us/call  {total[key]:.3f} s")
    if mode == "--cprofile":
        pstats.Stats(prof).sort_stats("tottime").print_stats(45)


if __name__ == "__main__":
    main()
