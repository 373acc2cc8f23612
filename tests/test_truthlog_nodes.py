"""The mocap and status nodes' outputs, and what a hover stack's MCAP holds of them.

Oracles: numpy's array arithmetic and scipy's rotation for the mocap sample, status records
written out by hand, and the ``mcap`` package's reader with ``json.loads`` for the log."""

from __future__ import annotations

import json
import math
import struct
from enum import Enum
from types import SimpleNamespace

import numpy as np
import pytest
from mcap.reader import make_reader
from scipy.spatial.transform import Rotation

from rdm.nodes.onboard_arming import FlightState
from rdm.plant import Plant
from rdm.scenarios.common import sim_stack_options
from rdm.scenarios.hover import HOVER_Z, make_script
from rdm.scenarios.stack import MocapNode, StatusNode, build_stack


class _Recorder:
    def __init__(self) -> None:
        self.calls: list = []

    def set_mocap(self, position, velocity, yaw=None) -> bool:
        self.calls.append((position, velocity, yaw))
        return True


def _bits(values) -> list:
    return [(type(v), struct.pack("<d", v)) for v in values]


def _yaw(q) -> float:
    w, x, y, z = np.asarray(q, dtype=float).reshape(-1)
    return float(Rotation.from_quat([x, y, z, w]).as_euler("ZYX")[0])


def _check_calls(calls: list, ticks: list, period: float, yaw_tol: float = 1e-12) -> None:
    """Each call against numpy: ``ticks`` is every tick's (position, quaternion, enabled);
    an enabled tick sends the position's floats, ``(p - last) / period`` on float64 arrays
    against the tick before (0 at the first), the quaternion's yaw (scipy)."""
    want = []
    last = None
    for p, q, enabled in ticks:
        p = np.asarray(p, dtype=float).reshape(-1)
        v = np.zeros(p.size) if last is None else (p - last) / period
        if enabled:
            want.append((p, v, q))
        last = p
    assert len(calls) == len(want)
    for (position, velocity, yaw), (p, v, q) in zip(calls, want, strict=True):
        assert type(position) is list and type(velocity) is list
        assert _bits(position) == _bits(p.tolist())
        assert _bits(velocity) == _bits(v.tolist())
        assert type(yaw) is float and math.isclose(yaw, _yaw(q), abs_tol=yaw_tol)


def test_mocap_samples_in_flight_are_numpys():
    plant = Plant("rdm", seed=6, ceiling_height=1.6, floor_height=0.0)
    plant.reset(base_position=(0.0, 0.0, 0.05))
    rec = _Recorder()
    node = MocapNode(plant, rec, period=0.01)  # type: ignore[arg-type]
    ticks = []
    for k in range(120):
        if k == 10:
            plant.set_rotor_thrusts([9.8, 9.6, 9.8, 9.6])
        plant.step(10)
        if k == 60:
            node.enabled = False  # the state still advances
        if k == 70:
            node.enabled = True
        gt = plant.ground_truth()
        ticks.append((np.array(gt.cog_position), np.array(gt.base_quaternion), node.enabled))
        node.tick(plant.time)
    assert len(rec.calls) == 110
    assert np.linalg.norm(ticks[-1][0] - ticks[0][0]) > 0.01  # it flew: velocities not 0
    _check_calls(rec.calls, ticks, 0.01)


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
def test_mocap_samples_of_other_array_likes_are_numpys(make):
    plant = _FakePlant()
    rec = _Recorder()
    node = MocapNode(plant, rec, period=0.01)  # type: ignore[arg-type]
    r = np.random.default_rng(1)
    ticks = []
    for _ in range(5):
        q0 = r.standard_normal(4)
        p, q = make(r.standard_normal(3), q0 / np.linalg.norm(q0))
        plant.truth = SimpleNamespace(cog_position=p, base_quaternion=q)
        ticks.append((p, q, True))
        node.tick(0.0)
    _check_calls(rec.calls, ticks, 0.01, yaw_tol=1e-6)  # float32 quaternions: 1e-7 off unit


def _status_stack(state, command, duties, failsafes):
    onboard = SimpleNamespace(last_command=command, state=state)
    spinal = SimpleNamespace(duties=duties, counters=SimpleNamespace(failsafes=failsafes))
    return SimpleNamespace(onboard=onboard, spinal=spinal, status=[], logger=None)


class _Other(Enum):
    A = 3


_PERCH = SimpleNamespace(status=SimpleNamespace(name="OPTIMAL"))

#: (state, last command, failsafes, the record's state / base_thrust / perch_status /
#: perch_thrust / failsafes written out)
STATUS_CASES = [
    (FlightState.ARMED, None, {"a": 2, "b": 3}, (FlightState.ARMED.value, None, None, None, 5)),
    (
        _Other.A,
        SimpleNamespace(base_thrust=np.arange(4.0), perch_thrust=np.ones(4), perch=_PERCH),
        0,
        (3, [0.0, 1.0, 2.0, 3.0], "OPTIMAL", [1.0, 1.0, 1.0, 1.0], 0),
    ),
    (
        "idle",
        SimpleNamespace(base_thrust=[1.0, 2.0], perch_thrust=[1, 2], perch=None),
        {},
        ("idle", [1.0, 2.0], None, [1.0, 2.0], 0),
    ),
    (
        7,
        SimpleNamespace(base_thrust=(1.0,), perch_thrust=np.full((2, 2), 0.5, np.float32)),
        {"x": 1},
        ("7", [1.0], None, [0.5, 0.5, 0.5, 0.5], 1),
    ),
    (
        FlightState.ARMED,
        SimpleNamespace(base_thrust=np.zeros(2), perch_thrust=None, perch="x"),
        0,
        (FlightState.ARMED.value, [0.0, 0.0], None, None, 0),
    ),
]


@pytest.mark.parametrize(("state", "command", "failsafes", "want"), STATUS_CASES)
def test_status_record_written_out(state, command, failsafes, want):
    node = StatusNode(_status_stack(state, command, [0.5, 0.6], failsafes))  # type: ignore[arg-type]
    rec = node.record(0.25)
    keys = ("state", "base_thrust", "perch_status", "perch_thrust", "failsafes")
    assert list(rec) == [
        "t",
        "state",
        "base_thrust",
        "perch_status",
        "perch_thrust",
        "duties",
        "failsafes",
    ]
    assert rec["t"] == 0.25 and rec["duties"] == [0.5, 0.6]
    for k, w in zip(keys, want, strict=True):
        assert rec[k] == w and type(rec[k]) is type(w), k
        if isinstance(w, list):
            assert all(isinstance(v, float) for v in rec[k]), k


def _json_value(v):
    """A record value as the log's JSON holds it (NaN and infinities as null)."""
    if isinstance(v, np.ndarray):
        return [_json_value(x) for x in v.tolist()]
    if isinstance(v, list):
        return [_json_value(x) for x in v]
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def test_hover_stack_mcap_holds_the_truth_and_status_records(tmp_path):
    # 2.5 s from power-on: on the floor (contacts), take-off and flight.
    seconds = 2.5
    opts = sim_stack_options(0, "inproc", speed=None)
    stack = build_stack("hover", tmp_path, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))
    try:
        stack.loop.run(seconds)
    finally:
        stack.close()
    assert len(stack.truth) == int(seconds / 0.01)
    assert len(stack.status) == int(seconds / 0.025)
    topics: dict[str, list] = {}
    with open(stack.folder.mcap, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            assert schema is not None
            topics.setdefault(channel.topic, []).append(message)
    truth = topics["/plant/ground_truth"]
    assert len(truth) == len(stack.truth)
    for m, gt in zip(truth, stack.truth, strict=True):
        doc = json.loads(m.data)
        assert m.log_time == m.publish_time == round(float(gt.time) * 1e9)
        assert list(doc) == list(gt.__dataclass_fields__)
        for k, v in doc.items():
            assert v == _json_value(getattr(gt, k)), k
    status = topics["/onboard/status"]
    assert len(status) == len(stack.status)
    for k, (m, rec) in enumerate(zip(status, stack.status, strict=True)):
        assert m.sequence == k
        assert json.loads(m.data) == {key: _json_value(v) for key, v in rec.items()}
