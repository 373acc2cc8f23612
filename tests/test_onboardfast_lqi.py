"""The onboard node's LQI and model fast paths against their plain forms (docs/onboard.md).

* ``LqiSynthesizer.synthesize_wire`` (one Rust call: gains, ``rpy/gain`` terms and payload,
  finite / fell-back / clamped flags) against ``synthesize`` + ``gains_to_wire_terms``;
* ``ControlPipeline`` with ``fast_lqi`` on and off: counters in the same order, gains, wire
  terms, the lazily built ``lqi_result``, failure branches (solver error, NaN wire term,
  NaN non-wire gain);
* a whole node with ``fast_lqi`` against one without, over a flight: the same UART bytes;
* ``PerchResult._from`` against ``cls(**d)``.

The Rust side (the Lyapunov iteration and the Gauss-Jordan elimination written on slices)
is tested bit for bit against its nalgebra-expression reference in
``crates/rdm_core/src/control/riccati`` (``cargo test -p rdm_core riccati``).
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from fed_byte_link import FedByteLink
from onboard_rig import shadowed_rig

from rdm.control.attitude import gains_to_wire_terms
from rdm.control.lqi import LqiResult, LqiSynthesizer
from rdm.control.perch import PerchController, PerchResult
from rdm.nodes.onboard import OnboardNode
from rdm.nodes.onboard_config import OnboardConfig
from rdm.nodes.onboard_control import ControlPipeline

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
    fast, plain = LqiSynthesizer(), LqiSynthesizer()
    assert fast.kept_result() is None
    rng = np.random.default_rng(1)
    seen_methods = set()
    for k, (mass, inertia, alloc) in enumerate(_model_sequence(4, 120)):
        if k % 37 == 5:
            fast.reset()
            plain.reset()
        gains, wire, payload, finite, fell_back, clamped = fast.synthesize_wire(
            mass, inertia, alloc
        )
        res = plain.synthesize(mass, inertia, alloc)
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
        _same_result(fast.kept_result(), res)
        assert fast.has_solution and plain.has_solution
        if rng.random() < 0.1:  # the same error, and the warm start kept, on bad input
            with pytest.raises(ValueError) as e1:
                fast.synthesize_wire(float("nan"), inertia, alloc)
            with pytest.raises(ValueError) as e2:
                plain.synthesize(float("nan"), inertia, alloc)
            assert type(e1.value) is type(e2.value) and str(e1.value) == str(e2.value)
    assert seen_methods == {"sign", "kleinman"}


def _pipelines():
    node = OnboardNode(FedByteLink())
    fast = ControlPipeline(node.robot, node.config)
    plain = ControlPipeline(node.robot, node.config)
    assert fast.fast_lqi
    plain.fast_lqi = False
    return node, fast, plain


def _compare(fast: ControlPipeline, plain: ControlPipeline) -> None:
    assert list(fast.counts.items()) == list(plain.counts.items())
    if plain.gains is None:
        assert fast.gains is None and fast.gains_wire is None
        assert fast.lqi_result is None and plain.lqi_result is None
        return
    assert fast.gains.tobytes() == plain.gains.tobytes()
    assert fast.gains_wire.dtype == plain.gains_wire.dtype == np.int16
    assert fast.gains_wire.tobytes() == plain.gains_wire.tobytes()
    assert fast.gains_payload[0] is fast.gains_wire
    assert fast.gains_payload[1] == _payload(plain.gains_wire)
    _same_result(fast.lqi_result, plain.lqi_result)


def test_pipeline_fast_lqi_matches_plain():
    node, fast, plain = _pipelines()
    rng = np.random.default_rng(8)
    q = node.present_q.copy()
    for k in range(150):
        q[:6] += rng.normal(scale=0.2 if k % 23 == 0 else 0.003, size=6)
        for pipe in (fast, plain):
            pipe.update_model(q)
            pipe.synthesize()
        if k % 10 != 3:  # lqi_result read now and then (built lazily on the fast side)
            _compare(fast, plain)
    _compare(fast, plain)
    assert fast.counts["lqi_ok"] == 150
    fast.lqi_result = None  # still an attribute one can set
    assert fast.lqi_result is None


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


def test_pipeline_fast_lqi_failure_branches_match_plain():
    node, fast, plain = _pipelines()
    fast.lqi, plain.lqi = _Faulty(), _Faulty()
    q = node.present_q.copy()
    modes = ["raise", "ok", "nan_wire", "nan_wire", "ok", "nan_z", "ok", "raise", "nan_z"]
    for k, mode in enumerate(modes * 3):
        q[0] += 0.01
        results = []
        for pipe in (fast, plain):
            pipe.lqi.mode = mode
            pipe.update_model(q)
            results.append(pipe.synthesize())
        assert results[0] is results[1] is (mode == "ok")
        assert fast.lqi.resets == plain.lqi.resets
        if k % 2:
            _compare(fast, plain)
    _compare(fast, plain)
    for key in ("lqi_failed", "lqi_ok"):
        assert fast.counts[key] > 0


def test_node_fast_lqi_matches_plain_over_a_flight():
    """A node with ``fast_lqi`` against one with the plain LQI path ticking on the same
    Spinal bytes (arming, flight, perching on/off, moving servos): identical UART bytes
    every tick, counters and commands."""
    cfg = OnboardConfig(lqi_every=1)

    def plain_lqi(node: OnboardNode) -> None:
        node.control.fast_lqi = False

    rig, plain = shadowed_rig(cfg, plain_lqi)
    try:
        fast = rig.node
        assert fast.control.fast_lqi
        q = fast.present_q.copy()
        q[:6] = [0.1, -0.2, 0.3, 0.05, -0.1, 0.2]
        rig.servo_q = q
        rng = np.random.default_rng(5)

        def inputs(t: float) -> None:
            for node in (fast, plain):
                if abs(t - 0.5) < 1e-9:
                    node.set_target([0.0, 0.0, 1.0], 0.1)
                    node.arm()
                node.set_mocap([0.05 * np.sin(t), 0.02, 0.9 + 0.05 * t], [0.0, 0.01, 0.02], 0.05)
                if abs(t - 2.0) < 1e-9:
                    node.request_perch(True)
                if abs(t - 2.5) < 1e-9:
                    node.request_perch(False)
            if 1.2 < t < 1.8:  # servos moving: the model and the gains change
                rig.servo_q = q + rng.normal(scale=0.02, size=q.size)

        rig.run(0.0, 3.0, each=inputs)
        assert fast.arming.flying and fast.published["rpy/gain"] > 50
        for a, b in (
            (fast.counts, plain.counts),
            (fast.published, plain.published),
            (fast.control.counts, plain.control.counts),
        ):
            assert list(a.items()) == list(b.items())
        assert fast.last_command.base_thrust.tobytes() == plain.last_command.base_thrust.tobytes()
        _same_result(fast.control.lqi_result, plain.control.lqi_result)
    finally:
        rig.close()


def test_perch_result_without_init_matches_the_dataclass():
    node = OnboardNode(FedByteLink())
    pipe = node.control
    pipe.update_model(node.present_q)
    t = pipe.terms
    ctrl = PerchController(40.0, 1.0)
    rng = np.random.default_rng(2)
    statuses = set()
    for k in range(60):
        wrench = rng.normal(scale=3.0, size=6)
        wrench[2] -= 5.0
        if k % 13 == 0:
            wrench[0] = np.nan
        d = ctrl._inner.tick(wrench, t.foot_allocation, t.allocation_bar, t.mass, None)
        fast, plain = PerchResult._from(dict(d)), PerchResult._from_plain(dict(d))
        assert type(fast) is PerchResult and repr(fast) == repr(plain)
        assert list(fast.__dict__) == list(plain.__dict__)
        assert fast.ok == plain.ok
        statuses.add(fast.status)
        with pytest.raises(AttributeError):  # still frozen
            fast.status = "x"
    assert len(statuses) >= 2
    # a dict that is not exactly the fields takes the dataclass path (and its errors)
    with pytest.raises(TypeError):
        PerchResult._from({"status": "solved"})


def test_lstsq_solution_matches_numpy():
    from rdm.nodes.onboard_control import _lstsq_solution

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
    # np.linalg.lstsq as in the fast form; the model never hands one over, see update_model)
    cases.append((rng.normal(size=(4, 4)), [np.float64(1.0), 0.0, 0.0, 0.0]))  # plain path
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


def test_model_fast_matches_plain():
    node = OnboardNode(FedByteLink())
    fast = ControlPipeline(node.robot, node.config)
    plain = ControlPipeline(node.robot, node.config)
    plain.fast_model = False
    for pipe in (fast, plain):
        pipe.reuse_model = False  # evaluate every time
    rng = np.random.default_rng(4)
    q = node.present_q.copy()
    for k in range(80):
        q[:6] += rng.normal(scale=0.1, size=6)
        if k == 40:
            q[2] = np.nan
        assert fast.update_model(q) is plain.update_model(q)
        a, b = fast.terms, plain.terms
        assert type(a) is type(b)
        assert list(a.__dict__) == list(b.__dict__)
        for name, x in a.__dict__.items():
            y = getattr(b, name)
            if isinstance(x, np.ndarray):
                assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes()
            else:
                assert x == y, name
        with pytest.raises(AttributeError):  # still frozen
            a.mass = 1.0
        q[2] = 0.0 if k == 40 else q[2]
    assert list(fast.counts.items()) == list(plain.counts.items())


def test_trajectory_targets_are_np_interp():
    node = OnboardNode(FedByteLink())
    rng = np.random.default_rng(6)
    n_q = node.robot.n_q
    for trial in range(5):
        times = np.cumsum(rng.uniform(0.01, 0.5, size=2 + trial))
        points = [(float(t), rng.normal(size=n_q)) for t in times]
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


def test_p_matrix_terms_match_plain():
    from rdm.control.lqi import gyro_compensation
    from rdm.nodes.onboard_control import _p_matrix_terms, _p_matrix_terms_plain

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
        fast, plain = _p_matrix_terms(g), _p_matrix_terms_plain(g)
        assert fast == plain and all(type(v) is int for row in fast[0] for v in row)
        saturated += fast[2]
        for bad in (np.nan, np.inf, -np.inf):  # the same error from the same to_wire call
            spoiled = dict(g, pinv_pitch=g["pinv_pitch"].copy())
            spoiled["pinv_pitch"][k % len(spoiled["pinv_pitch"])] = bad
            errors = []
            for f in (_p_matrix_terms, _p_matrix_terms_plain):
                with pytest.raises((ValueError, OverflowError)) as e:
                    f(spoiled)
                errors.append((type(e.value), str(e.value)))
            assert errors[0] == errors[1]
    assert 0 < saturated < 60
    # anything but float64 arrays of the expected ranks: the plain form
    odd = dict(g, inertia=g["inertia"].tolist())
    assert _p_matrix_terms(odd) == _p_matrix_terms_plain(odd)


def test_p_matrix_wire_fast_model_matches_plain():
    node = OnboardNode(FedByteLink())
    fast = ControlPipeline(node.robot, node.config)
    plain = ControlPipeline(node.robot, node.config)
    plain.fast_model = False
    rng = np.random.default_rng(10)
    q = node.present_q.copy()
    for k in range(40):
        if k % 3:
            q[:6] += rng.normal(scale=0.05, size=6)
        for pipe in (fast, plain):
            pipe.update_model(q)
        assert fast.p_matrix_wire() == plain.p_matrix_wire()
    assert list(fast.counts.items()) == list(plain.counts.items())


def test_servo_payload_struct_decode_matches_the_codec():
    """New ``servo/states`` payloads unpacked with one struct (index, angle) against the
    codec's decode, both through ``_on_servo_states``: counters, joint state, caches."""
    import random

    from onboard_rig import REG, assert_same_servo_state, servo_readings

    servos, unit = REG.msg("spinal/ServoStates"), REG.msg("spinal/ServoState")
    fast, plain = OnboardNode(FedByteLink()), OnboardNode(FedByteLink())
    assert fast._servo_struct
    plain._servo_struct = False  # what a message tree of another layout takes: the codec
    n = len(fast.config.servo_map.servo_index)
    rng = random.Random(13)
    readings = servo_readings(rng, n, 40)
    for k in range(600):
        reading = readings[rng.randrange(len(readings))]
        if k % 7 == 0:  # fresh angles, extremes of the wire types
            reading = [(i, rng.choice([-32768, 32767, rng.randrange(4096)])) for i, _ in reading]
        if k % 11 == 0:
            reading = reading[: rng.randrange(len(reading) + 1)]  # partial / empty
        entries = [
            unit.new(index=i, angle=a, temp=rng.randrange(256), load=rng.randrange(-99, 99))
            for i, a in reading
        ]
        payload = servos.encode(servos.new(stamp=(k, 0), servos=entries))
        fast._on_servo_payload(payload)
        plain._on_servo_payload(payload)
        assert_same_servo_state(fast, plain)
        assert list(fast._servo_cache) == list(plain._servo_cache)
        assert list(fast._servo_raw) == list(plain._servo_raw)
    assert fast.counts["servo_unknown_index"] > 0 and fast.counts["servo_states_partial"] > 0
    # a payload whose count does not match its length: the codec's error on both
    bad = servos.encode(servos.new(stamp=(0, 0), servos=[unit.new(index=1, angle=5)]))[:-1]
    for node in (fast, plain):
        with pytest.raises(Exception) as e:
            node._on_servo_payload(bad)
        assert type(e.value).__name__ == "DecodeError"


def test_evaluate_control_is_what_evaluate_gives():
    from rdm.model import Robot

    node = OnboardNode(FedByteLink())
    robot = node.robot
    frame = node.config.imu_link
    other = Robot.default()  # a second workspace for the plain evaluation
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

    # a robot whose evaluate is overridden keeps the plain path
    class _Robot(Robot):
        def evaluate(self, q, base_pose=None):
            return super().evaluate(q, base_pose)

    custom = ControlPipeline(_Robot.default(), node.config)
    assert custom._evaluate_control is None
    assert ControlPipeline(robot, node.config)._evaluate_control is not None
