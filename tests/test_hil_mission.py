"""The operator's mission with ``rdm onboard`` as its own process (rdm.scenarios.hil_mission):
the simulated robot in real time on ptys, motion capture as signed pose datagrams, the
operator as ``rdm ctl`` processes and a ``rdm ctl --heartbeat``. Each run must end landed and
safe, and the node must have noticed the fault (its own final status line says so)."""

from __future__ import annotations

import numpy as np
import pytest

from rdm.scenarios import hil_mission

pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]


@pytest.mark.parametrize("fault", ["none", "replayed-command", "heartbeat-loss"])
def test_the_mission_lands_safe_with_the_node_as_a_process(tmp_path, fault) -> None:
    record = hil_mission.run(tmp_path, fault=fault, duration=32.0)
    assert record["outcome"] == "landed", record
    assert record["safe"] is True
    assert record["final_state"] == "idle"
    assert record["max_tilt_deg"] <= hil_mission.MAX_TILT_DEG
    link = record["ground_link"]
    assert link["authenticated"] is True
    assert link["commands"]["takeoff"] == 1 and link["commands"]["pose"] > 500
    words = [w.split()[2] for _, w in record["operator"] if w.startswith("rdm ctl")]
    if fault == "none":
        assert record["fault_detected"] is None
        assert words[0] == "takeoff" and "goto" in words and words[-1] == "land"
        assert link["commands"]["land"] == 1
    else:
        assert record["fault_detected"] is True, record
    if fault == "replayed-command":
        # the land captured at take-off changed nothing: the robot landed on the operator's
        # own land command, after the go-to
        assert link["commands"]["land"] == 1 and "goto" in words
        assert np.isfinite(record["touchdown_s"])
    if fault == "heartbeat-loss":
        assert record["monitors"]["ground_lost"] == 1
        assert "land" not in words  # the node landed by itself
