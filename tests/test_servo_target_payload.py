"""The onboard node's ``servo/target_states`` (``OnboardNode._send_servo_targets``, its payload
in one Rust call ``rdm._rdm.servo_target_payload``) against the message definition written out:
``spinal/ServoControlCmd`` is ``uint8[] index, int16[] angles`` (uint32 count, then the values,
little-endian), each angle ``round(zero + sign * q / scale)`` saturated to int16, framed as
rosserial frames a message (sync 0xff 0xfe, length, its checksum, topic id, payload, checksum).

On a node of a hover stack whose Spinal subscribes to ``servo/target_states``: random joint
targets (ties between two ticks, saturating values, NaN, inf, other lengths), vectoring
angles written over the joints or not (tuples, arrays, ints, too short), servo maps with
other signs, zero points, scales and indices (one past uint8): the frame on the wire and
``last_servo_goals`` are the written-out ones, or the node raises where no frame can carry
the goals. The call answers every case it can and declines the rest.
"""

from __future__ import annotations

import math
import random
import struct
import tempfile
from dataclasses import replace
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from rdm import _rdm
from rdm.nodes import onboard_send
from rdm.nodes.onboard_config import DYNAMIXEL_RAD_PER_TICK, DYNAMIXEL_ZERO, ServoMap

N = 10


def _stack(base: str):
    from rdm.scenarios.common import sim_stack_options
    from rdm.scenarios.hover import HOVER_Z, make_script
    from rdm.scenarios.stack import build_stack

    opts = sim_stack_options(0, "inproc", speed=None)
    return build_stack("goals", base, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))


def _value(rng: random.Random, scale: float) -> float:
    kind = rng.random()
    if kind < 0.6:
        return rng.uniform(-2.0, 2.0)
    if kind < 0.8:  # exactly half way between two ticks of the default map
        return (rng.randint(-400, 400) + 0.5) * scale
    if kind < 0.9:
        return rng.choice([50.0, -50.0, 1e300])  # saturates at int16
    return rng.choice([math.nan, math.inf, -math.inf, 0.0, -0.0])


def _servo_map(rng: random.Random) -> ServoMap:
    kind = rng.random()
    if kind < 0.4:
        return ServoMap()
    index = list(range(N))
    rng.shuffle(index)
    if kind < 0.5:
        index[rng.randrange(N)] = 256  # not a uint8: the codec path
    return ServoMap(
        servo_index=tuple(index),
        zero_point=tuple(rng.choice([DYNAMIXEL_ZERO, 0, 1000, -3]) for _ in range(N)),
        angle_scale=tuple(rng.choice([DYNAMIXEL_RAD_PER_TICK, 0.001, 0.1]) for _ in range(N)),
        angle_sign=tuple(rng.choice([1, -1]) for _ in range(N)),
    )


def _vectoring(rng: random.Random) -> Any:
    kind = rng.random()
    if kind < 0.2:
        return None
    alpha = [rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)]
    beta = [rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)]
    if kind < 0.4:
        return np.array(alpha), np.array(beta)
    if kind < 0.45:
        return (alpha[:1], beta)  # too short: both forms raise
    if kind < 0.5:
        return ((1, 0), (True, -2))  # ints and a bool, as float() takes them
    return tuple(alpha), tuple(beta)


def _frame(topic_id: int, payload: bytes) -> bytes:
    """A rosserial (protocol 2) frame, from the protocol's description."""
    length = struct.pack("<H", len(payload))
    topic = struct.pack("<H", topic_id)
    return (
        b"\xff\xfe"
        + length
        + bytes([255 - sum(length) % 256])
        + topic
        + payload
        + bytes([255 - (sum(topic) + sum(payload)) % 256])
    )


def _expected(targets: Any, vectoring: Any, pairs: Any, smap: ServoMap) -> tuple | None:
    """``(goals, payload)`` as the message definition gives them; None: no frame carries
    them (an index past uint8, a tick of NaN or inf, fewer vectoring angles than units, a
    vectoring joint past the targets)."""
    q = [float(v) for v in targets]
    if vectoring is not None:
        alpha, beta = vectoring
        if len(alpha) < len(pairs) or len(beta) < len(pairs):
            return None
        if any(j >= len(q) for pair in pairs for j in pair):
            return None  # a vectoring joint past the targets
        for i, (ja, jb) in enumerate(pairs):
            q[ja], q[jb] = float(alpha[i]), float(beta[i])
    n = min(len(smap.servo_index), len(q))
    index = smap.servo_index[:n]
    ticks = []
    for j in range(n):
        x = smap.zero_point[j] + smap.angle_sign[j] * q[j] / smap.angle_scale[j]
        if not math.isfinite(x) or not all(0 <= i <= 255 for i in index):
            return None
        ticks.append(max(-32768, min(32767, round(x))))
    return q[:n], struct.pack(f"<I{n}BI{n}h", n, *index, n, *ticks)


def test_frames_are_the_message_definitions(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = random.Random(4)
    calls = [0, 0]  # answered, declined
    inner = onboard_send._servo_target_payload
    assert inner is _rdm.servo_target_payload

    def counting(*args: Any) -> Any:
        got = inner(*args)
        calls[got is None] += 1
        return got

    monkeypatch.setattr(onboard_send, "_servo_target_payload", counting)
    sent = raised = 0
    with tempfile.TemporaryDirectory() as base:
        stack = _stack(base)
        try:
            stack.loop.run(3.0)  # negotiated and flying
            node = stack.onboard
            topic_id = node.session.outbound["servo/target_states"].topic_id
            pairs = node.control.vectoring_joints
            node.session.take_output()
            config, arming = node.config, node.arming
            for _ in range(1500):
                smap = _servo_map(rng)
                node.config = replace(config, servo_map=smap)
                n = rng.choice([N, N, N, N - 2, N + 2])
                targets: Any = [_value(rng, DYNAMIXEL_RAD_PER_TICK) for _ in range(n)]
                if rng.random() < 0.5:
                    targets = np.array(targets)
                node.last_alpha_beta = _vectoring(rng)
                node.arming = SimpleNamespace(flying=rng.random() < 0.8)
                vectoring = node.last_alpha_beta if node.arming.flying else None
                want = _expected(targets, vectoring, pairs, smap)
                case = (list(targets), smap, vectoring)
                if want is None:
                    with pytest.raises((ValueError, OverflowError, IndexError, struct.error)):
                        node._send_servo_targets(targets)
                    node.session.take_output()
                    raised += 1
                    continue
                node._send_servo_targets(targets)
                goals, payload = want
                assert node.session.take_output() == _frame(topic_id, payload), case
                got = node.last_servo_goals
                assert [type(g) for g in got] == [float] * len(goals), case
                assert repr(got) == repr(goals), case
                sent += 1
            node.config, node.arming = config, arming
        finally:
            stack.close()
    assert calls[0] > 600 and calls[1] > 300, calls
    assert sent > 600 and raised > 300, (sent, raised)


def test_declines_what_it_does_not_take() -> None:
    arr = np.linspace(-1.0, 1.0, N)
    smap = ServoMap()
    args = (smap.zero_point, smap.angle_sign, smap.angle_scale, smap.servo_index)
    pairs = ((2, 3), (6, 7))
    vectoring = ((0.1, 0.2), (0.3, 0.4))
    goals, payload = _rdm.servo_target_payload(arr, vectoring, pairs, *args)
    assert goals[2:4] == [0.1, 0.3] and goals[6:8] == [0.2, 0.4]
    assert len(payload) == 4 + N + 4 + 2 * N
    for bad in (
        (arr.astype(np.float32), vectoring, pairs, *args),  # not float64
        (arr.reshape(2, 5), vectoring, pairs, *args),  # not 1-D
        (list(arr), vectoring, pairs, *args),  # not an array
        (arr, vectoring, ((2, 3), (6, N)), *args),  # a pair outside the goals
        (arr, vectoring, ((-1, 3),), *args),  # Python's negative index
        (arr, ((0.1,), (0.3, 0.4)), pairs, *args),  # fewer angles than units
        (arr, (("a", 0.2), (0.3, 0.4)), pairs, *args),  # not a number
        (arr, None, pairs, ("zero",) * N, *args[1:]),  # a map value that is no number
        (arr, None, pairs, *args[:3], (0,) * (N - 1) + (-1,)),  # an index below uint8
    ):
        assert _rdm.servo_target_payload(*bad) is None
