"""The hover scenario as three processes over a REAL kernel CAN bus (vcan0) and pty UARTs.

robot (MuJoCo plant, plant bridge, 4 Neuron mirrors on vcan0, Leptrino mirror on a pty, mocap),
Spinal mirror (vcan0 + the Spinal UART pty) and onboard node (both ptys) run as separate
processes on a shared scaled clock (docs/processes.md). Asserted: the same physical outcome as
the in-process lockstep run of the same scenario (take-off, the target held, level, no
fail-safe), checked on the robot process's MuJoCo ground truth; and the Neuron PWM frames on
the kernel bus, decoded from the candump with an independent bit layout and equal to what the
Neuron mirrors applied. Nothing about timing is asserted: the deadline figures are printed.

The run uses the co-simulation clock (``gate``, the default): the controllers never run ahead
of the physics and the robot process waits for them, so the run goes as fast as the slowest
process allows, at most ``scale``. In the emulated VM the robot process needs ~30 ms of wall
time per simulated ms (MuJoCo under TCG), below the 0.05 asked. ``RDM_PROCESSES_SCALE`` and
``RDM_PROCESSES_DURATION`` override the defaults.
"""

from __future__ import annotations

import json
import os

import numpy as np

from rdm.protocol.neuron import decode_candump
from rdm.scenarios.processes import ProcessRunOptions, run_processes

SCALE = float(os.environ.get("RDM_PROCESSES_SCALE", "0.05"))
DURATION = float(os.environ.get("RDM_PROCESSES_DURATION", "4.0"))
PWM_ID = 0x00F  # MOTOR device, message 0 (slaves 1..6), broadcast slave field


def pwm_slots(payload: bytes) -> list[int]:
    """Six 10-bit PWM values of a broadcast frame (three per 32-bit half, bits 30-31 of each
    half reserved), decoded here without the project's codec."""
    word = int.from_bytes(payload, "little")
    return [(word >> (32 * (i // 3) + 10 * (i % 3))) & 0x3FF for i in range(6)]


def test_hover_as_three_processes_on_vcan0(vcan_channel, tmp_path):
    opts = ProcessRunOptions(can=f"socketcan:{vcan_channel}", duration=DURATION, scale=SCALE)
    run = run_processes(tmp_path / "hil", opts)
    print(
        json.dumps(
            {
                "metrics": run.metrics,
                "wall_s": run.wall_s,
                "startup_wall_s": run.startup_wall_s,
                "deadlines": {r: run.reports[r]["deadlines"] for r in run.reports},
            }
        )
    )
    m = run.metrics
    target = np.asarray(opts.target)
    t, cog = run.truth["t"], run.truth["cog"]
    assert t[-1] >= DURATION - 0.02  # the robot process simulated the whole run
    # Lockstep's outcome of this scenario (tests/test_sim.py, docs/processes.md): climbs
    # ~0.4 m, x/y within 1 cm over the last second, z overshoots by < 10 cm, level.
    assert m["climb_m"] > 0.3
    assert m["max_abs_err_x_last1s"] < 0.03 and m["max_abs_err_y_last1s"] < 0.03
    assert m["max_abs_err_z_last1s"] < 0.12
    assert m["max_roll_pitch_deg_after_arm"] < 5.0
    assert np.all(run.truth["thrust"][t < opts.arm_at] == 0.0)  # no thrust before arming
    assert abs(cog[-1, 2] - target[2]) < 0.12
    spinal = run.reports["spinal"]["diagnostics"]
    assert not spinal["failsafes"], spinal["failsafes"]
    assert not spinal["rejected"], spinal["rejected"]
    assert spinal["can"]["slaves"] == [1, 2, 3, 4] and spinal["can"]["state"] == "running"
    states = [s for _, s in run.reports["onboard"]["states"]]
    assert states[-1] == "armed" and "landing" not in states
    robot = run.reports["robot"]
    assert all(all(n["torque_on"]) for n in robot["neurons"].values())
    # The Neuron PWM frames crossed the kernel bus: the candump of a fourth socket on vcan0.
    frames = [r for r in decode_candump(run.candump) if r["id"] == PWM_ID]
    assert len(frames) > 250 * (DURATION - opts.arm_at)  # 500 Hz nominal after arming
    assert all(r["ok"] for r in frames)
    last = pwm_slots(bytes.fromhex(frames[-1]["data"]))
    applied = [robot["neurons"][f"neuron{i}"]["pwm"] for i in (1, 2, 3, 4)]
    assert last[:4] == applied
    assert min(applied) > 200  # the four ESCs spin (0..1000 = idle..full)
