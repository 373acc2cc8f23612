"""The perching scenario as three processes over a REAL kernel CAN bus (vcan0) and pty UARTs.

Same processes as ``test_processes_vcan.py`` (robot / Spinal / onboard, docs/processes.md), the
onboard process running ``rdm.scenarios.perching.PerchingScript`` with
``perching.onboard_config()``. To keep the emulated run short it uses the quick timing
(``perching.QUICK_TIMING``: 4 s fold, contact ~9 s) and stops ~2 s after the perch switch.
Asserted on the robot process's MuJoCo ground truth: the perch switch follows the physical
contact, the foot stays in contact at the ceiling without slip, the ZMP inside the plate, the
perching QP solves, no fail-safe; the Neuron PWM frames crossed the kernel bus. The host test
(tests/test_processes.py) compares the same outcome with the in-process lockstep run.
``RDM_PERCHING_DURATION`` overrides the duration.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from rdm.protocol.neuron import decode_candump
from rdm.scenarios.processes import ProcessRunOptions, run_processes, stack_ceiling

DURATION = float(os.environ.get("RDM_PERCHING_DURATION", "11.0"))
PWM_ID = 0x00F  # MOTOR device, message 0, broadcast slave field


# ~11 min in the emulated VM (11 simulated s at ~45 ms wall per simulated ms, + start-up)
@pytest.mark.timeout(1800)
def test_perching_as_three_processes_on_vcan0(vcan_channel, tmp_path):
    opts = ProcessRunOptions(
        can=f"socketcan:{vcan_channel}",
        scenario="perching",
        quick=True,
        duration=DURATION,
        scale=0.05,
    )
    run = run_processes(tmp_path / "hil", opts)
    onboard = run.reports["onboard"]
    print(
        json.dumps(
            {
                "metrics": run.metrics,
                "perching": onboard["perching"],
                "perch_status_counts": onboard["perch_status_counts"],
                "wall_s": run.wall_s,
                "startup_wall_s": run.startup_wall_s,
                "deadlines": {r: run.reports[r]["deadlines"] for r in run.reports},
            }
        )
    )
    m, tr = run.metrics, run.truth
    t = tr["t"]
    assert t[-1] >= DURATION - 0.02  # the robot process simulated the whole run
    assert m["perched"] == 1.0, onboard["perching"]
    # The switch comes from the PC's foot sensor (F_z > 3 N) after the plant's first contact.
    first_contact = t[np.argmax(tr["contact"])]
    # (1 us slack: the robot's times are k * 1 ms, the onboard's sums of 10 ms periods)
    assert tr["contact"].any() and first_contact - 1e-6 <= m["t_perch"] < first_contact + 1.0
    held = t >= m["t_perch"] + 0.5
    assert held.sum() >= 100  # >= 1 s of ground truth judged
    assert tr["contact"][held].all(), "the foot left the ceiling"
    assert m["slip_mm"] < 1.0
    assert abs(tr["foot"][held, 2].mean() - stack_ceiling()) < 0.01
    zmp = tr["zmp"][held]
    assert np.all(np.abs(zmp[:, 0]) <= 0.05 + 1e-9) and np.all(np.abs(zmp[:, 1]) <= 0.075 + 1e-9)
    assert np.all(tr["force"][held, 2] > 0.0)
    assert m["max_roll_pitch_deg_perched"] < 20.0
    counts = onboard["perch_status_counts"]
    assert counts.get("solved", 0) > 0, counts
    spinal = run.reports["spinal"]["diagnostics"]
    assert not spinal["failsafes"], spinal["failsafes"]
    assert spinal["can"]["slaves"] == [1, 2, 3, 4]
    frames = [r for r in decode_candump(run.candump) if r["id"] == PWM_ID]
    assert len(frames) > 250 * (DURATION - 1.5) and all(r["ok"] for r in frames)
