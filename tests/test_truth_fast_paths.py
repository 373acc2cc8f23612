"""Fast paths of the 100 Hz ground-truth record: the Ryu float writer
against Python's own ``repr`` / ``json.dumps``; the one-call MjData copies against the
plain numpy copies; the 1 kHz foot-sensor tuple path against the array path."""

from __future__ import annotations

import json
import math
import struct

import numpy as np
import pytest

from rdm._rdm import RotorPlantCore, json_float_list, json_record
from rdm.nodes.leptrino_sensor import LeptrinoSensorNode
from rdm.nodes.plant_bridge import BusLayout, PlantBridge
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
def test_ground_truth_one_call_equals_the_numpy_copies(fixed_base):
    plant = Plant("rdm", seed=4, ceiling_height=1.6, floor_height=0.0, fixed_base=fixed_base)
    plant.reset(base_position=(0.0, 0.0, 0.05))
    rng = np.random.default_rng(11)
    for k in range(300):
        if k % 50 == 0:
            plant.set_rotor_thrusts(rng.uniform(0.0, 12.0, 4))
            plant.set_servo_targets(rng.uniform(-0.5, 0.5, len(plant._qadr)))
        plant.step(1)
        if k % 7 == 0:
            _assert_bits_equal(plant._ground_truth(), plant._ground_truth_plain())
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
    _assert_bits_equal(plant._ground_truth(), plant._ground_truth_plain())


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
    _assert_bits_equal(plant._ground_truth(), plant._ground_truth_plain())
    assert core is plant._rotors


# --------------------------------------------------------- 1 kHz foot sensor as a tuple
class _CaptureUart:
    def __init__(self) -> None:
        self.sent = bytearray()

    def read_available(self) -> bytes:
        return b""

    def write(self, data: bytes) -> int:
        self.sent += data
        return len(data)

    def close(self) -> None:
        pass


def _node_state(node: LeptrinoSensorNode) -> tuple:
    return (
        node._wrench,
        dict(node.errors),
        node.saturated_samples,
        node.frames_sent,
        bytes(node.uart.sent),
    )


def test_wrench_values_equal_the_array_read_and_consume_the_same_normals():
    plants = [Plant("rdm", seed=9, ceiling_height=1.6, floor_height=0.0) for _ in range(2)]
    for p in plants:
        p.reset(base_position=(0.0, 0.0, 0.05))
    fast, plain = plants
    rng = np.random.default_rng(5)
    for k in range(600):
        if k % 100 == 0:
            thrusts = rng.uniform(0.0, 12.0, 4)
            for p in plants:
                p.set_rotor_thrusts(thrusts)
        for p in plants:
            p.step(1)
        values = fast.wrench_values("foot_wrench")
        force, torque = plain.wrench_force_torque("foot_wrench")
        assert type(values) is tuple and all(type(v) is float for v in values)
        assert struct.pack("<6d", *values) == struct.pack("<6d", *force, *torque)
    with pytest.raises(ValueError, match="sensor"):
        fast.wrench_values("nope")


def test_sample_values_at_equals_sample_at_on_random_and_bad_sensordata():
    plant = Plant("rdm", seed=1)
    core = plant.wrench_models["foot_wrench"]._core
    rng = np.random.default_rng(17)
    specials = np.array([np.nan, np.inf, -np.inf, 0.0, -0.0, 1e300, -1e300, 5e-324])
    for _ in range(2000):
        sd = rng.normal(0.0, 50.0, 12)
        mask = rng.random(12) < 0.15
        sd[mask] = rng.choice(specials, mask.sum())
        normals = rng.normal(size=6).tolist()
        fa, ta = rng.integers(0, 10, 2).tolist()
        values = core.sample_values_at(sd, fa, ta, normals)
        force, torque, _ = core.sample_at(sd, fa, ta, normals)
        assert struct.pack("<6d", *values) == struct.pack("<6d", *force, *torque)
    for fa, ta, field in [(10, 0, "force_adr"), (0, 11, "torque_adr"), (2**40, 0, "force_adr")]:
        with pytest.raises(ValueError, match=field) as fast_err:
            core.sample_values_at(np.zeros(12), fa, ta, [0.0] * 6)
        with pytest.raises(ValueError) as plain_err:
            core.sample_at(np.zeros(12), fa, ta, [0.0] * 6)
        assert str(fast_err.value) == str(plain_err.value)
    with pytest.raises(ValueError, match="normals") as fast_err:
        core.sample_values_at(np.zeros(12), 0, 0, [0.0] * 5)
    with pytest.raises(ValueError) as plain_err:
        core.sample_at(np.zeros(12), 0, 0, [0.0] * 5)
    assert str(fast_err.value) == str(plain_err.value)


def test_set_wrench_values_equals_set_wrench_on_random_and_bad_wrenches():
    nodes = [LeptrinoSensorNode(_CaptureUart(), "CFS034CA301U") for _ in range(2)]
    for node in nodes:
        node.streaming = True
    fast, plain = nodes
    lim = np.array(fast._limits)
    rng = np.random.default_rng(23)
    for k in range(3000):
        w = rng.normal(0.0, 0.7, 6) * lim
        if k % 5 == 1:
            w[rng.integers(6)] = rng.choice([np.nan, np.inf, -np.inf])
        elif k % 5 == 2:
            w = lim * rng.choice([1.0, -1.0, 1.0 + 1e-12, -0.0], 6)
        if k % 50 == 3:
            fast.set_wrench_values(tuple(w[:5].tolist()))  # wrong length: refused alike
            plain.set_wrench(w[:3], w[3:5])
        else:
            fast.set_wrench_values(tuple(w.tolist()))
            plain.set_wrench(w[:3], w[3:])
        for node in nodes:
            node.tick(k * 1e-3)
        assert _node_state(fast) == _node_state(plain)
    assert fast.errors["bad_wrench"] > 0 and fast.saturated_samples > 0


def test_bridge_sends_the_same_leptrino_bytes_through_the_tuple_path():
    plants = [Plant("rdm", seed=3, ceiling_height=1.6, floor_height=0.0) for _ in range(2)]
    nodes = [LeptrinoSensorNode(_CaptureUart(), "CFS034CA301U") for _ in range(2)]
    for p, node in zip(plants, nodes, strict=True):
        p.reset(base_position=(0.0, 0.0, 0.05))
        node.streaming = True
    tuple_bridge = PlantBridge(
        plants[0],
        layout=BusLayout(()),  # no Neuron mirrors: only the sampling steps run
        wrench_sinks={"foot_wrench": nodes[0].set_wrench},
        imu_period=None,
    )
    array_bridge = PlantBridge(
        plants[1],
        layout=BusLayout(()),
        wrench_sinks={"foot_wrench": lambda f, t: nodes[1].set_wrench(f, t)},
        imu_period=None,
    )
    assert set(tuple_bridge._wrench_tuple_sinks) == {"foot_wrench"}
    assert array_bridge._wrench_tuple_sinks == {}
    for k in range(400):
        if k == 100:
            for p in plants:
                p.set_rotor_thrusts([9.0, 9.5, 9.0, 9.5])
        for p, bridge, node in zip(plants, (tuple_bridge, array_bridge), nodes, strict=True):
            now = p.time
            bridge.tick(now)
            node.tick(now)
            p.step(1)
    assert _node_state(nodes[0]) == _node_state(nodes[1])
    assert nodes[0].frames_sent == 400
