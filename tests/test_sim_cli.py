"""``rdm sim`` as a user runs it: a subprocess of the installed package, progress on stderr,
the metrics as JSON on stdout, the run folder on disk."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

import rdm


def test_rdm_sim_hover_json_progress_and_run_folder(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(Path(rdm.__file__).resolve().parent.parent))
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "rdm.cli",
            "sim",
            "hover",
            "--duration",
            "3",
            "--out",
            str(tmp_path),
            "--json",
            "--wire-mcap",
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )
    assert out.returncode in (0, 1), out.stderr  # 1 = a metric failed (a 3 s hover is short)
    summary = json.loads(out.stdout)
    names = [m["name"] for m in summary["metrics"]]
    assert "final CoG height" in names
    assert "/ 3 s simulated" in out.stderr  # the progress line
    folder = tmp_path / "hover-seed0"
    for rel in ("signals.mcap", "can.log", "summary.json", "metrics.txt"):
        assert (folder / rel).stat().st_size > 0, rel
    assert json.loads((folder / "summary.json").read_text()) == summary
    # the figure, drawn by the plot worker process, is written before the command returns
    assert (folder / "plots" / "hover.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # --wire-mcap: every capture time-indexed, the wire MCAP beside them (stdout stays JSON)
    captures = sorted((folder / "uart").glob("*_tx.*[!x]"))  # not the .idx files
    assert [c.name for c in captures] == [
        "leptrino_foot.device_tx.lep",
        "leptrino_foot.host_tx.lep",
        "spinal.device_tx.bin",
        "spinal.host_tx.bin",
    ]
    for capture in captures:
        assert (capture.parent / (capture.name + ".idx")).stat().st_size > 8, capture
    with open(folder / "wire.mcap", "rb") as f:
        summary_ = make_reader(f).get_summary()
    counts = {
        summary_.channels[cid].topic: n
        for cid, n in summary_.statistics.channel_message_counts.items()
    }
    assert 590 <= counts["/wire/spinal/device_tx/imu"] <= 600  # 200 Hz over 3 s
    assert counts["/wire/can/pwm"] > 0
    assert f"wire.mcap: {sum(counts.values())} messages on {len(counts)} channels" in out.stderr


def test_rdm_sim_perching_imports_only_what_it_runs():
    """The registry imports a scenario's module when it runs: ``rdm sim perching`` does not
    load the other experiments, scipy.spatial or matplotlib before the figures."""
    env = dict(os.environ, PYTHONPATH=str(Path(rdm.__file__).resolve().parent.parent))
    code = (
        "import sys; from rdm.scenarios import SCENARIOS; import rdm.commands.sim; "
        "s = SCENARIOS['perching']; d = s.default_duration; r = s.run; "
        "print(d, r.__module__, sorted(m for m in ('rdm.scenarios.flight', "
        "'rdm.scenarios.tracking', 'rdm.scenarios.push', 'rdm.scenarios.tasks', "
        "'scipy.spatial', 'matplotlib') if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["64.0", "rdm.scenarios.perching_foot_at_plate", "[]"]


def test_every_registered_scenario_resolves_to_its_module():
    from rdm.scenarios import (
        DEFAULT_SCENARIO,
        SCENARIOS,
        flight,
        hover,
        mission,
        perching,
        perching_foot_at_plate,
        push,
        push_paper,
        tasks,
        tracking,
        wall_perching,
    )

    # the paper's posture (Sec. VII-B, Table VII) is the default perching run
    assert DEFAULT_SCENARIO == "perching" and perching_foot_at_plate.NAME == "perching"
    assert perching.NAME == "perching-hanging"
    expect = {
        "hover": (hover.run, hover.DEFAULT_DURATION),
        "flight": (flight.run, flight.DEFAULT_DURATION),
        "mission": (mission.run, mission.DEFAULT_DURATION),
        "perching": (perching_foot_at_plate.run, perching_foot_at_plate.DEFAULT_DURATION),
        "perching-hanging": (perching.run, perching.DEFAULT_DURATION),
        "wall-perching": (wall_perching.run, wall_perching.DEFAULT_DURATION),
        "push": (push.run, push.DEFAULT_DURATION),
        "push-paper-forces": (push_paper.run, push_paper.DEFAULT_DURATION),
        "tracking": (tracking.run, tracking.DEFAULT_DURATION),
        "drilling": (tasks.run_drilling, tasks.duration_of("drilling")),
        "painting": (tasks.run_painting, tasks.duration_of("painting")),
        "painting-panel": (tasks.run_painting_panel, tasks.duration_of("painting-panel")),
        "valve": (tasks.run_valve, tasks.duration_of("valve")),
    }
    assert set(SCENARIOS) == set(expect)
    for name, (run, duration) in expect.items():
        sc = SCENARIOS[name]
        assert sc.name == name and sc.run is run and sc.default_duration == duration, name
        assert sc.description and "\n" not in sc.description


def _sim(args: list[str], timeout: float = 600) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(Path(rdm.__file__).resolve().parent.parent))
    cmd = [sys.executable, "-m", "rdm.cli", "sim", *args]
    return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout)


def test_rdm_sim_servo_lead_reaches_the_onboard_node(tmp_path):
    out = _sim(["hover", "--duration", "1", "--servo-lead", "0.02", "--out", str(tmp_path)])
    assert out.returncode in (0, 1), out.stderr
    summary = json.loads((tmp_path / "hover-seed0" / "summary.json").read_text())
    assert summary["servo_lead_s"] == 0.02
    bad = _sim(["hover", "--servo-lead", "-0.1"], timeout=120)
    assert bad.returncode == 2 and "--servo-lead" in bad.stderr


def test_rdm_sim_rejects_unknown_scenario():
    out = _sim(["no-such-experiment"], timeout=120)
    assert out.returncode == 2
    assert "invalid choice" in out.stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--duration", "inf"], "--duration: 'inf' must be finite and > 0"),
        (["--duration", "nan"], "--duration: 'nan' must be finite and > 0"),
        (["--duration", "-1"], "--duration: '-1' must be finite and > 0"),
        (["--duration", "ten"], "--duration: 'ten': not a number"),
        (["--seed", "-5"], "--seed: '-5' must be >= 0"),
        (["--seed", "1.5"], "--seed: '1.5': not an integer"),
        (["--out", "/proc/rdm-no-such-folder", "--duration", "0.1"], "--out"),
    ],
)
def test_rdm_sim_refuses_bad_arguments_with_a_message_not_a_traceback(args, message):
    out = _sim(["hover", *args], timeout=120)
    assert out.returncode == 2, out.stderr
    assert message in out.stderr
    assert "Traceback" not in out.stderr


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["onboard", "--uart", "pty", "--duration", "-1"], "'-1' must be finite and > 0"),
        (["spinal", "--uart", "pty", "--can", "virtual:x", "--duration", "inf"], "'inf' must"),
        (["neuron", "--can", "virtual:x", "--duration", "0"], "'0' must be finite and > 0"),
        (["hil", "--scale", "inf"], "--scale: 'inf' must be finite and > 0"),
        (["hil", "--seed", "-1"], "--seed: '-1' must be >= 0"),
    ],
)
def test_the_node_commands_refuse_bad_durations_scales_and_seeds(argv, message, capsys):
    from rdm.cli import main

    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
