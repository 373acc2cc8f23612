"""The onboard node's foot-sensor scan, caches and small helpers against their plain forms
(docs/onboard.md), on real and random input, including corrupt bytes.

* ``LeptrinoStreamParser.feed_ok_samples`` (the Rust scan of the leading run of OK-sample
  frames) against ``feed`` byte-at-a-time and chunked: same payloads, events, counters and
  parser state; golden frames from ``firmware_protocol/leptrino/vectors.json``;
* ``FootSensorReader`` with ``fast_scan`` on and off: same counts (in the same order),
  wrench, stamp and bytes written;
* the float clip the control step uses against ``np.clip`` (signed zeros, NaN, inf).
"""

from __future__ import annotations

import json
import random
from pathlib import Path

import numpy as np
import pytest
from fed_byte_link import FedByteLink
from onboard_rig import servo_readings

from rdm import _rdm
from rdm.nodes.onboard_control import _all_finite, _clip
from rdm.nodes.onboard_foot import FootSensorReader
from rdm.protocol import leptrino as lp

VECTORS = Path(__file__).resolve().parents[1] / "firmware_protocol" / "leptrino" / "vectors.json"


def _state(p: lp.LeptrinoStreamParser) -> tuple:
    return (p.frames, dict(p.errors), p.discarded_bytes, p._state, bytes(p._buf), p._start, p._pos)


def _event_key(e: lp.StreamEvent) -> tuple:
    return (e.offset, e.payload, None if e.error is None else e.error.reason)


def _random_stream(rng: random.Random, n: int = 400) -> list[bytes]:
    """Samples (some with DLE bytes to stuff), result errors, acks, bad BCC, truncated frames,
    DLE STX restarts, bad escapes, over-long payloads and junk; one piece each."""
    out: list[bytes] = []
    for _ in range(n):
        kind = rng.random()
        raw = tuple(rng.choice([16, 0x1010, -4080, rng.randint(-32768, 32767)]) for _ in range(6))
        sample = lp.encode_response(lp.ForceData(raw, rng.choice([16, 25]), rng.choice([0, 16])))
        if kind < 0.6:
            out.append(sample)
        elif kind < 0.65:
            out.append(lp.encode_response(lp.ForceData(raw, 20, 0, result=1)))
        elif kind < 0.7:
            out.append(lp.encode_response(lp.Ack(lp.Command.DATA_STOP, lp.Result.OK, 0)))
        elif kind < 0.75:
            f = bytearray(sample)
            f[-1] ^= 0x21
            out.append(bytes(f))
        elif kind < 0.8:
            out.append(sample[: rng.randint(1, len(sample) - 1)])
        elif kind < 0.84:
            out.append(sample[:8] + b"\x10\x02" + sample[2:])
        elif kind < 0.88:
            out.append(sample[:6] + b"\x10\x55" + sample[6:])
        elif kind < 0.9:
            out.append(b"\x10\x02" + bytes([7]) * 300 + b"\x10\x03\x00")
        elif kind < 0.93:
            f = bytearray(sample)
            f[4] = 0x33  # another command byte
            out.append(bytes(f))
        else:
            out.append(bytes(rng.randint(0, 255) for _ in range(rng.randint(1, 5))))
    return out


def _chunks(pieces: list[bytes], rng: random.Random) -> list[bytes]:
    """Runs of whole pieces (as a UART read delivers them), now and then cut anywhere."""
    out, i = [], 0
    while i < len(pieces):
        n = rng.randint(1, 30)
        chunk = b"".join(pieces[i : i + n])
        i += n
        if rng.random() < 0.3:
            cut = rng.randint(0, len(chunk))
            out += [chunk[:cut], chunk[cut:]]
        else:
            out.append(chunk)
    return out


@pytest.mark.parametrize("seed", range(6))
def test_feed_ok_samples_matches_feed(seed):
    rng = random.Random(seed)
    data = _random_stream(rng)
    fast, plain, bytewise = (lp.LeptrinoStreamParser() for _ in range(3))
    summarised = 0
    for chunk in _chunks(data, rng):
        count, newest, rest = fast.feed_ok_samples(chunk)
        want = plain.feed(chunk)
        # the summarised run is a prefix of OK-sample payload events, newest last
        head, tail = want[:count], want[count:]
        assert all(e.error is None and lp.is_ok_sample(e.payload) for e in head)
        assert newest == (head[-1].payload if head else None)
        assert [_event_key(e) for e in rest] == [_event_key(e) for e in tail]
        assert _state(fast) == _state(plain)
        summarised += count
    for b in b"".join(data):
        bytewise.feed(bytes([b]))
    assert _state(fast)[:3] == _state(bytewise)[:3]
    assert summarised > 20
    assert fast.errors["bcc"] > 0 and fast.errors["restart"] > 0 and fast.discarded_bytes > 0


def test_feed_ok_samples_accepts_what_parse_response_accepts():
    """Independent check of the Rust classification: every payload it summarises parses to
    an OK ForceData, and every chunk of whole OK samples is summarised in full."""
    rng = random.Random(11)
    for _ in range(300):
        raws = [tuple(rng.randint(-32768, 32767) for _ in range(6)) for _ in range(25)]
        chunk = b"".join(lp.encode_response(lp.ForceData(r, 25, 0)) for r in raws)
        end, count, last_start, payload = _rdm.leptrino_ok_sample_run(chunk)
        assert (end, count) == (len(chunk), 25)
        resp = lp.parse_response(payload)
        assert isinstance(resp, lp.ForceData) and resp.result == lp.Result.OK
        assert resp.raw == raws[-1]
        assert chunk[last_start:] == lp.encode_response(lp.ForceData(raws[-1], 25, 0))


def test_feed_ok_samples_on_golden_frames():
    vectors = json.loads(VECTORS.read_text())["vectors"]
    for v in vectors:
        frame, payload = bytes.fromhex(v["frame"]), bytes.fromhex(v["payload"])
        parser, ref = lp.LeptrinoStreamParser(), lp.LeptrinoStreamParser()
        count, newest, rest = parser.feed_ok_samples(frame + frame)
        want = ref.feed(frame + frame)
        assert [e.payload for e in want] == [payload, payload]
        if lp.is_ok_sample(payload):
            assert (count, newest, rest) == (2, payload, [])
        else:
            assert count == 0 and [_event_key(e) for e in rest] == [_event_key(e) for e in want]
        assert _state(parser) == _state(ref)
    assert any(lp.is_ok_sample(bytes.fromhex(v["payload"])) for v in vectors)


def test_feed_ok_samples_while_not_idle_takes_the_plain_path():
    sample = lp.encode_response(lp.ForceData((1, 2, 3, 4, 5, 6), 25, 0))
    fast, plain = lp.LeptrinoStreamParser(), lp.LeptrinoStreamParser()
    for p in (fast, plain):
        p.feed(sample[:7])  # mid-frame
    count, newest, rest = fast.feed_ok_samples(sample[7:] + sample * 2)
    want = plain.feed(sample[7:] + sample * 2)
    assert count == 0 and newest is None
    assert [_event_key(e) for e in rest] == [_event_key(e) for e in want]
    assert _state(fast) == _state(plain)


def test_ok_sample_run_on_bad_input():
    assert _rdm.leptrino_ok_sample_run(b"") == (0, 0, 0, None)
    assert _rdm.leptrino_ok_sample_run(b"\x10") == (0, 0, 0, None)
    assert _rdm.leptrino_ok_sample_run(b"\x10\x02" + b"\x10" * 99) == (0, 0, 0, None)
    with pytest.raises(TypeError):
        _rdm.leptrino_ok_sample_run("not bytes")


@pytest.mark.parametrize("seed", range(4))
def test_foot_reader_fast_scan_matches_plain(seed):
    rng = random.Random(100 + seed)
    data = _random_stream(rng, 600)
    fast_link, plain_link = FedByteLink(), FedByteLink()
    fast, plain = FootSensorReader(fast_link), FootSensorReader(plain_link)
    plain.fast_scan = False
    for k, chunk in enumerate(_chunks(data, rng) + [b""] * 50):
        fast_link.pending = plain_link.pending = chunk
        now = 0.025 * k
        fast.poll(now)
        plain.poll(now)
        assert list(fast.counts.items()) == list(plain.counts.items())
        assert fast.stamp == plain.stamp
        if plain.wrench is None:
            assert fast.wrench is None
        else:
            assert fast.wrench.tobytes() == plain.wrench.tobytes()
        assert _state(fast.parser) == _state(plain.parser)
    assert fast_link.written == plain_link.written
    assert fast.counts["samples"] > 100 and fast.counts["start_sent"] > 1


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


def test_imu_converted_when_read_matches_every_message():
    """The node keeps the newest valid quaternion/gyro and converts on read: the same values
    as converting every message (independent: quaternion_to_euler / np.array of the last
    valid one), invalid ones counted and skipped, non-tuple gyro through ``_vector``."""
    from rdm.nodes.onboard import OnboardNode, quaternion_to_euler
    from rdm.protocol.rosserial.events import MessageReceived
    from rdm.protocol.rosserial.registry import spinal_registry

    imu = spinal_registry().msg("spinal/Imu")
    node = OnboardNode(FedByteLink())
    assert node.imu_euler is None and node.imu_gyro is None
    rng = random.Random(9)
    want_euler = want_gyro = None
    invalid = 0
    for k in range(400):
        q = [rng.uniform(-1, 1) for _ in range(4)]
        norm = sum(v * v for v in q) ** 0.5
        q = [v / norm for v in q]
        if rng.random() < 0.15:
            q[rng.randrange(4)] = rng.choice([float("nan"), 3.0])
        gyro = [rng.uniform(-2, 2) for _ in range(3)]
        if rng.random() < 0.15:
            gyro[rng.randrange(3)] = float("inf")
        msg = imu.new(quaternion=q, gyro=gyro)
        if k % 7 == 0:  # a numpy gyro takes _vector's numpy path
            msg = imu.new(quaternion=q, gyro=np.array(gyro, dtype=np.float32))
        node._on_event(MessageReceived("imu", "spinal/Imu", 100, msg))
        ok_q = all(np.isfinite(q)) and abs(sum(v * v for v in q) - 1) <= 0.1
        if not ok_q:
            invalid += 1
        else:
            want_euler = quaternion_to_euler(*[float(v) for v in msg.quaternion])
            g = np.asarray(msg.gyro, dtype=float)
            if np.all(np.isfinite(g)):
                want_gyro = g
        if rng.random() < 0.3:
            assert node.imu_euler == want_euler
            if want_gyro is None:
                assert node.imu_gyro is None
            else:
                assert node.imu_gyro.tobytes() == want_gyro.tobytes()
    assert node.counts["imu_invalid"] == invalid > 0


@pytest.mark.parametrize("offset", [(0.0,) * 6, (10.0, -3.0, 0.5, 1e4, -2e4, 7.25), (1e99,) * 6])
def test_take_matches_parse_response_and_to_wrench(offset):
    reader = FootSensorReader(FedByteLink(), offset=offset)
    rated = np.array(lp.MODELS["CFS034CA301U"].rated)
    rng = random.Random(21)
    for _ in range(500):
        raw = tuple(rng.randint(-32768, 32767) for _ in range(6))
        payload = lp.encode_response(lp.ForceData(raw, rng.randint(-5, 80), 3))
        payload = lp.LeptrinoStreamParser().feed(payload)[0].payload
        reader._take(payload)
        assert reader.wrench.tobytes() == reader._take_reference(payload).tobytes()
        want = (np.array(raw, dtype=float) - np.array(offset)) * rated / 10000.0
        np.testing.assert_allclose(reader.wrench, want, rtol=1e-15, atol=0)


def test_foot_reader_wrong_offset_length_takes_the_plain_path():
    reader = FootSensorReader(FedByteLink(), offset=(0.0,) * 5)
    assert not reader._skip_older
    reader.link.pending = lp.encode_response(lp.ForceData((1, 2, 3, 4, 5, 6), 20, 0))
    with pytest.raises(lp.LeptrinoError):
        reader.poll(0.0)


def test_floats_is_float_of_each():
    from rdm.nodes.onboard import _floats

    rng = np.random.default_rng(8)
    for a in (
        rng.normal(size=4),
        np.array([0.0, -0.0, np.nan, 1e308]),
        rng.normal(size=4).astype(np.float32),
        [1, 2.5],
    ):
        got, want = _floats(a), [float(v) for v in a]
        assert [type(v) for v in got] == [float] * len(want)
        assert np.array(got).tobytes() == np.array(want).tobytes()


def test_model_cache_of_recent_q_matches_evaluating_every_tick():
    """q flickering between a few servo readings (and a bad q now and then): the cached terms
    and pinv message equal an evaluation at every tick, counters included."""
    from rdm.model import Robot
    from rdm.nodes.onboard_config import OnboardConfig
    from rdm.nodes.onboard_control import MODEL_CACHE_SIZE, ControlPipeline

    robot = Robot.default()
    cfg = OnboardConfig()
    fast, plain = ControlPipeline(robot, cfg), ControlPipeline(robot, cfg)
    plain.reuse_model = False
    rng = np.random.default_rng(12)
    base = rng.uniform(-0.3, 0.3, size=robot.n_q)
    pool = [base + 0.0015 * rng.integers(-2, 3, size=robot.n_q) for _ in range(6)]
    bad = base.copy()
    bad[1] = np.nan
    q_live = np.zeros(robot.n_q)
    cached_hits = 0
    for k in range(400):
        q = bad if k % 37 == 5 else pool[rng.integers(len(pool))]
        before = fast._model_key
        cached_hits += before != q.tobytes() and q.tobytes() in fast._model_cache
        q_live[:] = q
        assert fast.update_model(q_live) == plain.update_model(q_live.copy())
        for name in ("q", "inertia", "allocation", "allocation_bar", "foot_allocation"):
            assert getattr(fast.terms, name).tobytes() == getattr(plain.terms, name).tobytes()
        for name in ("link_rotations", "hover_thrust", "imu_to_cog"):
            assert getattr(fast.terms, name).tobytes() == getattr(plain.terms, name).tobytes()
        assert fast.terms.mass == plain.terms.mass
        if rng.random() < 0.8:
            assert fast.p_matrix_wire() == plain.p_matrix_wire()
        assert fast.desire_coordinate() == plain.desire_coordinate()
        assert fast.counts == plain.counts
        assert len(fast._model_cache) <= MODEL_CACHE_SIZE
    assert cached_hits > 50 and plain.counts["model_error"] > 5


def test_servo_states_follow_the_servo_map():
    """Repeated, partial, unknown-index and duplicate-index ``servo/states`` readings (the
    repeated ones applied from the node's reading cache): after every message the node holds
    the present q, seen flags, joint targets and counters the servo map's rule gives, written
    out here: joint j of servo index i is i's position in ``servo_index`` (none, or j past
    the model's joints: counted unknown), q_j = sign * (raw - zero) * scale, a reading that
    does not cover every joint counts partial, and the joint targets hold the present q once
    every joint was seen."""
    from collections import Counter

    from rdm.nodes.onboard import OnboardNode
    from rdm.protocol.rosserial.registry import spinal_registry

    reg = spinal_registry()
    states, unit = reg.msg("spinal/ServoStates"), reg.msg("spinal/ServoState")
    node = OnboardNode(FedByteLink())
    smap, n_q = node.config.servo_map, node.robot.n_q
    q, seen, counts, targets = node.present_q.copy(), np.zeros(n_q, bool), Counter(), None
    n = len(smap.servo_index)
    rng = random.Random(31)
    readings = servo_readings(rng, n, 12)
    for k in range(600):
        reading = readings[rng.randrange(len(readings))]
        if k == 0:
            reading = readings[0][:3]  # partial first: the hold waits for every joint
        node._on_servo_states(states.new(servos=[unit.new(index=i, angle=a) for i, a in reading]))
        covered = set()
        for i, a in reading:
            j = smap.servo_index.index(i) if i in smap.servo_index else None
            if j is None or j >= n_q:
                counts["servo_unknown_index"] += 1
                continue
            q[j] = smap.angle_sign[j] * (a - smap.zero_point[j]) * smap.angle_scale[j]
            seen[j] = True
            covered.add(j)
        if len(covered) != n_q:
            counts["servo_states_partial"] += 1
        if targets is None and seen.all():
            targets = q.copy()
        assert node.present_q.tobytes() == q.tobytes()
        assert node._seen.tobytes() == seen.tobytes()
        assert (node.joint_targets is None) == (targets is None)
        if targets is not None:
            assert node.joint_targets.tobytes() == targets.tobytes()
        assert dict(node.counts) == dict(counts)
        if k % 50 == 0:  # someone else moves present_q: the cached writes still apply
            node.present_q[:] = q[:] = rng.random()
    assert counts["servo_unknown_index"] > 0 and counts["servo_states_partial"] > 0
    assert 0 < len(node._servo_cache) <= 8


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


def test_desire_coordinate_message_rebuilt_with_the_model_terms():
    """The cached ``desire_coordinate`` message encodes as one built from scratch from the
    present terms, across q changes and returns to an earlier q (cached terms)."""
    from rdm.model import Robot
    from rdm.nodes.onboard import OnboardNode
    from rdm.protocol.rosserial.registry import spinal_registry

    robot = Robot.default()
    codec = spinal_registry().msg("spinal/DesireCoord")
    node = OnboardNode(FedByteLink(), robot=robot)
    rng = np.random.default_rng(5)
    pool = [rng.uniform(-0.3, 0.3, size=robot.n_q) for _ in range(3)]
    builds = set()
    for k in range(30):
        node.present_q[:] = pool[rng.integers(3)]
        node._control(0.025 * k)
        roll, pitch, yaw = node.control.desire_coordinate()
        # independent: ZYX angles of the IMU link's rotation in the CoG frame, from the model
        o = robot.evaluate(node.present_q)
        rot = (
            np.asarray(o["frames"]["cog"])[:3, :3].T
            @ np.asarray(o["frames"][node.config.imu_link])[:3, :3]
        )
        np.testing.assert_allclose(
            [roll, pitch, yaw],
            [
                np.arctan2(rot[2, 1], rot[2, 2]),
                -np.arcsin(rot[2, 0]),
                np.arctan2(rot[1, 0], rot[0, 0]),
            ],
            atol=1e-12,
        )
        fresh = codec.new(roll=roll, pitch=pitch, yaw=yaw)
        assert codec.encode(node._desire_msg[1]) == codec.encode(fresh)
        builds.add(id(node._desire_msg[1]))
    assert 3 <= len(builds) < 30  # rebuilt on change only
