"""The plant bridge's per-millisecond coupling in the Rust Neuron bank (``rust_bridge``) against
the Python path: same files from the hover stack, same servo targets / duties / positions."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
from hover_run_files import hover_run_files

from rdm import _rdm
from rdm.nodes.neuron_bank import NeuronSpec
from rdm.nodes.servo_model import ServoConfig


def _stack_bridge(tmp_path, **options):
    from rdm.scenarios.common import sim_stack_options
    from rdm.scenarios.stack import build_stack

    stack = build_stack("b", tmp_path, sim_stack_options(0, "inproc", speed=None, **options))
    try:
        return next(n for n in stack.loop.nodes if n.name == "plant_bridge").rust_coupling
    finally:
        stack.close()


def test_stack_option_selects_the_path(tmp_path):
    assert _stack_bridge(tmp_path / "a") is True  # the default
    assert _stack_bridge(tmp_path / "b", rust_bridge=False) is False
    # Python Neuron mirrors: always the Python path.
    assert _stack_bridge(tmp_path / "c", neuron_backend="python") is False


def _bank() -> _rdm.NeuronBank:
    spec = NeuronSpec(1, (ServoConfig(dynamixel_id=1), ServoConfig(dynamixel_id=2)))
    return _rdm.NeuronBank([spec.core_dict()])


def test_bridge_coupling_values_against_numpy():
    """Positions pushed from a qpos snapshot are ``2048 + q * 4096 / 2pi`` (numpy), duties of
    a stopped ESC are 0.5, targets stay put while torque is off."""
    bank = _bank()
    scale = np.array([4096 / (2 * np.pi), -4096 / (2 * np.pi)])
    bank.attach_bridge(2048, [3, 5], scale.tolist(), [(0, 0, 0), (0, 1, 1)], [(0, 0)], [0])
    qpos = np.array([0.0, 0.0, 0.0, 0.3, 0.0, -1.1, 0.0])
    targets = np.array([0.1, 0.2])
    duties = np.array([0.7])
    t_changed, d_changed = bank.bridge_tick(qpos, targets, duties)
    assert (t_changed, d_changed) == (False, True)
    assert duties.tolist() == [0.5]
    assert targets.tolist() == [0.1, 0.2]
    bank.bridge_push_positions()
    positions = [s["position"] for s in bank.board_state(0)["servos"]]
    assert positions == (2048 + qpos[[3, 5]] * scale).tolist()
    # The same counter: nothing re-read.
    assert bank.bridge_tick(qpos, targets, duties) == (False, False)


def test_bridge_errors_name_the_argument():
    bank = _bank()
    q = np.zeros(4)
    with pytest.raises(_rdm.NeuronBankError, match="no bridge attached"):
        bank.bridge_tick(q, np.zeros(2), np.zeros(1))
    with pytest.raises(_rdm.NeuronBankError, match=r"servos\[1\]"):
        bank.attach_bridge(2048, [0, 1], [1.0, 1.0], [(0, 0, 0), (0, 7, 1)], [], [0])
    with pytest.raises(_rdm.NeuronBankError, match=r"scale\[0\]"):
        bank.attach_bridge(2048, [0, 1], [0.0, 1.0], [(0, 0, 0), (0, 1, 1)], [], [0])
    bank.attach_bridge(2048, [0, 9], [1.0, 1.0], [(0, 0, 0), (0, 1, 1)], [(0, 0)], [0])
    with pytest.raises(_rdm.NeuronBankError, match=r"qadr\[1\]"):
        bank.bridge_tick(q, np.zeros(2), np.zeros(1))
    bank.attach_bridge(2048, [0, 1], [1.0, 1.0], [(0, 0, 0), (0, 1, 1)], [(0, 0)], [0])
    with pytest.raises(_rdm.NeuronBankError, match="length"):
        bank.bridge_tick(q, np.zeros(3), np.zeros(1))
    bank.bridge_tick(np.array([np.nan, 0.0, 0.0, 0.0]), np.zeros(2), np.zeros(1))
    with pytest.raises(_rdm.NeuronBankError, match="not finite"):
        bank.bridge_push_positions()


def test_hover_stack_files_identical_with_rust_bridge(tmp_path):
    """4 simulated s from power-on (boot, configuration, arming, take-off): every file of the
    run folder is the same bytes with the coupling in Rust or in Python."""
    py = hover_run_files(tmp_path / "py", "py", 4.0, rust_bridge=False)
    rs = hover_run_files(tmp_path / "rs", "rs", 4.0, rust_bridge=True)
    assert {"can.log", "signals.mcap"} <= set(py)
    assert sorted(py) == sorted(rs)
    for name in py:
        assert hashlib.sha256(rs[name]).hexdigest() == hashlib.sha256(py[name]).hexdigest(), name
    assert py["can.log"].count(b"\n") > 4000
