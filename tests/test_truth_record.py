"""The 100 Hz ground-truth record: the Ryu float writer against Python's own ``repr`` /
``json.dumps``; the one-call MjData copies against MuJoCo's arrays (``truth_reference``),
bad layouts and views named in the errors."""

from __future__ import annotations

import json
import math
import struct

import numpy as np
import pytest
from truth_reference import ground_truth_reference

from rdm._rdm import RotorPlantCore, json_float_list, json_record
from rdm.plant import Plant
from rdm.plant.truth import GroundTruth


def _python_text(values: np.ndarray) -> str:
    return ",".join(float.__repr__(float(v)) if math.isfinite(v) else "null" for v in values)


def test_float_list_equals_python_repr_on_random_bit_patterns():
    rng = np.random.default_rng(20261122)
    bits = rng.integers(0, 2**64, size=200_000, dtype=np.uint64)
    values = bits.view(np.float64)
    assert json_float_list(values) == _python_text(values)


def test_float_list_equals_python_repr_on_short_decimals_and_ties():
    # Short decimals, dyadic fractions (exact ties live there), their neighbours, powers of
    # two and ten, subnormals and the layout switch points (1e-5, 1e16).
    rng = np.random.default_rng(7)
    base = np.concatenate(
        [
            rng.integers(0, 10**6, 20_000) / 10.0 ** rng.integers(0, 9, 20_000),
            rng.integers(0, 2**40, 20_000) / 2.0 ** rng.integers(0, 60, 20_000),
            2.0 ** np.arange(-1074, 1024, dtype=float),
            10.0 ** np.arange(-323, 309, dtype=float),
            [575395288650688.25, 161624357233039.625, 1e-5, 9.999999999999999e-6, 1e16],
            [1e16 - 2, 5e-324, 2.2250738585072014e-308, np.finfo(float).max, 0.0, -0.0],
        ]
    )
    with np.errstate(over="ignore"):  # the largest double's upper neighbour is inf (null)
        up = np.nextafter(base, np.inf)
        down = np.nextafter(base, -np.inf)
    values = np.concatenate([base, up, down, -base])
    assert json_float_list(values) == _python_text(values)


def test_record_text_equals_json_dumps_on_random_truth_like_records():
    rng = np.random.default_rng(3)
    for _ in range(500):
        raw = rng.integers(0, 2**64, size=12, dtype=np.uint64).view(np.float64)
        scaled = rng.normal(size=12) * 10.0 ** rng.integers(-8, 8, size=12)
        record = {
            "time": float(scaled[0]),
            "base_position": scaled[:3].copy(),
            "bits": raw.copy(),
            "foot_in_contact": bool(rng.integers(2)),
            "foot_contact_points": int(rng.integers(0, 9)),
            "foot_slip_yaw": struct.unpack("<d", struct.pack("<d", float(raw[0])))[0],
            "rotor_thrusts": scaled[3:7].tolist(),
        }
        expected_values = {
            k: (
                [x if math.isfinite(x) else None for x in np.asarray(v, dtype=float).tolist()]
                if isinstance(v, (np.ndarray, list))
                else (v if not isinstance(v, float) or math.isfinite(v) else None)
            )
            for k, v in record.items()
        }
        assert json_record(record) == json.dumps(expected_values, separators=(",", ":"))


# ------------------------------------------------------------- ground truth in one call
def _assert_bits_equal(a: GroundTruth, b: GroundTruth) -> None:
    for k in GroundTruth.__dataclass_fields__:
        x, y = getattr(a, k), getattr(b, k)
        assert type(x) is type(y), k
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and x.shape == y.shape, k
            assert x.tobytes() == y.tobytes(), k  # same bits (NaN, -0.0)
            assert x.flags.owndata or x.base is not None, k
        elif isinstance(x, float):
            assert struct.pack("<d", x) == struct.pack("<d", y), k
        else:
            assert x == y, k


@pytest.mark.parametrize("fixed_base", [False, True])
def test_ground_truth_one_call_equals_mujocos_arrays(fixed_base):
    plant = Plant("rdm", seed=4, ceiling_height=1.6, floor_height=0.0, fixed_base=fixed_base)
    plant.reset(base_position=(0.0, 0.0, 0.05))
    rng = np.random.default_rng(11)
    for k in range(300):
        if k % 50 == 0:
            plant.set_rotor_thrusts(rng.uniform(0.0, 12.0, 4))
            plant.set_servo_targets(rng.uniform(-0.5, 0.5, len(plant._qadr)))
        plant.step(1)
        if k % 7 == 0:
            _assert_bits_equal(plant._ground_truth(), ground_truth_reference(plant))
    # The arrays are copies: the next step does not change a record already taken.
    gt = plant._ground_truth()
    before = {k: np.copy(getattr(gt, k)) for k in ("base_position", "joint_positions")}
    plant.step(5)
    plant.sync()
    for k, v in before.items():
        assert getattr(gt, k).tobytes() == v.tobytes()


def test_ground_truth_one_call_copies_nan_and_inf_state_bits():
    plant = Plant("rdm", seed=0)
    plant.sync()
    d = plant._data
    d.qvel[:6] = [np.nan, -0.0, np.inf, -np.inf, 5e-324, -np.nan]
    d.qpos[plant._qadr[0]] = np.nan
    d.xpos[plant._foot_body] = [np.nan, -0.0, 1e308]
    _assert_bits_equal(plant._ground_truth(), ground_truth_reference(plant))


def test_truth_arrays_errors_name_the_field():
    plant = Plant("rdm", seed=0)
    plant.sync()
    core, d = plant._rotors, plant._data
    views = (d.xpos, d.xquat, d.qpos, d.qvel, d.subtree_com)
    fresh = RotorPlantCore([], [], None, d.site_xpos, d.site_xmat, d.ctrl)
    with pytest.raises(ValueError, match="set_truth_layout"):
        fresh.truth_arrays(*views)
    n_body = d.xpos.shape[0]
    cases = [
        ((n_body, 0, [0], [0], False), "xpos"),
        ((0, n_body + 3, [0], [0], False), "xpos"),
        ((0, 0, [d.qpos.size], [0], False), "qpos"),
        ((0, 0, [0], [d.qvel.size + 1], False), "qvel"),
    ]
    for layout, field in cases:
        fresh.set_truth_layout(*layout)
        with pytest.raises(IndexError, match=field):
            fresh.truth_arrays(*views)
    fresh.set_truth_layout(0, 0, [0], [0], False)
    with pytest.raises(IndexError, match="qvel"):
        fresh.truth_arrays(d.xpos, d.xquat, d.qpos, np.zeros(5), d.subtree_com)
    with pytest.raises(ValueError, match="xpos"):
        fresh.truth_arrays(d.xpos[::2], d.xquat, d.qpos, d.qvel, d.subtree_com)
    with pytest.raises(TypeError):
        fresh.truth_arrays(d.xpos.astype(np.float32), d.xquat, d.qpos, d.qvel, d.subtree_com)
    # The plant's own layout still works after all that on another core.
    _assert_bits_equal(plant._ground_truth(), ground_truth_reference(plant))
    assert core is plant._rotors
