"""The onboard node's servo goals in one call (``rdm._rdm.servo_target_payload``, used by
``OnboardNode._send_servo_targets``) against the Python form it replaces
(``_send_servo_targets_plain``).

On a node of a hover stack whose Spinal subscribes to ``servo/target_states``: random joint
targets (ties between two ticks, saturating values, NaN, inf, other lengths), vectoring
angles written over the joints or not (tuples, arrays, ints, too short), servo maps with
other signs, zero points, scales and indices (one past uint8): both forms give the same
frames on the wire, the same ``last_servo_goals`` (values and types), the same counters, or
the same exception. The call answers every case it can and declines the rest.
"""

from __future__ import annotations

import math
import random
import tempfile
from dataclasses import replace
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from rdm import _rdm
from rdm.nodes import onboard_send as onboard_module
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


def _outcome(node: Any, targets: Any) -> tuple:
    published, counts = dict(node.published), dict(node.counts)
    try:
        node._send_servo_targets(targets)
    except Exception as exc:  # the same exception is what is compared
        node.session.take_output()
        return ("raised", type(exc).__name__, str(exc))
    goals = node.last_servo_goals
    return (
        "sent",
        node.session.take_output(),
        repr(goals),
        [type(g).__name__ for g in goals],
        {k: v - published.get(k, 0) for k, v in node.published.items()},
        {k: v - counts.get(k, 0) for k, v in node.counts.items()},
    )


def test_one_call_equals_the_python_form(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = random.Random(4)
    calls = [0, 0]  # answered, declined
    inner = onboard_module._servo_target_payload
    assert inner is _rdm.servo_target_payload

    def counting(*args: Any) -> Any:
        got = inner(*args)
        calls[got is None] += 1
        return got

    monkeypatch.setattr(onboard_module, "_servo_target_payload", counting)
    with tempfile.TemporaryDirectory() as base:
        stack = _stack(base)
        try:
            stack.loop.run(3.0)  # negotiated and flying
            node = stack.onboard
            assert node._direct_remote("servo/target_states", "spinal/ServoControlCmd")
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
                outcomes = []
                for fast in (True, False):
                    node.fast_servo_targets = fast
                    outcomes.append(_outcome(node, targets))
                assert outcomes[0] == outcomes[1], (targets, smap, node.last_alpha_beta)
            node.config, node.arming = config, arming
        finally:
            stack.close()
    assert calls[0] > 600 and calls[1] > 300, calls


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
