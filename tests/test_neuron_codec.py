"""Neuron codec: golden vectors, id layout, PWM slot rules, IMU scaling, strict rejection."""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from rdm.protocol import neuron as nr

VECTORS = json.loads(
    (Path(__file__).resolve().parents[1] / "firmware_protocol/neuron/vectors.json").read_text()
)["vectors"]


def _dir(text: str) -> nr.Direction:
    return nr.Direction(text)


@pytest.mark.parametrize("vector", VECTORS, ids=[v["name"] for v in VECTORS])
def test_golden_vector_decodes_to_meaning_and_reencodes(vector):
    can_id, data = int(vector["id"], 16), bytes.fromhex(vector["data"])
    frame = nr.decode_frame(can_id, data, _dir(vector["direction"]))
    assert vector["kind"] == frame.KIND
    assert frame.DIRECTION.value == vector["direction"]
    fields = frame.as_dict()
    assert fields.pop("kind") == vector["kind"]
    assert fields == vector["fields"]
    assert frame.can_id == can_id
    assert frame.encode() == data
    if "spinal_frame" in vector:
        assert frame.spinal_frame() == pytest.approx(vector["spinal_frame"], rel=1e-12)


def test_golden_vectors_cover_every_frame_type():
    kinds = {v["kind"] for v in VECTORS}
    expected = {
        "pwm",
        "imu",
        "servo_target_angle",
        "servo_target_current",
        "servo_state",
        "enum_request",
        "enum_response",
        "initial_config_request",
    }
    expected |= {f"initial_config_{i}" for i in range(4)}
    expected |= {c.KIND for c in nr.BOARD_CONFIG_CLASSES.values()}
    assert kinds == expected
    assert len(nr.BOARD_CONFIG_CLASSES) == 13


def test_id_layout():
    assert nr.make_id(7, 2, 5) == 0x725
    assert nr.CanId.split(0x725) == nr.CanId(7, 2, 5)
    assert nr.PwmFrame(1, (0,) * 6).can_id == 0x01F
    assert nr.EnumRequest().can_id == 0x70F
    assert nr.ServoState(9, 3, 0, 0, False, False, False, 0, 0).can_id == 0x239
    assert nr.ImuFrame(2, nr.ImuMessage.MAG, 0, 0, 0).can_id == 0x122
    with pytest.raises(nr.NeuronFrameError, match="not an 11-bit"):
        nr.CanId.split(0x800)
    with pytest.raises(nr.NeuronFrameError, match="device"):
        nr.make_id(8, 0, 0)


def _reference_pwm_bytes(values):
    """Fact sheet sec. 2.4 byte formulas, written out independently of the codec."""
    out = []
    for a, b, c in (values[0:3], values[3:6]):
        out += [a & 0xFF, ((b & 0x3F) << 2) | (a >> 8), ((c & 0xF) << 4) | (b >> 6), c >> 4]
    return bytes(out)


@settings(max_examples=500, deadline=None)
@given(st.lists(st.integers(0, 1000), min_size=1, max_size=12))
def test_pwm_pack_slot_rules(values):
    frames = nr.pack_pwm(values)
    assert len(frames) == (1 if len(values) <= 6 else 2)
    padded = values + [0] * (12 - len(values))
    for frame in frames:
        part = padded[6 * frame.frame_index : 6 * frame.frame_index + 6]
        assert frame.encode() == _reference_pwm_bytes(part)
        assert frame.can_id == (frame.frame_index << 4) | 15
    # Each Neuron s reads exactly value s-1 from the frame carrying it.
    for slave in range(1, 15):
        got = [nr.pwm_for_slave(f, slave) for f in frames]
        got = [g for g in got if g is not None]
        if slave <= len(values):
            assert got == [values[slave - 1]]
        elif slave > 12 or (slave > 6 and len(frames) == 1):
            assert got == []
        else:
            assert got == [0]  # unused slot = Neuron stop value


def test_pwm_duty_conversion_is_c_truncation():
    assert nr.duty_to_pwm_value(0.5) == 0
    assert nr.duty_to_pwm_value(1.0) == 1000
    assert nr.duty_to_pwm_value(0.59) == int(0.59 * 2000 - 1000)  # 179 (truncated), 1180 us
    assert nr.PwmFrame(0, (0, 1000, 1, 2, 3, 4)).pulse_us()[:2] == (1000, 2000)
    for bad in (0.49, 1.01, math.nan, math.inf):
        with pytest.raises(nr.NeuronFrameError, match="duty"):
            nr.duty_to_pwm_value(bad)


def test_pwm_rejects_out_of_range_and_reserved_bits():
    with pytest.raises(nr.NeuronFrameError, match=r"values\[2\]=1001"):
        nr.PwmFrame(0, (0, 0, 1001, 0, 0, 0))
    with pytest.raises(nr.NeuronFrameError, match="motor count 13"):
        nr.pack_pwm([0] * 13)
    with pytest.raises(nr.NeuronFrameError, match="reserved_bits"):
        nr.decode_frame(0x00F, bytes([0, 0, 0, 0x40, 0, 0, 0, 0]))
    # 10-bit value 1023 is representable but not a Spinal value (0..1000)
    with pytest.raises(nr.NeuronFrameError, match="range"):
        nr.decode_frame(0x00F, _reference_pwm_bytes([1023, 0, 0, 0, 0, 0]))


def test_imu_scaling_and_remap_fact_sheet_numbers():
    # Full-scale gyro raw 32767 on sensor y -> -2000 dps about Spinal x.
    g = nr.ImuFrame(1, nr.ImuMessage.GYRO, 0, 32767, 0).spinal_frame()
    assert g == pytest.approx((-math.radians(2000.0), 0.0, 0.0), rel=1e-12)
    # 4096 LSB = 1 g on sensor x -> Spinal y.
    a = nr.ImuFrame(1, nr.ImuMessage.ACC, 4096, 0, -8192).spinal_frame()
    assert a == pytest.approx((0.0, 9.80665, -2 * 9.80665), rel=1e-12)
    # Mag: 32760 LSB = 4912 uT; x and z flip sign, y stays.
    m = nr.ImuFrame(1, nr.ImuMessage.MAG, 32760, -32760, 32760).spinal_frame()
    assert m == pytest.approx((-4912.0, -4912.0, -4912.0), rel=1e-12)


def test_servo_words_sign_extension_and_flags():
    data = struct.pack("<2H", 0x8000 | 0x4000, 0x3FFF)  # ack + -16384, no flag + 16383
    f = nr.decode_frame(0x203, data, nr.Direction.SPINAL_TO_NEURON)
    assert f == nr.ServoTargetAngles(3, (-16384, 16383), (True, False))
    with pytest.raises(nr.NeuronFrameError, match="16384"):
        nr.ServoTargetCurrents(3, (16384,), (True,))
    with pytest.raises(nr.NeuronFrameError, match="dlc"):
        nr.decode_frame(0x213, b"\x00\x00\x00", nr.Direction.SPINAL_TO_NEURON)


@pytest.mark.parametrize(
    ("can_id", "data", "reason"),
    [
        (0x105, b"\x00" * 5, "dlc"),  # IMU must be 6 bytes
        (0x10F, b"\x00" * 6, "unknown_id"),  # IMU from the broadcast id
        (0x135, b"\x00" * 6, "unknown_id"),  # IMU message 3 does not exist
        (0x245, b"\x00" * 8, "unknown_id"),  # servo message 4
        (0x305, b"", "unknown_id"),  # device 3
        (0x600, b"", "unknown_id"),  # CANFD test device is not Neuron traffic
        (0x003, b"\x00" * 8, "unknown_id"),  # PWM must be broadcast
        (0x00F, b"\x00" * 7, "dlc"),
        (0x715, b"\x00" * 3, "dlc"),  # config 0 is 0 or 5 bytes
        (0x725, bytes([13]) + b"\x00" * 2, "range"),  # unknown board-config sub-command
        (0x725, bytes([3, 0, 0]), "dlc"),  # PID gain needs 8 bytes
        (0x735, bytes([0, 0, 0, 0, 0, 0, 0, 4]), "reserved_bits"),
        (0x745, bytes([4]) + b"\x00" * 7, "range"),  # servo index 4
        (0x715, bytes([5, 0, 0, 0, 0]), "range"),  # servo_num 5 > MAX_SERVO_NUM
        (0x715, bytes([1, 2, 0, 0, 0]), "range"),  # flag byte 2
        (0x225, bytes([0, 0, 0, 0x08, 0, 0, 0, 0]), "reserved_bits"),
        (0x705, b"\x00", "dlc"),
        (0x7FF, b"", "unknown_id"),
    ],
)
def test_bad_frames_rejected_with_reason_and_counted(can_id, data, reason):
    with pytest.raises(nr.NeuronFrameError) as info:
        nr.decode_frame(can_id, data)
    assert info.value.reason == reason
    assert isinstance(info.value, ValueError)
    dec = nr.NeuronDecoder()
    res = dec.feed(can_id, data)
    assert not res.ok and res.error is not None
    assert dec.errors[reason] == 1 and sum(dec.counts.values()) == 0


def test_dlc_over_8_extended_and_remote_rejected():
    dec = nr.NeuronDecoder()
    assert not dec.feed(0x00F, bytes(12)).ok
    assert not dec.feed(0x00F, bytes(8), extended=True).ok
    assert not dec.feed(0x00F, b"", remote=True).ok
    assert dec.errors == {"dlc": 1, "not_standard_id": 1, "remote": 1}


def test_direction_resolves_shared_ids():
    pid = nr.SetServoPidGain(4, 1, 1, 2, 3)
    data = pid.encode()  # byte 0 = 3 also reads as INITIAL_CONFIG_1 for servo index 3
    kinds = {f.KIND for f in nr.decode_candidates(pid.can_id, data)}
    assert kinds == {"initial_config_1", "board_config_set_servo_pid_gain"}
    with pytest.raises(nr.NeuronFrameError, match="ambiguous"):
        nr.decode_frame(pid.can_id, data)
    assert nr.decode_frame(pid.can_id, data, nr.Direction.SPINAL_TO_NEURON) == pid
    with pytest.raises(nr.NeuronFrameError) as info:
        nr.decode_frame(0x714, bytes(5), nr.Direction.SPINAL_TO_NEURON)
    assert info.value.reason in ("dlc", "direction")


def test_decoder_uses_learned_servo_count():
    dec = nr.NeuronDecoder()
    state = nr.ServoState(2, 0, 10, 30, False, False, False, 0, 0)
    first = dec.feed(state.can_id, state.encode())
    assert first.ok and first.alternatives  # 4 target words or servo 0 state: unknown yet
    dec.feed(0x712, nr.InitialConfig0(2, 2, False, False, 0).encode())
    second = dec.feed(state.can_id, state.encode())
    assert second.frame == state and second.alternatives == ()
    assert dec.counts["servo_state"] == 2 and dec.ambiguous == 1


def test_initialization_sequence():
    seq = nr.initialization_sequence([3, 1, 2])
    assert [(f.can_id, f.encode()) for f in seq] == [
        (0x70F, b""),
        (0x711, b""),
        (0x712, b""),
        (0x713, b""),
    ]


@settings(max_examples=5000, deadline=None)
@given(st.integers(-5, 0x900), st.binary(max_size=12), st.booleans(), st.booleans())
# a servo state with a non-zero padding byte (found by this test): decoded, padding dropped
@example(0x201, b"\x00" * 7 + b"\x01", False, False)
def test_fuzz_random_frames_never_crash(can_id, data, extended, remote):
    dec = nr.NeuronDecoder()
    res = dec.feed(can_id, data, extended=extended, remote=remote)
    assert res.ok == (res.error is None)
    if res.ok:
        # everything accepted re-encodes to the exact bytes, except a servo state's byte 7
        # (struct padding of the firmware's message: ignored on decode, written 0)
        expected = data[:7] + b"\x00" if isinstance(res.frame, nr.ServoState) else data
        assert res.frame.can_id == can_id and res.frame.encode() == expected
        assert dec.counts[res.frame.KIND] == 1
    else:
        assert isinstance(res.error, nr.NeuronFrameError)
        assert dec.total_errors == 1


def test_initial_config_reply_order_and_checks():
    c0 = nr.InitialConfig0(5, 2, False, True, 100)
    servos = [
        (
            nr.InitialConfig1(5, i, 10 + i, 1, 2, 3),
            nr.InitialConfig2(5, i, 0, 1, 2, True, False),
            nr.InitialConfig3(5, i, 0, 0, 1, 1),
        )
        for i in range(2)
    ]
    frames = nr.initial_config_reply(c0, servos)
    assert [f.can_id for f in frames] == [0x715, 0x725, 0x735, 0x745, 0x725, 0x735, 0x745]
    # Spinal's side decodes the whole reply unambiguously once CONFIG_0 is known
    dec = nr.NeuronDecoder(direction=nr.Direction.NEURON_TO_SPINAL)
    assert [dec.feed(f.can_id, f.encode()).frame for f in frames] == frames
    with pytest.raises(nr.NeuronFrameError, match="servo_num=2 but 1"):
        nr.initial_config_reply(c0, servos[:1])
    with pytest.raises(nr.NeuronFrameError, match="index 0"):
        nr.initial_config_reply(c0, servos[::-1])
