"""The fault campaign (``rdm sim mission --fault KIND|all --seeds N``) and its byte faults.

* ``CorruptingLink``: on 200,000 zero bytes each fault count is within 5 sigma of its binomial
  mean, every surviving damaged byte has exactly one bit set (one flip, never two), and the
  output length is the input's minus the lost plus the repeated bytes.
* The campaign's rows against each run folder's own ``summary.json`` (read back with
  ``json.loads``): counts of safe ends, detections, outcomes, the fault-to-touchdown times.
  The UART-noise and battery-sag faults must end safe and be detected in every run.
* The plant-side faults (``rdm.scenarios.mission_faults``): IMU outliers at their rate and
  beyond Spinal's ranges, each one dropped by Spinal's estimator (its ``out_of_range``
  counter equals the injected count) and the flight ending safe; a dead rotor gives no
  thrust, Spinal's tilt fail-safe notices, and the record says "crashed", not safe.
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
from rdm.plant.ceiling import NoCeilingEffect
from rdm.plant.sensors import ImuReading
from rdm.scenarios import mission
from rdm.scenarios.mission_faults import (
    SPIKE_ACC,
    SPIKE_GYRO,
    SPIKE_PROBABILITY,
    DeadRotor,
    SpikingImu,
)
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


def test_imu_spikes_are_rare_outliers_beyond_the_sensor_range():
    clean = ImuReading(np.array([0.1, -0.2, 0.3]), np.array([0.0, 0.0, 9.8]), np.ones(3), False)
    imu = SpikingImu(lambda: clean, seed=4)
    n = 40_000
    samples = [imu() for _ in range(n)]
    changed = [r for r in samples if r is not clean]
    assert len(changed) == imu.spikes
    sigma = math.sqrt(n * SPIKE_PROBABILITY * (1 - SPIKE_PROBABILITY))
    assert abs(imu.spikes - n * SPIKE_PROBABILITY) < 5 * sigma
    for r in changed:  # one gyro and one accelerometer axis beyond the range, the rest kept
        g = np.abs(r.gyro) == SPIKE_GYRO
        a = np.abs(r.accel) == SPIKE_ACC
        assert g.sum() == 1 and a.sum() == 1
        assert np.array_equal(r.gyro[~g], clean.gyro[~g])
        assert np.array_equal(r.accel[~a], clean.accel[~a])
        assert np.array_equal(r.mag, clean.mag)
    assert SPIKE_GYRO > 34.91 and SPIKE_ACC > 78.5  # Spinal's estimator ranges
    assert DeadRotor(NoCeilingEffect()).thrust_ratio(0.3) == 0.0


def test_imu_spikes_mission_ends_safe_and_each_spike_is_dropped(tmp_path):
    result = mission.run(
        tmp_path, duration=mission.QUICK_DURATION, seed=0, fault="imu-spikes", quick=True
    )
    record, stack = result.facts["mission"], result.stack
    spikes = stack.plant.imu.spikes
    assert spikes > 10  # the injection ran: about 3 a second after the fault
    # every outlier reached Spinal's estimator and was dropped there, no other sample was
    assert stack.spinal.core.estimator_counters["out_of_range"] == spikes
    assert record["safe"] and record["fault_detected"] and record["outcome"] == "landed"


def test_dead_esc_mission_is_detected_and_reported_as_a_crash(tmp_path):
    result = mission.run(
        tmp_path, duration=mission.QUICK_DURATION, seed=0, fault="dead-esc", quick=True
    )
    record, stack = result.facts["mission"], result.stack
    assert isinstance(stack.plant.ceiling_effects[0], DeadRotor)
    assert stack.spinal.counters.failsafes["failsafe_tilt"] >= 1
    # a quadrotor without one rotor cannot stay level: the record must not claim a safe end
    assert record["fault_detected"] and not record["safe"]
    assert record["outcome"] == "crashed" and record["max_tilt_deg"] > mission.MAX_TILT_DEG


def test_the_help_names_every_fault() -> None:
    """``rdm sim --help`` (written out so the parser imports no scenario) lists each fault
    of ``mission.FAULTS``."""
    import argparse
    import re

    from rdm.commands.sim import add_arguments
    from rdm.scenarios.mission import FAULTS

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    text = " ".join(parser.format_help().split())
    named = set(re.findall(r"[a-z]+(?:-[a-z0-9]+)+", text))
    assert set(FAULTS) - {"none"} <= named
