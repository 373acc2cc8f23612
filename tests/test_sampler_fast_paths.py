"""The plant side's per-millisecond fast paths against their plain forms.

Every fast path keeps its plain form reachable; these compare them bit for bit (signed zeros
and NaN included) on real plant states and random, bad input: sensor samples read from
``sensordata`` in Rust against the Python list path, the ground truth against its reference
form, the one-call duty commands against one ``Esc.command_duty`` per rotor, the mocap node
against the array formula.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from float_bits import same_bits

from rdm.plant import Plant
from rdm.plant.esc import Esc, EscParams
from rdm.plant.truth import GroundTruth
from rdm.scenarios.stack import MocapNode, quaternion_yaw


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
