"""The onboard node's receive side (``rdm.nodes.onboard_receive``) against the rosserial codec
and the servo map's rule, on real, random and corrupt input:

* ``servo_states_decodes`` and the Imu length rule are exactly the codec's accept set;
* ``ServerSession.deferred``: ``imu`` / ``servo/states`` frames returned as ``(handler,
  payload)``: once decoded, the events of a session that decodes them, counters in order;
* the node's payload handlers (one ``struct`` each) against the node fed the codec's decoded
  message; the IMU read lazily against ``quaternion_to_euler`` of the last valid message;
* the joint state after every ``servo/states`` against the servo map's rule written out.
"""

from __future__ import annotations

import random
import struct

import numpy as np
import pytest
from fed_byte_link import FedByteLink
from onboard_rig import REG, assert_same_servo_state, handshake, servo_readings

from rdm.nodes.onboard import OnboardNode
from rdm.nodes.onboard_receive import quaternion_to_euler, servo_states_decodes
from rdm.protocol.rosserial.codec import DecodeError
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
    by_payload, by_codec = OnboardNode(FedByteLink()), OnboardNode(FedByteLink())
    rng = random.Random(7)
    for k in range(1500):
        p = _imu_payload(rng)
        by_payload._on_imu_payload(p)
        by_codec._on_event(MessageReceived("imu", "spinal/Imu", 101, IMU.decode(p)))
        assert list(by_payload.counts.items()) == list(by_codec.counts.items())
        if rng.random() < 0.3 or k == 1499:
            assert by_payload.imu_euler == by_codec.imu_euler
            a, b = by_payload.imu_gyro, by_codec.imu_gyro
            assert (a is None) == (b is None)
            if a is not None:
                assert a.tobytes() == b.tobytes()
    assert by_payload.counts["imu_invalid"] > 0 and by_payload.imu_euler is not None


def test_servo_payload_handler_matches_the_decoded_message():
    by_payload, by_codec = OnboardNode(FedByteLink()), OnboardNode(FedByteLink())
    n = len(by_payload.config.servo_map.servo_index)
    rng = random.Random(11)
    readings = servo_readings(rng, n, 14)
    for k in range(800):
        reading = readings[rng.randrange(len(readings))] if k else readings[0][:3]
        temp = rng.choice([0, 0, 0, 41])  # same (index, angle), other bytes now and then
        msg = SERVOS.new(
            stamp=(k, 0), servos=[UNIT.new(index=i, angle=a, temp=temp) for i, a in reading]
        )
        p = SERVOS.encode(msg)
        by_payload._on_servo_payload(p)
        by_codec._on_event(MessageReceived("servo/states", "spinal/ServoStates", 102, msg))
        assert_same_servo_state(by_payload, by_codec)
        if k % 60 == 0:  # someone else moves present_q: the cached writes still apply
            by_payload.present_q[:] = by_codec.present_q[:] = rng.random()
    assert 0 < len(by_payload._servo_raw) <= 8
    assert by_payload.counts["servo_unknown_index"] > 0


def test_session_deferred_topics_match_decoding():
    """A deferred session and one that decodes fed the same stream (handshake, then imu and
    servo/states frames with good, short, long and random payloads, corrupt frames, noise):
    the deferred events resolve to the decoding session's events; counters equal, same order."""
    by_payload, by_codec = ServerSession(REG), ServerSession(REG)
    seen: list[tuple[str, bytes]] = []
    by_payload.deferred.update(
        {
            "imu": ("spinal/Imu", lambda p: len(p) == 60, lambda p: seen.append(("imu", p))),
            "servo/states": (
                "spinal/ServoStates",
                servo_states_decodes,
                lambda p: seen.append(("servo/states", p)),
            ),
        }
    )
    handshake([by_payload, by_codec])
    ids = {r.name: tid for tid, r in by_codec.inbound.items()}
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
        got, want = by_payload.feed(chunk, t), by_codec.feed(chunk, t)
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
        decoded = [
            ("rx", e.topic, repr(e.message))
            if isinstance(e, MessageReceived) and e.topic in ("imu", "servo/states")
            else e
            for e in want
        ]
        assert resolved == decoded
        assert list(by_payload.counts.items()) == list(by_codec.counts.items())
        assert by_payload.parser.counts == by_codec.parser.counts
    assert by_payload.counts["rx_dropped"] > 0 and by_payload.counts["rx_messages"] > 100


def test_servo_payload_struct_decode_matches_the_codec():
    """New ``servo/states`` payloads unpacked with one struct (index, angle) against the
    codec's decode, both through ``_on_servo_states``: counters, joint state, caches."""
    import random

    from onboard_rig import REG, assert_same_servo_state, servo_readings

    servos, unit = REG.msg("spinal/ServoStates"), REG.msg("spinal/ServoState")
    by_payload, by_codec = OnboardNode(FedByteLink()), OnboardNode(FedByteLink())
    assert by_payload._servo_struct
    by_codec._servo_struct = False  # what a message tree of another layout takes: the codec
    n = len(by_payload.config.servo_map.servo_index)
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
        by_payload._on_servo_payload(payload)
        by_codec._on_servo_payload(payload)
        assert_same_servo_state(by_payload, by_codec)
        assert list(by_payload._servo_cache) == list(by_codec._servo_cache)
        assert list(by_payload._servo_raw) == list(by_codec._servo_raw)
    assert (
        by_payload.counts["servo_unknown_index"] > 0
        and by_payload.counts["servo_states_partial"] > 0
    )
    # a payload whose count does not match its length: the codec's error on both
    bad = servos.encode(servos.new(stamp=(0, 0), servos=[unit.new(index=1, angle=5)]))[:-1]
    for node in (by_payload, by_codec):
        with pytest.raises(Exception) as e:
            node._on_servo_payload(bad)
        assert type(e.value).__name__ == "DecodeError"


def test_imu_converted_when_read_matches_every_message():
    """The node keeps the newest valid quaternion/gyro and converts on read: the same values
    as converting every message (independent: quaternion_to_euler / np.array of the last
    valid one), invalid ones counted and skipped, non-tuple gyro through ``_vector``."""

    from rdm.nodes.onboard_config import OnboardConfig
    from rdm.nodes.onboard_monitors import MonitorLimits
    from rdm.protocol.rosserial.events import MessageReceived
    from rdm.protocol.rosserial.registry import spinal_registry

    imu = spinal_registry().msg("spinal/Imu")
    # every random reading a jump: the plausibility limits on jumps out of the way here
    # (tests/test_onboard_imu_plausibility.py checks them)
    loose = MonitorLimits(imu_gyro_rate_max=1e9, imu_attitude_rate_max=1e9)
    node = OnboardNode(FedByteLink(), config=OnboardConfig(monitors=loose))
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


def test_servo_states_follow_the_servo_map():
    """Repeated, partial, unknown-index and duplicate-index ``servo/states`` readings (the
    repeated ones applied from the node's reading cache): after every message the node holds
    the present q, seen flags, joint targets and counters the servo map's rule gives, written
    out here: joint j of servo index i is i's position in ``servo_index`` (none, or j past
    the model's joints: counted unknown), q_j = sign * (raw - zero) * scale, a reading that
    does not cover every joint counts partial, a reading that moves a seen joint by more than
    SERVO_JUMP_MAX_RAD is not taken (counted implausible) unless it is the fourth such in a
    row (counted resync), and the joint targets hold the present q once every joint was
    seen."""
    from collections import Counter

    from rdm.nodes.onboard import OnboardNode
    from rdm.nodes.onboard_receive import SERVO_JUMP_MAX_RAD
    from rdm.protocol.rosserial.registry import spinal_registry

    reg = spinal_registry()
    states, unit = reg.msg("spinal/ServoStates"), reg.msg("spinal/ServoState")
    node = OnboardNode(FedByteLink())
    smap, n_q = node.config.servo_map, node.robot.n_q
    q, seen, counts, targets = node.present_q.copy(), np.zeros(n_q, bool), Counter(), None
    in_a_row = 0
    n = len(smap.servo_index)
    rng = random.Random(31)
    readings = servo_readings(rng, n, 12)
    for k in range(600):
        reading = readings[rng.randrange(len(readings))]
        if k == 0:
            reading = readings[0][:3]  # partial first: the hold waits for every joint
        node._on_servo_states(states.new(servos=[unit.new(index=i, angle=a) for i, a in reading]))
        covered, pairs = set(), []
        for i, a in reading:
            j = smap.servo_index.index(i) if i in smap.servo_index else None
            if j is None or j >= n_q:
                counts["servo_unknown_index"] += 1
                continue
            pairs.append((j, smap.angle_sign[j] * (a - smap.zero_point[j]) * smap.angle_scale[j]))
            covered.add(j)
        if len(covered) != n_q:
            counts["servo_states_partial"] += 1
        if any(seen[j] and abs(v - q[j]) > SERVO_JUMP_MAX_RAD for j, v in pairs):
            in_a_row += 1
            take = in_a_row > 3
            counts["servo_states_resync" if take else "servo_states_implausible"] += 1
            in_a_row = 0 if take else in_a_row
        else:
            take, in_a_row = True, 0
        if take:
            for j, v in pairs:  # a joint given twice: the last value
                q[j] = v
                seen[j] = True
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
    assert counts["servo_states_implausible"] > 0 and counts["servo_states_resync"] > 0
    assert 0 < len(node._servo_cache) <= 8
