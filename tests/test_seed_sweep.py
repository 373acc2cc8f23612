"""``rdm sim SCENARIO --seeds N``: each seed's run folder is read back independently
(``summary.json`` with ``json.loads``) and the sweep's rows must hold exactly those values,
their median (``statistics.median``), ordered percentiles and pass counts; bad options exit 2
naming the option; a run that fails is reported, not fatal."""

from __future__ import annotations

import json
import math
import os
import statistics
import subprocess
import sys
from pathlib import Path

import pytest

import rdm
from rdm.scenarios.seed_sweep import report, run_seed


def _sim(args: list[str], timeout: float = 600) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(Path(rdm.__file__).resolve().parent.parent))
    cmd = [sys.executable, "-m", "rdm.cli", "sim", *args]
    return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout)


def test_sweep_rows_are_the_runs_own_metrics(tmp_path):
    sweep = ["--seeds", "3", "--seed", "4", "--duration", "3", "--workers", "2"]
    out = _sim(["hover", *sweep, "--out", str(tmp_path), "--json"])
    assert out.returncode in (0, 1), out.stderr
    doc = json.loads(out.stdout)
    assert doc == json.loads((tmp_path / "sweep-hover.json").read_text())
    assert doc["seeds"] == [4, 5, 6] and doc["runs_completed"] == 3 and not doc["failed_runs"]
    runs = [
        json.loads((tmp_path / f"hover-seed{k}" / "summary.json").read_text()) for k in (4, 5, 6)
    ]
    assert [r["seed"] for r in runs] == [4, 5, 6]
    assert doc["runs_all_passed"] == sum(bool(r["all_passed"]) for r in runs)
    names = [m["name"] for m in runs[0]["metrics"]]
    assert [m["name"] for m in doc["metrics"]] == names
    varied = 0
    for row in doc["metrics"]:
        own = [next(m for m in r["metrics"] if m["name"] == row["name"]) for r in runs]
        values = [m["ours"] for m in own]
        assert row["values"] == values
        assert row["paper"] == own[0]["paper"] and row["unit"] == own[0]["unit"]
        verdicts = [m["passed"] for m in own if m["passed"] is not None]
        assert (row["passed"], row["judged"]) == (sum(verdicts), len(verdicts))
        finite = [v for v in values if v is not None and math.isfinite(v)]
        assert row["n_nan"] == 3 - len(finite)
        if finite:
            assert row["median"] == statistics.median(finite)
            assert row["min"] <= row["p10"] <= row["median"] <= row["p90"] <= row["max"]
            assert (row["min"], row["max"]) == (min(finite), max(finite))
            varied += len(set(finite)) > 1
    assert varied >= 1  # the seeds change the noise: not one run copied three times


def test_sweep_refuses_bad_options():
    for args, word in (
        (["hover", "--seeds", "0"], "--seeds"),
        (["all"], "--seeds"),
        (["hover", "--workers", "2"], "--workers"),
        (["hover", "--seeds", "2", "--wire-mcap"], "--seeds"),
    ):
        out = _sim(args, timeout=120)
        assert out.returncode == 2 and word in out.stderr, (args, out.stderr)
        assert "Traceback" not in out.stderr


def test_the_default_duration_is_the_scenarios(tmp_path):
    from rdm.scenarios import SCENARIOS
    from rdm.scenarios.mission import QUICK_DURATION

    done = run_seed("hover", str(tmp_path), 0, None, {})
    assert done.error is None
    assert done.summary["simulated_s"] == pytest.approx(SCENARIOS["hover"].default_duration)
    quick = run_seed("mission", str(tmp_path), 0, None, {"quick": True})
    assert quick.error is None and quick.summary["simulated_s"] <= QUICK_DURATION


def test_a_failed_seed_is_reported_not_fatal(tmp_path):
    bad = run_seed("hover", str(tmp_path), 0, -1.0, {})
    good = run_seed("hover", str(tmp_path), 1, 1.0, {})
    assert bad.summary is None and bad.error and good.error is None
    doc = report("hover", [bad, good])
    assert doc["runs_completed"] == 1
    assert doc["failed_runs"] == [{"seed": 0, "error": bad.error}]
    json.loads(json.dumps(doc, allow_nan=False))
