"""``rdm hil mission``: the simulated robot in real time in this process, ``rdm onboard`` as its
own process on ptys, operated by ``rdm ctl`` processes over the signed ground link on
localhost. The whole mission (take off, go to, fold, perch, move the arm, unperch, unfold,
land) through the command line with ``--json``; the ground-link faults in the quick form (a
replayed and a garbage datagram must change nothing; a lost heartbeat lands). The record's
claims are checked against the run's own ground truth (MuJoCo's ``truth.jsonl``)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from mcap.reader import make_reader

from rdm.scenarios import hil_mission

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]


def truth(folder: str) -> dict[str, np.ndarray]:
    """The ground truth the run folder logged (``/plant/ground_truth`` in its MCAP, read with
    the mcap package)."""
    with open(f"{folder}/signals.mcap", "rb") as fh:
        rows = [
            json.loads(m.data)
            for _, _, m in make_reader(fh).iter_messages(topics=["/plant/ground_truth"])
        ]
    return {
        "t": np.array([r["time"] for r in rows]),
        "z": np.array([r["cog_position"][2] for r in rows]),
        "contact": np.array([bool(r["foot_in_contact"]) for r in rows]),
    }


def test_the_whole_mission_through_the_command_line(tmp_path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "rdm.cli", "hil", "mission", "--json", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=280,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    record = json.loads(proc.stdout)
    assert (record["outcome"], record["safe"], record["final_state"]) == ("landed", True, "idle")
    said = [text.split()[2] for _, text in record["operator"] if text.startswith("rdm ctl")]
    assert said == [
        "takeoff", "goto", "goto", "joints", "perch", "joints", "joints", "unperch", "joints",
        "land",
    ] or said == [
        "takeoff", "goto", "joints", "perch", "joints", "joints", "unperch", "joints", "land",
    ]  # fmt: skip
    assert record["max_tilt_deg"] <= hil_mission.MAX_TILT_DEG
    assert record["max_duty"] <= 0.9375
    gt = truth(record["run_folder"])
    t_perch = next(t for t, text in record["operator"] if text == "rdm ctl perch")
    t_unperch = next(t for t, text in record["operator"] if text == "rdm ctl unperch")
    perched = (gt["t"] > t_perch) & (gt["t"] < t_unperch)
    assert gt["contact"][perched].mean() > 0.5  # it perched, and held until the unperch
    assert gt["contact"][(gt["t"] > t_unperch - 2.0) & (gt["t"] < t_unperch)].all()
    floor = gt["z"][np.searchsorted(gt["t"], hil_mission.ARM_AT) - 1]  # settled, not yet armed
    assert abs(gt["z"][-1] - floor) < 0.05  # back on the floor
    folder = tmp_path / "hil-mission-none-seed0"
    assert json.loads((folder / "summary.json").read_text()) == record
    assert not (folder / "INCOMPLETE").exists()


@pytest.mark.parametrize("fault", ["replayed-command", "garbage-datagram", "heartbeat-loss"])
def test_ground_link_faults_end_safe_and_are_detected(tmp_path, fault) -> None:
    record = hil_mission.run(tmp_path, fault=fault, quick=True)
    assert (record["outcome"], record["safe"], record["fault_detected"]) == (
        "landed",
        True,
        True,
    ), record
    link = record["ground_link"]
    if fault == "replayed-command":  # the old land changed nothing: the go-to was flown
        assert any("goto" in text for _, text in record["operator"])
        assert link["rejected"].get("stale", 0) + link["rejected"].get("replayed", 0) == 1
    elif fault == "garbage-datagram":
        assert link["rejected"].get("too_deep") == 1 and link["rejected"].get("malformed") == 1
    else:  # lost at least once (a go-to datagram after the loss restores it for a while)
        assert record["monitors"]["ground_lost"] >= 1
        assert record["ground_link"]["heartbeat"]["trips"] == record["monitors"]["ground_lost"]
