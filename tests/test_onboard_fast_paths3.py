"""The onboard node's deferred rosserial decode and direct payloads against their plain forms
(docs/onboard.md), on real, random and corrupt input:

* ``ServerSession.deferred``: ``imu`` / ``servo/states`` frames returned as ``(handler,
  payload)`` instead of decoded messages: same events (once decoded), counters and order;
  ``servo_states_decodes`` and the Imu length rule are exactly the codec's accept set;
* the node's payload handlers against ``_on_event`` of the decoded message;
* payloads the node packs itself (rpy/gain, four_axes/command, servo/target_states) and the
  payloads of unchanged messages against the codec's bytes;
* a whole node with every fast path on against one with them off, fed the same bytes by a
  scripted Spinal (real ``ClientSession``): identical UART output, counters and commands.
"""

from __future__ import annotations

import random
import struct
from typing import Any

import numpy as np
import pytest
from fed_byte_link import FedByteLink
from onboard_rig import REG, assert_same_servo_state, servo_readings

from rdm.nodes.onboard import OnboardNode, _four_axis_payload, servo_states_decodes
from rdm.protocol.rosserial.client import ClientSession
from rdm.protocol.rosserial.codec import DecodeError, EncodeError
from rdm.protocol.rosserial.events import MessageReceived
from rdm.protocol.rosserial.framing import encode_frame
from rdm.protocol.rosserial.server import ServerSession

IMU, SERVOS = REG.msg("spinal/Imu"), REG.msg("spinal/ServoStates")
UNIT = REG.msg("spinal/ServoState")


def _decodes(codec, payload: bytes) -> bool:
    try:
        codec.decode(payload)
    except DecodeError:
        return False
    return True


def _random_payloads(rng: random.Random, n: int) -> list[bytes]:
    out = []
    for _ in range(n):
        kind = rng.random()
        if kind < 0.4:  # a real ServoStates, maybe cut or extended
            k = rng.randint(0, 12)
            msg = SERVOS.new(
                servos=[
                    UNIT.new(index=rng.randint(0, 20), angle=rng.randint(-3000, 3000))
                    for _ in range(k)
                ]
            )
            p = SERVOS.encode(msg)
            if rng.random() < 0.3:
                p = p[: rng.randint(0, len(p))]
            elif rng.random() < 0.2:
                p += bytes(rng.randint(1, 9))
            out.append(p)
        elif kind < 0.7:  # a count that does not fit
            body = bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 40)))
            out.append(bytes(8) + struct.pack("<I", rng.choice([0, 1, 5, 2**31, 2**32 - 1])) + body)
        else:
            out.append(bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 80))))
    return out


def test_servo_states_decodes_is_exactly_what_the_codec_decodes():
    rng = random.Random(5)
    payloads = _random_payloads(rng, 3000)
    got = [servo_states_decodes(p) for p in payloads]
    assert got == [_decodes(SERVOS, p) for p in payloads]
    assert any(got) and not all(got)


def test_imu_length_rule_is_exactly_what_the_codec_decodes():
    rng = random.Random(6)
    for n in range(0, 130):
        p = bytes(rng.getrandbits(8) for _ in range(n))
        assert _decodes(IMU, p) is (len(p) == 60) is (IMU.fixed_size == len(p))


def _imu_payload(rng: random.Random) -> bytes:
    kind = rng.random()
    if kind < 0.2:  # random bits: NaN, inf, huge, denormal floats
        return bytes(rng.getrandbits(8) for _ in range(60))
    q = [rng.uniform(-1, 1) for _ in range(4)]
    norm = sum(v * v for v in q) ** 0.5
    q = [v / norm for v in q]
    if kind < 0.35:
        q[rng.randrange(4)] = rng.choice([float("nan"), float("inf"), 3.0, 0.0])
    gyro = [rng.uniform(-2, 2) for _ in range(3)]
    if rng.random() < 0.15:
        gyro[rng.randrange(3)] = rng.choice([float("inf"), float("nan")])
    acc = [rng.uniform(-20, 20) for _ in range(3)]
    return IMU.encode(IMU.new(quaternion=q, gyro=gyro, acc=acc))


def test_imu_payload_handler_matches_the_decoded_message():
    fast, plain = OnboardNode(FedByteLink()), OnboardNode(FedByteLink())
    rng = random.Random(7)
    for k in range(1500):
        p = _imu_payload(rng)
        fast._on_imu_payload(p)
        plain._on_event(MessageReceived("imu", "spinal/Imu", 101, IMU.decode(p)))
        assert list(fast.counts.items()) == list(plain.counts.items())
        if rng.random() < 0.3 or k == 1499:
            assert fast.imu_euler == plain.imu_euler
            a, b = fast.imu_gyro, plain.imu_gyro
            assert (a is None) == (b is None)
            if a is not None:
                assert a.tobytes() == b.tobytes()
    assert fast.counts["imu_invalid"] > 0 and fast.imu_euler is not None


def test_servo_payload_handler_matches_the_decoded_message():
    fast, plain = OnboardNode(FedByteLink()), OnboardNode(FedByteLink())
    n = len(fast.config.servo_map.servo_index)
    rng = random.Random(11)
    readings = servo_readings(rng, n, 14)
    for k in range(800):
        reading = readings[rng.randrange(len(readings))] if k else readings[0][:3]
        temp = rng.choice([0, 0, 0, 41])  # same (index, angle), other bytes now and then
        msg = SERVOS.new(
            stamp=(k, 0), servos=[UNIT.new(index=i, angle=a, temp=temp) for i, a in reading]
        )
        p = SERVOS.encode(msg)
        fast._on_servo_payload(p)
        plain._on_event(MessageReceived("servo/states", "spinal/ServoStates", 102, msg))
        assert_same_servo_state(fast, plain)
        if k % 60 == 0:  # someone else moves present_q: the cached writes still apply
            fast.present_q[:] = plain.present_q[:] = rng.random()
    assert 0 < len(fast._servo_raw) <= 8
    assert fast.counts["servo_unknown_index"] > 0


def _handshake(servers: list[ServerSession]) -> ClientSession:
    client = ClientSession.from_layout()
    for s in servers:
        s.start(0.0)
    for ms in range(0, 400, 5):
        out = b""
        for s in servers:
            out = s.take_output()  # the same bytes from each
        data = b"".join(e for e in [out])
        client.spin(data, ms)
        wire = client.take_output()
        for s in servers:
            s.feed(wire, ms / 1000)
    assert client.configured
    return client


def test_session_deferred_topics_match_decoding():
    """A deferred session and a plain one fed the same stream (handshake, then imu and
    servo/states frames with good, short, long and random payloads, corrupt frames, noise):
    the deferred events resolve to the plain session's events; counters equal, same order."""
    fast, plain = ServerSession(REG), ServerSession(REG)
    seen: list[tuple[str, bytes]] = []
    fast.deferred.update(
        {
            "imu": ("spinal/Imu", lambda p: len(p) == 60, lambda p: seen.append(("imu", p))),
            "servo/states": (
                "spinal/ServoStates",
                servo_states_decodes,
                lambda p: seen.append(("servo/states", p)),
            ),
        }
    )
    _handshake([fast, plain])
    ids = {r.name: tid for tid, r in plain.inbound.items()}
    rng = random.Random(13)
    servo_payloads = _random_payloads(rng, 200)
    t = 0.4
    for _ in range(300):
        chunk = b""
        for _ in range(rng.randint(0, 6)):
            kind = rng.random()
            if kind < 0.4:
                p = _imu_payload(rng)
                if rng.random() < 0.2:
                    p = p[: rng.randint(0, 59)] if rng.random() < 0.5 else p + b"\x00"
                frame = encode_frame(ids["imu"], p)
            elif kind < 0.75:
                frame = encode_frame(ids["servo/states"], rng.choice(servo_payloads))
            elif kind < 0.85:
                frame = encode_frame(ids["battery_voltage_status"], struct.pack("<f", 24.0))
            else:
                frame = bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 30)))
            if rng.random() < 0.05:
                b = bytearray(frame)
                b[rng.randrange(len(b))] ^= 0x10
                frame = bytes(b)
            chunk += frame
        t += 0.025
        got, want = fast.feed(chunk, t), plain.feed(chunk, t)
        resolved = []
        for e in got:
            if e.__class__ is tuple:
                seen.clear()
                e[0](e[1])
                topic, payload = seen[0]
                codec = IMU if topic == "imu" else SERVOS
                resolved.append(("rx", topic, repr(codec.decode(payload))))  # NaN-safe
            else:
                resolved.append(e)
        plain_form = [
            ("rx", e.topic, repr(e.message))
            if isinstance(e, MessageReceived) and e.topic in ("imu", "servo/states")
            else e
            for e in want
        ]
        assert resolved == plain_form
        assert list(fast.counts.items()) == list(plain.counts.items())
        assert fast.parser.counts == plain.parser.counts
    assert fast.counts["rx_dropped"] > 0 and fast.counts["rx_messages"] > 100


PINV_TOPIC = "p_matrix_pseudo_inverse_inertia"


def _two_sessions() -> tuple[ServerSession, ServerSession]:
    """Two server sessions after the same handshake, their output taken."""
    fast, plain = ServerSession(REG), ServerSession(REG)
    _handshake([fast, plain])
    fast.take_output(), plain.take_output()
    return fast, plain


def _pinv_message(n: int) -> Any:
    """A pinv + inertia message of ``n`` units (300: larger than the device buffer)."""
    pinv = REG.msg("spinal/PMatrixPseudoInverseWithInertia")
    unit = REG.msg("spinal/PMatrixPseudoInverseUnit")
    return pinv.new(pseudo_inverse=[unit.new(r=i, p=-i, y=3) for i in range(n)], inertia=[1] * 6)


def _outcome(call: Any, *args: Any) -> Any:
    """What ``call(*args)`` returned, or the type and text of what it raised."""
    try:
        return call(*args)
    except Exception as exc:  # compared by the caller
        return (type(exc), str(exc))


def test_publish_payload_matches_publish():
    fast, plain = _two_sessions()
    for n in (4, 0, 300):
        msg = _pinv_message(n)
        payload = fast.outbound[PINV_TOPIC].codec.encode(msg)
        assert _outcome(fast.publish_payload, PINV_TOPIC, payload) == _outcome(
            plain.publish, PINV_TOPIC, msg
        )
        assert fast.take_output() == plain.take_output()
        assert list(fast.counts.items()) == list(plain.counts.items())
    with pytest.raises(KeyError):
        fast.publish_payload("no/such_topic", b"")


def test_try_publish_payload_queues_what_publish_payload_does():
    fast, plain = _two_sessions()
    taken = 0
    for n in (4, 0, 300, 7):
        payload = fast.outbound[PINV_TOPIC].codec.encode(_pinv_message(n))
        for form in (payload, bytearray(payload)):
            took = fast.try_publish_payload(PINV_TOPIC, form)
            if not took:  # nothing queued or counted: the plain call decides
                assert fast.take_output() == b"" and fast.counts == plain.counts
                fast_result = _outcome(fast.publish_payload, PINV_TOPIC, form)
            plain_result = _outcome(plain.publish_payload, PINV_TOPIC, form)
            if took:
                taken += 1
                assert isinstance(plain_result, int)  # the plain call queued a frame too
            else:
                assert fast_result == plain_result
            assert fast.take_output() == plain.take_output()
            assert list(fast.counts.items()) == list(plain.counts.items())
    assert taken == 6  # the payloads that fit, bytes or bytearray
    assert not fast.try_publish_payload("no/such_topic", b"")
    assert fast.take_output() == b""


def test_direct_payloads_are_the_codec_bytes():
    rng = np.random.default_rng(17)
    gains = REG.msg("spinal/RollPitchYawTerms")
    term = REG.msg("spinal/RollPitchYawTerm")
    names = ("roll_p", "roll_i", "roll_d", "pitch_p", "pitch_i", "pitch_d", "yaw_d")
    for n in (0, 1, 4, 9):
        wire = rng.integers(-32768, 32768, size=(n, 7)).astype(np.int16)
        wire[:, 0] = [-32768, 32767, 0, -1, 5, 6, 7, 8, 9][:n]
        rows = [dict(zip(names, map(int, r), strict=True)) for r in wire]
        msg = gains.new(motors=[term.new(**row) for row in rows])
        # independent: count, then each row as 7 little-endian int16
        indep = struct.pack("<I", n) + b"".join(struct.pack("<7h", *map(int, r)) for r in wire)
        direct = struct.pack("<I", n) + wire.astype("<i2").tobytes()
        assert gains.encode(msg) == indep == direct
    four = REG.msg("spinal/FourAxisCommand")
    for _ in range(300):
        angles = tuple(float(v) for v in rng.normal(size=3))
        thrust = rng.uniform(0, 30, size=rng.integers(0, 9))
        if rng.random() < 0.1:
            thrust[:1] = np.nan
        payload = _four_axis_payload(angles, thrust)
        assert payload == four.encode(four.new(angles=list(angles), base_thrust=thrust.tolist()))
    for bad_angles, bad_thrust in (((1e300, 0.0, 0.0), [1.0]), ((0.0, 0.0), [1.0])):
        assert _four_axis_payload(bad_angles, np.array(bad_thrust)) is None
        with pytest.raises((EncodeError, OverflowError)):  # the codec's own error
            four.encode(four.new(angles=list(bad_angles), base_thrust=bad_thrust))


def test_perch_zero_hold_and_command_match_the_plain_step():
    """The rate-limited perch thrust held at +0.0 without ``np.maximum`` (and the command built
    without the frozen ``__init__``) against a pipeline that takes ``np.maximum`` every tick,
    through perching on/off, a NaN foot sample and NaN inputs."""
    from rdm.nodes.onboard_control import ControlCommand, ControlPipeline, Setpoint, State

    node = OnboardNode(FedByteLink())
    fast = ControlPipeline(node.robot, node.config)
    plain = ControlPipeline(node.robot, node.config)
    assert fast._delta_positive
    plain._delta_positive = False  # the plain path: np.maximum every tick
    q = node.present_q.copy()
    rng = np.random.default_rng(21)
    for pipe in (fast, plain):
        pipe.update_model(q)
        assert pipe.synthesize()
    for k in range(200):
        perch = 40 <= k < 90 or 150 <= k < 160
        pos = rng.normal(scale=0.1, size=3)
        if k == 120:
            pos[0] = np.nan
        foot = None if k % 7 == 0 else rng.normal(scale=2.0, size=6)
        out = []
        for pipe in (fast, plain):
            pipe.set_perching(perch)
            state = State(pos.copy(), np.zeros(3), 0.01)
            sp = Setpoint(np.array([0.0, 0.0, 0.1]), np.zeros(3), 0.0)
            try:
                out.append(pipe.step(state, sp, q, foot, 0.025))
            except ValueError as exc:
                out.append(str(exc))
        a, b = out
        assert type(a) is type(b)
        if isinstance(a, ControlCommand):
            assert repr(a) == repr(b) and a.base_thrust.tobytes() == b.base_thrust.tobytes()
            assert a.perch_thrust.tobytes() == b.perch_thrust.tobytes()
            built = ControlCommand(*(getattr(a, f) for f in a.__dataclass_fields__))
            assert repr(built) == repr(a) and a.__dict__.keys() == built.__dict__.keys()
        assert fast.perch_thrust.tobytes() == plain.perch_thrust.tobytes()
        assert list(fast.counts.items()) == list(plain.counts.items())
    assert fast._perch_zeros is not None


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
