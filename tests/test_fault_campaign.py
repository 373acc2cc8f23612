"""The fault campaign (``rdm sim mission --fault KIND|all --seeds N``) and its byte faults.

* ``CorruptingLink``: on 200,000 zero bytes each fault count is within 5 sigma of its binomial
  mean, every surviving damaged byte has exactly one bit set (one flip, never two), and the
  output length is the input's minus the lost plus the repeated bytes.
* The campaign's rows against each run folder's own ``summary.json`` (read back with
  ``json.loads``): counts of safe ends, detections, outcomes, the fault-to-touchdown times.
  The UART-noise and battery-sag faults must end safe and be detected in every run.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import rdm
from rdm.sim.byte_faults import CorruptingLink


class _Source:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def read_available(self) -> bytes:
        data, self.data = self.data, b""
        return data


def test_byte_faults_follow_their_probability():
    n, p = 200_000, 0.02
    link = CorruptingLink(_Source(bytes(n)), p, seed=3)
    out = np.frombuffer(link.read_available(), dtype=np.uint8)
    c = link.counts()
    sigma = math.sqrt(n * p * (1 - p))
    for key in ("flipped", "lost"):
        assert abs(c[key] - n * p) < 5 * sigma, (key, c)
    kept = n - c["lost"]
    assert abs(c["repeated"] - kept * p) < 5 * math.sqrt(kept * p * (1 - p))
    assert out.size == n - c["lost"] + c["repeated"]
    damaged = out[out != 0]
    assert damaged.size > 0
    assert all(bin(int(b)).count("1") == 1 for b in damaged)  # one bit flipped per byte
    # about the flipped share survives: flips that were not lost, repeated ones twice
    expected = c["flipped"] * (1 - p) * (1 + p)
    assert abs(damaged.size - expected) < 5 * math.sqrt(expected)
    assert CorruptingLink(_Source(b"abc"), 0.0, seed=1).read_available() == b"abc"
    with pytest.raises(ValueError, match="p"):
        CorruptingLink(_Source(b""), 1.5, seed=1)


def _sim(args: list[str], timeout: float = 600) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(Path(rdm.__file__).resolve().parent.parent))
    cmd = [sys.executable, "-m", "rdm.cli", "sim", *args]
    return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout)


@pytest.mark.parametrize("fault", ["uart-noise-1e-3", "battery-sag"])
def test_campaign_rows_are_the_runs_records(tmp_path, fault):
    campaign = ["--fault", fault, "--seeds", "2", "--workers", "2"]
    out = _sim(["mission", *campaign, "--out", str(tmp_path), "--json"])
    assert out.returncode in (0, 1), out.stderr
    doc = json.loads(out.stdout)
    assert doc == json.loads((tmp_path / "faults-mission.json").read_text())
    (row,) = doc["faults"]
    records = [
        json.loads((tmp_path / f"mission-{fault}-seed{k}" / "summary.json").read_text())["mission"]
        for k in (0, 1)
    ]
    assert row["runs"] == row["completed"] == 2 and not row["failed_runs"]
    assert row["safe"] == sum(r["safe"] for r in records)
    assert row["detected"] == sum(bool(r["fault_detected"]) for r in records)
    assert row["outcomes"] == {
        o: sum(r["outcome"] == o for r in records) for o in {r["outcome"] for r in records}
    }
    times = [r["touchdown_s"] - r["fault_at_s"] for r in records if r["outcome"] == "landed"]
    assert row["fault_to_touchdown_s"]["max"] == pytest.approx(max(times))
    assert row["max_tilt_deg"] == max(r["max_tilt_deg"] for r in records)
    # the safety claim: every run ends safe and the node noticed the fault
    assert row["safe"] == 2 and row["detected"] == 2 and out.returncode == 0
    assert all(r["fault"] == fault and r["fault_at_s"] > 0 for r in records)


def test_campaign_refuses_bad_options():
    for args in (
        ["hover", "--fault", "all", "--seeds", "2"],
        ["mission", "--fault", "x", "--seeds", "2"],
    ):
        out = _sim(args, timeout=120)
        assert out.returncode == 2 and "--fault" in out.stderr and "Traceback" not in out.stderr
