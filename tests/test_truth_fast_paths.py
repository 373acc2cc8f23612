"""Fast paths of the 100 Hz ground-truth record (helper mstruth): the Ryu float writer
against Python's own ``repr`` / ``json.dumps``."""

from __future__ import annotations

import json
import math
import struct

import numpy as np

from rdm._rdm import json_float_list, json_record


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
