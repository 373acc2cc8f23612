"""The mocap and status nodes' fast paths against their plain forms, and a whole hover stack
with those fast paths and the native MCAP path on against the same stack with them off."""

from __future__ import annotations

import functools
import struct
from types import SimpleNamespace

import numpy as np
import pytest

import rdm.scenarios.stack as stack_module
from rdm.plant import Plant
from rdm.scenarios.common import sim_stack_options
from rdm.scenarios.hover import HOVER_Z, make_script
from rdm.scenarios.stack import MocapNode, StatusNode, build_stack
from rdm.sim import McapLogger


class _Recorder:
    def __init__(self) -> None:
        self.calls: list = []

    def set_mocap(self, position, velocity, yaw=None) -> bool:
        self.calls.append((position, velocity, yaw))
        return True


def _bits(values) -> list:
    return [(type(v), struct.pack("<d", v)) for v in values]


def _same_calls(a: list, b: list) -> None:
    assert len(a) == len(b)
    for (pa, va, ya), (pb, vb, yb) in zip(a, b, strict=True):
        assert type(pa) is type(pb) is list and type(va) is type(vb) is list
        assert _bits(pa) == _bits(pb) and _bits(va) == _bits(vb)
        assert _bits([ya]) == _bits([yb])


def test_mocap_fast_path_equals_the_plain_tick_in_flight():
    plant = Plant("rdm", seed=6, ceiling_height=1.6, floor_height=0.0)
    plant.reset(base_position=(0.0, 0.0, 0.05))
    fast_rec, plain_rec = _Recorder(), _Recorder()
    fast = MocapNode(plant, fast_rec, period=0.01)  # type: ignore[arg-type]
    plain = MocapNode(plant, plain_rec, period=0.01)  # type: ignore[arg-type]
    plain.fast_paths = False
    for k in range(120):
        if k == 10:
            plant.set_rotor_thrusts([9.8, 9.6, 9.8, 9.6])
        plant.step(10)
        if k == 60:
            fast.enabled = plain.enabled = False  # the state still advances
        if k == 70:
            fast.enabled = plain.enabled = True
        fast.tick(plant.time)
        plain.tick(plant.time)
        assert _bits(fast._last) == _bits(plain._last)
    _same_calls(fast_rec.calls, plain_rec.calls)
    assert len(fast_rec.calls) == 110


class _FakePlant:
    def __init__(self) -> None:
        self.truth = None

    def ground_truth(self):
        return self.truth


@pytest.mark.parametrize(
    "make",
    [
        lambda p, q: (list(p), list(q)),  # lists
        lambda p, q: (np.asarray(p, np.float32), np.asarray(q, np.float32)),
        lambda p, q: (np.asarray(p).reshape(3, 1), np.asarray(q).reshape(1, 4)),
        lambda p, q: (np.asarray(p).astype(">f8"), tuple(q)),
        lambda p, q: (np.append(p, 1.0), q),  # a 4-vector "position"
    ],
)
def test_mocap_fast_path_equals_the_plain_tick_on_other_array_likes(make):
    recs = []
    for fast_paths in (True, False):
        plant = _FakePlant()
        rec = _Recorder()
        node = MocapNode(plant, rec, period=0.01)  # type: ignore[arg-type]
        node.fast_paths = fast_paths
        r = np.random.default_rng(1)
        for _ in range(5):
            p, q = make(r.standard_normal(3), r.standard_normal(4))
            plant.truth = SimpleNamespace(cog_position=p, base_quaternion=q)
            node.tick(0.0)
        recs.append(rec.calls)
    _same_calls(*recs)


def _status_stack(state, command, duties, failsafes):
    onboard = SimpleNamespace(last_command=command, state=state)
    spinal = SimpleNamespace(duties=duties, counters=SimpleNamespace(failsafes=failsafes))
    return SimpleNamespace(onboard=onboard, spinal=spinal, status=[], logger=None)


def _same_record(a: dict, b: dict) -> None:
    assert list(a) == list(b)
    for k in a:
        x, y = a[k], b[k]
        assert type(x) is type(y), k
        if isinstance(x, list):
            assert [type(v) for v in x] == [type(v) for v in y], k
        assert x == y, k


def test_status_record_equals_the_plain_record_on_odd_inputs():
    from enum import Enum

    from rdm.nodes.onboard_arming import FlightState

    class Other(Enum):
        A = 3

    perch = SimpleNamespace(status=SimpleNamespace(name="OPTIMAL"))
    commands = [
        None,
        SimpleNamespace(base_thrust=np.arange(4.0), perch_thrust=np.ones(4), perch=perch),
        SimpleNamespace(base_thrust=[1.0, 2.0], perch_thrust=[1, 2], perch=None),
        SimpleNamespace(base_thrust=(1.0,), perch_thrust=np.ones((2, 2), np.float32)),
        SimpleNamespace(base_thrust=np.zeros(2), perch_thrust=None, perch="x"),
    ]
    states = [FlightState.ARMED, Other.A, "idle", 7]
    for c in commands:
        for st in states:
            for fs in ({"a": 2, "b": 3}, 0):
                stack = _status_stack(st, c, [0.5, 0.6], fs)
                node = StatusNode(stack)  # type: ignore[arg-type]
                _same_record(node.record(0.25), node.record_plain(0.25))


def _hover(base, fast: bool, monkeypatch, seconds: float):
    if not fast:
        monkeypatch.setattr(
            stack_module, "McapLogger", functools.partial(McapLogger, fast_messages=False)
        )
    else:
        monkeypatch.setattr(stack_module, "McapLogger", McapLogger)
    opts = sim_stack_options(0, "inproc", speed=None)
    stack = build_stack("hover", base, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))
    status = next(n for n in stack.loop.nodes if n.name == "status")
    if not fast:
        stack.plant.truth_free_record = False
        stack.mocap.fast_paths = False
        status.fast_paths = False
    else:
        assert stack.logger._batch is not None
        arrays = stack.plant._ground_truth_arrays

        def counted_arrays():
            stack.arrays_records += 1
            return arrays()

        stack.arrays_records = 0
        stack.plant._ground_truth_arrays = counted_arrays
        tracker = stack.plant._tracker
        plate_contact = tracker.plate_contact

        def counted_plate_contact(data):
            touching = plate_contact(data)
            stack.resting_records += not touching
            return touching

        stack.resting_records = 0
        tracker.plate_contact = counted_plate_contact
        checked = []
        record = status.record

        def checking_record(now: float) -> dict:
            rec = record(now)
            _same_record(rec, status.record_plain(now))
            checked.append(now)
            return rec

        status.record = checking_record  # type: ignore[method-assign]
    try:
        stack.loop.run(seconds)
    finally:
        stack.close()
    if fast:
        assert len(checked) == int(seconds / 0.025)
    return stack


def test_hover_stack_with_the_fast_paths_equals_the_plain_stack(tmp_path, monkeypatch):
    # 2.5 s from power-on: on the floor (contacts), take-off and flight (the one-call truth).
    seconds = 2.5
    fast = _hover(tmp_path / "fast", True, monkeypatch, seconds)
    plain = _hover(tmp_path / "plain", False, monkeypatch, seconds)
    # on the floor the robot rests on its root and middle links (contacts, the plate free):
    # those records are the one-call record too, as the flying robot's
    assert 20 < fast.resting_records < len(fast.truth) - 20
    assert fast.arrays_records == 0
    assert len(fast.truth) == len(plain.truth) == int(seconds / 0.01)
    for a, b in zip(fast.truth, plain.truth, strict=True):
        assert list(a.__dict__) == list(b.__dict__)
        for k, x in a.__dict__.items():
            y = b.__dict__[k]
            assert type(x) is type(y), k
            if isinstance(x, np.ndarray):
                assert x.tobytes() == y.tobytes(), k
            else:
                assert struct.pack("<d", x) == struct.pack("<d", y), k
    assert len(fast.status) == len(plain.status)
    for a, b in zip(fast.status, plain.status, strict=True):
        _same_record(a, b)
    for f in ("signals.mcap", "can.log"):
        assert (fast.folder.root / f).read_bytes() == (plain.folder.root / f).read_bytes(), f
