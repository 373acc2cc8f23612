"""Neuron mirror against the fact sheet (sec. 2.2-2.6), over python-can ``virtual:`` buses.

A test bus plays Spinal: requests are built from raw bytes with ``struct`` (independent of
the codec under use), replies are decoded with cantools and the Neuron->Spinal DBC.
"""

from __future__ import annotations

import itertools
import math
import random
import struct
from pathlib import Path

import can
import cantools
import pytest

from rdm.link.can import open_can
from rdm.nodes.base import drain
from rdm.nodes.neuron_mirror import NeuronMirror
from rdm.nodes.servo_model import ServoConfig

DBC_DIR = Path(__file__).resolve().parents[1] / "firmware_protocol" / "neuron"
N2S = cantools.database.load_file(DBC_DIR / "neuron_neuron_to_spinal.dbc")
_channels = itertools.count()


@pytest.fixture
def bus_pair():
    """``make(n)`` returns n virtual buses on one fresh channel; all shut down afterwards."""
    opened: list[can.BusABC] = []
    channel = f"neuron_mirror_test_{next(_channels)}"

    def make(n: int = 1) -> list[can.BusABC]:
        buses = [open_can(f"virtual:{channel}") for _ in range(n)]
        opened.extend(buses)
        return buses

    yield make
    for b in opened:
        b.shutdown()


def tx(bus: can.BusABC, can_id: int, data: bytes = b"", **kw) -> None:
    bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False, **kw))


def replies(bus: can.BusABC) -> list[tuple[int, int, dict]]:
    """(id, dlc, cantools-decoded signals) of every frame pending on Spinal's bus."""
    out = []
    for msg in drain(bus):
        sig = N2S.decode_message(
            msg.arbitration_id,
            bytes(msg.data),
            decode_choices=False,
            scaling=False,
            allow_truncated=True,
        )
        out.append((msg.arbitration_id, msg.dlc, sig))
    return out


def pwm_payload(values: list[int]) -> bytes:
    """Sec. 2.4 byte formulas, written out: d0 = v0[7:0], d1 = v1[5:0]<<2 | v0[9:8], ..."""
    out = bytearray()
    for v0, v1, v2 in (values[0:3], values[3:6]):
        out += bytes(
            [v0 & 0xFF, ((v1 & 0x3F) << 2) | (v0 >> 8), ((v2 & 0xF) << 4) | (v1 >> 6), v2 >> 4]
        )
    return bytes(out)


def words(*pairs: tuple[int, bool]) -> bytes:
    """Servo words: bit 15 flag, bits 14..0 a 15-bit two's-complement value."""
    return b"".join(struct.pack("<H", (int(f) << 15) | (v & 0x7FFF)) for v, f in pairs)


SERVOS = [
    ServoConfig(dynamixel_id=7, p_gain=900, i_gain=3, d_gain=40, profile_velocity=0),
    ServoConfig(dynamixel_id=8, send_data_flag=False, current_limit=600, initial_position=1000),
    ServoConfig(dynamixel_id=9, external_encoder_flag=True, joint_resolution=3000),
]


def test_enumeration_answer_and_hardware_filter(bus_pair):
    spinal, b3, b5 = bus_pair(3)
    n3, n5 = NeuronMirror(b3, 3, SERVOS[:1]), NeuronMirror(b5, 5)
    tx(spinal, 0x70F)  # ENUM_REQUEST: device 7, message 0, broadcast slave 15, DLC 0
    n3.tick(0.0)
    n5.tick(0.0)
    got = replies(spinal)
    assert sorted((i, d) for i, d, _ in got) == [(0x703, 0), (0x705, 0)]
    # A request addressed to slave 5 is invisible to slave 3 (filter on the low 4 id bits).
    tx(spinal, 0x715)
    n3.tick(0.001)
    n5.tick(0.001)
    assert n3.rx_filtered >= 1 and n3.rx_errors.total() == 0
    assert [i for i, _, _ in replies(spinal)] == [0x715]  # INITIAL_CONFIG_0 of slave 5 only


def test_initial_config_reply_carries_the_servo_configuration(bus_pair):
    spinal, b = bus_pair(2)
    node = NeuronMirror(b, 4, SERVOS, imu=True, pulley_skip_thresh=321)
    tx(spinal, 0x714)  # INITIAL_CONFIG_REQUEST to slave 4, DLC 0
    node.tick(0.0)
    got = replies(spinal)
    assert got[0][:2] == (0x714, 5)
    c0 = got[0][2]
    assert (c0["ServoNum"], c0["ImuSendFlag"], c0["TtlRs485Mixed"], c0["PulleySkipThresh"]) == (
        3,
        1,
        0,
        321,
    )
    rest = got[1:]
    assert [i for i, _, _ in rest] == [0x724, 0x734, 0x744] * 3
    for k, cfg in enumerate(SERVOS):
        c1, c2, c3 = (sig for _, _, sig in rest[3 * k : 3 * k + 3])
        assert c1 == {
            "Index": k,
            "DynamixelId": cfg.dynamixel_id,
            "PGain": cfg.p_gain,
            "IGain": cfg.i_gain,
            "DGain": cfg.d_gain,
        }
        assert c2 == {
            "Index": k,
            "PresentPosition": cfg.initial_position,
            "ProfileVelocity": cfg.profile_velocity,
            "CurrentLimit": cfg.current_limit,
            "SendDataFlag": int(cfg.send_data_flag),
            "ExternalEncoderFlag": int(cfg.external_encoder_flag),
        }
        assert (c3["Index"], c3["JointResolution"], c3["ServoResolution"]) == (
            k,
            cfg.joint_resolution,
            cfg.servo_resolution,
        )


def _config(spinal, node, t):
    node.tick(t)
    got = replies(spinal)
    by = {}
    for i, _, sig in got:
        by.setdefault(i, []).append(sig)
    return by


def test_board_config_sub_commands_are_applied_and_answered(bus_pair):
    spinal, b = bus_pair(2)
    node = NeuronMirror(b, 2, SERVOS)
    cfg_id = 0x722  # BOARD_CONFIG_REQUEST: device 7, message 2, slave 2
    tx(spinal, cfg_id, struct.pack("<BBHHH", 3, 1, 1111, 22, 333))  # SET_SERVO_PID_GAIN idx 1
    by = _config(spinal, node, 0.0)
    assert by[0x722][1] == {"Index": 1, "DynamixelId": 8, "PGain": 1111, "IGain": 22, "DGain": 333}
    tx(spinal, cfg_id, struct.pack("<BBH", 4, 0, 250))  # SET_SERVO_PROFILE_VEL
    tx(spinal, cfg_id, struct.pack("<BBB", 5, 1, 1))  # SET_SEND_DATA_FLAG idx 1 on
    tx(spinal, cfg_id, struct.pack("<BBH", 6, 2, 777))  # SET_SERVO_CURRENT_LIMIT idx 2
    tx(spinal, cfg_id, struct.pack("<BB", 1, 1))  # SET_IMU_SEND_FLAG
    tx(spinal, cfg_id, struct.pack("<BH", 12, 999))  # SET_SERVO_PULLEY_SKIP_THRESH
    tx(spinal, cfg_id, struct.pack("<BB", 8, 1))  # SET_DYNAMIXEL_TTL_RS485_MIXED
    by = _config(spinal, node, 0.001)
    assert len(by[0x712]) == 6  # the full config set after every sub-command
    last2 = by[0x732][-3:]
    assert [s["ProfileVelocity"] for s in last2] == [250, 0, 0]
    assert [s["SendDataFlag"] for s in last2] == [1, 1, 1]
    assert [s["CurrentLimit"] for s in last2] == [1193, 600, 777]
    assert by[0x712][-1] == {
        "ServoNum": 3,
        "ImuSendFlag": 1,
        "TtlRs485Mixed": 1,
        "PulleySkipThresh": 999,
    }
    # Homing offset shifts the reading frame of the present position.
    tx(spinal, cfg_id, struct.pack("<BBi", 2, 0, -48))
    assert _config(spinal, node, 0.002)[0x732][0]["PresentPosition"] == 2048 - 48
    # Resolution ratio only while torque is off.
    tx(spinal, 0x212, words((0, True), (0, False), (0, False)))  # torque on for servo 0
    tx(spinal, cfg_id, struct.pack("<BBhh", 10, 0, 1234, 4321))
    tx(spinal, 0x212, words((0, False), (0, False), (0, False)))  # torque off
    tx(spinal, cfg_id, struct.pack("<BBhh", 10, 1, 1234, 4321))
    c3 = _config(spinal, node, 0.003)[0x742]
    assert (c3[0]["JointResolution"], c3[0]["ServoResolution"]) == (4096, 4096)  # refused
    assert (c3[4]["JointResolution"], c3[4]["ServoResolution"]) == (1234, 4321)  # accepted
    # A servo index the Neuron does not have: counted, ignored, no answer.
    tx(spinal, cfg_id, struct.pack("<BBH", 4, 3, 5))
    assert _config(spinal, node, 0.004) == {}
    assert node.rx_errors["servo_index"] == 1


def test_set_slave_id_takes_effect_after_reboot(bus_pair):
    spinal, b = bus_pair(2)
    node = NeuronMirror(b, 2, SERVOS[:1], reboot_ms=50)
    tx(spinal, 0x722, bytes([0, 9]))  # SET_SLAVE_ID 9 (flash write)
    assert 0x712 in _config(spinal, node, 0.0)  # answered under the old id
    tx(spinal, 0x722, bytes([7]))  # REBOOT: no answer
    node.tick(0.001)
    assert replies(spinal) == []
    tx(spinal, 0x70F)  # during the reset nothing is heard
    node.tick(0.02)
    assert replies(spinal) == []
    node.tick(0.051)
    tx(spinal, 0x70F)
    node.tick(0.052)
    assert [(i, d) for i, d, _ in replies(spinal)] == [(0x709, 0)]
    assert node.reboots == 1


def test_pwm_slot_per_slave_id_and_esc_flag(bus_pair):
    spinal, *buses = bus_pair(7)
    ids = [1, 6, 7, 12, 13]
    nodes = [NeuronMirror(b, s) for b, s in zip(buses, ids, strict=False)]
    no_esc = NeuronMirror(buses[5], 2, esc=False)
    v = [11, 222, 333, 444, 555, 1000, 70, 80, 90, 100, 110, 999]
    tx(spinal, 0x00F, pwm_payload(v[:6]))
    tx(spinal, 0x01F, pwm_payload(v[6:]))
    for n in [*nodes, no_esc]:
        n.tick(0.0)
    # Slave s <= 6 reads slot s of msg 0, 7..12 slot s-6 of msg 1, 13 and 14 nothing.
    assert [n.esc.value for n in nodes] == [11, 1000, 70, 999, 0]
    assert [n.esc.pulse_us for n in nodes] == [1011, 2000, 1070, 1999, 1000]
    assert nodes[0].esc.duty == pytest.approx(1011 / 2000)
    assert no_esc.esc.value == 0


def test_watchdog_stops_the_motor_after_100ms_without_frames(bus_pair):
    spinal, b, other = bus_pair(3)
    node = NeuronMirror(b, 1, SERVOS[:1])
    tx(spinal, 0x00F, pwm_payload([500, 0, 0, 0, 0, 0]))
    node.tick(1.000)
    assert node.esc.value == 500
    for ms in range(1001, 1101):
        if ms == 1050:
            tx(other, 0x702)  # a frame of slave 2: filtered by hardware, resets nothing
        node.tick(ms / 1000)
        assert node.esc.value == 500, ms
    node.tick(1.101)  # more than 100 ms since the last accepted frame
    assert node.esc.value == 0 and node.esc.pulse_us == 1000
    # Any accepted frame (here a servo-current word to this slave) re-arms it; the held
    # value comes back.
    tx(spinal, 0x211, words((0, False)))
    node.tick(1.102)
    assert node.esc.value == 500
    node.tick(1.202)
    assert node.esc.value == 500
    node.tick(1.203)
    assert node.esc.value == 0


def _states(spinal, node, t, angle_words):
    tx(spinal, 0x200 | node.slave_id, angle_words)
    node.tick(t)
    return replies(spinal)


def test_servo_angle_frame_triggers_states_then_imu(bus_pair):
    spinal, b = bus_pair(2)
    node = NeuronMirror(b, 3, SERVOS, imu=True)
    got = _states(spinal, node, 0.0, words((0, False), (0, False), (0, False)))
    # Servo 1 has no send_data_flag: states of servos 0 and 2, then gyro, acc, mag.
    assert [i for i, _, _ in got] == [0x203, 0x223, 0x103, 0x113, 0x123]
    assert got[1][2]["Angle"] == SERVOS[2].initial_position
    assert got[3][2] == {"AccX": 0, "AccY": 0, "AccZ": 4096}
    # A target-current frame does not trigger a report.
    tx(spinal, 0x213, words((0, False), (0, False), (0, False)))
    node.tick(0.001)
    assert replies(spinal) == []
    # Wrong word count for this Neuron: counted and ignored.
    got = _states(spinal, node, 0.002, words((0, False)))
    assert got == [] and node.rx_errors["servo_count"] == 1


def test_goal_handshake_and_first_order_motion(bus_pair):
    spinal, b = bus_pair(2)
    cfg = ServoConfig(
        initial_position=1000, time_constant=0.05, min_position=-100, max_position=4000
    )
    node = NeuronMirror(b, 1, [cfg])
    # Torque off: goals are ignored.
    _states(spinal, node, 0.000, words((3000, True)))
    assert node.servo_goals() == [1000]
    tx(spinal, 0x211, words((0, True)))  # torque on
    node.tick(0.001)
    # The Neuron now reports its goal (= present) with status bit 2 ...
    (state,) = [s for _, _, s in _states(spinal, node, 0.002, words((3000, False)))]
    assert state["GoalReported"] == 1 and state["Angle"] == 1000
    # ... and ignores goals until one carries the ack bit.
    assert node.servo_goals() == [1000]
    (state,) = [s for _, _, s in _states(spinal, node, 0.003, words((3000, True)))]
    assert state["GoalReported"] == 0
    assert node.servo_goals() == [3000]
    # First-order response: error(t) = error(0) * exp(-t / tau) for 1 ms steps.
    t0, p0 = 0.003, node.servos[0].position
    for k in range(1, 101):
        node.tick(t0 + k / 1000)
    expected = 3000 + (p0 - 3000) * math.exp(-0.100 / 0.05)
    assert node.servos[0].position == pytest.approx(expected, abs=1e-6)
    (state,) = [s for _, _, s in _states(spinal, node, t0 + 0.1001, words((3000, True)))]
    assert state["Angle"] == round(expected) and state["Moving"] == 1
    # Current report: position error times current_per_tick, within the limit.
    assert state["Current"] == min(cfg.current_limit, round((3000 - expected) * 2.0))
    # Joint limit: a goal above max_position is clamped to it.
    _states(spinal, node, t0 + 0.102, words((9000, True)))
    assert node.servo_goals() == [4000]
    # Negative 15-bit goals are sign-extended (bit 14 is the sign): -5, not 32763 (-> 4000).
    _states(spinal, node, t0 + 0.103, words((-5, True)))
    assert node.servo_goals() == [-5]


def test_profile_velocity_limits_the_speed(bus_pair):
    spinal, b = bus_pair(2)
    node = NeuronMirror(b, 1, [ServoConfig(initial_position=0, profile_velocity=10)])
    tx(spinal, 0x211, words((0, True)))
    node.tick(0.0)
    _states(spinal, node, 0.001, words((4000, True)))
    start = node.servos[0].position
    for k in range(2, 202):
        node.tick(k / 1000)
    speed = (node.servos[0].position - start) / 0.2
    assert speed == pytest.approx(10 * 0.229 / 60 * 4096, rel=1e-9)  # 0.229 rpm per unit


def test_imu_values_round_trip_through_spinal_scaling(bus_pair):
    spinal, b = bus_pair(2)
    node = NeuronMirror(b, 2, [ServoConfig()], imu=True)
    gyro, acc, mag = (0.5, -1.25, 2.0), (0.3, -9.0, 9.81), (20.0, -35.5, 41.0)
    node.set_imu(gyro=gyro, acc=acc, mag=mag)
    got = {i: s for i, _, s in _states(spinal, node, 0.0, words((0, False)))}
    g, a, m = got[0x102], got[0x112], got[0x122]
    kg, ka, km = 2000 / 32767 * math.pi / 180, 9.80665 / 4096, 4912 / 32760
    # Spinal: gyro/acc (x, y, z) = (-raw_y, raw_x, raw_z), mag = (-raw_x, raw_y, -raw_z).
    assert (-g["GyroY"] * kg, g["GyroX"] * kg, g["GyroZ"] * kg) == pytest.approx(gyro, abs=kg)
    assert (-a["AccY"] * ka, a["AccX"] * ka, a["AccZ"] * ka) == pytest.approx(acc, abs=ka)
    assert (-m["MagX"] * km, m["MagY"] * km, -m["MagZ"] * km) == pytest.approx(mag, abs=km)
    with pytest.raises(ValueError, match="gyro"):
        node.set_imu(gyro=(math.nan, 0, 0))


def test_plant_driven_servos_report_what_the_plant_sets(bus_pair):
    spinal, b = bus_pair(2)
    node = NeuronMirror(b, 1, [ServoConfig(), ServoConfig()], plant_driven=True)
    tx(spinal, 0x211, words((0, True), (0, True)))
    node.tick(0.0)
    _states(spinal, node, 0.001, words((2500, True), (1500, True)))
    assert node.servo_goals() == [2500, 1500]
    node.tick(0.5)  # no built-in motion in plant mode
    node.set_present_positions([2400.4, 1600.6])
    got = [s for _, _, s in _states(spinal, node, 0.501, words((2500, True), (1500, True)))]
    assert [s["Angle"] for s in got] == [2400, 1601]
    with pytest.raises(ValueError):
        node.set_present_positions([1.0])


def test_bad_and_unknown_frames_are_counted_never_fatal(bus_pair):
    spinal, b = bus_pair(2)
    node = NeuronMirror(b, 1, SERVOS[:2])
    tx(spinal, 0x70F, b"\x01")  # ENUM_REQUEST with DLC 1
    tx(spinal, 0x00F, b"\xff" * 8)  # PWM with reserved bits set
    tx(spinal, 0x101, b"\x00" * 6)  # an IMU frame (Neuron->Spinal direction) to slave 1
    tx(spinal, 0x601, b"")  # CANFD test device
    tx(spinal, 0x7F1, b"")  # initializer message 15
    tx(spinal, 0x721, b"\x63")  # unknown board-config sub-command
    spinal.send(can.Message(arbitration_id=0x1ABCDE01, data=b"", is_extended_id=True))
    spinal.send(can.Message(arbitration_id=0x70F, is_remote_frame=True, is_extended_id=False))
    rng = random.Random(7)
    for _ in range(400):
        tx(
            spinal,
            rng.choice([0x00F, 0x01F, 0x201, 0x211, 0x701, 0x711, 0x721, 0x70F]),
            bytes(rng.randrange(256) for _ in range(rng.randrange(9))),
        )
    node.tick(0.0)
    assert node.rx_errors["dlc"] >= 1 and node.rx_errors["reserved_bits"] >= 1
    assert node.rx_errors["direction"] >= 1 and node.rx_errors["unknown_id"] >= 2
    assert node.rx_errors["not_standard_id"] == 1 and node.rx_errors["remote"] == 1
    # Every frame is decoded (kinds) or refused by the decoder (errors); servo_count and
    # servo_index are errors found after decoding, so they appear in both.
    semantic = node.rx_errors["servo_count"] + node.rx_errors["servo_index"]
    assert sum(node.rx_kinds.values()) + node.rx_errors.total() - semantic == 408
    # Still alive and correct afterwards.
    replies(spinal)
    tx(spinal, 0x70F)
    node.tick(0.001)
    assert [i for i, _, _ in replies(spinal)] == [0x701]


def test_invalid_construction_is_refused(bus_pair):
    (b,) = bus_pair(1)
    with pytest.raises(ValueError, match="slave_id"):
        NeuronMirror(b, 15)
    with pytest.raises(ValueError, match="MAX_SERVO_NUM"):
        NeuronMirror(b, 1, [ServoConfig()] * 5)
    with pytest.raises(ValueError, match="initial_position"):
        ServoConfig(initial_position=5000)
