"""LQI synthesis and the CARE solver against scipy and independent numpy re-derivations."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from rdm.control import lqi

DRAG_RATIO = 0.016
TABLE_V_Q = np.array([20.0, 30.0, 90.0, 12.8, 600.0, 80.0, 100.0, 50.0, 20.0, 0.15, 1.0, 0.5])


def random_robot(rng: np.random.Generator) -> tuple[float, np.ndarray, np.ndarray]:
    """Random physically plausible (m, I, Q_bar) from a random 4-rotor layout (eqs. 8-9)."""
    mass = rng.uniform(1.5, 8.0)
    rot = scipy.spatial.transform.Rotation.random(random_state=rng).as_matrix()
    inertia = rot @ np.diag(rng.uniform([0.02, 0.02, 0.05], [0.3, 0.6, 0.8])) @ rot.T
    alloc = np.zeros((4, 4))
    for i in range(4):
        ang = i * np.pi / 2 + rng.uniform(-0.4, 0.4)
        rad = rng.uniform(0.2, 0.8)
        p = np.array([rad * np.cos(ang), rad * np.sin(ang), rng.uniform(-0.05, 0.05)])
        tilt = scipy.spatial.transform.Rotation.from_euler("xy", rng.uniform(-0.3, 0.3, 2))
        u = tilt.apply([0.0, 0.0, 1.0])
        sigma = (-1.0) ** i
        v = np.cross(p, u) - DRAG_RATIO * sigma * u
        alloc[:, i] = [u[2], *v]
    return mass, inertia, alloc


def lqi_model(mass: float, inertia: np.ndarray, alloc: np.ndarray):
    """Eqs. (21)-(26) written in the paper's order, then permuted to the JSK order."""
    a = np.zeros((8, 8))
    a[:4, 4:] = np.eye(4)
    m_bar = np.zeros((4, 4))
    m_bar[0, 0] = mass
    m_bar[1:, 1:] = inertia
    b = np.vstack([np.zeros((4, 4)), np.linalg.solve(m_bar, alloc)])
    c = np.hstack([np.eye(4), np.zeros((4, 4))])
    a_bar = np.block([[a, np.zeros((8, 4))], [-c, np.zeros((4, 4))]])
    b_bar = np.vstack([b, np.zeros((4, 4))])
    perm = [0, 4, 1, 5, 2, 6, 3, 7, 8, 9, 10, 11]  # JSK state i = paper state perm[i]
    return a_bar[np.ix_(perm, perm)], b_bar[perm, :]


def scipy_k(a, b, q, r):
    p = scipy.linalg.solve_continuous_are(a, b, q, r)
    return p, -np.linalg.solve(r, b.T @ p)


def rel(x, y):
    return np.linalg.norm(x - y) / np.linalg.norm(y)


def test_augmented_system_matches_paper_equations():
    rng = np.random.default_rng(0)
    for _ in range(50):
        m, i, q = random_robot(rng)
        a_ref, b_ref = lqi_model(m, i, q)
        a, b = lqi.augmented_system(m, i, q)
        np.testing.assert_allclose(a, a_ref, atol=0)
        np.testing.assert_allclose(b, b_ref, rtol=1e-12, atol=1e-14)


def test_care_matches_scipy_on_random_lqi_and_generic_problems():
    rng = np.random.default_rng(1)
    worst = 0.0
    for case in range(300):
        if case % 3 == 2:
            # Generic problem: random A (may be unstable), random B, random SPD weights.
            a = rng.normal(size=(12, 12))
            b = rng.normal(size=(12, 4))
            g = rng.normal(size=(12, 12))
            q = g @ g.T / 12 + 0.1 * np.eye(12)
            h = rng.normal(size=(4, 4))
            r = h @ h.T + 0.5 * np.eye(4)
        else:
            a, b = lqi_model(*random_robot(rng))
            q = np.diag(TABLE_V_Q * rng.uniform(0.2, 5.0, 12))
            r = np.diag(rng.uniform(0.5, 2.0, 4))
        p, k, report = lqi.solve_care(a, b, q, r)
        p_ref, k_ref = scipy_k(a, b, q, r)
        worst = max(worst, rel(p, p_ref))
        assert rel(p, p_ref) < 1e-8, case
        assert rel(k, k_ref) < 1e-8, case
        np.testing.assert_array_equal(p, p.T)
        assert np.linalg.eigvalsh(p).min() > 0
        residual = a.T @ p + p @ a - p @ b @ np.linalg.solve(r, b.T @ p) + q
        assert np.linalg.norm(residual) < 1e-8 * np.linalg.norm(q) * max(1, np.linalg.cond(p))
        assert report["method"] == "sign"
        assert np.linalg.eigvals(a + b @ k).real.max() < 0


def test_synthesizer_closed_loop_stable_and_warm_matches_scipy():
    rng = np.random.default_rng(2)
    synth = lqi.LqiSynthesizer()
    robot = random_robot(rng)
    methods = []
    for case in range(200):
        if case % 25 == 0:
            robot = random_robot(rng)
        else:  # small joint motion between two gain updates
            m, i, q = robot
            robot = (
                m,
                i * (1 + rng.uniform(-0.005, 0.005)),
                q * (1 + rng.uniform(-0.005, 0.005, q.shape)),
            )
        res = synth.synthesize(*robot)
        methods.append(res.method)
        a, b = lqi_model(*robot)
        _, k_ref = scipy_k(a, b, np.diag(TABLE_V_Q), np.eye(4))
        assert rel(res.k, k_ref) < 1e-8, case
        assert np.linalg.eigvals(a + b @ res.k).real.max() < 0
    assert methods.count("kleinman") >= 150


def test_kleinman_warm_start_and_fallback_agree_with_cold():
    rng = np.random.default_rng(3)
    for _ in range(50):
        m, i, q = random_robot(rng)
        a, b = lqi_model(m, i, q)
        qw, r = np.diag(TABLE_V_Q), np.eye(4)
        p_cold, k_cold, _ = lqi.solve_care(a, b, qw, r)
        # Warm start from a neighbouring configuration's scipy gain.
        a2, b2 = lqi_model(m, i * 1.03, q * 0.98)
        _, k_near = scipy_k(a2, b2, qw, r)
        p_w, k_w, rep = lqi.solve_care(a, b, qw, r, k0=k_near)
        assert rep["method"] == "kleinman" and not rep["fell_back"]
        assert rel(k_w, k_cold) < 1e-8 and rel(p_w, p_cold) < 1e-8
        # Bad warm start (not stabilising): the fallback must produce the same solution.
        for bad in (np.zeros((4, 12)), -k_near):
            _, k_f, rep = lqi.solve_care(a, b, qw, r, k0=bad)
            assert rep["fell_back"] and rep["method"] == "sign"
            assert rel(k_f, k_cold) < 1e-12


def numpy_gain_set(k: np.ndarray, clamp: bool) -> np.ndarray:
    """Sec. 4 mapping re-derived: axis j (z, roll, pitch, yaw) -> (-K[2j], K[8+j], -K[2j+1])."""
    out = np.zeros((4, 4, 3))
    for rotor in range(4):
        for axis_out, j in ((0, 1), (1, 2), (2, 3), (3, 0)):  # output order roll, pitch, yaw, z
            out[rotor, axis_out] = [-k[rotor, 2 * j], k[rotor, 8 + j], -k[rotor, 2 * j + 1]]
    if clamp:
        for axis, term in ((0, 0), (0, 2), (1, 0), (1, 2), (2, 2)):
            peak = np.abs(out[:, axis, term]).max()
            if peak > 32.767:
                out[:, axis, term] *= 32.767 / peak
    return out


def test_gain_mapping_and_clamp_match_numpy_on_scipy_gains():
    rng = np.random.default_rng(4)
    clamped_any = False
    for _ in range(100):
        a, b = lqi_model(*random_robot(rng))
        q = np.diag(TABLE_V_Q * rng.uniform(0.1, 300.0))
        _, k_ref = scipy_k(a, b, q, np.eye(4))
        for clamp in (False, True):
            np.testing.assert_allclose(
                lqi.gain_set_from_k(k_ref, clamp), numpy_gain_set(k_ref, clamp), rtol=1e-14
            )
        g = lqi.gain_set_from_k(k_ref, True)
        clamped_any |= bool(np.abs(numpy_gain_set(k_ref, False)).max() > 32.767)
        for axis, term in ((0, 0), (0, 2), (1, 0), (1, 2), (2, 2)):
            assert np.abs(g[:, axis, term]).max() <= 32.767 + 1e-12
    assert clamped_any, "no case exercised clampGain"


def test_synthesizer_gain_set_is_the_mapping_of_its_k():
    rng = np.random.default_rng(5)
    synth = lqi.LqiSynthesizer()
    res = synth.synthesize(*random_robot(rng))
    np.testing.assert_allclose(res.gains, numpy_gain_set(res.k, True), rtol=1e-14)
    no_clamp = lqi.LqiSynthesizer(clamp_gain=False).synthesize(*random_robot(rng))
    np.testing.assert_allclose(no_clamp.gains, numpy_gain_set(no_clamp.k, False), rtol=1e-14)


def test_gyro_compensation_and_eq29_against_numpy():
    rng = np.random.default_rng(6)
    for _ in range(50):
        _, inertia, alloc = random_robot(rng)
        k = rng.normal(size=(4, 12))
        x = rng.normal(size=12)
        w = rng.normal(size=3)
        thrust, gyro = lqi.flight_thrust(k, x, alloc, inertia, w)
        pinv = np.linalg.pinv(alloc)
        expected = k @ x + pinv @ np.concatenate([[0.0], np.cross(w, inertia @ w)])
        np.testing.assert_allclose(thrust, expected, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(gyro["pinv_roll"], pinv[:, 1], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(gyro["pinv_yaw"], pinv[:, 3], rtol=1e-9, atol=1e-12)
        assert not gyro["pseudo_inverse"]
    # Rank-deficient allocation: pseudo-inverse, reported.
    _, inertia, alloc = random_robot(rng)
    alloc[:, 3] = alloc[:, 2]
    gyro = lqi.gyro_compensation(alloc, inertia)
    assert gyro["pseudo_inverse"] and gyro["rank"] == 3
    np.testing.assert_allclose(gyro["pinv_pitch"], np.linalg.pinv(alloc)[:, 2], atol=1e-9)


def test_pc_axes_against_numpy():
    rng = np.random.default_rng(7)
    gains = rng.normal(size=(4, 4, 3))
    gains[:, 2, 2] = [0.3, 1.7, -2.0, 0.9]  # yaw D: rotor 1 is the largest positive
    ctrl = lqi.PcAxisController()
    iz = iy = 0.0
    for _ in range(20):
        ez, ezd, ey = rng.normal(size=3)
        ff = rng.normal(size=4)
        base, yaw_cmd, rotor = ctrl.step(gains, ez, ezd, ey, ff, 0.025)
        iz += ez * 0.025
        iy += ey * 0.025
        np.testing.assert_allclose(
            base, ff + gains[:, 3, 0] * ez + gains[:, 3, 1] * iz + gains[:, 3, 2] * ezd
        )
        assert rotor == 1
        assert yaw_cmd == pytest.approx(gains[1, 2, 0] * ey + gains[1, 2, 1] * iy)


def test_bad_inputs_raise_named_errors():
    rng = np.random.default_rng(8)
    m, inertia, alloc = random_robot(rng)
    synth = lqi.LqiSynthesizer()
    with pytest.raises(lqi.LqiSynthesisError, match="mass"):
        synth.synthesize(float("nan"), inertia, alloc)
    bad = inertia.copy()
    bad[1, 1] = np.inf
    with pytest.raises(lqi.LqiSynthesisError, match="inertia"):
        synth.synthesize(m, bad, alloc)
    bad = alloc.copy()
    bad[0, 0] = np.nan
    with pytest.raises(lqi.LqiSynthesisError, match="allocation"):
        synth.synthesize(m, inertia, bad)
    with pytest.raises(lqi.CareSolveError):  # cannot control yaw with two rotor pairs equal
        synth.synthesize(m, inertia, alloc[:, [0, 0, 2, 2]])
    with pytest.raises(_rdm_error(), match="allocation"):
        synth.synthesize(m, inertia, alloc[:3])
    a, b = lqi_model(m, inertia, alloc)
    with pytest.raises(lqi.CareSolveError, match="`q`"):
        lqi.solve_care(a, b, np.full((12, 12), np.nan), np.eye(4))
    with pytest.raises(lqi.CareSolveError, match="`r`"):
        lqi.solve_care(a, b, np.eye(12), -np.eye(4))
    with pytest.raises(lqi.LqiSynthesisError, match=r"weights\.r"):
        lqi.LqiSynthesizer(r_weights=np.zeros(4))
    assert issubclass(lqi.LqiSynthesisError, ValueError)


def _rdm_error():
    from rdm import _rdm

    return _rdm.RdmError
