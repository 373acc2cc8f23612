"""``rdm sim perching-hanging --randomize N``: the draws stay in their documented ranges and are
reproducible; the MuJoCo model a draw builds carries its friction, masses and CoG (read back
from the compiled model against a nominal one); the campaign's counts are the run folders'
own ``summary.json`` verdicts (read back with ``json.loads``), its JSON valid, its PNG a PNG; a
draw with noisy motion capture (seed 36) flies without a false lost rotor."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

import rdm
from rdm.plant import Plant
from rdm.plant.mjcf import CEILING_GEOM
from rdm.scenarios.common import roll_pitch, truth_arrays
from rdm.scenarios.robustness import Conditions, _Scene, draw


def test_draws_are_reproducible_and_in_range():
    draws = [draw(s) for s in range(200)]
    assert draw(7) == draws[7] and draws[7] != draws[8]
    for c in draws:
        assert 0.7 <= c.friction_scale <= 1.3 and 0.95 <= c.mass_scale <= 1.05
        assert all(abs(v) <= 0.005 for v in c.cog_offset_m) and c.cog_offset_m[1] == 0.0
        assert 0.7 <= c.servo_kp_scale <= 1.3 and 0.005 <= c.mocap_latency_s <= 0.025
        assert 1.0 <= c.mocap_noise_scale <= 3.0 and 22.8 <= c.battery_voltage <= 25.2
    spread = np.array([c.friction_scale for c in draws])
    assert spread.min() < 0.75 and spread.max() > 1.25  # the range is used, not one value


def test_a_draw_changes_the_compiled_model():
    c = Conditions(1.2, 1.04, (0.003, 0.0, -0.002), 1.0, 0.01, 1.0, 25.2)
    nominal, drawn = (
        Plant("rdm", ceiling_height=1.6),
        Plant("rdm", ceiling_height=1.6, scene=_Scene(c)),
    )
    m0, m1 = nominal.model, drawn.model
    np.testing.assert_allclose(m1.body_mass[1:], m0.body_mass[1:] * 1.04, rtol=1e-12)
    for geom in (CEILING_GEOM, "foot_plate_box"):
        g0, g1 = m0.geom(geom).friction, m1.geom(geom).friction
        np.testing.assert_allclose(g1[:2], g0[:2] * 1.2, rtol=1e-12)
        assert g1[2] == g0[2]
    root = m0.body("root_link").id
    np.testing.assert_allclose(
        m1.body_ipos[root] - m0.body_ipos[root], [0.003, 0.0, -0.002], atol=1e-12
    )


def test_campaign_counts_are_the_runs_verdicts(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(Path(rdm.__file__).resolve().parent.parent))
    cmd = [sys.executable, "-m", "rdm.cli", "sim", "perching-hanging", "--randomize", "2"]
    cmd += ["--seed", "3"]
    cmd += ["--duration", "17", "--workers", "2", "--out", str(tmp_path), "--json"]
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode in (0, 1), out.stderr
    doc = json.loads(out.stdout)
    assert doc == json.loads((tmp_path / "robustness-perching.json").read_text())
    assert (tmp_path / "robustness-perching.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert doc["runs"] == 2 and [r["seed"] for r in doc["per_run"]] == [3, 4]
    verdicts = []
    for r in doc["per_run"]:
        assert r["conditions"] == json.loads(json.dumps(asdict(draw(r["seed"]))))
        summary = json.loads((Path(r["folder"]) / "summary.json").read_text())
        assert summary["seed"] == r["seed"]
        verdicts.append(summary["all_passed"])
        assert r["success"] == summary["all_passed"]
        failed = [m["name"] for m in summary["metrics"] if m["passed"] is False]
        assert r["failed_metrics"] == failed
    assert doc["succeeded"] == sum(verdicts)
    assert doc["success_rate"] == pytest.approx(sum(verdicts) / 2)
    assert (out.returncode == 0) == all(verdicts)


def test_randomize_refuses_other_scenarios():
    env = dict(os.environ, PYTHONPATH=str(Path(rdm.__file__).resolve().parent.parent))
    cmd = [sys.executable, "-m", "rdm.cli", "sim", "hover", "--randomize", "2"]
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 2 and "--randomize" in out.stderr and "Traceback" not in out.stderr


def test_drawn_noisy_motion_capture_cuts_no_motor(tmp_path, monkeypatch):
    """Seed 36's draw (motion capture 2.6 x the nominal noise, 23 ms late): the roll target
    jumps 1-2.5 deg from tick to tick and the attitude loop follows it, which the light
    rotor's rule once took for a dead rotor 3 at 3.55 s and cut the motors. No rotor is
    lost, so no ``rotor_lost`` and no cut: the robot still flies at 5 s, its true tilt small
    (docs/flying.md "A lost rotor")."""
    from rdm.scenarios import perching, robustness

    results = []
    run = perching.run

    def keep(*args, **kwargs):
        results.append(run(*args, **kwargs))
        return results[-1]

    monkeypatch.setattr(perching, "run", keep)
    out = robustness.run_drawn(str(tmp_path), 36, 5.0, True)
    assert "error" not in out
    stack = results[0].stack
    counts = stack.onboard.monitors.counts
    assert counts["rotor_lost"] == 0 and counts["rotor_lost_cut"] == 0
    assert stack.spinal.core.armed
    a = truth_arrays(stack)
    flying = (a["t"] > 3.0) & (a["t"] < 4.0)  # before the joint motion
    assert np.degrees(np.abs(roll_pitch(a["quat"][flying]))).max() < 10.0
