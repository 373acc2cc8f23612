"""`rdm bench` end to end from `rdm.cli.main`: every case, peer and field in the JSON with
finite values, zero failed solves of our own; missing peers are skipped, not fatal.
No timing thresholds here (targets live in the report only)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import pytest

from rdm.bench.cases import CASES
from rdm.cli import main

SUMMARY_FIELDS = ("median_us", "p99_us", "p999_us", "max_us", "mean_us", "min_us")
CASE_FIELDS = (*SUMMARY_FIELDS, "budget_us", "fraction_of_budget")
PEER_FIELDS = (*SUMMARY_FIELDS, "fraction_of_budget", "speedup", "max_error")


def finite(x: object) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def run_json(tmp_path: Path, *args: str) -> tuple[dict, str]:
    out = tmp_path / "bench.json"
    assert main(["bench", *args, "--json", str(out)]) == 0
    return json.loads(out.read_text()), str(out)


def test_quick_run_writes_every_case_peer_and_field(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    doc, _ = run_json(tmp_path, "--quick", "--iterations", "200")
    captured = capsys.readouterr()
    assert doc["schema"] == "rdm.bench/1"
    expected = {m for c in CASES.values() for m in c.measurements}
    assert set(doc["cases"]) == expected
    for name, c in doc["cases"].items():
        for f in CASE_FIELDS:
            assert finite(c[f]), (name, f, c[f])
            assert c[f] >= 0
        assert c["n"] == 200
        assert c["failures"] == 0, name
        assert c["median_us"] <= c["p99_us"] <= c["p999_us"] <= c["max_us"]
        assert c["fraction_of_budget"] == pytest.approx(c["median_us"] / c["budget_us"])
        for stat, frac in c["fractions_of_budget"].items():
            assert frac == pytest.approx(c[f"{stat}_us"] / c["budget_us"])
        assert c["target"], name
        for kind, t in c["target"].items():
            assert finite(t["limit"]) and finite(t["value"]), (name, kind)
            assert isinstance(t["met"], bool)
        group = CASES[c["group"]]
        assert set(c["peers"]) == set(group.peers)
        for peer, p in c["peers"].items():
            assert "skipped" not in p, (peer, p)
            for f in PEER_FIELDS:
                assert finite(p[f]), (name, peer, f)
            assert p["n"] == 200
            assert p["speedup"] == pytest.approx(p["median_us"] / c["median_us"])
            assert p["failures"] == sum(p["failure_statuses"].values())
    assert doc["failed_solves_ours"] == 0
    # Peers solving the same problems agree with us where they claim success.
    lqi_peer = doc["cases"]["lqi_warm_rust"]["peers"]["scipy_care"]
    assert lqi_peer["max_error"] < 1e-6
    tick_peers = doc["cases"]["tick_40hz_rust"]["peers"]
    # Exact active-set answer vs an interior point at gap 1e-8: ≤ 5e-3 N (docs/perch.md).
    assert tick_peers["clarabel_py_setup_solve"]["max_error"] < 5e-3
    assert tick_peers["osqp_eps1e-6_update_solve"]["max_error"] < 1e-2
    m = doc["machine"]
    assert m["cpu_model"] and m["logical_cores"] >= 1
    assert len(m["load_average_start"]) == 3 and len(m["load_average_end"]) == 3
    assert 0.0 <= m["cpu_steal_share"] <= 1.0 and "cpu_ticks_start" not in m
    assert m["wheel_build_profile"] in ("release", "debug")
    for pkg in ("numpy", "scipy", "osqp", "clarabel"):
        assert m["versions"][pkg]
    # Human report on stdout, progress on stderr.
    for name in expected:
        assert name in captured.out
    assert f"[{len(CASES)}/{len(CASES)}]" in captured.err


def test_only_selects_a_case_and_unknown_names_fail(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    doc, _ = run_json(tmp_path, "--only", "spinal_step_python", "--iterations", "50")
    assert set(doc["cases"]) == {"spinal_step_rust", "spinal_step_python"}
    assert main(["bench", "--only", "nope"]) == 2
    assert "unknown case 'nope'" in capsys.readouterr().err


def test_missing_peers_are_skipped_with_a_reason(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    # A None entry in sys.modules makes `import osqp` raise ImportError, as if absent.
    monkeypatch.setitem(sys.modules, "osqp", None)
    doc, _ = run_json(tmp_path, "--only", "tick_40hz", "--iterations", "40")
    peers = doc["cases"]["tick_40hz_rust"]["peers"]
    for name, p in peers.items():
        if name.startswith("osqp"):
            assert "osqp not importable" in p["skipped"]
        else:
            assert finite(p["median_us"]) and p["failures"] == 0
    t = doc["cases"]["tick_40hz_rust"]["target"]["faster_than:osqp_setup_solve"]
    assert t["value"] is None and t["met"] is None
    assert "SKIPPED" in capsys.readouterr().out


def test_missing_scipy_skips_the_care_peer(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "scipy", None)
    doc, _ = run_json(tmp_path, "--only", "lqi", "--iterations", "20")
    for name in ("lqi_warm_rust", "lqi_cold_python"):
        assert "scipy not importable" in doc["cases"][name]["peers"]["scipy_care"]["skipped"]
        assert finite(doc["cases"][name]["median_us"])
