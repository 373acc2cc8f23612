"""The CAN master's rules as the Spinal mirror uses them on a running stack (docs/spinal.md),
each against the rule written out here.

* The duty hand-over (``CanMaster.set_motor_duties``) on random and bad input (NaN, inf, out
  of range, ints, numpy floats, wrong lengths): the documented error text or acceptance, and
  the one-call ``try_set_motor_duties`` accepting exactly the lists of plain floats in range.
* Servo goals (``CanMaster.set_servo_targets``): 15-bit ints of known servos, the documented
  errors otherwise.
* ``CanMaster.tick_wire_steady``: the steady ms's frame count, -1 whenever the ms was not
  steady (not running, events, a log to drain), with ``last_wire_tick`` as ``tick_wire``'s
  result.
"""

from __future__ import annotations

import math
import random
import tempfile

import numpy as np
import pytest

from rdm import _rdm

TICKS = 2600  # past the 2 s CAN boot: the master runs, servos report, duties flow


def _stack(base: str):
    from rdm.scenarios.common import sim_stack_options
    from rdm.scenarios.hover import HOVER_Z, make_script
    from rdm.scenarios.stack import build_stack

    opts = sim_stack_options(0, "inproc", speed=None)
    return build_stack("master_rules", base, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))


@pytest.fixture(scope="module")
def running_stack():
    with tempfile.TemporaryDirectory() as base:
        stack = _stack(base)
        stack.loop.run_ticks(TICKS)
        yield stack
        stack.close()


def _reference_check(duties, n: int) -> str | None:
    """The Python master's rule, re-stated: the error text, or None when accepted."""
    if len(duties) != n:
        return f"set_motor_duties: {len(duties)} duties for {n}"
    for i, d in enumerate(duties):
        if not isinstance(d, (int, float)) or not math.isfinite(d) or not 0.5 <= d <= 1.0:
            return f"set_motor_duties: duties[{i}]={d!r} not in 0.5..1.0"
    return None


def test_duty_hand_over_follows_the_rule(running_stack) -> None:
    master = running_stack.spinal.master
    n = master.motor_number
    assert n > 0
    rng = np.random.default_rng(7)
    cases: list = [[0.5] * n, [1.0] * n, [0.75] * (n + 1), [0.75] * (n - 1), []]
    for _ in range(300):
        d = rng.uniform(0.3, 1.2, n).tolist()
        k = int(rng.integers(n))
        kind = int(rng.integers(6))
        if kind == 1:
            d[k] = math.nan
        elif kind == 2:
            d[k] = math.inf
        elif kind == 3:
            d[k] = 1  # an int: accepted by the checks, not by the one-call path
        elif kind == 4:
            d[k] = np.float64(0.8)  # a float subclass
        cases.append(d)
    for duties in cases:
        expected = _reference_check(duties, n)
        try:
            master.set_motor_duties(list(duties))
            outcome = None
        except ValueError as exc:
            outcome = str(exc)
        assert outcome == expected, duties
        exact = len(duties) == n and all(type(d) is float for d in duties) and expected is None
        assert master._core.try_set_motor_duties(list(duties)) is exact


def _outcome(call, *args):
    """None, or the type name and text of what ``call(*args)`` raised."""
    try:
        call(*args)
    except Exception as exc:  # the type and text are what is compared
        return type(exc).__name__, str(exc)
    return None


def test_servo_targets_follow_the_rule(running_stack) -> None:
    master = running_stack.spinal.master
    keys = master.servo_keys()
    assert keys == list(master.servo_states)
    for targets in (
        {keys[0]: 2048, keys[-1]: 100},
        {(keys[0][0], 99): 1},
        {(200, 0): 1},
        {keys[0]: 1 << 20},
        {keys[0]: 1.5},
    ):
        expected = None
        for (slave, index), value in targets.items():  # the documented rule, re-stated
            if not isinstance(value, int) or not -(2**14) <= value < 2**14:
                expected = (
                    "ValueError",
                    f"servo ({slave}, {index}) target {value!r} not a 15-bit int",
                )
                break
            try:
                master._position(slave, index)
            except KeyError as exc:
                expected = ("KeyError", str(exc))
                break
        assert _outcome(master.set_servo_targets, targets) == expected
        if expected is None:
            for (slave, index), value in targets.items():
                assert master.servo(slave, index).goal_position == value


def test_tick_wire_steady_gives_the_frames_of_a_steady_ms_else_minus_one() -> None:
    master, wire = _rdm.CanMaster(50, 0), _rdm.CanWire()
    rng = random.Random(3)
    drain_at = 7
    minus_seen = 0
    t = 0
    for _ in range(3000):
        stamp = t / 1000.0 + rng.random() * 1e-4
        before = wire.frames
        got = master.tick_wire_steady(t, stamp, wire, drain_at)
        state, events, sent, logged = master.last_wire_tick
        assert wire.frames - before == sent  # the frames the ms put on the wire
        if state == 3 and events == 0 and logged < drain_at:  # RUNNING, nothing pending
            assert got == sent
        else:
            assert got == -1
            minus_seen += 1
        if events:
            assert len(master.pop_events()) > 0
        if logged >= drain_at or rng.random() < 0.01:
            wire.drain_log("can0")
        if rng.random() < 0.05:
            master.set_motor_duties([])
        t += rng.choice((1, 1, 1, 2, 7, 40, 0))
    assert minus_seen > 0 and wire.frames > 0
