"""The plant side's per-millisecond fast paths against their plain forms.

Every fast path keeps its plain form reachable; these compare them bit for bit (signed zeros
and NaN included) on real plant states and random, bad input: the Rust JSON record writer
against ``json.dumps``, sensor samples read from ``sensordata`` in Rust against the Python
list path, the ground truth against its reference form, the one-call duty commands against
one ``Esc.command_duty`` per rotor, the mocap node against the array formula.
"""

from __future__ import annotations

import json
import math
import struct

import mcap
import numpy as np
import pytest
from float_bits import same_bits
from mcap.reader import make_reader

from rdm._rdm import json_record
from rdm.plant import Plant
from rdm.plant.esc import Esc, EscParams
from rdm.plant.truth import GroundTruth
from rdm.scenarios.stack import MocapNode, quaternion_yaw
from rdm.sim.json_record import encode_record, encode_record_plain
from rdm.sim.mcap_fast import VERIFIED_MCAP
from rdm.sim.mcap_log import McapLogger, _jsonable


def _reference(values: dict) -> str:
    return json.dumps(_jsonable(dict(values)), separators=(",", ":"))


# ----------------------------------------------------------------------------- JSON records
def _random_value(rng: np.random.Generator):
    bits = rng.integers(0, 2**64, size=4, dtype=np.uint64).view(np.float64)
    choices = [
        lambda: float(bits[0]),
        lambda: float(rng.standard_normal() * 10.0 ** rng.integers(-8, 18)),
        lambda: np.float64(bits[1]),
        lambda: bool(rng.integers(2)),
        lambda: np.bool_(rng.integers(2)),
        lambda: int(rng.integers(-(2**62), 2**62)),
        lambda: 2**70 + int(rng.integers(100)),
        lambda: np.int64(rng.integers(-1000, 1000)),
        lambda: None,
        lambda: "".join(rng.choice(list('ab "\\\n\t\x01\x7f\u00e9\u2603\U0001f600'), 5)),
        lambda: bits.copy(),
        lambda: np.arange(12, dtype=float).reshape(3, 4)[:, 1] * bits[2],  # strided
        lambda: bits.reshape(2, 2),
        lambda: bits.astype(np.float32),
        lambda: bits.astype(">f8"),
        lambda: np.array([True, False]),
        lambda: [float(b) for b in bits],
        lambda: [np.float64(b) for b in bits],
        lambda: [1.0, 2],
        lambda: [],
        lambda: {"nested": 1.0},
        lambda: (1.0, 2.0),
    ]
    return choices[int(rng.integers(len(choices)))]()


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_rust_record_writer_equals_json_dumps_or_declines():
    rng = np.random.default_rng(11)
    declined = written = 0
    for _ in range(4000):
        keys = rng.choice(["t", "base_position", "a/b.c:d+e-f g", 'q"uote', "\u00e9", "x"], 4)
        record = {str(k): _random_value(rng) for k in keys}
        if rng.integers(10) == 0:
            record[3] = 1.0  # a non-str key
        text = json_record(record)
        plain = encode_record_plain(record)
        try:
            ref = _reference(record)
        except TypeError:
            ref = None  # json.dumps itself refuses (a non-str key of a mapping works...)
        if text is None:
            declined += 1
        else:
            written += 1
            assert text == ref, record
        # the logger's entry point: the Rust text, else the Python fast path, same bytes
        assert encode_record(record) == (text if text is not None else plain)
        if plain is not None:
            assert plain == ref
    assert declined > 100 and written > 100


def test_rust_record_writer_edge_values():
    record = {
        "specials": np.array([0.0, -0.0, np.nan, np.inf, -np.inf, 5e-324, 1e16, 1e-5, 0.1]),
        "s": 'perched \u00e9"x\\\u0000\U0001f600',
        "big": 2**63 - 1,
        "neg": -(2**63),
        "f32": np.float64(-0.0),
        "b": True,
        "none": None,
        "list": [float("nan"), -0.0, 1e300],
    }
    assert json_record(record) == _reference(record)
    assert json_record({"big": 2**63}) is None  # beyond i64: Python writes it
    assert encode_record({"big": 2**63}) == _reference({"big": 2**63})
    assert json_record({"s": "\ud800"}) is None  # lone surrogate
    assert json_record([("a", 1.0)]) is None  # not a dict
    assert json_record({}) == "{}"


def test_log_truth_writes_the_field_dict_bytes(tmp_path):
    plant = Plant("rdm", seed=1, ceiling_height=1.2, floor_height=0.0)
    plant.reset(base_position=(0.0, 0.0, 0.3), thrusts=[4.0, 4.5, 5.0, 4.2])
    truths = []
    for _ in range(40):
        plant.step(5)
        truths.append(plant.ground_truth())
    fast, plain = tmp_path / "fast.mcap", tmp_path / "plain.mcap"
    with McapLogger(fast) as a, McapLogger(plain) as b:
        for gt in truths:
            a.log_truth(gt)
            fields = {k: getattr(gt, k) for k in gt.__dataclass_fields__}
            b.log_json("/plant/ground_truth", float(gt.time), fields)
    assert fast.read_bytes() == plain.read_bytes()
    with open(fast, "rb") as f:
        msgs = [json.loads(m.data) for _, _, m in make_reader(f).iter_messages()]
    assert len(msgs) == 40 and msgs[-1]["time"] == truths[-1].time


# ------------------------------------------------------------------------------ sensors
def _flying_pair(seed: int = 3) -> tuple[Plant, Plant]:
    plants = []
    for _ in range(2):
        p = Plant("rdm", seed=seed, ceiling_height=1.2, floor_height=0.0)
        p.reset(base_position=(0.0, 0.0, 0.6), thrusts=[4.0, 4.5, 5.0, 4.2])
        p.set_rotor_thrusts([5.0, 3.0, 6.0, 4.0])  # tumbles: every reading moves
        plants.append(p)
    return plants[0], plants[1]


def test_plant_readings_from_sensordata_equal_the_list_path():
    fast, plain = _flying_pair()
    for step in range(400):
        fast.step(1)
        plain.step(1)
        a, b = fast.imu(), plain.imu_plain()
        for x, y in ((a.gyro, b.gyro), (a.accel, b.accel), (a.mag, b.mag)):
            assert same_bits(x, y), step
        assert a.saturated == b.saturated
        for key in fast.wrench_models:
            u, w = fast.wrench(key), plain.wrench_plain(key)
            assert same_bits(u.force, w.force) and same_bits(u.torque, w.torque), (step, key)
            assert np.array_equal(u.saturated, w.saturated)


def test_sample_at_equals_the_python_form_on_random_and_bad_values():
    fast, plain = _flying_pair(seed=8)
    imu_a, imu_b = fast.imu_model, plain.imu_model
    key = next(iter(fast.wrench_models))
    w_a, w_b = fast.wrench_models[key], plain.wrench_models[key]
    rng = np.random.default_rng(4)
    # (no value whose v / lsb overflows: the Python quantiser raises there, sensor_noise.rs)
    specials = np.array([np.nan, np.inf, -np.inf, -0.0, 1e30, 5e-324, 1e4, -3e3])
    for k in range(500):
        sd = rng.standard_normal(40) * 10.0 ** rng.integers(-3, 4)
        sd[rng.integers(40, size=3)] = rng.choice(specials, 3)
        view = sd[::2] if k % 3 == 0 else sd  # strided views too
        adr = rng.integers(0, len(view) - 3, size=3).tolist()
        a = imu_a.sample_at(view, *adr)
        b = imu_b.sample_lists_plain(*(view[i : i + 3].tolist() for i in adr))
        assert all(
            same_bits(x, y) for x, y in ((a.gyro, b.gyro), (a.accel, b.accel), (a.mag, b.mag))
        )
        assert a.saturated == b.saturated
        f, t = adr[0], adr[1]
        u = w_a.sample_at(view, f, t)
        w = w_b.sample_list_plain(view[f : f + 3].tolist() + view[t : t + 3].tolist())
        assert same_bits(u.force, w.force) and same_bits(u.torque, w.torque)
        assert np.array_equal(u.saturated, w.saturated)
    # An address past the end: ValueError naming it, on both paths; the streams stay aligned.
    sd = np.zeros(10)
    with pytest.raises(ValueError, match="torque_adr"):
        w_a.sample_at(sd, 0, 8)
    with pytest.raises(ValueError):
        w_b.sample_list_plain(sd[0:3].tolist() + sd[8:11].tolist())
    with pytest.raises(ValueError, match="mag_adr"):
        imu_a.sample_at(sd, 0, 3, 2**40)
    with pytest.raises(ValueError):
        imu_b.sample_lists_plain(sd[0:3].tolist(), sd[3:6].tolist(), sd[10:13].tolist())
    with pytest.raises(OverflowError):
        w_a.sample_at(sd, -1, 0)  # negative address: refused by the conversion
    w_b._normals.take(6)
    assert same_bits(w_a.sample_at(sd, 0, 3).force, w_b.sample_list_plain([0.0] * 6).force)


# -------------------------------------------------------------------------- ground truth
def _truth_fields(gt: GroundTruth) -> dict:
    return {k: getattr(gt, k) for k in gt.__dataclass_fields__}


def _assert_same_truth(a: GroundTruth, b: GroundTruth) -> None:
    fa, fb = _truth_fields(a), _truth_fields(b)
    assert list(fa) == list(fb)
    for k in fa:
        x, y = fa[k], fb[k]
        assert type(x) is type(y), k
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and same_bits(x, y), k
        elif isinstance(x, float):
            assert same_bits(x, y), k
        else:
            assert x == y, k


def test_ground_truth_equals_the_reference_form_through_contact_and_flight():
    # Starts on the floor (contacts, an anchor), then lifts off (release after 0.1 s).
    plants = []
    for _ in range(2):
        p = Plant("rdm", seed=2, ceiling_height=1.6, floor_height=0.0)
        p.reset(base_position=(0.0, 0.0, 0.05))
        plants.append(p)
    fast, plain = plants
    saw = set()
    for k in range(900):
        if k == 200:
            for p in plants:
                p.set_rotor_thrusts([9.0, 9.5, 9.0, 9.5])
        for p in plants:
            p.step(1)
        if k % 3 == 0:
            a, b = fast._ground_truth(), plain._ground_truth_plain()
            _assert_same_truth(a, b)
            saw.add((a.foot_contact_points > 0, bool(np.any(a.foot_slip != 0))))
    assert (True, False) in saw or (True, True) in saw  # in contact at some point
    assert any(not c for c, _ in saw)  # and in flight


def test_ground_truth_from_values_equals_the_dataclass_init():
    plant = Plant("rdm", seed=0)
    gt = plant._ground_truth_plain()
    values = list(_truth_fields(gt).values())
    fast = GroundTruth.from_values(*values)
    assert list(fast.__dict__) == list(GroundTruth(*values).__dict__)
    _assert_same_truth(fast, GroundTruth(*values))
    with pytest.raises(AttributeError):
        fast.time = 1.0  # still frozen
    with pytest.raises(TypeError):
        GroundTruth.from_values(*values[:-1])


# ------------------------------------------------------------------------- duty commands
def test_duty_commands_in_one_call_equal_one_command_per_esc():
    fast, plain = _flying_pair(seed=5)
    rng = np.random.default_rng(9)
    specials = [np.nan, np.inf, -np.inf, 0.5, 1.0, 0.49999999999999994, -0.0, 7.0]
    for k in range(600):
        if k % 50 == 0:
            volts = float(rng.uniform(15.0, 26.0))
            fast.set_battery_voltage(volts)
            plain.set_battery_voltage(volts)
        duties = rng.uniform(0.4, 1.05, 4)
        if k % 7 == 0:
            duties[rng.integers(4)] = specials[k % len(specials)]
        fast.set_rotor_duties(duties)
        plain.set_rotor_duties_plain(duties)
        for a, b in zip(fast.escs, plain.escs, strict=True):
            assert same_bits(a.target_thrust, b.target_thrust), k
            assert same_bits(a.duty, b.duty) and a.rejected == b.rejected
        fast.step(1)
        plain.step(1)
        assert same_bits(fast.rotor_thrusts(), plain.rotor_thrusts())
    assert sum(e.rejected for e in fast.escs) > 10
    with pytest.raises(ValueError, match="duties"):
        fast.set_rotor_duties(np.zeros(3))
    with pytest.raises(ValueError, match="duties"):
        plain.set_rotor_duties_plain(np.zeros(3))


def test_duty_map_equals_the_firmware_inverse_formula():
    # Independent numpy form of the SQRT-mode map (esc.py module doc) on a detached Esc.
    params = EscParams()
    for volts in (25.2, 22.2, 16.8):
        esc = Esc(params, volts)
        for duty in np.linspace(0.45, 1.1, 27):
            esc.command_duty(float(duty))
            x = 100.0 * min(max(duty, 0.5), 1.0)
            f = (0.1 * params.p2 * x * x + 0.1 * params.p1 * x + params.p0) / (
                (params.v_ref / volts) ** 2
            )
            want = 0.0 if duty <= 0.5 else min(max(f, 0.0), params.thrust_max)
            assert math.isclose(esc.target_thrust, want, rel_tol=0, abs_tol=1e-12)


def test_duty_commands_where_python_raises_keep_the_python_path():
    plant = Plant("rdm", seed=0)
    plant.escs[2].voltage = 0.0  # (v_ref / 0) ** 2 raises: no map for the core
    with pytest.raises(ZeroDivisionError):
        plant.set_rotor_duties([0.7, 0.7, 0.7, 0.7])
    plant.escs[2].voltage = 24.0
    plant.set_rotor_duties([0.7, 0.7, 0.7, 0.7])
    ref = Esc(plant.escs[2].params, 24.0)
    ref.command_duty(0.7)
    assert plant.escs[2].target_thrust == ref.target_thrust


# ------------------------------------------------------------------------------- mocap
class _MocapRecorder:
    """Records what the mocap node hands the onboard node (its ``set_mocap`` signature)."""

    def __init__(self) -> None:
        self.calls: list = []

    def set_mocap(self, position, velocity, yaw=None) -> bool:
        self.calls.append((list(position), list(velocity), yaw))
        return True


def test_mocap_node_equals_the_array_formula():
    fast, _ = _flying_pair(seed=6)
    rec = _MocapRecorder()
    node = MocapNode(fast, rec, period=0.01)  # type: ignore[arg-type]
    last = None
    for _ in range(60):
        fast.step(10)
        node.tick(fast.time)
        gt = fast.ground_truth()
        p = np.asarray(gt.cog_position, dtype=float)
        v = np.zeros(3) if last is None else (p - last) / 0.01
        last = p
        pos, vel, yaw = rec.calls[-1]
        assert same_bits(pos, p) and same_bits(vel, v)
        assert all(type(x) is float for x in pos + vel)
        assert same_bits(yaw, quaternion_yaw(gt.base_quaternion))


# ------------------------------------------------------------------------------- MCAP
@pytest.mark.parametrize("chunk_size", [64 * 1024, 700, 1])
def test_fast_message_records_give_the_same_file(tmp_path, chunk_size):
    # On an mcap release outside VERIFIED_MCAP the fast writer stays off and both files come
    # from the library's own path: the file checks below still hold.
    verified = _mcap_verified()
    files = {}
    for fast in (True, False):
        rng = np.random.default_rng(chunk_size)  # the same messages for both paths
        path = tmp_path / f"{fast}.mcap"
        with McapLogger(path, chunk_size=chunk_size, fast_messages=fast) as log:
            assert (log._fast is not None) is (fast and verified)
            t = 0.0
            for k in range(600):
                t += float(rng.choice([0.0, 0.001, 0.0105]))
                topic = ["/plant/ground_truth", "/onboard/status", "/x/y"][k % 3]
                n = int(rng.integers(0, 300))
                log.log_json(topic, t, {"t": t, "v": rng.standard_normal(n), "k": k})
                if k == 300:
                    log.log_json("/late", 0.5 * t, {"late": True})  # earlier time: min/max
            with pytest.raises(ValueError):
                log.log_json("/x/y", -1.0, {"t": -1.0})
            counted = log.messages
        files[fast] = path.read_bytes()
        assert counted == 601
    assert files[True] == files[False]
    with open(tmp_path / "True.mcap", "rb") as f:
        reader = make_reader(f)
        stats = reader.get_summary().statistics
        msgs = list(reader.iter_messages())
    assert stats.message_count == len(msgs) == 601


def _mcap_verified() -> bool:
    return ".".join(mcap.__version__.split(".")[:2]) in VERIFIED_MCAP


def test_fast_writer_is_off_on_an_unverified_mcap_release(tmp_path, monkeypatch):
    monkeypatch.setattr(mcap, "__version__", "9.9.0")
    with McapLogger(tmp_path / "x.mcap") as log:
        assert log._fast is None
        log.log_json("/x", 1.0, {"t": 1.0})
    with open(tmp_path / "x.mcap", "rb") as f:
        assert [m.log_time for _, _, m in make_reader(f).iter_messages()] == [1_000_000_000]


def test_fast_message_records_fail_as_the_library(tmp_path):
    # A time beyond uint64 ns: the library's own error, on the write and again on finish
    # (its statistics already hold the time), on both paths.
    counters = []
    for fast in (True, False):
        log = McapLogger(tmp_path / f"{fast}.mcap", fast_messages=fast)
        log.log_json("/x", 1.0, {"t": 1.0})
        with pytest.raises(struct.error):
            log.log_json("/x", 2e10, {"t": 1.0})
        with pytest.raises(struct.error):
            log.finish()
        counters.append((log.messages, dict(log._seq)))
    assert counters[0] == counters[1] == (1, {1: 2})
