"""``/onboard/signals`` in the run's MCAP: what the onboard PC's controller received and
commanded, checked against the ground truth of the same run and the bytes on the UART."""

from __future__ import annotations

import json

import numpy as np
from mcap.reader import make_reader
from scipy.spatial.transform import Rotation

from rdm.scenarios.common import run_stack, sim_stack_options, truth_arrays
from rdm.scenarios.hover import HOVER_Z, make_script
from rdm.scenarios.stack import build_stack


def _json_channel(path, topic: str) -> list[dict]:
    with open(path, "rb") as f:
        reader = make_reader(f)
        return [
            json.loads(m.data)
            for _, channel, m in reader.iter_messages(topics=[topic])
            if channel.message_encoding == "json"
        ]


def test_signals_follow_the_truth_and_the_wire(tmp_path):
    stack = build_stack(
        "signals",
        tmp_path,
        sim_stack_options(0, "inproc", log=True),
        make_script(np.array([0.483, 0.0, HOVER_Z])),
    )
    run_stack(stack, 4.0)
    status = _json_channel(stack.folder.mcap, "/onboard/status")
    signals = _json_channel(stack.folder.mcap, "/onboard/signals")
    assert len(signals) == len(status) == len(stack.status) >= 150
    assert [s["t"] for s in signals] == [s["t"] for s in status]
    a = truth_arrays(stack)
    t = a["t"]
    flying = [s for s in signals if s["target_angles"] is not None and s["t"] > 3.0]
    assert len(flying) > 30
    for s in flying:
        k = int(np.argmin(np.abs(t - s["t"])))
        assert abs(t[k] - s["t"]) <= 0.005
        # mocap is the true CoG at 100 Hz: within 10 ms of flight of it
        assert np.linalg.norm(np.subtract(s["mocap_position"], a["cog"][k])) < 0.02
        # Spinal's estimate as the PC received it against the true attitude (a few degrees:
        # the estimate's own error and up to 10 ms between the two samples)
        true_rpy = Rotation.from_quat(np.roll(a["quat"][k], -1)).as_euler("xyz")
        assert np.all(np.abs(np.subtract(s["imu_euler"][:2], true_rpy[:2])) < np.radians(3))
        # joint angles as Spinal reported them: one encoder count plus the servos' motion
        assert np.max(np.abs(np.subtract(s["present_q"][:6], a["q"][k][:6]))) < 0.02
        assert len(s["flight_thrust"]) == 4 and all(np.isfinite(s["flight_thrust"]))
        assert len(s["servo_goals"]) == len(s["present_q"])
        assert s["setpoint_position"] == [0.483, 0.0, HOVER_Z]
    # the goals are what went over the UART: the last servo/target_states of the run
    from rdm.protocol.rosserial.capture import decode_uart, load_layout

    capture = (stack.folder.uart_dir / "spinal.host_tx.bin").read_bytes()
    sent = [
        r["fields"]
        for r in decode_uart(capture, layout=load_layout())
        if r.get("topic") == "servo/target_states"
    ]
    assert len(sent) > 50
    smap = stack.onboard.config.servo_map
    last = signals[-1]["servo_goals"]
    raw = [smap.to_raw(j, q) for j, q in enumerate(last)]
    assert sent[-1]["angles"] == raw[: len(sent[-1]["angles"])]
