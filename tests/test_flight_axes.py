"""``ControlPipeline.step``'s flight part in one Rust call (``_rdm.flight_axes``) against the
composition of the controllers' own entry points, written out here: the position loop
(``PositionController.step_outputs``, held at zero error while perched), the choice per
vectoring unit between its angles and the joint targets, the PC-side axes
(``PcAxisController.step``, the yaw error wrapped by atan2(sin, cos), the z loop held while
perched). Two pipelines, one stepping each way, fed the same random sequence of states,
setpoints, joint targets and mode switches, give the same commands bit for bit, the same
controller integrals and the same counters; integer and list inputs are read as floats;
inputs the call cannot take raise a ValueError with nothing stepped.
"""

from __future__ import annotations

import dataclasses
import math
import types

import numpy as np
import pytest

from rdm import _rdm
from rdm.model import Robot
from rdm.nodes.onboard_config import OnboardConfig
from rdm.nodes.onboard_control import ControlPipeline, Setpoint, State


@pytest.fixture
def rust_results(monkeypatch) -> list:
    """What every ``_rdm.flight_axes`` call of the test returns, in call order."""
    results: list = []
    real = _rdm.flight_axes

    def recorded(*args):
        results.append(real(*args))
        return results[-1]

    monkeypatch.setattr(_rdm, "flight_axes", recorded)
    return results


def _composed_axes(
    ctl: ControlPipeline,
    state: State,
    setpoint: Setpoint,
    joint_targets: np.ndarray,
    feed_forward: np.ndarray,
    dt: float,
) -> tuple:
    """The flight axes from the controllers' entry points (the tuple ``_rdm.flight_axes``
    returns)."""
    t, gains = ctl.terms, ctl.gains
    held = ctl.perching
    position = np.asarray(state.position, dtype=float)[:2]
    velocity = np.zeros(2) if held else np.asarray(state.velocity, dtype=float)[:2]
    pos = ctl.position.step_outputs(
        position,
        velocity,
        position if held else np.asarray(setpoint.position, dtype=float)[:2],
        velocity if held else np.asarray(setpoint.velocity, dtype=float)[:2],
        setpoint.yaw,
        t.link_rotations,
        dt,
    )
    alpha, beta, applied = [], [], []
    singular = 0
    vectoring, min_nz = ctl.config.vectoring, ctl.config.vectoring_min_nz
    for i, (ja, jb) in enumerate(ctl.vectoring_joints):
        ok = vectoring and abs(float(pos["direction"][i][2])) >= min_nz
        singular += bool(not ok and vectoring)
        alpha.append(float(pos["alpha"][i]) if ok else float(joint_targets[ja]))
        beta.append(float(pos["beta"][i]) if ok else float(joint_targets[jb]))
        applied.append(ok)
    z_err = 0.0 if held else float(setpoint.position[2] - state.position[2])
    vz_err = 0.0 if held else float(setpoint.velocity[2] - state.velocity[2])
    yaw_err = setpoint.yaw - state.yaw
    base, yaw_term, yaw_rotor = ctl.pc_axes.step(
        gains,
        z_err,
        vz_err,
        math.atan2(math.sin(yaw_err), math.cos(yaw_err)),
        np.ascontiguousarray(feed_forward, dtype=float),
        dt,
    )
    return (
        float(pos["roll"]),
        float(pos["pitch"]),
        float(yaw_term),
        tuple(alpha),
        tuple(beta),
        tuple(applied),
        singular,
        np.asarray(base, dtype=float),
        yaw_rotor,
    )


def _pipeline(rust: bool, **config: object) -> ControlPipeline:
    ctl = ControlPipeline(Robot.default(), OnboardConfig(**config))
    if not rust:  # every step through the controllers' entry points
        ctl._flight_axes = types.MethodType(_composed_axes, ctl)
    return ctl


def _ready(ctl: ControlPipeline, q: np.ndarray) -> None:
    assert ctl.update_model(q)
    assert ctl.synthesize()


def _bits(value: object) -> object:
    """Every float of a command field as its bit pattern (so -0.0 != 0.0 and NaN == NaN)."""
    if isinstance(value, np.ndarray):
        return (value.dtype.str, value.shape, value.tobytes())
    if isinstance(value, float):
        return ("f", _float_bits(value))
    if isinstance(value, tuple | list):
        return (type(value).__name__, [_bits(v) for v in value])
    return value


def _float_bits(x: float) -> int:
    return int(np.float64(x).view(np.int64))


def _command_bits(c: object) -> object:
    if c is None:
        return None
    return {
        k: _bits(getattr(c, k))
        for k in (
            "angles",
            "base_thrust",
            "flight_thrust",
            "perch_thrust",
            "alpha",
            "beta",
            "vectoring_applied",
            "yaw_rotor",
        )
    }


def _state_bits(ctl: ControlPipeline) -> object:
    return (
        ctl.position.integral.tobytes(),
        tuple(_float_bits(v) for v in ctl.pc_axes.integrals),
        dict(ctl.counts),
        ctl.perch_thrust.tobytes(),
    )


def _random_inputs(rng: np.random.Generator, n_q: int) -> tuple:
    scale = rng.choice([1e-3, 0.1, 1.0, 5.0])
    state = State(
        rng.normal(0.0, scale, 3), rng.normal(0.0, scale, 3), float(rng.uniform(-4.0, 4.0))
    )
    setpoint = Setpoint(
        rng.normal(0.0, scale, 3), rng.normal(0.0, scale, 3), float(rng.uniform(-4.0, 4.0))
    )
    targets = rng.uniform(-1.5, 1.5, n_q)
    return state, setpoint, targets


@pytest.mark.parametrize(
    "config",
    [
        {},
        {"vectoring_min_nz": 0.9999},  # some units fall back to the joint targets
        {"vectoring": False},
        {"feed_forward": "none"},
    ],
)
def test_flight_axes_equal_the_composed_controllers_over_a_random_sequence(config, rust_results):
    rng = np.random.default_rng(16)
    rust, composed = _pipeline(True, **config), _pipeline(False, **config)
    n_q = rust.robot.n_q
    qs = [rng.uniform(-0.8, 0.8, n_q) for _ in range(4)]
    for k in range(400):
        if k % 50 == 0:
            q = qs[(k // 50) % len(qs)]
            _ready(rust, q)
            _ready(composed, q)
        if k % 70 == 35:  # perched stretches: the xy and z loops held
            on = not rust.perching
            rust.set_perching(on)
            composed.set_perching(on)
        state, setpoint, targets = _random_inputs(rng, n_q)
        dt = float(rng.choice([0.025, 0.02, 0.031]))
        foot = rng.normal(0.0, 5.0, 6) if rng.random() < 0.8 else None
        a = rust.step(state, setpoint, targets, foot, dt)
        b = composed.step(state, setpoint, targets, foot, dt)
        assert _command_bits(a) == _command_bits(b), k
        assert _state_bits(rust) == _state_bits(composed), k
    # every tick through the Rust call: every input of this sequence is one it reads
    assert len(rust_results) == 400
    assert all(r is not None for r in rust_results)
    if config.get("vectoring_min_nz"):
        assert rust.counts["vectoring_singular"] > 0
    assert rust.counts["perch_entered"] > 0


def test_wrap_of_the_yaw_error_is_atan2_of_sin_and_cos():
    """Yaw errors across many turns: the Rust sin/cos/atan2 wrap gives Python's floats."""
    rust, composed = _pipeline(True), _pipeline(False)
    q = np.zeros(rust.robot.n_q)
    _ready(rust, q)
    _ready(composed, q)
    for yaw in [*np.linspace(-40.0, 40.0, 801).tolist(), math.pi, -math.pi, 1e-300, 3e8]:
        state = State(np.zeros(3), np.zeros(3), 0.0)
        setpoint = Setpoint(np.zeros(3), np.zeros(3), yaw)
        a = rust.step(state, setpoint, q, None, 0.025)
        b = composed.step(state, setpoint, q, None, 0.025)
        assert _command_bits(a) == _command_bits(b), yaw
    assert rust.pc_axes.integrals == composed.pc_axes.integrals


@pytest.mark.parametrize("odd", ["int_position", "list_velocity"])
def test_integer_and_list_inputs_are_read_as_floats(odd, rust_results):
    rust, composed = _pipeline(True), _pipeline(False)
    q = np.full(rust.robot.n_q, 0.1)
    _ready(rust, q)
    _ready(composed, q)
    state = State(np.array([0.1, -0.2, 1.0]), np.array([0.01, 0.0, -0.1]), 0.2)
    setpoint = Setpoint(np.array([0.0, 0.0, 1.2]), np.zeros(3), 0.0)
    if odd == "int_position":
        state = State(np.array([0, 1, 1]), state.velocity, state.yaw)
    else:
        state = State(state.position, [0.01, 0.0, -0.1], state.yaw)
    a = rust.step(state, setpoint, q, None, 0.025)
    b = composed.step(state, setpoint, q, None, 0.025)
    assert len(rust_results) == 1 and rust_results[0] is not None
    assert _command_bits(a) == _command_bits(b)
    assert _state_bits(rust) == _state_bits(composed)


@pytest.mark.parametrize("bad", ["short_targets", "nan_setpoint_z", "zero_dt"])
def test_inputs_the_call_cannot_take_raise_with_nothing_stepped(bad):
    rust = _pipeline(True)
    q = np.full(rust.robot.n_q, 0.1)
    _ready(rust, q)
    state = State(np.array([0.1, -0.2, 1.0]), np.array([0.01, 0.0, -0.1]), 0.2)
    setpoint = Setpoint(np.array([0.0, 0.0, 1.2]), np.zeros(3), 0.0)
    targets, dt = q.copy(), 0.025
    if bad == "short_targets":
        targets = targets[:2]  # a joint vector the units' indices do not fit
    elif bad == "nan_setpoint_z":
        setpoint = Setpoint(np.array([0.0, 0.0, np.nan]), np.zeros(3), 0.0)
    else:
        dt = 0.0
    before = _state_bits(rust)
    with pytest.raises(ValueError):
        rust.step(state, setpoint, targets, None, dt)
    assert _state_bits(rust) == before


def test_truth_values_are_taken_as_python_takes_them(rust_results):
    """A perching flag or a vectoring switch that is not a bool (an int, numpy's bool) is
    read by its truth value, and the Rust call takes it."""
    rng = np.random.default_rng(7)
    for perching, vectoring in ((1, np.True_), (0, np.False_), (np.True_, 1)):
        rust, composed = _pipeline(True), _pipeline(False)
        q = np.full(rust.robot.n_q, 0.2)
        _ready(rust, q)
        _ready(composed, q)
        for ctl in (rust, composed):
            ctl.perching = perching
            ctl.config = dataclasses.replace(ctl.config, vectoring=vectoring)
        state, setpoint, targets = _random_inputs(rng, rust.robot.n_q)
        rust_results.clear()
        a = rust.step(state, setpoint, targets, None, 0.025)
        b = composed.step(state, setpoint, targets, None, 0.025)
        # taken by the Rust call (the rust pipeline's one call; the composed one makes none)
        assert len(rust_results) == 1 and rust_results[0] is not None
        assert _command_bits(a) == _command_bits(b)
        assert _state_bits(rust) == _state_bits(composed)
