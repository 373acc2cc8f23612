"""The onboard node's send side (``rdm.nodes.onboard_send``) against the rosserial codec and
the message definitions written out: the payloads the node packs itself (``rpy/gain``,
``four_axes/command``) are the codec's bytes and the definitions' layout; the messages kept
while unchanged (gains, pinv, desired coordinate) encode as messages built from scratch;
``ServerSession.publish_payload`` / ``try_publish_payload`` queue the frame ``publish`` queues
for the codec's bytes, with the same refusals and counters. The servo targets:
tests/test_servo_target_payload.py.
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np
import pytest
from fed_byte_link import FedByteLink
from onboard_rig import handshake

from rdm.model import Robot
from rdm.nodes.onboard import OnboardNode
from rdm.nodes.onboard_send import _floats, _four_axis_payload
from rdm.protocol.rosserial.codec import EncodeError
from rdm.protocol.rosserial.registry import spinal_registry
from rdm.protocol.rosserial.server import ServerSession

REG = spinal_registry()
ROBOT = Robot.default()


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


def test_desire_coordinate_message_rebuilt_with_the_model_terms():
    """The cached ``desire_coordinate`` message encodes as one built from scratch from the
    present terms, across q changes and returns to an earlier q (cached terms)."""

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


PINV_TOPIC = "p_matrix_pseudo_inverse_inertia"


def _pinv_message(n: int) -> Any:
    """A pinv + inertia message of ``n`` units (300: larger than the device buffer)."""
    pinv = REG.msg("spinal/PMatrixPseudoInverseWithInertia")
    unit = REG.msg("spinal/PMatrixPseudoInverseUnit")
    return pinv.new(pseudo_inverse=[unit.new(r=i, p=-i, y=3) for i in range(n)], inertia=[1] * 6)


def _two_sessions() -> tuple[ServerSession, ServerSession]:
    """Two server sessions after the same handshake, their output taken."""
    direct, via_codec = ServerSession(REG), ServerSession(REG)
    handshake([direct, via_codec])
    direct.take_output(), via_codec.take_output()
    return direct, via_codec


def _outcome(call: Any, *args: Any) -> Any:
    """What ``call(*args)`` returned, or the type and text of what it raised."""
    try:
        return call(*args)
    except Exception as exc:  # compared by the caller
        return (type(exc), str(exc))


def test_publish_payload_matches_publish():
    direct, via_codec = _two_sessions()
    for n in (4, 0, 300):
        msg = _pinv_message(n)
        payload = direct.outbound[PINV_TOPIC].codec.encode(msg)
        assert _outcome(direct.publish_payload, PINV_TOPIC, payload) == _outcome(
            via_codec.publish, PINV_TOPIC, msg
        )
        assert direct.take_output() == via_codec.take_output()
        assert list(direct.counts.items()) == list(via_codec.counts.items())
    with pytest.raises(KeyError):
        direct.publish_payload("no/such_topic", b"")


def test_try_publish_payload_queues_what_publish_payload_does():
    direct, via_codec = _two_sessions()
    taken = 0
    for n in (4, 0, 300, 7):
        payload = direct.outbound[PINV_TOPIC].codec.encode(_pinv_message(n))
        for form in (payload, bytearray(payload)):
            took = direct.try_publish_payload(PINV_TOPIC, form)
            if not took:  # nothing queued or counted: publish_payload decides
                assert direct.take_output() == b"" and direct.counts == via_codec.counts
                direct_result = _outcome(direct.publish_payload, PINV_TOPIC, form)
            codec_result = _outcome(via_codec.publish_payload, PINV_TOPIC, form)
            if took:
                taken += 1
                assert isinstance(codec_result, int)  # publish_payload queued a frame too
            else:
                assert direct_result == codec_result
            assert direct.take_output() == via_codec.take_output()
            assert list(direct.counts.items()) == list(via_codec.counts.items())
    assert taken == 6  # the payloads that fit, bytes or bytearray
    assert not direct.try_publish_payload("no/such_topic", b"")
    assert direct.take_output() == b""


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


def test_floats_is_float_of_each():

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
