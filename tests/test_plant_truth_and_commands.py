"""The plant's sensor samples on random and bad ideal values, its ground truth, its duty
commands and the mocap node, against independent references.

Oracles: the noise models' numpy array form with numpy's generator called once per sample;
the ground truth derived from MuJoCo's own data (``truth_reference``); the dataclass's own
``__init__``; the firmware's inverse SQRT-mode formula; the mocap node's array formula.
Comparisons are bit for bit (signed zeros and NaN included) where the reference fixes the
operations, to a tolerance where it does not.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from float_bits import same_bits
from truth_reference import ground_truth_reference

from rdm.plant import Plant
from rdm.plant.description import load_robot
from rdm.plant.esc import Esc, EscParams
from rdm.plant.sensors import (
    ACCEL_LSB,
    ACCEL_RANGE,
    GYRO_LSB,
    GYRO_RANGE,
    LEPTRINO_FULL_SCALE_COUNTS,
    MAG_LSB,
    ImuModel,
    ImuNoise,
    WrenchNoise,
    WrenchSensorModel,
)
from rdm.plant.truth import GroundTruth
from rdm.scenarios.stack import MocapNode, quaternion_yaw


def _flying_plant(seed: int = 3) -> Plant:
    p = Plant("rdm", seed=seed, ceiling_height=1.2, floor_height=0.0)
    p.reset(base_position=(0.0, 0.0, 0.6), thrusts=[4.0, 4.5, 5.0, 4.2])
    p.set_rotor_thrusts([5.0, 3.0, 6.0, 4.0])  # tumbles: every reading moves
    return p


# ------------------------------------------------------------------------------ sensors
def _imu_reference(ideal: list[np.ndarray], biases, noise: ImuNoise, rng) -> tuple:
    """The IMU sample in numpy: bias, nine normals of one generator call, gyro and
    accelerometer clipped (saturation flagged), every axis quantised to its LSB."""
    w = rng.normal(0.0, 1.0, 9)
    g = ideal[0] + biases[0] + noise.gyro_std * w[0:3]
    a = ideal[1] + biases[1] + noise.accel_std * w[3:6]
    m = ideal[2] + biases[2] + noise.mag_std * w[6:9]
    saturated = bool(np.any(np.abs(g) > GYRO_RANGE) or np.any(np.abs(a) > ACCEL_RANGE))
    g = np.clip(g, -GYRO_RANGE, GYRO_RANGE)
    a = np.clip(a, -ACCEL_RANGE, ACCEL_RANGE)
    q = [np.round(v / lsb) * lsb for v, lsb in ((g, GYRO_LSB), (a, ACCEL_LSB), (m, MAG_LSB))]
    return (*q, saturated)


def _wrench_reference(ideal: np.ndarray, rated: np.ndarray, noise: WrenchNoise, rng) -> tuple:
    """The wrench sample in numpy: six normals of one generator call, saturation at the rated
    capacity, clipped, quantised to rated / 10000."""
    w = (
        ideal
        + np.asarray(noise.bias)
        + noise.noise_fraction_of_rated * rated * rng.normal(0.0, 1.0, 6)
    )
    saturated = np.abs(w) >= rated
    w = np.clip(w, -rated, rated)
    lsb = rated / LEPTRINO_FULL_SCALE_COUNTS
    return np.round(w / lsb) * lsb, saturated


class _Fixed:
    """A generator stand-in that hands out given normals."""

    def __init__(self, normals: np.ndarray) -> None:
        self._normals = normals

    def normal(self, loc: float, scale: float, size: int) -> np.ndarray:
        assert (loc, scale, size) == (0.0, 1.0, len(self._normals))
        return self._normals


def test_sample_at_equals_the_array_form_on_random_and_bad_values():
    noise = ImuNoise()
    imu = ImuModel(noise, np.random.default_rng(8))
    imu_rng = np.random.default_rng(8)
    biases = [imu_rng.normal(0.0, s, 3) for s in (
        noise.gyro_bias_std, noise.accel_bias_std, noise.mag_bias_std)]  # fmt: skip
    for got, want in zip((imu.gyro_bias, imu.accel_bias, imu.mag_bias), biases, strict=True):
        assert same_bits(got, want)
    spec = next(iter(load_robot("rdm").wrench_sensors.values()))
    w_noise = WrenchNoise(bias=(0.1, -0.2, 0.0, 0.01, -0.0, 0.02))
    wrench = WrenchSensorModel(spec, w_noise, np.random.default_rng(9))
    w_rng = np.random.default_rng(9)
    rng = np.random.default_rng(4)
    # (no value whose v / lsb overflows: numpy and the core both give inf there)
    specials = np.array([np.nan, np.inf, -np.inf, -0.0, 1e30, 5e-324, 1e4, -3e3])
    saturated = 0
    for k in range(500):
        sd = rng.standard_normal(40) * 10.0 ** rng.integers(-3, 4)
        sd[rng.integers(40, size=3)] = rng.choice(specials, 3)
        view = sd[::2] if k % 3 == 0 else sd  # strided views too
        adr = rng.integers(0, len(view) - 3, size=3).tolist()
        a = imu.sample_at(view, *adr)
        with np.errstate(invalid="ignore"):
            g, acc, m, sat = _imu_reference([view[i : i + 3] for i in adr], biases, noise, imu_rng)
        assert same_bits(a.gyro, g) and same_bits(a.accel, acc) and same_bits(a.mag, m), k
        assert a.saturated == sat
        saturated += sat
        f, t = adr[0], adr[1]
        u = wrench.sample_at(view, f, t)
        with np.errstate(invalid="ignore"):
            want, wsat = _wrench_reference(
                np.concatenate([view[f : f + 3], view[t : t + 3]]), wrench.rated, w_noise, w_rng
            )
        assert same_bits(u.force, want[:3]) and same_bits(u.torque, want[3:]), k
        assert np.array_equal(u.saturated, wsat)
        # the tuple form (the Leptrino mirror's input) on normals handed in
        normals = rng.normal(0.0, 1.0, 6)
        values = wrench._core.sample_values_at(view, f, t, normals.tolist())
        with np.errstate(invalid="ignore"):
            want, _ = _wrench_reference(
                np.concatenate([view[f : f + 3], view[t : t + 3]]),
                wrench.rated,
                w_noise,
                _Fixed(normals),
            )
        assert type(values) is tuple and same_bits(values, want), k
    assert saturated > 10
    # An address past the end: ValueError naming it; the refused read used its normals.
    sd = np.zeros(10)
    with pytest.raises(ValueError, match="torque_adr"):
        wrench.sample_at(sd, 0, 8)
    with pytest.raises(ValueError, match="mag_adr"):
        imu.sample_at(sd, 0, 3, 2**40)
    with pytest.raises(OverflowError):
        wrench.sample_at(sd, -1, 0)  # negative address: refused by the conversion
    for fa, ta, field in [(10, 0, "force_adr"), (0, 11, "torque_adr"), (2**40, 0, "force_adr")]:
        with pytest.raises(ValueError, match=field):
            wrench._core.sample_values_at(np.zeros(12), fa, ta, [0.0] * 6)
    with pytest.raises(ValueError, match="normals"):
        wrench._core.sample_values_at(np.zeros(12), 0, 0, [0.0] * 5)
    w_rng.normal(0.0, 1.0, 12)
    imu_rng.normal(0.0, 1.0, 9)
    want, _ = _wrench_reference(np.zeros(6), wrench.rated, w_noise, w_rng)
    assert same_bits(wrench.sample_at(sd, 0, 3).force, want[:3])
    g, acc, m, _ = _imu_reference([np.zeros(3)] * 3, biases, noise, imu_rng)
    assert same_bits(imu.sample_at(sd, 0, 3, 6).gyro, g)


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


def test_ground_truth_equals_mujocos_data_through_contact_and_flight():
    # Starts on the floor (contacts, an anchor), then lifts off (release after 0.1 s). The
    # second plant, given the same commands, has its truth derived from MuJoCo's data.
    plants = []
    for _ in range(2):
        p = Plant("rdm", seed=2, ceiling_height=1.6, floor_height=0.0)
        p.reset(base_position=(0.0, 0.0, 0.05))
        plants.append(p)
    plant, twin = plants
    saw = set()
    for k in range(900):
        if k == 200:
            for p in plants:
                p.set_rotor_thrusts([9.0, 9.5, 9.0, 9.5])
        for p in plants:
            p.step(1)
        if k % 3 == 0:
            a, b = plant._ground_truth(), ground_truth_reference(twin)
            _assert_same_truth(a, b)
            saw.add((a.foot_contact_points > 0, bool(np.any(a.foot_slip != 0))))
    assert (True, False) in saw or (True, True) in saw  # in contact at some point
    assert any(not c for c, _ in saw)  # and in flight


def test_the_core_record_equals_the_dataclass_init():
    # RotorPlantCore.truth_record fills the record's __dict__ without the frozen __init__:
    # the same fields in the same order, the same values, still frozen.
    plant = Plant("rdm", seed=0)
    made = plant._ground_truth()
    values = list(_truth_fields(made).values())
    assert list(made.__dict__) == list(GroundTruth(*values).__dict__)
    _assert_same_truth(made, GroundTruth(*values))
    _assert_same_truth(made, ground_truth_reference(plant))
    with pytest.raises(AttributeError):
        made.time = 1.0  # still frozen


# ------------------------------------------------------------------------- duty commands
def _steady_thrust(params: EscParams, duty: float, volts: float) -> tuple[float, float, int]:
    """(duty held, steady thrust, rejections) of the firmware's inverse SQRT-mode map (the
    module doc of rdm.plant.esc): a non-finite duty is refused and stops the motor, the duty
    is clamped to [0.5, 1], 0.5 stops it, the thrust is clamped to [0, thrust_max]."""
    rejected = 0 if math.isfinite(duty) else 1
    d = min(max(duty if rejected == 0 else 0.5, 0.5), 1.0)
    if d <= 0.5:
        return d, 0.0, rejected
    x = 100.0 * d
    f = (0.1 * params.p2 * x * x + 0.1 * params.p1 * x + params.p0) / (params.v_ref / volts) ** 2
    return d, min(max(f, 0.0), params.thrust_max), rejected


def test_duty_commands_equal_the_firmware_inverse_formula_per_rotor():
    plant = _flying_plant(seed=5)
    rng = np.random.default_rng(9)
    specials = [np.nan, np.inf, -np.inf, 0.5, 1.0, 0.49999999999999994, -0.0, 7.0]
    volts = 23.0
    plant.set_battery_voltage(volts)
    rejected = [e.rejected for e in plant.escs]
    for k in range(600):
        if k % 50 == 0:
            volts = float(rng.uniform(15.0, 26.0))
            plant.set_battery_voltage(volts)
        duties = rng.uniform(0.4, 1.05, 4)
        if k % 7 == 0:
            duties[rng.integers(4)] = specials[k % len(specials)]
        plant.set_rotor_duties(duties)
        for i, (esc, duty) in enumerate(zip(plant.escs, duties.tolist(), strict=True)):
            d, thrust, r = _steady_thrust(esc.params, duty, volts)
            rejected[i] += r
            assert same_bits(esc.duty, d) and same_bits(esc.target_thrust, thrust), k
            assert esc.rejected == rejected[i], k
        plant.step(1)
    assert sum(rejected) > 10
    with pytest.raises(ValueError, match="duties"):
        plant.set_rotor_duties(np.zeros(3))


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


@pytest.mark.parametrize("volts", [0.0, -24.0, math.nan, math.inf, 1e-160, 1e200])
def test_a_voltage_without_a_finite_duty_map_is_refused(volts):
    """0 V, a negative or non-finite voltage, one whose (v_ref / V) ** 2 overflows (1e-160)
    or rounds to 0 (1e200): refused with the argument's name, the ESC keeps its map."""
    plant = Plant("rdm", seed=0)
    esc = plant.escs[2]
    with pytest.raises(ValueError, match=r"^voltage: "):
        esc.voltage = volts
    with pytest.raises(ValueError, match=r"^voltage: "):
        plant.set_battery_voltage(volts)
    with pytest.raises(ValueError, match=r"^voltage: "):
        Esc(esc.params, volts)
    assert esc.voltage == esc.params.v_ref
    plant.set_rotor_duties([0.7, 0.7, 0.7, 0.7])
    _, want, _ = _steady_thrust(esc.params, 0.7, esc.params.v_ref)
    assert same_bits(esc.target_thrust, want)


def test_the_escs_are_fixed():
    plant = Plant("rdm", seed=0)
    with pytest.raises(AttributeError):
        plant.escs = list(plant.escs)
    with pytest.raises(TypeError):
        plant.escs[0] = Esc()  # type: ignore[index]


# ------------------------------------------------------------------------------- mocap
class _MocapRecorder:
    """Records what the mocap node hands the onboard node (its ``set_mocap`` signature)."""

    def __init__(self) -> None:
        self.calls: list = []

    def set_mocap(self, position, velocity, yaw=None) -> bool:
        self.calls.append((list(position), list(velocity), yaw))
        return True


def test_mocap_node_equals_the_array_formula():
    plant = _flying_plant(seed=6)
    rec = _MocapRecorder()
    node = MocapNode(plant, rec, period=0.01)  # type: ignore[arg-type]
    last = None
    for _ in range(60):
        plant.step(10)
        node.tick(plant.time)
        gt = plant.ground_truth()
        p = np.asarray(gt.cog_position, dtype=float)
        v = np.zeros(3) if last is None else (p - last) / 0.01
        last = p
        pos, vel, yaw = rec.calls[-1]
        assert same_bits(pos, p) and same_bits(vel, v)
        assert all(type(x) is float for x in pos + vel)
        assert same_bits(yaw, quaternion_yaw(gt.base_quaternion))
