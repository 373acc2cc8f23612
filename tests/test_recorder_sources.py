"""What the flight recorder keeps beyond the port bytes: the robot description and
configuration copies (a replay after the files moved or changed), the loop's timing
histograms (read back against the node's own status), ``rdm sim --record-onboard``."""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from spinal_peer import spinal_mirror_pty

import rdm

pytestmark = pytest.mark.timeout(300)
RDM = [sys.executable, "-m", "rdm.cli"]
ENV = dict(
    os.environ,
    PYTHONUNBUFFERED="1",
    PYTHONPATH=str(Path(rdm.__file__).resolve().parent.parent),
)
SHIPPED = Path(rdm.__file__).resolve().parent / "data" / "robots" / "rdm"


def rdm_cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*RDM, *args], capture_output=True, text=True, timeout=240, env=ENV, cwd=cwd
    )


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def file_robot_run(tmp_path_factory) -> dict:
    """``rdm onboard --robot robots/heavy.toml --config robot.toml`` against the Spinal
    mirror for 3 s, armed: a description whose first link is 0.1 kg heavier than the
    shipped one (its LQI gains, sent to Spinal, differ) and a configuration file."""
    base = tmp_path_factory.mktemp("files")
    robots = base / "robots"
    robots.mkdir()
    urdf = (SHIPPED / "rdm.urdf").read_text()
    assert urdf.count('<mass value="0.35"/>') == 1
    (robots / "heavy.urdf").write_text(urdf.replace('<mass value="0.35"/>', '<mass value="0.45"/>'))
    toml = (SHIPPED / "rdm.toml").read_text().replace('urdf = "rdm.urdf"', 'urdf = "heavy.urdf"')
    (robots / "heavy.toml").write_text(toml)
    example = rdm_cli("config", "example").stdout
    (base / "robot.toml").write_text(
        example.replace("command_retry_s = 0.5", "command_retry_s = 0.4")
    )
    hashes = {
        "robot.urdf": sha256(robots / "heavy.urdf"),
        "robot.toml": sha256(robots / "heavy.toml"),
        "config.toml": sha256(base / "robot.toml"),
    }
    with spinal_mirror_pty(f"sources{os.getpid()}") as pty:
        out = rdm_cli("onboard", "--robot", "robots/heavy.toml", "--config", "robot.toml",
                      "--uart", f"serial:{pty}", "--foot-sensor", "none", "--arm",
                      "--duration", "3", "--record", "rec", cwd=base)  # fmt: skip
    assert out.returncode == 0, out.stderr
    status = json.loads(out.stdout.strip().splitlines()[-1])
    return {"base": base, "record": base / "rec", "status": status, "hashes": hashes}


# ------------------------------------------------------------------ robot and config files
def test_a_robot_and_config_from_files_replay_after_the_files_moved_and_changed(
    file_robot_run, tmp_path
) -> None:
    base, record = file_robot_run["base"], file_robot_run["record"]
    header = json.loads((record / "seg0000" / "journal.jsonl").read_text().splitlines()[0])
    assert header["robot"] == "robots/heavy.toml"
    for name, digest in file_robot_run["hashes"].items():
        assert header["files"][name]["sha256"] == digest == sha256(record / name)
    assert header["files"]["config.toml"]["origin"] == str(base / "robot.toml")
    check = rdm_cli("config", "check", "robot.toml", "--robot", "robots/heavy.toml", cwd=base)
    assert check.returncode == 0, check.stderr
    assert json.loads(check.stdout)["config"]["command_retry_s"] == 0.4
    # the files move and change: the replay uses the recorded copies and says so
    shutil.move(base / "robots", base / "robots-moved")
    config = base / "robot.toml"
    config.write_text(config.read_text().replace("command_retry_s = 0.4", "command_retry_s = 0.3"))
    out = rdm_cli("replay", str(record))
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.startswith("rdm replay: identical:")
    notes = [x for x in out.stderr.splitlines() if x.startswith("rdm replay: note: ")]
    assert notes == [
        f"rdm replay: note: {base / 'robots' / 'heavy.urdf'} is gone (moved or deleted); the "
        "recorded copy robot.urdf is used",
        f"rdm replay: note: {base / 'robots' / 'heavy.toml'} is gone (moved or deleted); the "
        "recorded copy robot.toml is used",
        f"rdm replay: note: {config} was edited since the recording (sha256 "
        f"{file_robot_run['hashes']['config.toml'][:12]} recorded, {sha256(config)[:12]} now); "
        "the recorded copy config.toml is used",
    ]
    # the robot matters: with the shipped description in its place the replay differs
    shipped = tmp_path / "shipped"
    shutil.copytree(record, shipped)
    shutil.copy(SHIPPED / "rdm.urdf", shipped / "robot.urdf")
    journal = shipped / "seg0000" / "journal.jsonl"
    lines = journal.read_text().splitlines()
    head = json.loads(lines[0])
    head["files"]["robot.urdf"]["sha256"] = sha256(SHIPPED / "rdm.urdf")
    journal.write_text("\n".join([json.dumps(head), *lines[1:]]) + "\n")
    out = rdm_cli("replay", str(shipped), "--json")
    assert out.returncode == 1, out.stderr
    assert json.loads(out.stdout)["streams"]["spinal"]["first_difference"] is not None
    # a damaged copy is refused in one line
    with open(shipped / "robot.toml", "a") as f:
        f.write(" ")
    out = rdm_cli("replay", str(shipped))
    assert out.returncode == 2 and out.stderr.count("\n") == 1
    assert "robot.toml: the recorded copy's sha256 is not the header's (damaged)" in out.stderr


def test_a_recording_bound_smaller_than_the_copies_is_refused(tmp_path) -> None:
    out = rdm_cli("onboard", "--uart", "pty", "--duration", "0.1", "--record",
                  str(tmp_path / "rec"), "--record-max-mb", "0.005")  # fmt: skip
    assert out.returncode == 2 and out.stderr.count("\n") == 1
    copies = (SHIPPED / "rdm.urdf").stat().st_size + (SHIPPED / "rdm.toml").stat().st_size
    assert out.stderr == (
        f"rdm onboard: --record-max-mb 0.005: the bound must exceed the {copies} bytes of the "
        "robot description and configuration copies\n"
    )


# ------------------------------------------------------------------ loop timing
def _quantile_ms(h: dict, q: float) -> float:
    """Nearest-rank quantile of a recorded histogram, from its counts by numpy: each sample
    stands at its bin's upper edge (past the bins: the maximum), capped at the maximum."""
    edges = [(i + 1) * h["bin_s"] for i, c in h["counts"] for _ in range(c)]
    samples = np.array(edges + [h["max_s"]] * h["overflow"])
    value = np.percentile(samples, q * 100, method="inverted_cdf")
    return round(min(float(value), h["max_s"]) * 1e3, 3)


def _mcap_records(path: Path, topic: str) -> list[tuple[int, dict]]:
    with open(path, "rb") as f:
        return [
            (m.log_time, json.loads(m.data))
            for _, _, m in make_reader(f).iter_messages(topics=[topic])
        ]


def test_the_loop_histograms_are_in_the_recording(file_robot_run) -> None:
    """``loop_timing.json`` holds the whole histograms whose figures the node printed;
    ``signals.mcap`` holds them every second, cumulative, ending with the same counts."""
    record, status = file_robot_run["record"], file_robot_run["status"]
    loop = status["loop"]
    doc = json.loads((record / "loop_timing.json").read_text())
    assert doc["status"] == loop
    hist = doc["histograms"]
    assert hist["late"] == loop["late"] and hist["period_s"] == 0.025
    assert hist["late_tolerance_s"] == 0.002
    for name in ("tick", "lateness", "period", "period_jitter"):
        h = hist[name]
        assert h["n"] == loop[name]["n"] == sum(c for _, c in h["counts"]) + h["overflow"]
        assert h["bins"] == 4000 and h["bin_s"] == 50e-6
        assert round(h["max_s"] * 1e3, 3) == loop[name]["max_ms"]
        assert _quantile_ms(h, 0.5) == loop[name]["p50_ms"], name
        assert _quantile_ms(h, 0.99) == loop[name]["p99_ms"], name
    assert hist["tick"]["n"] == hist["lateness"]["n"] == status["ticks"]
    assert hist["period"]["n"] == status["ticks"] - 1
    # ticks later than the tolerance, counted from the lateness histogram's bins (exact:
    # 2 ms is a bin edge, and a sample in the bin starting there is late unless exactly 2 ms)
    late_bins = sum(c for i, c in hist["lateness"]["counts"] if i >= 40)
    assert late_bins + hist["lateness"]["overflow"] >= hist["late"]
    assert sum(c for i, c in hist["lateness"]["counts"] if i >= 41) <= hist["late"]

    records = _mcap_records(record / "seg0000" / "signals.mcap", "/onboard/loop_timing")
    assert len(records) >= 3  # every second of the 3 s run, and the last at the end
    times = [t for t, _ in records]
    assert times == sorted(times)
    for (_, a), (_, b) in itertools.pairwise(records):
        for name in ("tick", "lateness", "period", "period_jitter"):
            assert b[name]["n"] >= a[name]["n"]
            before = dict(a[name]["counts"])
            assert all(c >= before.get(i, 0) for i, c in b[name]["counts"])
    assert records[-1][1] == hist


# ------------------------------------------------------------------ rdm sim
def test_rdm_sim_record_onboard_replays_byte_for_byte(tmp_path) -> None:
    """``rdm sim hover --record-onboard``: the run folder carries the node's recording, the
    bytes it wrote are the simulator's own capture of that wire, and ``rdm replay RUN``
    reproduces them."""
    out = rdm_cli("sim", "hover", "--duration", "3", "--out", str(tmp_path), "--record-onboard")
    assert out.returncode in (0, 1), out.stderr  # 1: a metric failed (a 3 s hover is short)
    run = tmp_path / "hover-seed0"
    assert f"onboard recording: {run / 'onboard'} (rdm replay {run})" in out.stdout
    rec = run / "onboard"
    assert json.loads((rec / "summary.json").read_text())["replayable"] is True
    assert not (rec / "INCOMPLETE").exists()
    sent = (rec / "seg0000" / "uart" / "spinal.host_tx.bin").read_bytes()
    assert len(sent) > 10_000 and sent == (run / "uart" / "spinal.host_tx.bin").read_bytes()
    assert (rec / "robot.urdf").read_bytes() == (SHIPPED / "rdm.urdf").read_bytes()
    result = rdm_cli("replay", str(run), "--json")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["identical"] and report["ticks"] == 120 and report["notes"] == []
    assert report["streams"]["spinal"]["replayed_bytes"] == len(sent)
    # a version-1 header (a shipped robot by name, no copies) still replays
    old = tmp_path / "v1"
    shutil.copytree(rec, old)
    (old / "robot.urdf").unlink()
    (old / "robot.toml").unlink()
    journal = old / "seg0000" / "journal.jsonl"
    lines = journal.read_text().splitlines()
    head = json.loads(lines[0])
    del head["files"]
    head["version"] = 1
    journal.write_text("\n".join([json.dumps(head), *lines[1:]]) + "\n")
    assert rdm_cli("replay", str(old)).returncode == 0
    # a segment missing between two kept ones is named
    (old / "seg0002").mkdir()
    (old / "seg0002" / "journal.jsonl").write_text(lines[0] + "\n")
    out = rdm_cli("replay", str(old))
    assert out.returncode == 2 and out.stderr == (
        f"rdm replay: {old}: seg0001/journal.jsonl is missing, seg0002 follows it; a replay "
        "needs every segment in order\n"
    )


def test_rdm_sim_record_onboard_is_for_one_run(tmp_path) -> None:
    out = rdm_cli("sim", "hover", "--seeds", "2", "--record-onboard", "--out", str(tmp_path))
    assert out.returncode == 2
    assert out.stderr == "rdm sim: --record-onboard is for one run (no --seeds or --randomize)\n"
