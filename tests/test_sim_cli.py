"""``rdm sim`` as a user runs it: a subprocess of the installed package, progress on stderr,
the metrics as JSON on stdout, the run folder on disk."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

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


def test_rdm_sim_rejects_unknown_scenario():
    env = dict(os.environ, PYTHONPATH=str(Path(rdm.__file__).resolve().parent.parent))
    out = subprocess.run(
        [sys.executable, "-m", "rdm.cli", "sim", "no-such-experiment"],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert out.returncode == 2
    assert "invalid choice" in out.stderr
