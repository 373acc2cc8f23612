"""The Rust rotor step (``RotorPlantCore``) against the plain Python form, bit for bit."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from rdm._rdm import RotorPlantCore
from rdm.plant import Plant
from rdm.plant.ceiling import NoCeilingEffect, ParametricCeilingEffect


def _bits(x: float) -> bytes:
    return b"nan" if math.isnan(x) else struct.pack("<d", x)


def _python_step(thrust, target, alpha, effects, h, xpos, xmat, sites):
    """The pre-Rust Plant.step arithmetic: lag, distance, thrust_ratio, product."""
    out = []
    for i, sid in enumerate(sites):
        thrust[i] += alpha[i] * (target[i] - thrust[i])
        if h is None:
            dist = math.inf
        else:
            az = xmat.item(sid, 8)
            dist = max(h - xpos.item(sid, 2), 0.0) / az if az > 1e-6 else math.inf
        out.append(thrust[i] * effects[i].thrust_ratio(dist))
    return out


SPECIAL = [math.nan, math.inf, -math.inf, 0.0, -0.0, 1e-7, 1e-6, -1.0, 1e300, 2.0]


@pytest.mark.parametrize("seed", range(6))
def test_core_step_equals_python_form_bit_for_bit(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n_rot, nsite, nact = 4, 9, 11
    sites = rng.choice(nsite, n_rot, replace=False).tolist()
    acts = rng.choice(nact, n_rot, replace=False).tolist()
    xpos = np.zeros((nsite, 3))
    xmat = np.zeros((nsite, 9))
    ctrl = np.full(nact, -7.0)
    seen_cap = seen_mid = seen_one = False
    for h in (None, 0.75, 0.0, 2.0):
        core = RotorPlantCore(sites, acts, h, xpos, xmat, ctrl)
        for _ in range(300):
            effects = []
            for i in range(n_rot):
                kind = rng.integers(3)
                if kind == 0:
                    effects.append(NoCeilingEffect())
                    core.set_ceiling_unity(i)
                else:
                    e = ParametricCeilingEffect(
                        radius=float(rng.uniform(0.02, 0.3)),
                        k1=float(rng.choice([4.7, 0.05, rng.uniform(0.1, 10)])),
                        k2_over_radius=float(rng.uniform(0.1, 2.0)),
                        max_ratio=float(rng.choice([1.5, 1.0, 1.2, rng.uniform(1, 3)])),
                    )
                    effects.append(e)
                    core.set_ceiling_parametric(i, e.radius, e.k1, e.k2_over_radius, e.max_ratio)
            thrust = rng.uniform(-1, 20, n_rot).tolist()
            target = rng.uniform(0, 20, n_rot).tolist()
            alpha = rng.uniform(0, 1, n_rot).tolist()
            for i in range(n_rot):
                core.set_thrust(i, thrust[i])
                core.set_target(i, target[i])
                core.set_alpha(i, alpha[i])
            xpos[:] = rng.uniform(-0.5, 2.5, xpos.shape)
            xmat[:] = rng.uniform(-1, 1, xmat.shape)
            for sid in sites:  # special heights / axes, incl. NaN and inf distances
                if rng.random() < 0.3:
                    xpos[sid, 2] = SPECIAL[rng.integers(len(SPECIAL))]
                if rng.random() < 0.3:
                    xmat[sid, 8] = SPECIAL[rng.integers(len(SPECIAL))]
            want = _python_step(thrust, target, alpha, effects, h, xpos, xmat, sites)
            core.step()
            got = core.applied()
            assert [_bits(x) for x in got] == [_bits(x) for x in want]
            assert [_bits(ctrl[a]) for a in acts] == [_bits(x) for x in want]
            assert [core.thrust(i) for i in range(n_rot)] == thrust
            for e, t, w in zip(effects, thrust, want, strict=True):
                if isinstance(e, ParametricCeilingEffect) and t > 0:
                    seen_cap |= w == t * e.max_ratio and e.max_ratio > 1
                    seen_mid |= t < w < t * e.max_ratio
                    seen_one |= w == t
    others = [c for i, c in enumerate(ctrl) if i not in acts]
    assert others == [-7.0] * len(others)  # only the rotor controls are written
    assert seen_cap and seen_mid and seen_one


def test_core_refuses_bad_indices_and_writes_nothing() -> None:
    xpos, xmat, ctrl = np.zeros((2, 3)), np.zeros((2, 9)), np.zeros(2)
    with pytest.raises(ValueError, match="site_ids"):
        RotorPlantCore([0, 5], [0, 1], 1.0, xpos, xmat, ctrl).step()
    with pytest.raises(ValueError, match="actuator_ids"):
        RotorPlantCore([0, 1], [0, 2], 1.0, xpos, xmat, ctrl).apply()
    with pytest.raises(ValueError, match="actuator_ids"):
        RotorPlantCore([0, 1], [0], 1.0, xpos, xmat, ctrl)
    with pytest.raises(IndexError, match="rotor index 2"):
        RotorPlantCore([0, 1], [0, 1], 1.0, xpos, xmat, ctrl).set_thrust(2, 1.0)
    assert ctrl.tolist() == [0.0, 0.0]


class _OwnParametric(ParametricCeilingEffect):
    """Same formula, but not the exact class: the plant keeps the Python path for it."""


def test_plant_rust_path_equals_python_path_over_a_flight_near_the_ceiling() -> None:
    plants = []
    for cls in (ParametricCeilingEffect, _OwnParametric):
        p = Plant("rdm", seed=0, ceiling_height=0.75)
        p.ceiling_effects = [cls(radius=r.radius) for r in p.description.rotors]
        p.reset(base_position=(0.0, 0.0, 0.6), base_quaternion=(0.99, 0.05, 0.1, 0.0))
        plants.append(p)
    fast, slow = plants
    assert fast._state.rotors_in_core and not slow._state.rotors_in_core
    for k in range(60):
        duties = [0.6 + 0.01 * ((k * (i + 3)) % 17) for i in range(4)]
        for p in plants:
            p.set_rotor_duties(duties)
            if k == 30:
                p.set_battery_voltage(23.0)
            p.step(5)
        assert fast.rotor_thrusts().tobytes() == slow.rotor_thrusts().tobytes()
        assert fast.data.qpos.tobytes() == slow.data.qpos.tobytes()
    thrusts = fast.rotor_thrusts()
    lagged = np.array([e.thrust for e in fast.escs])
    assert np.all(thrusts > lagged)  # near the ceiling: the effect is in play
    # the ESC objects read and write the core's state
    fast.escs[2]._thrust = 3.25
    assert fast._rotors.thrust(2) == 3.25 and fast.escs[2].thrust == 3.25


def test_core_refuses_arrays_it_cannot_read_or_write_without_borrow_tracking() -> None:
    # the per-step slices skip rust-numpy's borrow checker (crates/rdm_py/src/untracked.rs):
    # what that checker caught is refused here instead, and nothing is written
    xpos, xmat = np.zeros((2, 3)), np.zeros((2, 9))
    shared = np.zeros(2 * 3 + 2)
    with pytest.raises(ValueError, match="must not share memory"):
        RotorPlantCore([0, 1], [0, 1], 1.0, shared[:6].reshape(2, 3), xmat, shared[4:6])
    ctrl = np.full(2, -7.0)
    ctrl.flags.writeable = False
    with pytest.raises(ValueError, match="ctrl: not writeable"):
        RotorPlantCore([0, 1], [0, 1], 1.0, xpos, xmat, ctrl).step()
    with pytest.raises(ValueError, match="site_xmat: must be C-contiguous"):
        RotorPlantCore([0, 1], [0, 1], 1.0, xpos, np.asfortranarray(xmat), np.zeros(2)).step()
    ctrl = np.full(4, -7.0)[::2]  # strided: not contiguous
    with pytest.raises(ValueError, match="ctrl: must be C-contiguous"):
        RotorPlantCore([0, 1], [0, 1], 1.0, xpos, xmat, ctrl).step()
    assert ctrl.tolist() == [-7.0, -7.0]
