"""The LQI synthesizer answers a repeated problem with its kept solution.

A, Q and R are fixed per synthesizer, so B-bar (eq. 25) decides the problem: a call whose
B-bar is bitwise one of the last four solved returns that solution (``reused``), anything
else is solved. Oracle for the gains: scipy's CARE solution of the same problem.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_lqi import TABLE_V_Q, lqi_model, random_robot, rel, scipy_k

from rdm.control import lqi


def _scipy_gain(robot: tuple[float, np.ndarray, np.ndarray]) -> np.ndarray:
    a, b = lqi_model(*robot)
    return scipy_k(a, b, np.diag(TABLE_V_Q), np.eye(4))[1]


def test_same_problem_returns_the_last_solution() -> None:
    robot = random_robot(np.random.default_rng(11))
    synth = lqi.LqiSynthesizer()
    first = synth.synthesize(*robot)
    assert synth.reused == 0
    again = synth.synthesize(robot[0], robot[1].copy(), robot[2].copy())  # equal copies
    assert synth.reused == 1
    assert again.k.tobytes() == first.k.tobytes()
    assert again.gains.tobytes() == first.gains.tobytes()
    assert rel(again.k, _scipy_gain(robot)) < 1e-8


def test_any_other_problem_is_solved() -> None:
    rng = np.random.default_rng(12)
    m, inertia, alloc = random_robot(rng)
    synth = lqi.LqiSynthesizer()
    synth.synthesize(m, inertia, alloc)
    nudged = [
        (np.nextafter(m, 10.0), inertia, alloc),  # one ulp of mass
        (m, inertia, alloc * (1 + 1e-9)),
        (m, inertia * (1 - 1e-9), alloc),
    ]
    for robot in nudged:
        res = synth.synthesize(*robot)
        assert rel(res.k, _scipy_gain(robot)) < 1e-8
    assert synth.reused == 0
    synth.reset()  # a cold start solves even the same problem
    synth.synthesize(*nudged[-1])
    assert synth.reused == 0


def test_wire_form_hands_out_the_same_read_only_objects() -> None:
    robot = random_robot(np.random.default_rng(13))
    synth = lqi.LqiSynthesizer()
    first = synth.synthesize_wire(*robot)
    second = synth.synthesize_wire(*robot)
    assert synth.reused == 1
    for a, b in zip(first, second, strict=True):
        assert a is b
    gains, wire, payload = first[:3]
    assert wire is not None and payload is not None
    for array in (gains, wire):
        with pytest.raises(ValueError):
            array[0] = 0
    # the kept result is still the solved one, and equal to a fresh synthesizer's
    fresh = lqi.LqiSynthesizer().synthesize_wire(*robot)
    assert fresh[0].tobytes() == gains.tobytes() and fresh[2] == payload
    kept = synth.kept_result()
    assert kept is not None and kept.gains.tobytes() == gains.tobytes()


def test_a_failed_call_in_between_is_not_hidden() -> None:
    robot = random_robot(np.random.default_rng(14))
    synth = lqi.LqiSynthesizer()
    good = synth.synthesize_wire(*robot)
    bad = (robot[0], robot[1], np.full_like(robot[2], np.nan))
    with pytest.raises(ValueError):
        synth.synthesize_wire(*bad)
    assert synth.reused == 0  # NaN never matches
    again = synth.synthesize_wire(*robot)  # the last solved problem: its solution again
    assert synth.reused == 1
    assert again[0].tobytes() == good[0].tobytes() and again[2] == good[2]


def test_a_problem_returned_to_is_answered_with_its_kept_solution() -> None:
    rng = np.random.default_rng(16)
    robots = [random_robot(rng) for _ in range(6)]
    synth = lqi.LqiSynthesizer()
    first = synth.synthesize_wire(*robots[0])
    second = synth.synthesize_wire(*robots[1])
    back = synth.synthesize_wire(*robots[0])  # as a joint flickering between two counts
    assert synth.reused == 1
    assert back[0].tobytes() == first[0].tobytes() and back[2] == first[2]
    assert back[0] is not second[0]  # not the objects handed out for the other problem
    assert rel(synth.synthesize(*robots[0]).k, _scipy_gain(robots[0])) < 1e-8
    assert synth.reused == 2
    for robot in robots[2:]:  # four newer solves: the first problem is no longer kept
        synth.synthesize_wire(*robot)
    assert synth.reused == 2
    synth.synthesize_wire(*robots[0])
    assert synth.reused == 2


def _fifo_solves(keys: list, kept: int) -> int:
    """Solves of a synthesizer that keeps its last ``kept`` solved problems."""
    ring: list = []
    solves = 0
    for key in keys:
        if key in ring:
            continue
        solves += 1
        ring = [*ring, key][-kept:]
    return solves


def test_the_hover_stack_reuses_while_the_configuration_holds(tmp_path) -> None:
    from rdm.scenarios.common import sim_stack_options
    from rdm.scenarios.hover import HOVER_Z, make_script
    from rdm.scenarios.stack import build_stack

    opts = sim_stack_options(0, "inproc", speed=None, log=False)
    stack = build_stack("reuse", tmp_path, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))
    try:
        control = stack.onboard.control
        keys: list = []  # the B-bar of each call, from the model terms it is built from
        synthesize = control.synthesize

        def recording() -> bool:
            t = control.terms
            keys.append((t.mass, t.inertia.tobytes(), t.allocation_bar.tobytes()))
            return synthesize()

        control.synthesize = recording
        stack.loop.run(4.0)
        reused, ok = control.lqi.reused, control.counts["lqi_ok"]
    finally:
        stack.close()
    # 40 Hz from the handshake on: most ticks hold q (joints and vectoring still)
    assert ok == len(keys) > 100 and reused > ok // 2
    # the solves are the problems not among the last four solved, fewer than with the last
    # one only (the held arm's reading flickers between encoder counts)
    assert ok - reused == _fifo_solves(keys, 4) < _fifo_solves(keys, 1)


def test_a_solve_through_the_dict_form_is_not_answered_with_older_wire_objects() -> None:
    """``synthesize`` and ``synthesize_wire`` share the core: a problem solved through the
    dict form and then asked again through the wire form is that problem's answer, not the
    objects the wire form kept for an earlier one."""
    rng = np.random.default_rng(15)
    first, second = random_robot(rng), random_robot(rng)
    synth = lqi.LqiSynthesizer()
    old = synth.synthesize_wire(*first)
    synth.synthesize(*second)
    again = synth.synthesize_wire(*second)
    assert synth.reused == 1
    fresh = lqi.LqiSynthesizer().synthesize_wire(*second)
    assert again[0].tobytes() == fresh[0].tobytes() and again[2] == fresh[2]
    assert again[0] is not old[0] and again[2] != old[2]
