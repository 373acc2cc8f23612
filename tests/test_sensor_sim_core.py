"""The Rust sensor paths (noise cores, Leptrino frame) against independent references.

``rdm._rdm.WrenchNoiseCore`` / ``ImuNoiseCore`` (behind ``WrenchSensorModel.sample_list`` and
``ImuModel.sample_lists``) against an independent numpy array form (``np.clip``, ``np.round``),
bit for bit (signed zeros, NaN, inf, saturation, ties of the rounding);
the Leptrino node's sample frames (its ``rdm._rdm.LeptrinoStreamCore``) through
``rdm.protocol.leptrino``'s stream parser and response decoder against the counts' rule
written out.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rdm.nodes.leptrino_sensor import LeptrinoSensorNode
from rdm.plant.description import WrenchSensorSpec
from rdm.plant.sensors import (
    ACCEL_LSB,
    ACCEL_RANGE,
    GYRO_LSB,
    GYRO_RANGE,
    MAG_LSB,
    ImuModel,
    ImuNoise,
    WrenchNoise,
    WrenchSensorModel,
)
from rdm.protocol import leptrino as lp

SPECIALS = [0.0, -0.0, math.nan, math.inf, -math.inf, 1e300, -1e300, 5e-324]


def _same(x, y) -> bool:
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    return np.array_equal(x, y, equal_nan=True) and np.array_equal(np.signbit(x), np.signbit(y))


def _spec(rated: float) -> WrenchSensorSpec:
    # lsb = rated / 10000 = 2**-10: ties (k + 0.5) * lsb are exact, so ties-to-even is tested.
    return WrenchSensorSpec("test", "foot", "test", (rated,) * 3, (rated / 2,) * 3)


def _wrench_inputs(gen: np.random.Generator, rated: np.ndarray, n: int):
    lsb = rated / 10000.0
    for i in range(n):
        kind = i % 4
        if kind == 0:  # ordinary
            yield (gen.normal(0.0, 0.3, 6) * rated).tolist()
        elif kind == 1:  # exact ties of v / lsb (noise 0 below), -0.0 rounding
            yield ((gen.integers(-50, 50, 6) + 0.5) * lsb).tolist()
        elif kind == 2:  # at, just beyond and far beyond the rated capacity
            yield (rated * gen.choice([1.0, -1.0, 1.0000001, -3.0, 0.99999], 6)).tolist()
        else:
            yield gen.choice(SPECIALS, 6).tolist()


@pytest.mark.parametrize("quantize", [True, False])
@pytest.mark.parametrize("frac", [0.003, 0.0])
def test_wrench_core_equals_numpy_array_form(quantize, frac):
    spec = _spec(10000.0 * 2.0**-10)
    noise = WrenchNoise(frac, bias=(0.0, 0.001, -0.002, 0.0, 0.0, 1e-4), quantize=quantize)
    model = WrenchSensorModel(spec, noise, np.random.default_rng(4))
    ref_rng = np.random.default_rng(4)
    rated = np.array([*spec.force_range, *spec.torque_range])
    gen = np.random.default_rng(9)
    for ideal in _wrench_inputs(gen, rated, 2000):
        r = model.sample_list(ideal)
        # numpy array form, written here from the model's definition
        with np.errstate(invalid="ignore", over="ignore"):
            v = np.array(ideal) + np.array(noise.bias) + frac * rated * ref_rng.normal(0, 1, 6)
            sat = np.abs(v) >= rated
            v = np.clip(v, -rated, rated)
            if quantize:
                v = np.where(np.isfinite(v), np.round(v / (rated / 10000.0)) * (rated / 10000.0), v)
        got = np.concatenate([r.force, r.torque])
        assert _same(got, v), (ideal, got, v)
        assert np.array_equal(r.saturated, sat)
        assert r.saturated.dtype == np.bool_


def test_wrench_ties_round_to_even_and_zero_keeps_its_sign():
    spec = _spec(10000.0 * 2.0**-10)
    m = WrenchSensorModel(spec, WrenchNoise(0.0), np.random.default_rng(0))
    lsb, tlsb = 2.0**-10, 2.0**-11  # torque range = force range / 2
    r = m.sample_list([0.5 * lsb, 1.5 * lsb, 2.5 * lsb, -0.5 * tlsb, -2.5 * tlsb, -0.1 * tlsb])
    assert r.force.tolist() == [0.0, 2 * lsb, 2 * lsb]
    assert r.torque.tolist() == [0.0, -2 * tlsb, 0.0]
    assert math.copysign(1.0, r.torque[0]) == -1.0 and math.copysign(1.0, r.torque[2]) == -1.0
    assert math.copysign(1.0, r.force[0]) == 1.0


def test_wrench_noise_and_bias_changes_take_effect():
    spec = _spec(10.0)
    m = WrenchSensorModel(spec, WrenchNoise(0.0), np.random.default_rng(0))
    m.noise = WrenchNoise(0.0, bias=(1.0, 0.0, 0.0, 0.0, 0.0, 0.0), quantize=False)
    assert m.sample_list([0.25] * 6).force.tolist() == [1.25, 0.25, 0.25]
    with pytest.raises(ValueError):
        m.rated[0] = 1.0  # read-only: the core holds a copy


def _imu_inputs(gen: np.random.Generator, n: int):
    for i in range(n):
        kind = i % 4
        if kind == 0:
            yield [
                gen.normal(0, 2, 3).tolist(),
                gen.normal(0, 20, 3).tolist(),
                gen.normal(0, 50, 3).tolist(),
            ]
        elif kind == 1:  # ties of the quantisers
            yield [
                ((gen.integers(-9, 9, 3) + 0.5) * GYRO_LSB).tolist(),
                ((gen.integers(-9, 9, 3) + 0.5) * ACCEL_LSB).tolist(),
                ((gen.integers(-9, 9, 3) + 0.5) * MAG_LSB).tolist(),
            ]
        elif kind == 2:  # saturation of gyro / accel
            yield [
                (GYRO_RANGE * gen.choice([1.0, -1.0, 1.1, 0.999], 3)).tolist(),
                (ACCEL_RANGE * gen.choice([1.0, -1.0, 1.1, 0.999], 3)).tolist(),
                [1e6, -1e6, 0.0],
            ]
        else:
            yield [gen.choice(SPECIALS[:6], 3).tolist() for _ in range(3)]


@pytest.mark.parametrize("quantize", [True, False])
@pytest.mark.parametrize("zero_noise", [True, False])
def test_imu_core_equals_numpy_array_form(quantize, zero_noise):
    kw = {"gyro_std": 0.0, "accel_std": 0.0, "mag_std": 0.0} if zero_noise else {}
    noise = ImuNoise(quantize=quantize, **kw)
    model = ImuModel(noise, np.random.default_rng(6))
    ref = np.random.default_rng(6)
    gb, ab, mb = (ref.normal(0.0, s, 3) for s in (0.5 * math.pi / 180, 0.05, 1.0))
    assert _same(gb, model.gyro_bias) and _same(mb, model.mag_bias)
    gen = np.random.default_rng(2)
    for gyro, acc, mag in _imu_inputs(gen, 2000):
        r = model.sample_lists(gyro, acc, mag)
        w = ref.normal(0.0, 1.0, 9)
        with np.errstate(invalid="ignore", over="ignore"):
            g = np.array(gyro) + gb + noise.gyro_std * w[0:3]
            a = np.array(acc) + ab + noise.accel_std * w[3:6]
            m = np.array(mag) + mb + noise.mag_std * w[6:9]
            sat = bool(np.any(np.abs(g) > GYRO_RANGE) or np.any(np.abs(a) > ACCEL_RANGE))
            g = np.clip(g, -GYRO_RANGE, GYRO_RANGE)
            a = np.clip(a, -ACCEL_RANGE, ACCEL_RANGE)
            if quantize:
                g, a, m = (
                    np.where(np.isfinite(x), np.round(x / lsb) * lsb, x)
                    for x, lsb in ((g, GYRO_LSB), (a, ACCEL_LSB), (m, MAG_LSB))
                )
        for got, want in ((r.gyro, g), (r.accel, a), (r.mag, m)):
            assert _same(got, want), (got, want)
        assert r.saturated is sat


def test_imu_bias_assignment_reaches_the_core_and_in_place_change_is_refused():
    m = ImuModel(
        ImuNoise(gyro_std=0.0, accel_std=0.0, mag_std=0.0, quantize=False), np.random.default_rng(1)
    )
    mine = np.array([0.5, 0.25, 0.0])
    m.gyro_bias = mine
    assert mine.flags.writeable  # the model keeps its own read-only copy
    m.accel_bias = (0.0, 0.0, 0.0)
    m.mag_bias = (1.0, 1.0, 1.0)
    r = m.sample_lists([1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [3.0, 3.0, 3.0])
    assert r.gyro.tolist() == [1.5, 1.25, 1.0]
    assert r.accel.tolist() == [2.0, 2.0, 2.0] and r.mag.tolist() == [4.0, 4.0, 4.0]
    with pytest.raises(ValueError):
        m.gyro_bias[0] = 0.0
    m.noise = ImuNoise(gyro_std=0.0, accel_std=0.0, mag_std=0.0, quantize=True)
    r = m.sample_lists([0.0] * 3, [0.0] * 3, [0.0] * 3)
    assert r.mag.tolist() == [round(1.0 / MAG_LSB) * MAG_LSB] * 3


# ------------------------------------------------------------------------ Leptrino frames


def _counts(wrench, rated) -> tuple[int, ...] | None:
    """The raw counts of the sensor's manual, round(value * 10000 / rated) (ties to even),
    or None when a value is not finite or a count leaves int16."""
    if not all(math.isfinite(w) for w in wrench):
        return None
    raw = tuple(round(w * 10000 / r) for w, r in zip(wrench, rated, strict=True))
    return raw if all(-0x8000 <= c <= 0x7FFF for c in raw) else None


def _decoded(frame: bytes) -> lp.ForceData:
    """One frame through the PC side's stream parser and response decoder."""
    (event,) = lp.LeptrinoStreamParser().feed(frame)
    assert event.error is None
    sample = lp.parse_response(event.payload)
    assert isinstance(sample, lp.ForceData)
    return sample


def test_leptrino_frames_decode_to_the_rated_counts():
    """The node's sample frame of a wrench, decoded by the PC side, holds round(w * 10000 /
    rated) per axis (ties to even), with DLE bytes stuffed; at the int16 limits a wrench
    beyond them is clipped to them (counted). Catches a truncating or half-up rounding, a
    swapped axis, a missing DLE stuffing and a clip at the rated value."""
    gen = np.random.default_rng(3)
    unit = lp.SensorModel("unit", (10000.0,) * 6)  # raw = round(w): exact ties below
    ties = [k + 0.5 for k in range(-6, 6)]
    unit_cases = [ties[i : i + 6] for i in range(0, 7)]
    unit_cases += [[16.0, 16.0 * 257, -16.0, 4112.0, 0.0, -0.0]]  # DLE bytes: stuffing
    unit_cases += [[32767.0, -32767.0, 32766.6, -32766.6, 0.0, 0.0]]  # int16 limits
    seen_dle = 0
    for model in (unit, lp.MODELS["CFS034CA301U"]):
        node = LeptrinoSensorNode(_Uart(), model)
        rated = list(model.rated)
        cases = [(gen.normal(0, 0.5, 6) * np.array(rated)).tolist() for _ in range(750)]
        for w in cases + (unit_cases if model is unit else []):
            node.set_wrench(w[:3], w[3:])
            frame = node._stream.sample_frame()
            sample = _decoded(frame)
            assert sample.raw == _counts(w, rated), w
            assert (sample.temperature, sample.status, sample.term_no, sample.result) == (
                250,
                0,
                0,
                0,
            )
            seen_dle += b"\x10\x10" in frame
        assert node.saturated_samples == 0
    assert seen_dle
    node = LeptrinoSensorNode(_Uart(), unit)
    node.set_wrench([32767.4, -32768.4, 1e9], [-1e9, 0.0, 0.0])  # beyond int16: clipped
    assert _decoded(node._stream.sample_frame()).raw == (32767, -32767, 32767, -32767, 0, 0)
    assert node.saturated_samples == 1
    node.set_wrench([1.0] * 3, [1.0] * 3)
    for temp, term in ((-32768, 0), (32767, 254), (-1, 16)):
        node.temperature, node.sensor_no = temp, term
        sample = _decoded(node._stream.sample_frame())
        assert (sample.raw, sample.temperature, sample.term_no) == ((1,) * 6, temp, term)


class _Uart:
    def __init__(self) -> None:
        self.out = bytearray()
        self.inbox = b""

    def read_available(self) -> bytes:
        data, self.inbox = self.inbox, b""
        return data

    def write(self, data: bytes) -> int:
        self.out += data
        return len(data)

    def close(self) -> None:
        pass


def test_leptrino_node_stream_decodes_to_the_wrench_in_rated_counts():
    # Oracle: the PC side's parser and response decoder, and the counts' rule written out
    # (round(value * 10000 / rated), the sensor's manual).
    gen = np.random.default_rng(8)
    uart = _Uart()
    node = LeptrinoSensorNode(uart, "CFS034CA301U")
    node.streaming = True
    rated = np.array(node.model.rated)
    for k in range(600):
        if k % 2 == 0:  # the bridge's 500 Hz against the node's 1 kHz
            w = gen.normal(0, 0.4, 6) * rated * (3.5 if k % 10 == 0 else 1.0)
            if k % 50 == 0:
                w[1] = math.nan  # refused: the previous wrench stays
            node.set_wrench(w[:3], w[3:])
        if k == 300:
            node.temperature = -12  # a new temperature re-encodes
        if k == 400:
            node.sensor_no = 3
        uart.out.clear()
        node.tick(k * 0.001)
        (event,) = lp.LeptrinoStreamParser().feed(bytes(uart.out))
        sample = lp.parse_response(event.payload)
        assert isinstance(sample, lp.ForceData)
        counts = tuple(round(v * 10000 / r) for v, r in zip(node.wrench, rated, strict=True))
        assert sample.raw == counts
        assert sample.temperature == node.temperature and sample.term_no == node.sensor_no
        assert sample.status == 0 and sample.result == 0
    assert node.saturated_samples > 0 and node.errors["bad_wrench"] > 0


def test_leptrino_node_refuses_a_temperature_outside_int16():
    node = LeptrinoSensorNode(_Uart(), "CFS034CA301U")
    node.set_wrench([1.0, 2.0, 3.0], [0.1, 0.2, 0.3])
    frame = node._stream.sample_frame()
    with pytest.raises(ValueError, match=r"temperature 25\.0 must be an int"):
        node.temperature = 25.0  # a float
    with pytest.raises(ValueError, match=r"temperature 40000 must be an int in -32768\.\.32767"):
        node.temperature = 40000
    with pytest.raises(ValueError, match=r"sensor_no 255 must be an int in 0\.\.254"):
        node.sensor_no = 255
    with pytest.raises(ValueError, match="temperature"):
        LeptrinoSensorNode(_Uart(), "CFS034CA301U", temperature=-32769)
    # the refused values left the stream as it was
    assert node.temperature == 250 and node._stream.sample_frame() == frame
