"""A robot's rotor count comes from its description: the six-rotor test robot
(tests/data/robots/hexa) and random eight-rotor layouts through the LQI core, the gyro
compensation, the wire forms, the configuration check and the control pipeline, each checked
against scipy / numpy computed independently of the core."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
import scipy.spatial.transform
from lqi_reference import hover_state_model

from rdm import _rdm
from rdm.cli import main as rdm_main
from rdm.control import lqi
from rdm.model import Robot
from rdm.nodes.onboard_config import OnboardConfig
from rdm.nodes.onboard_control import ControlPipeline

HEXA = Path(__file__).parent / "data" / "robots" / "hexa" / "hexa.toml"
#: diag(W1) of Table V (JSK state order), written out here rather than read from the core.
TABLE_V_Q = np.array([20.0, 30.0, 90.0, 12.8, 600.0, 80.0, 100.0, 50.0, 20.0, 0.15, 1.0, 0.5])
DRAG_RATIO = 0.016


def scipy_gain(mass: float, inertia: np.ndarray, alloc: np.ndarray, r: np.ndarray) -> np.ndarray:
    """K = -R^-1 B^T P of the hover LQI system, P from scipy's CARE solver."""
    a, b = hover_state_model(mass, inertia, alloc)
    p = scipy.linalg.solve_continuous_are(a, b, np.diag(TABLE_V_Q), np.diag(r))
    return -np.linalg.solve(np.diag(r), b.T @ p)


def rel(x: np.ndarray, y: np.ndarray) -> float:
    return float(np.linalg.norm(x - y) / np.linalg.norm(y))


def hexa_terms(q: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, dict]:
    robot = Robot.load(HEXA)
    e = robot.evaluate(q)
    return float(e["mass"]), np.asarray(e["inertia"]), np.asarray(e["allocation_bar"]), e


def random_layout(rng: np.random.Generator, rotors: int) -> tuple[float, np.ndarray, np.ndarray]:
    """Random plausible (m, I, Q_bar) of ``rotors`` rotors around the CoG (eqs. 8-9)."""
    mass = rng.uniform(1.5, 8.0)
    rot = scipy.spatial.transform.Rotation.random(random_state=rng).as_matrix()
    inertia = rot @ np.diag(rng.uniform([0.02, 0.02, 0.05], [0.3, 0.6, 0.8])) @ rot.T
    alloc = np.zeros((4, rotors))
    for i in range(rotors):
        ang = i * 2 * np.pi / rotors + rng.uniform(-0.3, 0.3)
        rad = rng.uniform(0.2, 0.8)
        p = np.array([rad * np.cos(ang), rad * np.sin(ang), rng.uniform(-0.05, 0.05)])
        tilt = scipy.spatial.transform.Rotation.from_euler("xy", rng.uniform(-0.3, 0.3, 2))
        u = tilt.apply([0.0, 0.0, 1.0])
        v = np.cross(p, u) - DRAG_RATIO * (-1.0) ** i * u
        alloc[:, i] = [u[2], *v]
    return mass, inertia, alloc


def test_hexa_allocation_is_eq8_of_its_six_rotors():
    """The model reads six rotors from the file; Q_bar's columns are eq. (8) of each rotor
    (thrust direction z, p x u - c sigma u in the CoG frame) rebuilt in numpy from the spins
    the TOML gives. Catches a description loader or model that drops the extra rotors."""
    robot = Robot.load(HEXA)
    assert robot.n_rotors == 6
    assert [r["name"] for r in robot.rotors] == [f"rotor{i}" for i in range(1, 7)]
    _, _, alloc, e = hexa_terms(np.zeros(robot.n_q))
    assert alloc.shape == (4, 6)
    spins = [1, -1, 1, -1, 1, -1]
    for i, sigma in enumerate(spins):
        p = np.asarray(e["rotor_positions"][i]) - np.asarray(e["cog"])
        u = np.asarray(e["rotor_directions"][i])
        v = np.cross(p, u) - DRAG_RATIO * sigma * u
        np.testing.assert_allclose(alloc[:, i], [u[2], *v], atol=1e-12)


def test_hexa_lqi_gains_match_scipy():
    """Six-rotor gains out of the core (12 states, 6 inputs, warm and cold solves) equal the
    scipy CARE gain on the same system at several joint configurations; the closed loop is
    stable. Catches a rotor count stuck at 4 (shape), a padded input that leaks into P or K,
    a wrong R padding (K differs) and a row/rotor mix-up in the gain set."""
    robot = Robot.load(HEXA)
    synth = lqi.LqiSynthesizer(rotors=6)
    assert synth.rotors == 6
    rng = np.random.default_rng(6)
    methods = []
    for case in range(8):
        q = np.zeros(robot.n_q) if case == 0 else rng.uniform(-0.3, 0.3, robot.n_q)
        mass, inertia, alloc, _ = hexa_terms(q)
        res = synth.synthesize(mass, inertia, alloc)
        methods.append(res.method)
        k_ref = scipy_gain(mass, inertia, alloc, np.ones(6))
        assert res.k.shape == (6, 12)
        assert rel(res.k, k_ref) < 1e-8, case
        a, b = hover_state_model(mass, inertia, alloc)
        assert np.linalg.eigvals(a + b @ res.k).real.max() < 0
        # sec. 4 mapping of the reference K, per rotor (K's axes z, roll, pitch, yaw; the
        # gain array's roll, pitch, yaw, z): P = -position column, I = integral, D = -rate
        assert res.gains.shape == (6, 4, 3)
        assert tuple(res.clamp_scales) == (1.0,) * 5  # nothing clamped: the mapping alone
        for rotor in range(6):
            for axis, gains_axis in ((0, 3), (1, 0), (2, 1), (3, 2)):
                expected = [
                    -k_ref[rotor, 2 * axis],
                    k_ref[rotor, 8 + axis],
                    -k_ref[rotor, 2 * axis + 1],
                ]
                np.testing.assert_allclose(
                    res.gains[rotor, gains_axis], expected, rtol=1e-7, atol=1e-9
                )
    assert "kleinman" in methods


def test_eight_rotor_layouts_match_scipy_with_weights():
    """Random eight-rotor layouts (the capacity) with per-rotor R weights: the core's K equals
    scipy's. Catches weights applied to the wrong rotor or cut to four."""
    rng = np.random.default_rng(8)
    r = np.array([1.0, 2.0, 0.5, 1.5, 1.0, 3.0, 0.8, 1.2])
    synth = lqi.LqiSynthesizer(r_weights=r)
    assert synth.rotors == 8
    for case in range(6):
        mass, inertia, alloc = random_layout(rng, 8)
        res = synth.synthesize(mass, inertia, alloc)
        assert rel(res.k, scipy_gain(mass, inertia, alloc, r)) < 1e-8, case


def test_six_rotor_wire_forms_and_gyro_compensation():
    """rpy/gain carries one term per rotor (count 6, then 6 x 7 int16); the gyro
    compensation's pinv columns equal numpy's pseudo-inverse of the 4 x 6 Q_bar."""
    mass, inertia, alloc, _ = hexa_terms(np.zeros(10))
    synth = lqi.LqiSynthesizer(rotors=6)
    gains, wire, payload, finite, _, _ = synth.synthesize_wire(mass, inertia, alloc)
    assert finite and gains.shape == (6, 4, 3) and wire.shape == (6, 7)
    assert payload[:4] == (6).to_bytes(4, "little") and len(payload) == 4 + 6 * 7 * 2
    np.testing.assert_array_equal(np.frombuffer(payload[4:], "<i2").reshape(6, 7), wire)
    np.testing.assert_array_equal(
        _rdm.gains_to_wire_terms(np.ascontiguousarray(gains)), np.asarray(wire)
    )
    g = lqi.gyro_compensation(alloc, inertia)
    pinv = np.linalg.pinv(alloc)
    for name, col in (("pinv_roll", 1), ("pinv_pitch", 2), ("pinv_yaw", 3)):
        np.testing.assert_allclose(g[name], pinv[:, col], rtol=1e-9, atol=1e-12)


def test_rotor_count_errors_name_the_argument():
    with pytest.raises(ValueError, match="rotors"):
        lqi.LqiSynthesizer(rotors=9)
    with pytest.raises(ValueError, match="rotors"):
        lqi.LqiSynthesizer(rotors=0)
    synth = lqi.LqiSynthesizer(rotors=6)
    _, inertia, alloc = random_layout(np.random.default_rng(0), 4)
    with pytest.raises(ValueError, match="allocation"):
        synth.synthesize(2.0, inertia, alloc)
    with pytest.raises(ValueError, match="r_weights"):
        lqi.LqiSynthesizer(r_weights=np.ones(4), rotors=6)
    with pytest.raises(ValueError, match="motor_outputs"):
        _rdm.SpinalStep(200.0, motor_outputs=9)


def test_config_check_accepts_the_hexa_robot(tmp_path, capsys):
    """``rdm config check`` resolves a file against the six-rotor description (motor_num 6;
    the control pipeline built); the same file against the shipped four-rotor robot is
    refused in one line naming the file and field."""
    cfg = tmp_path / "hexa.toml"
    cfg.write_text("motor_num = 6\nlqi_r_weights = [1.0, 1.0, 1.0, 1.0, 2.0, 2.0]\n")
    assert rdm_main(["config", "check", str(cfg), "--robot", str(HEXA)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["config"]["motor_num"] == 6
    assert rdm_main(["config", "check", str(cfg), "--robot", "rdm"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(cfg) in err[0] and "motor_num" in err[0]
    bad = tmp_path / "bad.toml"
    bad.write_text("motor_num = 9\n")
    assert rdm_main(["config", "check", str(bad), "--robot", str(HEXA)]) == 2
    assert "motor_num" in capsys.readouterr().err


def test_hexa_control_pipeline_has_no_perching_controller():
    """The pipeline builds for six rotors (the error it gave was "rotor_thrust_max must have 4
    entries"); without a perching QP of that size a perch request is refused and counted."""
    robot = Robot.load(HEXA)
    pipeline = ControlPipeline(robot, OnboardConfig(motor_num=6))
    assert pipeline.perch is None
    pipeline.set_perching(True)
    assert not pipeline.perching and pipeline.counts["perch_unavailable"] == 1
    assert pipeline.perch_thrust.shape == (6,)
