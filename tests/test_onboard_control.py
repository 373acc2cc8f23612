"""The onboard control pipeline (``rdm.nodes.onboard_control``) against independent oracles:
the model terms against a numpy re-derivation and ``np.cross``, the hover thrust against
``np.linalg.lstsq``, the pinv wire terms against x1000 truncation written out with numpy, the
LQI wire form against ``synthesize`` + ``gains_to_wire_terms``, the synthesis failure branches
against their stated counters, the model cache against a pipeline that never saw another q,
the perch thrust's rate limit against ``np.maximum``, the float helpers against ``np.clip`` and
``np.isfinite``, trajectory targets against ``np.interp``.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from fed_byte_link import FedByteLink

from rdm.control.attitude import gains_to_wire_terms
from rdm.control.lqi import LqiResult, LqiSynthesizer
from rdm.model import Robot
from rdm.nodes.onboard import OnboardNode
from rdm.nodes.onboard_config import OnboardConfig
from rdm.nodes.onboard_control import (
    MODEL_CACHE_SIZE,
    ControlCommand,
    ControlPipeline,
    Setpoint,
    State,
    _all_finite,
    _clip,
    _lstsq_solution,
    _p_matrix_terms,
    foot_allocation,
)

ROBOT = Robot.default()


def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def _foot_allocation_np_cross(allocation: np.ndarray, foot_in_cog: np.ndarray) -> np.ndarray:
    """Q̄_foot with ``np.cross``: rows f_z and M_C - p_foot x F."""
    full = np.asarray(allocation, dtype=float)
    p_foot = np.asarray(foot_in_cog, dtype=float)[:3, 3]
    moments = full[3:6] - np.cross(p_foot, full[0:3].T).T
    return np.vstack([full[2], moments])


def test_foot_allocation_is_bitwise_np_cross():
    rng = np.random.default_rng(1)
    for _ in range(200):
        full = rng.normal(size=(6, 4)) * 10.0 ** rng.integers(-3, 3)
        pose = np.eye(4)
        pose[:3, 3] = rng.normal(size=3)
        assert _same(foot_allocation(full, pose), _foot_allocation_np_cross(full, pose))


def _terms_equal(a, b) -> None:
    for name in (
        "q",
        "inertia",
        "allocation",
        "allocation_bar",
        "foot_allocation",
        "link_rotations",
        "hover_thrust",
        "imu_to_cog",
    ):
        assert _same(getattr(a, name), getattr(b, name)), name
    assert a.mass == b.mass


def test_model_terms_against_numpy_rederivation():
    pipe = ControlPipeline(ROBOT, OnboardConfig())
    q = np.array([0.3, -0.2, 0.1, 0.4, 0.0, -0.1] + [0.05] * (ROBOT.n_q - 6))
    assert pipe.update_model(q) and pipe.update_model(q.copy())  # second: reused
    o = ROBOT.evaluate(q)
    full = np.asarray(o["allocation"], dtype=float)
    p = np.asarray(o["foot_in_cog"], dtype=float)[:3, 3]
    # M_foot = M_C - p x F, column by column
    want = np.array(
        [[full[2, i], *(full[3:6, i] - np.cross(p, full[0:3, i]))] for i in range(full.shape[1])]
    ).T
    np.testing.assert_allclose(pipe.terms.foot_allocation, want, rtol=0, atol=1e-12)
    qbar = np.asarray(o["allocation_bar"], dtype=float)
    w = np.array([o["mass"] * pipe.config.gravity, 0, 0, 0])
    np.testing.assert_allclose(qbar @ pipe.terms.hover_thrust, w, atol=1e-9)


def test_model_cache_of_recent_q_is_a_fresh_evaluation():
    """q flickering between a few servo readings (and a bad q now and then), the present q
    mutated in place as the node's is: the cached terms, pinv message and desired coordinate
    equal those of a pipeline that never saw another q; counters as stated."""
    robot, cfg = ROBOT, OnboardConfig()
    pipe = ControlPipeline(robot, cfg)
    rng = np.random.default_rng(12)
    base = rng.uniform(-0.3, 0.3, size=robot.n_q)
    pool = [base + 0.0015 * rng.integers(-2, 3, size=robot.n_q) for _ in range(6)]
    bad = base.copy()
    bad[0] = np.nan
    q_live = np.zeros(robot.n_q)
    errors = 0
    for k in range(120):
        q = bad if k % 37 == 36 else pool[rng.integers(len(pool))]
        q_live[:] = q
        fresh = ControlPipeline(robot, cfg)
        ok = fresh.update_model(q.copy())
        assert pipe.update_model(q_live) is ok
        errors += not ok
        if not ok:
            continue
        _terms_equal(pipe.terms, fresh.terms)
        assert pipe.p_matrix_wire() == fresh.p_matrix_wire()
        assert pipe.desire_coordinate() == fresh.desire_coordinate()
        assert len(pipe._model_cache) <= MODEL_CACHE_SIZE
    assert pipe.counts["model_error"] == errors > 0


_RESULT_FIELDS = ("k", "p", "b", "gains")


_RESULT_VALUES = ("clamp_scales", "method", "iterations", "fell_back", "relative_residual")


def _same_result(a: LqiResult, b: LqiResult) -> None:
    assert type(a) is type(b) is LqiResult
    assert list(a.__dict__) == list(b.__dict__)
    for name in _RESULT_FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), name
    for name in _RESULT_VALUES:
        assert getattr(a, name) == getattr(b, name), name


def _model_sequence(seed: int, n: int):
    """(mass, inertia, allocation_bar) along a random joint walk, with a few jumps."""
    node = OnboardNode(FedByteLink())
    pipe = node.control
    rng = np.random.default_rng(seed)
    q = node.present_q.copy()
    out = []
    for k in range(n):
        q[:6] += rng.normal(scale=0.3 if k % 17 == 0 else 0.005, size=6)
        assert pipe.update_model(q)
        t = pipe.terms
        out.append((t.mass, t.inertia, t.allocation_bar))
    return out


def _payload(wire: np.ndarray) -> bytes:
    return struct.pack("<I", wire.shape[0]) + wire.astype("<i2").tobytes()


def test_synthesize_wire_matches_synthesize_and_wire_terms():
    by_wire, by_result = LqiSynthesizer(), LqiSynthesizer()
    assert by_wire.kept_result() is None
    rng = np.random.default_rng(1)
    seen_methods = set()
    for k, (mass, inertia, alloc) in enumerate(_model_sequence(4, 120)):
        if k % 37 == 5:
            by_wire.reset()
            by_result.reset()
        gains, wire, payload, finite, fell_back, clamped = by_wire.synthesize_wire(
            mass, inertia, alloc
        )
        res = by_result.synthesize(mass, inertia, alloc)
        seen_methods.add(res.method)
        assert gains.dtype == np.float64 and gains.shape == res.gains.shape
        assert gains.tobytes() == res.gains.tobytes()
        ref_wire = np.asarray(gains_to_wire_terms(res.gains), dtype=np.int16)
        assert wire.dtype == ref_wire.dtype and wire.shape == ref_wire.shape
        assert wire.flags.c_contiguous and wire.tobytes() == ref_wire.tobytes()
        assert payload == _payload(ref_wire)
        assert finite is bool(np.all(np.isfinite(res.gains)))
        assert fell_back is res.fell_back
        assert clamped is any(s != 1.0 for s in res.clamp_scales)
        _same_result(by_wire.kept_result(), res)
        assert by_wire.has_solution and by_result.has_solution
        if rng.random() < 0.1:  # the same error, and the warm start kept, on bad input
            with pytest.raises(ValueError) as e1:
                by_wire.synthesize_wire(float("nan"), inertia, alloc)
            with pytest.raises(ValueError) as e2:
                by_result.synthesize(float("nan"), inertia, alloc)
            assert type(e1.value) is type(e2.value) and str(e1.value) == str(e2.value)
    assert seen_methods == {"sign", "kleinman"}


class _Faulty:
    """An LqiSynthesizer whose results are spoiled on demand (both interfaces, each as the
    real one behaves on such a result)."""

    def __init__(self) -> None:
        self.real = LqiSynthesizer()
        self.mode = "ok"
        self.resets = 0
        self._kept: LqiResult | None = None

    def _spoil(self, res: LqiResult) -> LqiResult:
        if self.mode == "raise":
            raise ValueError("spoiled")
        gains = res.gains.copy()
        if self.mode == "nan_wire":
            gains[0, 0, 0] = np.nan  # roll P: a wire term
        elif self.mode == "nan_z":
            gains[1, 3, 1] = np.inf  # z I: not on the wire
        spoiled = object.__new__(LqiResult)
        spoiled.__dict__.update(res.__dict__, gains=gains)
        return spoiled

    def synthesize(self, mass, inertia, alloc) -> LqiResult:
        return self._spoil(self.real.synthesize(mass, inertia, alloc))

    def synthesize_wire(self, mass, inertia, alloc):
        res = self._spoil(self.real.synthesize(mass, inertia, alloc))
        finite = bool(np.all(np.isfinite(res.gains)))
        try:
            wire = np.asarray(gains_to_wire_terms(res.gains), dtype=np.int16)
            payload = _payload(wire)
        except ValueError:
            wire = payload = None
        if wire is not None and finite:
            self._kept = res
        clamped = any(s != 1.0 for s in res.clamp_scales)
        return res.gains, wire, payload, finite, res.fell_back, clamped

    def kept_result(self) -> LqiResult | None:
        return self._kept

    def reset(self) -> None:
        self.resets += 1
        self.real.reset()


def test_synthesis_failure_branches_count_and_keep_the_last_gains():
    """A failed solve counts ``lqi_failed`` and resets the warm start; a non-finite wire term
    the same (its wire terms cannot be built); a non-finite gain off the wire counts
    ``lqi_failed`` without a reset; the last good gains stay in every case."""
    node = OnboardNode(FedByteLink())
    pipe = ControlPipeline(node.robot, node.config)
    pipe.lqi = _Faulty()
    q = node.present_q.copy()
    modes = ["raise", "ok", "nan_wire", "nan_wire", "ok", "nan_z", "ok", "raise", "nan_z"]
    last_good = None
    for mode in modes * 3:
        q[0] += 0.01
        pipe.lqi.mode = mode
        pipe.update_model(q)
        counts, resets = dict(pipe.counts), pipe.lqi.resets
        ok = pipe.synthesize()
        assert ok is (mode == "ok")
        delta = {k: v - counts.get(k, 0) for k, v in pipe.counts.items() if v != counts.get(k, 0)}
        if ok:
            assert delta.get("lqi_ok") == 1 and "lqi_failed" not in delta
            last_good = pipe.gains.copy()
            want = np.asarray(gains_to_wire_terms(last_good), dtype=np.int16)
            assert pipe.gains_wire.tobytes() == want.tobytes()
            assert pipe.gains_payload[1] == _payload(want)
            _same_result(pipe.lqi_result, pipe.lqi.kept_result())
        else:
            assert delta == {"lqi_failed": 1}
            assert pipe.lqi.resets == resets + (mode in ("raise", "nan_wire"))
            if last_good is None:
                assert pipe.gains is None
            else:
                assert pipe.gains.tobytes() == last_good.tobytes()


def test_lqi_result_is_the_dataclass_the_init_builds():
    from dataclasses import fields

    from rdm.control.lqi import LqiResult, LqiSynthesizer

    node = OnboardNode(FedByteLink())
    pipe = node.control
    pipe.update_model(node.present_q)
    t = pipe.terms
    res = LqiSynthesizer().synthesize(t.mass, t.inertia, t.allocation_bar)
    built = LqiResult(**{f.name: getattr(res, f.name) for f in fields(LqiResult)})
    assert type(res) is LqiResult and repr(res) == repr(built)
    assert list(res.__dict__) == list(built.__dict__)
    with pytest.raises(AttributeError):  # still frozen
        res.method = "x"


def test_lstsq_solution_matches_numpy():

    rng = np.random.default_rng(12)
    cases = []
    for m, n in ((4, 4), (4, 6), (6, 4), (4, 1), (1, 4)):
        for k in range(40):
            a = rng.normal(size=(m, n)) * 10.0 ** rng.integers(-3, 4)
            if k % 5 == 1:
                a[:, -1] = a[:, 0]  # rank deficient
            if k % 9 == 2:
                a[:] = 0.0
            cases.append((a, [float(v) for v in rng.normal(size=m)]))
    # (no NaN/inf matrix: LAPACK's gelsd does not return on those with this OpenBLAS, in
    # np.linalg.lstsq as in this call; the model never hands one over, see update_model)
    cases.append(
        (rng.normal(size=(4, 4)), [np.float64(1.0), 0.0, 0.0, 0.0])
    )  # numpy scalars: np.linalg.lstsq
    cases.append((rng.normal(size=(4, 4)).astype(np.float32), [1.0, 0.0, 0.0, 0.0]))
    for a, rhs in cases:
        ref = np.linalg.lstsq(a, rhs, rcond=None)[0]
        out = _lstsq_solution(a, rhs)
        assert out.dtype == ref.dtype and out.shape == ref.shape
        assert out.tobytes() == ref.tobytes()
    with pytest.raises(np.linalg.LinAlgError) as got:  # wrong shapes: the wrapper's error
        _lstsq_solution(np.ones((4, 4)), [1.0, 2.0])
    with pytest.raises(np.linalg.LinAlgError) as ref_err:
        np.linalg.lstsq(np.ones((4, 4)), [1.0, 2.0], rcond=None)
    assert str(got.value) == str(ref_err.value)


def _wire_oracle(v: float) -> tuple[int, bool]:
    """x1000 truncated toward zero, saturated to int16 (numpy)."""
    x = np.trunc(np.float64(v) * 1000.0)
    return int(np.clip(x, -32768, 32767)), bool(x < -32768 or x > 32767)


def test_p_matrix_terms_are_the_truncated_wire_values():
    from rdm.control.lqi import gyro_compensation

    node = OnboardNode(FedByteLink())
    pipe = node.control
    rng = np.random.default_rng(9)
    q = node.present_q.copy()
    saturated = 0
    for k in range(60):
        q[:6] += rng.normal(scale=0.2, size=6)
        assert pipe.update_model(q)
        g = gyro_compensation(pipe.terms.allocation_bar, pipe.terms.inertia)
        if k % 4 == 1:  # large entries: saturated terms
            g = {key: v * 1e3 if isinstance(v, np.ndarray) else v for key, v in g.items()}
        rows, inertia, sat = _p_matrix_terms(g)
        cols = [g["pinv_roll"], g["pinv_pitch"], g["pinv_yaw"]]
        want_rows = [tuple(_wire_oracle(c[i]) for c in cols) for i in range(len(cols[0]))]
        i = np.asarray(g["inertia"])
        comps = [i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[1, 2], i[0, 2]]
        want_inertia = [_wire_oracle(v) for v in comps]
        assert rows == [tuple(w for w, _ in row) for row in want_rows]
        assert inertia == [w for w, _ in want_inertia]
        assert all(type(v) is int for row in rows for v in row)
        assert sat == any(s for row in want_rows for _, s in row) | any(s for _, s in want_inertia)
        saturated += sat
        for bad in (np.nan, np.inf, -np.inf):  # no wire value for a non-finite term
            spoiled = dict(g, pinv_pitch=g["pinv_pitch"].copy())
            spoiled["pinv_pitch"][k % len(spoiled["pinv_pitch"])] = bad
            with pytest.raises((ValueError, OverflowError)):
                _p_matrix_terms(spoiled)
    assert 0 < saturated < 60
    # lists instead of arrays: the same values
    odd = dict(g, inertia=g["inertia"].tolist(), pinv_roll=list(g["pinv_roll"]))
    assert _p_matrix_terms(odd) == _p_matrix_terms(g)


def test_evaluate_control_is_what_evaluate_gives():
    from rdm.model import Robot

    node = OnboardNode(FedByteLink())
    robot = node.robot
    frame = node.config.imu_link
    other = Robot.default()  # a second workspace for the full evaluation
    rng = np.random.default_rng(15)
    q = node.present_q.copy()
    for _k in range(60):
        q[:6] += rng.normal(scale=0.3, size=6)
        lean = robot.evaluate_control(q, frame)
        full = other.evaluate(q)
        ref = (
            full["mass"],
            full["inertia"],
            full["allocation"],
            full["allocation_bar"],
            full["foot_in_cog"],
            full["unit_parent_rotations"],
            full["frames"]["cog"],
            full["frames"][frame],
        )
        assert type(lean) is tuple and len(lean) == len(ref)
        assert type(lean[0]) is float and lean[0] == ref[0]
        for a, b in zip(lean[1:], ref[1:], strict=True):
            if isinstance(b, list):
                assert type(a) is list and len(a) == len(b)
                pairs = list(zip(a, b, strict=True))
            else:
                pairs = [(a, b)]
            for x, y in pairs:
                assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes()
    bad = q.copy()
    bad[0] = np.nan
    for f in (lambda: robot.evaluate_control(bad, frame), lambda: other.evaluate(bad)):
        with pytest.raises(ValueError):
            f()
    with pytest.raises(ValueError):
        robot.evaluate_control(q, "no-such-frame")

    # a robot whose evaluate is overridden is evaluated through it
    class _Robot(Robot):
        def evaluate(self, q, base_pose=None):
            return super().evaluate(q, base_pose)

    custom = ControlPipeline(_Robot.default(), node.config)
    assert custom._evaluate_control is None
    assert ControlPipeline(robot, node.config)._evaluate_control is not None


def test_position_step_outputs_match_position_command():
    """``step_outputs`` (what the pipeline reads) carries the values ``step`` wraps, on
    random inputs; bad input raises the same error from both."""
    from rdm.control.position import PositionControlError, PositionController
    from rdm.model import Robot
    from rdm.nodes.onboard_config import OnboardConfig
    from rdm.nodes.onboard_control import ControlPipeline

    pipe = ControlPipeline(Robot.default(), OnboardConfig())
    rng = np.random.default_rng(17)
    a, b = PositionController(), PositionController()
    for k in range(300):
        q = rng.uniform(-0.4, 0.4, size=pipe.robot.n_q)
        assert pipe.update_model(q)
        rot = pipe.terms.link_rotations
        args = [rng.normal(size=2) for _ in range(4)]
        yaw, dt = float(rng.uniform(-3, 3)), 0.025
        if k % 40 == 7:
            args[0] = np.array([np.nan, 0.0])
            with pytest.raises(PositionControlError) as e1:
                a.step(*args, yaw, rot, dt)
            with pytest.raises(PositionControlError) as e2:
                b.step_outputs(*args, yaw, rot, dt)
            assert str(e1.value) == str(e2.value)
            continue
        cmd, out = a.step(*args, yaw, rot, dt), b.step_outputs(*args, yaw, rot, dt)
        assert cmd.acceleration.tobytes() == out["acceleration"].tobytes()
        assert (cmd.roll, cmd.pitch) == (out["roll"], out["pitch"])
        assert cmd.alpha == tuple(out["alpha"]) and cmd.beta == tuple(out["beta"])
        assert cmd.direction.tobytes() == np.array(out["direction"], dtype=float).tobytes()
        assert [float(d[2]) for d in out["direction"]] == [float(v) for v in cmd.direction[:, 2]]
        assert cmd.integral_clamped == out["integral_clamped"]
        assert a.integral.tobytes() == b.integral.tobytes()


def test_perch_thrust_rate_limit_is_np_maximum():
    """Out of perching the perch thrust falls by the rate limit per tick, floored at +0.0
    (``np.maximum(previous - limit, 0.0)`` bit for bit, held without recomputing once all
    +0.0); the command is the frozen dataclass its fields build, through perching on/off,
    a missing foot sample and NaN inputs."""
    node = OnboardNode(FedByteLink())
    pipe = ControlPipeline(node.robot, node.config)
    assert pipe._delta_positive
    limit = np.asarray(pipe.perch.params()["thrust_rate_limit"], dtype=float)
    q = node.present_q.copy()
    rng = np.random.default_rng(21)
    pipe.update_model(q)
    assert pipe.synthesize()
    for k in range(200):
        perch = 40 <= k < 90 or 150 <= k < 160
        pos = rng.normal(scale=0.1, size=3)
        if k == 120:
            pos[0] = np.nan
        foot = None if k % 7 == 0 else rng.normal(scale=2.0, size=6)
        before = pipe.perch_thrust.copy()
        pipe.set_perching(perch)
        state = State(pos.copy(), np.zeros(3), 0.01)
        sp = Setpoint(np.array([0.0, 0.0, 0.1]), np.zeros(3), 0.0)
        try:
            out = pipe.step(state, sp, q, foot, 0.025)
        except ValueError:
            continue
        if not perch:
            assert pipe.perch_thrust.tobytes() == np.maximum(before - limit, 0.0).tobytes()
        if isinstance(out, ControlCommand):
            built = ControlCommand(*(getattr(out, f) for f in out.__dataclass_fields__))
            assert repr(built) == repr(out) and out.__dict__.keys() == built.__dict__.keys()
            assert out.perch_thrust.tobytes() == pipe.perch_thrust.tobytes()
            with pytest.raises(AttributeError):  # still frozen
                out.yaw_rotor = 0
    assert pipe._perch_zeros is not None


def test_clip_is_np_clip_bitwise():
    rng = np.random.default_rng(3)
    hi = np.array([10.0, 12.0, 9.5, 11.0])
    specials = [0.0, -0.0, np.nan, np.inf, -np.inf, 10.0, 12.0, -1e-300]
    for _ in range(500):
        x = rng.normal(size=4) * 8.0
        for i in range(4):
            if rng.random() < 0.3:
                x[i] = specials[rng.integers(len(specials))]
        assert _clip(x, 0.0, hi).tobytes() == np.clip(x, 0.0, hi).tobytes()


def test_all_finite_is_np_all_isfinite():
    rng = np.random.default_rng(4)
    shapes = [(0,), (4,), (4, 0), (4, 4, 3), (2, 3)]
    for _ in range(300):
        a = rng.normal(size=shapes[rng.integers(len(shapes))])
        if a.size and rng.random() < 0.5:
            a.flat[rng.integers(a.size)] = rng.choice([np.nan, np.inf, -np.inf])
        assert _all_finite(a) is bool(np.all(np.isfinite(a)))


def test_trajectory_targets_are_np_interp():
    node = OnboardNode(FedByteLink())
    rng = np.random.default_rng(6)
    n_q = node.robot.n_q
    for trial in range(5):
        times = np.cumsum(rng.uniform(0.01, 0.5, size=2 + trial))
        points = [(float(t), rng.uniform(-1.5, 1.5, size=n_q)) for t in times]
        assert node.set_trajectory(points)
        qs = np.array([q for _, q in points])
        probes = [times[0] - 1.0, float(times[-1]) + 1.0, *times.tolist()]
        probes += rng.uniform(times[0] - 0.1, times[-1] + 0.1, size=50).tolist()
        for now in probes:
            got = node._current_joint_targets(now)
            want = np.array([np.interp(now, times, qs[:, j]) for j in range(n_q)])
            assert got.dtype == want.dtype and got.shape == want.shape
            assert got.tobytes() == want.tobytes()
    assert node.set_joint_targets(np.zeros(6))  # the trajectory is dropped
    assert node._current_joint_targets(0.0) is node.joint_targets
