"""The onboard node's fast paths give exactly what the plain computations give
(docs/onboard.md).

* ``foot_allocation`` (p x F written out) against ``np.cross``;
* ``ControlPipeline.update_model`` / ``p_matrix_wire`` reused while q holds, against a
  pipeline that evaluates every time (``reuse_model = False``) and against an independent
  numpy re-derivation of Q̄_foot and the hover thrust;
* ``FootSensorReader`` converting only the newest sample of a batch, against the per-sample
  path and against the test's own (raw - offset) * rated / 10000;
* the node's ``rpy/gain`` and ``p_matrix_pseudo_inverse_inertia`` messages rebuilt only on
  change, against messages built from scratch with the registry and encoded by the codec.
"""

from __future__ import annotations

import random

import numpy as np
import pytest
from fed_byte_link import FedByteLink

from rdm.model import Robot
from rdm.nodes.onboard import OnboardNode
from rdm.nodes.onboard_config import OnboardConfig
from rdm.nodes.onboard_control import ControlPipeline, foot_allocation, foot_allocation_reference
from rdm.nodes.onboard_foot import FootSensorReader
from rdm.protocol import leptrino as lp
from rdm.protocol.rosserial import spinal_registry

ROBOT = Robot.default()


def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def test_foot_allocation_is_bitwise_np_cross():
    rng = np.random.default_rng(1)
    for _ in range(200):
        full = rng.normal(size=(6, 4)) * 10.0 ** rng.integers(-3, 3)
        pose = np.eye(4)
        pose[:3, 3] = rng.normal(size=3)
        assert _same(foot_allocation(full, pose), foot_allocation_reference(full, pose))


def _q_sequence(rng: np.random.Generator) -> list[np.ndarray]:
    """q values with repeats (held servos), small changes, -0.0 and a bad q in between."""
    q = np.zeros(ROBOT.n_q)
    out = []
    for k in range(60):
        if k % 3 == 0:
            q = q.copy()
            q[rng.integers(0, 6)] += rng.normal() * 0.05
        if k == 20:
            q = -0.0 * np.ones(ROBOT.n_q)
        out.append(q.copy())
        if k == 40:
            bad = q.copy()
            bad[0] = np.nan
            out.append(bad)
    return out


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


def test_model_reuse_matches_evaluating_every_tick():
    cfg = OnboardConfig()
    fast, plain = ControlPipeline(ROBOT, cfg), ControlPipeline(ROBOT, cfg)
    plain.reuse_model = False
    q_live = np.zeros(ROBOT.n_q)  # mutated in place, as the node's present_q
    hits = 0
    for q in _q_sequence(np.random.default_rng(2)):
        hits += q_live.tobytes() == q.tobytes()
        q_live[:] = q
        assert fast.update_model(q_live) == plain.update_model(q_live.copy())
        _terms_equal(fast.terms, plain.terms)
        assert fast.p_matrix_wire() == plain.p_matrix_wire()
        assert fast.desire_coordinate() == plain.desire_coordinate()
        assert fast.counts == plain.counts
    assert hits > 20  # the cache was exercised
    assert plain.counts["model_error"] == 1


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


def _stream(rng: random.Random) -> tuple[list[bytes], list[list[tuple[int, ...]]]]:
    """Batches of frames: mostly samples, some acks, result errors, bad BCC, junk; also the
    raw values of the good samples per batch, in order."""
    batches, goods = [], []
    for _ in range(80):
        chunk, good = b"", []
        for _ in range(rng.randint(0, 14)):
            kind = rng.random()
            raw = tuple(rng.randint(-32768, 32767) for _ in range(6))
            if kind < 0.7:
                chunk += lp.encode_response(lp.ForceData(raw, rng.randint(0, 80), 0))
                good.append(raw)
            elif kind < 0.78:
                chunk += lp.encode_response(lp.ForceData(raw, 20, 0, result=1))
            elif kind < 0.84:
                chunk += lp.encode_response(lp.Ack(lp.Command.DATA_STOP, lp.Result.OK, 0))
            elif kind < 0.9:
                f = bytearray(lp.encode_response(lp.ForceData(raw, 20, 0)))
                f[-1] ^= 0x5A  # BCC
                chunk += bytes(f)
            else:
                chunk += bytes(rng.randint(0, 255) for _ in range(rng.randint(1, 6)))
        batches.append(chunk)
        goods.append(good)
    return batches, goods


@pytest.mark.parametrize("offset", [(0.0,) * 6, (10.0, -3.0, 0.5, 1e4, -2e4, 7.0)])
def test_foot_reader_newest_only_matches_every_sample(offset):
    batches, goods = _stream(random.Random(5))
    fast_link, plain_link = FedByteLink(), FedByteLink()
    fast = FootSensorReader(fast_link, offset=offset)
    plain = FootSensorReader(plain_link, offset=offset)
    plain._skip_older = False
    assert fast._skip_older
    rated = np.array(lp.MODELS["CFS034CA301U"].rated)
    last_good = None
    for k, (chunk, good) in enumerate(zip(batches, goods, strict=True)):
        fast_link.pending = plain_link.pending = chunk
        now = 0.025 * k
        fast.poll(now)
        plain.poll(now)
        assert fast.counts == plain.counts
        assert fast.stamp == plain.stamp
        assert (fast.wrench is None) == (plain.wrench is None)
        if fast.wrench is not None:
            assert _same(fast.wrench, plain.wrench)
        if good:
            last_good = good[-1]
        if last_good is not None:  # independent: (raw - offset) * rated / 10000
            want = (np.array(last_good, dtype=float) - np.array(offset)) * rated / 10000.0
            np.testing.assert_allclose(fast.wrench, want, rtol=1e-15, atol=0)
    assert fast_link.written == plain_link.written
    assert fast.counts["samples"] > 200 and fast.counts["result_error"] > 0


def test_foot_reader_plain_path_for_a_non_finite_offset():
    reader = FootSensorReader(FedByteLink(), offset=(np.inf, 0, 0, 0, 0, 0))
    assert not reader._skip_older
    reader.link.pending = lp.encode_response(lp.ForceData((1, 2, 3, 4, 5, 6), 20, 0)) * 3
    reader.poll(0.0)
    assert reader.counts["non_finite"] == 3 and reader.wrench is None


REG = spinal_registry()


def _fresh_gains_bytes(wire: np.ndarray) -> bytes:
    names = ("roll_p", "roll_i", "roll_d", "pitch_p", "pitch_i", "pitch_d", "yaw_d")
    term = REG.msg("spinal/RollPitchYawTerm")
    msg = REG.msg("spinal/RollPitchYawTerms").new(
        motors=[term.new(**{k: int(v) for k, v in zip(names, row, strict=True)}) for row in wire]
    )
    return REG.msg("spinal/RollPitchYawTerms").encode(msg)


def test_gains_and_pinv_messages_rebuilt_only_on_change():
    node = OnboardNode(FedByteLink(), robot=ROBOT)
    codec = REG.msg("spinal/RollPitchYawTerms")
    rng = np.random.default_rng(3)
    wires = [rng.integers(-3000, 3000, size=(4, 7)).astype(np.int16) for _ in range(3)]
    wires.append(rng.uniform(-3000, 3000, size=(4, 7)))  # not int16: the int(v) path
    for wire in [wires[0], wires[0].copy(), wires[1], wires[3], wires[0], wires[2], wires[2]]:
        node.control.gains_wire = wire
        node._send_gains()  # not negotiated: counted, the message is still built
        assert codec.encode(node._gains_msg[1]) == _fresh_gains_bytes(wire)
    pinv = REG.msg("spinal/PMatrixPseudoInverseWithInertia")
    unit = REG.msg("spinal/PMatrixPseudoInverseUnit")
    for q in (np.zeros(ROBOT.n_q), np.zeros(ROBOT.n_q), np.full(ROBOT.n_q, 0.1)):
        node.present_q[:] = q
        node._control(0.0)
        rows, inertia = node.control.p_matrix_wire()
        fresh = pinv.new(
            pseudo_inverse=[unit.new(r=r, p=p, y=y) for r, p, y in rows], inertia=inertia
        )
        assert pinv.encode(node._p_matrix_msg[1]) == pinv.encode(fresh)


def test_leptrino_whole_frame_path_equals_byte_at_a_time():
    """Whole frames in one chunk take the regex path; byte-at-a-time never can."""
    gen = random.Random(11)
    stream = b""
    for _ in range(300):
        r = gen.random()
        payload = bytes(gen.choice([0x10, 0x02, 0x03, gen.randrange(256)]) for _ in range(20))
        if r < 0.55:
            stream += lp.frame(payload)
        elif r < 0.65:  # bad BCC
            stream += lp.frame(payload)[:-1] + bytes([gen.randrange(256)])
        elif r < 0.72:  # empty payload
            stream += b"\x10\x02\x10\x03" + bytes([gen.choice([3, 7])])
        elif r < 0.8:  # DLE STX inside a frame, then the frame
            stream += b"\x10\x02\x01\x02\x10\x02" + lp.frame(payload)[2:]
        elif r < 0.87:  # bad escape
            stream += b"\x10\x02\x05\x10\x07" + lp.frame(payload)
        else:
            stream += bytes(gen.choice([0x10, 0x02, 0x03, gen.randrange(256)]) for _ in range(5))
    whole, single = lp.LeptrinoStreamParser(), lp.LeptrinoStreamParser()
    calls = 0
    original = lp._WHOLE_FRAME

    class Counting:
        def match(self, data, pos):
            nonlocal calls
            calls += 1
            return original.match(data, pos)

    lp._WHOLE_FRAME = Counting()
    try:
        events_whole = whole.feed(stream)
    finally:
        lp._WHOLE_FRAME = original
    events_single = [e for b in stream for e in single.feed(bytes([b]))]
    assert repr(events_whole) == repr(events_single)
    assert whole == single  # counters, position, state and buffer
    assert calls > 150 and whole.frames > 150
    assert {"bcc", "length", "restart", "escape"} <= set(whole.errors)


def _vector_plain(value, n):
    """The numpy form of ``rdm.nodes.onboard._vector`` (flatten, length n, all finite)."""
    try:
        v = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        return None
    return v if v.shape == (n,) and np.all(np.isfinite(v)) else None


@pytest.mark.parametrize(
    "value",
    [
        (0.1, -2.5, 3e-9),
        [0.0, -0.0, 1e300],
        (0.1, float("nan"), 0.0),
        (float("inf"), 0.0, 0.0),
        (1, 2, 3),  # ints: the numpy path
        (0.1, 0.2),
        (0.1, 0.2, 0.3, 0.4),
        [[0.1], [0.2], [0.3]],
        ("0.5", 1.0, 2.0),
        ("x", 1.0, 2.0),
        None,
        np.array([0.1, -2.5, 3e-9]),  # float arrays: the ndarray path
        np.array([0.0, -0.0, np.nan]),
        np.array([0.0, -np.inf, 1.0]),
        np.array([1.0, 2.0, 3.0, 4.0])[::2][:3],  # a strided view, length 2
        np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])[::2],  # a strided view, length 3
        np.array([[0.1, 0.2, 0.3]]),
        np.array([1, 2, 3]),
        np.array([0.1, 0.2, 0.3], dtype=np.float32),
    ],
)
def test_vector_fast_path_equals_numpy_form(value):
    from rdm.nodes.onboard import _vector

    got, want = _vector(value, 3), _vector_plain(value, 3)
    assert (got is None) == (want is None), (got, want)
    if want is not None:
        assert _same(got, want)
        # a float64 vector stays a view of the caller's memory on both paths (a script that
        # later writes its setpoint in place moves the target too)
        assert np.shares_memory(got, value) == np.shares_memory(want, value)


def test_setpoint_ramp_distance_is_numpys_norm() -> None:
    """``SetpointRamp.step``'s distance (``sqrt(d.dot(d))``) against ``np.linalg.norm`` on
    random vectors, and ``arrived`` against ``np.all(position == goal)``."""
    from rdm.scenarios.common import SetpointRamp

    rng = np.random.default_rng(3)
    for _ in range(500):
        start, goal = rng.normal(size=3) * rng.choice([1e-6, 1.0, 1e3]), rng.normal(size=3)
        speed, dt = float(rng.uniform(0.01, 2.0)), 0.01
        ramp = SetpointRamp(start, speed)
        ramp.set_goal(goal)
        delta = goal - start
        dist = float(np.linalg.norm(delta))
        ramp.step(dt)
        reach = speed * dt
        want = goal if dist <= reach else start + delta / dist * reach
        assert ramp.position.tobytes() == np.asarray(want, dtype=float).tobytes()
        assert ramp.arrived == bool(np.all(ramp.position == ramp.goal))
    ramp = SetpointRamp(np.array([0.0, -0.0, 1.0]), 1.0)
    ramp.set_goal(np.array([-0.0, 0.0, 1.0]))
    assert ramp.arrived  # -0.0 == 0.0, as numpy compares
    ramp.set_goal(np.array([np.nan, 0.0, 1.0]))
    assert not ramp.arrived
