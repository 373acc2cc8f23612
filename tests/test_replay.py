"""The onboard node's flight recorder and ``rdm replay``: a lockstep run and a process run
replay byte for byte; a planted difference is found at its byte; rotation bounds the folder;
the folder rules of a run folder hold."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from spinal_peer import read_line, spinal_mirror_pty
from test_onboard_cli import free_udp_port

from rdm.ground.auth import load_key, write_key
from rdm.ground.client import GroundClient
from rdm.link.capture_index import read_capture_index
from rdm.nodes.flight_recorder import decode_value, encode_value
from rdm.nodes.flight_replay import replay

pytestmark = pytest.mark.timeout(300)
RDM = [sys.executable, "-m", "rdm.cli"]
ENV = dict(os.environ, PYTHONUNBUFFERED="1")
#: Simulated seconds of the lockstep run: arming at 1.5 s, commands to Spinal from then on.
LOCKSTEP_S = 3.0


def rdm(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*RDM, *args], capture_output=True, text=True, timeout=240, env=ENV, cwd=cwd
    )


def folder_bytes(root: Path) -> int:
    return sum(p.stat().st_size for p in root.rglob("*") if p.is_file())


@pytest.fixture(scope="module")
def lockstep_run(tmp_path_factory) -> Path:
    """A ``hover`` stack (the simulator's Spinal, foot sensor and motion capture on the node's
    ports and inputs) with its onboard node recorded into the run folder's ``onboard/``."""
    from rdm.scenarios.common import sim_stack_options
    from rdm.scenarios.hover import HOVER_Z, make_script
    from rdm.scenarios.stack import build_stack

    base = tmp_path_factory.mktemp("lockstep")
    run = base / "hover-seed0"
    opts = dataclasses.replace(
        sim_stack_options(0, "inproc"), record_onboard=str(run / "onboard"), log=False
    )
    stack = build_stack("hover", base, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))
    try:
        stack.loop.run(LOCKSTEP_S)
    finally:
        stack.close()
    return run


def test_a_lockstep_run_replays_byte_for_byte(lockstep_run) -> None:
    """The recorder's captures are the bytes on the simulator's own wire (its device-end
    captures, written independently), and the replay writes the same bytes."""
    rec = lockstep_run / "onboard" / "seg0000" / "uart"
    sim = lockstep_run / "uart"
    # what the node wrote is what the simulated Spinal end received, byte for byte
    assert (rec / "spinal.host_tx.bin").read_bytes() == (sim / "spinal.host_tx.bin").read_bytes()
    # what the node read is what Spinal sent up to the node's last tick
    read = (rec / "spinal.device_tx.bin").read_bytes()
    assert len(read) > 10_000 and (sim / "spinal.device_tx.bin").read_bytes().startswith(read)
    foot = (rec / "leptrino_foot.device_tx.lep").read_bytes()
    assert foot and (sim / "leptrino_foot.device_tx.lep").read_bytes().startswith(foot)
    # each read is indexed at the tick that made it: 40 Hz ticks from 0
    idx = read_capture_index(rec / "spinal.device_tx.bin")
    assert all(t % 25_000_000 == 0 for t in idx.times_ns)

    report = replay(lockstep_run)  # the run folder: its onboard/ recording
    assert report["identical"], report
    assert report["ticks"] == round(LOCKSTEP_S * 40)
    assert report["calls"] > 100  # motion capture at 100 Hz, the target and arm
    spinal = report["streams"]["spinal"]
    assert (
        spinal["recorded_bytes"]
        == spinal["replayed_bytes"]
        == len((rec / "spinal.host_tx.bin").read_bytes())
    )
    out = rdm("replay", str(lockstep_run), "--json")
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["identical"] is True


def _planted(run: Path, tmp_path: Path, capture: str, offset: int) -> tuple[int, dict]:
    copy = tmp_path / "planted"
    shutil.copytree(run / "onboard", copy)
    path = copy / "seg0000" / "uart" / capture
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x01
    path.write_bytes(bytes(data))
    out = rdm("replay", str(copy), "--json")
    assert out.returncode in (0, 1), out.stderr
    return out.returncode, json.loads(out.stdout)


def test_a_flipped_output_byte_is_reported_at_its_offset_and_time(lockstep_run, tmp_path):
    rec = lockstep_run / "onboard" / "seg0000" / "uart" / "spinal.host_tx.bin"
    offset = len(rec.read_bytes()) * 2 // 3
    code, report = _planted(lockstep_run, tmp_path, "spinal.host_tx.bin", offset)
    assert code == 1 and report["identical"] is False
    diff = report["streams"]["spinal"]["first_difference"]
    assert diff["offset"] == offset
    assert diff["recorded"] == diff["replayed"] ^ 0x01
    t = read_capture_index(rec).time_ns_of(offset) / 1e9
    assert diff["recorded_time_s"] == pytest.approx(t) == pytest.approx(diff["replayed_time_s"])


def test_a_flipped_input_byte_changes_what_the_node_writes(lockstep_run, tmp_path) -> None:
    """Byte 10 lies in Spinal's first rosserial frame (a topic of its handshake): corrupted,
    the node learns the topic later and its output differs."""
    code, report = _planted(lockstep_run, tmp_path, "spinal.device_tx.bin", 10)
    assert code == 1 and report["streams"]["spinal"]["first_difference"] is not None


def test_a_changed_input_call_changes_what_the_node_writes(lockstep_run, tmp_path) -> None:
    """The hover target in the journal moved by 1 mm: the commands after arming differ."""
    copy = tmp_path / "moved"
    shutil.copytree(lockstep_run / "onboard", copy)
    journal = copy / "seg0000" / "journal.jsonl"
    lines = journal.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if '"call":"set_target"' in line)
    entry = json.loads(lines[k])
    target = decode_value(entry["args"])[0]
    entry["args"] = encode_value([target + np.array([0.0, 0.0, 0.001]), 0.0])
    lines[k] = json.dumps(entry)
    journal.write_text("\n".join(lines) + "\n")
    report = replay(copy)
    assert not report["identical"]
    assert report["streams"]["spinal"]["first_difference"]["recorded_time_s"] >= 1.5


def test_input_values_keep_their_type_and_bits() -> None:
    values = [0.1 + 0.2, np.array([1e-300, -0.0, np.nan]), (1, "a"), {"k": [np.float64(2.5)]}]
    back = decode_value(json.loads(json.dumps(encode_value(values))))
    assert back[0] == 0.1 + 0.2 and isinstance(back[2], tuple)
    assert back[1].tobytes() == values[1].tobytes()
    assert type(back[3]["k"][0]) is np.float64
    with pytest.raises(TypeError, match="object"):
        encode_value([object()])


# ------------------------------------------------------------------------------ processes
@pytest.fixture
def spinal_pty():
    """``rdm spinal`` (the Spinal mirror) on a pty; yields the path the node opens."""
    with spinal_mirror_pty(f"replay{os.getpid()}") as path:
        yield path


def test_a_process_run_replays_byte_for_byte(spinal_pty, tmp_path) -> None:
    """``rdm onboard`` against the Spinal mirror with ground-link commands (motion capture,
    a gain profile), stopped by SIGTERM: ``rdm replay`` writes the same bytes."""
    key = tmp_path / "robot.key"
    write_key(key)
    port = free_udp_port()
    record = tmp_path / "rec"
    proc = subprocess.Popen(
        [*RDM, "onboard", "--uart", f"serial:{spinal_pty}", "--foot-sensor", "none", "--arm",
         "--control", f"udp:127.0.0.1:{port}", "--key", str(key), "--record", str(record)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV,
    )  # fmt: skip
    try:
        read_line(proc, "rdm onboard: ready")
        client = GroundClient(f"udp:127.0.0.1:{port}", load_key(key), timeout_s=5.0)
        try:
            for _ in range(600):  # until 40 gain messages went out (about 1 s after handshake)
                node = client.command("status")["result"]["node"]
                if node["published"].get("rpy/gain", 0) >= 40:
                    break
            for k in range(20):
                args = {"position": [0.01 * k, 0.0, 0.1], "velocity": [0.0] * 3, "yaw": 0.0}
                ack = client.command("mocap", args)
                assert ack["outcome"] == "accepted", ack
            client.command("takeoff", {"height": 0.3})
        finally:
            client.close()
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    status = json.loads(out.strip().splitlines()[-1])
    assert not (record / "INCOMPLETE").exists()
    summary = json.loads((record / "summary.json").read_text())
    assert summary["replayable"] and summary["calls"] >= 21
    assert status["ticks"] == summary["ticks"]
    lines = (record / "seg0000" / "journal.jsonl").read_text().splitlines()
    datagrams = [bytes.fromhex(json.loads(x)["datagram"]) for x in lines if '"note"' in x]
    assert sum(b'"cmd":"mocap"' in d for d in datagrams) == 20  # each as it arrived
    calls = [json.loads(x)["call"] for x in lines if '"call"' in x]
    assert calls.count("set_mocap") == 20 and calls[0] == "arm" and "takeoff" in calls

    result = rdm("replay", str(record))
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.startswith("rdm replay: identical:")
    report = replay(record)
    sent = (record / "seg0000" / "uart" / "spinal.host_tx.bin").read_bytes()
    assert report["streams"]["spinal"]["replayed_bytes"] == len(sent) > 5_000
    assert report["calls"] == summary["calls"] and report["ticks"] == summary["ticks"]


def test_rotation_bounds_the_folder(spinal_pty, tmp_path) -> None:
    """A 30 kB bound: segments of 3.75 kB rotate, the oldest are deleted, the folder stays
    within the bound and one segment; the replay then says the start is missing."""
    record = tmp_path / "rec"
    out = rdm("onboard", "--uart", f"serial:{spinal_pty}", "--foot-sensor", "none",
              "--duration", "3", "--record", str(record), "--record-max-mb", "0.03")  # fmt: skip
    assert out.returncode == 0, out.stderr
    summary = json.loads((record / "summary.json").read_text())
    assert summary["dropped_segments"] >= 1 and not summary["replayable"]
    assert summary["max_bytes"] == 30_000 and summary["segment_bytes"] == 3_750
    # ASSUMPTION: one tick adds at most 4 kB (the handshake's burst) to a full segment
    assert folder_bytes(record) <= 30_000 + 3_750 + 4_000
    assert not (record / "seg0000").exists()
    kept = sorted(p.name for p in record.glob("seg*"))
    assert kept[0] == f"seg{summary['dropped_segments']:04d}" == f"seg{summary['segments'][0]:04d}"
    result = rdm("replay", str(record))
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr == (
        f"rdm replay: {record}: cannot replay exactly: rotation deleted seg0000.."
        f"seg{summary['dropped_segments'] - 1:04d} and the first segment kept is {kept[0]}; a "
        "replay starts at the flight's start (the node's state at a later segment is not "
        "recorded)\n"
    )
    # the robot description's copies are kept and counted in the bound
    assert summary["copies_bytes"] == sum(
        (record / n).stat().st_size for n in ("robot.urdf", "robot.toml")
    )


def test_the_record_folder_follows_the_run_folder_rules(tmp_path) -> None:
    """A non-empty folder is refused in one line unless --replace; a symbolic link is never
    followed; --no-record writes nothing; the default folder is under runs/."""
    full = tmp_path / "full"
    full.mkdir()
    (full / "keep.txt").write_text("x")
    base = ["onboard", "--uart", "pty", "--duration", "0.2"]
    out = rdm(*base, "--record", str(full))
    assert out.returncode == 2 and out.stderr.count("\n") == 1
    assert "not empty; --replace" in out.stderr and (full / "keep.txt").exists()
    assert rdm(*base, "--record", str(full), "--replace").returncode == 0
    assert not (full / "keep.txt").exists() and (full / "summary.json").is_file()
    target = tmp_path / "target"
    target.mkdir()
    (tmp_path / "link").symlink_to(target)
    out = rdm(*base, "--record", str(tmp_path / "link"))
    assert out.returncode == 2 and "symbolic link" in out.stderr
    assert not any(target.iterdir())
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    assert rdm(*base, "--no-record", cwd=cwd).returncode == 0 and not any(cwd.iterdir())
    assert rdm(*base, cwd=cwd).returncode == 0
    (made,) = (cwd / "runs").iterdir()
    assert made.name.startswith("onboard-") and (made / "seg0000" / "journal.jsonl").is_file()


def test_a_broken_journal_is_refused_in_one_line(lockstep_run, tmp_path) -> None:
    copy = tmp_path / "broken"
    shutil.copytree(lockstep_run / "onboard", copy)
    journal = copy / "seg0000" / "journal.jsonl"
    lines = journal.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if '"call":"arm"' in line)
    lines[k] = lines[k].replace('"args"', '"argz"')
    journal.write_text("\n".join(lines) + "\n")
    out = rdm("replay", str(copy))
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert out.stderr == f"rdm replay: {journal}: line {k + 1}: 'args'\n"
