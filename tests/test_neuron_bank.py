"""The Neuron bank (``rdm.nodes.neuron_bank``, the Rust firmware core) against the fact sheet:
bad frames counted by reason, enumeration and config replies decoded with cantools and the
Neuron->Spinal DBC (an independent reading) and with ``struct``, the watchdog, BOARD_CONFIG,
reboot, a slave-id change, colliding boards; random frame streams full of bad frames against
golden digests.
"""

from __future__ import annotations

import hashlib
import itertools
import random
import struct
from collections import Counter
from pathlib import Path

import can
import cantools
import pytest

from rdm.link.inproc_can import InProcessBus
from rdm.nodes.base import drain
from rdm.nodes.neuron_bank import NeuronBankNode, NeuronSpec
from rdm.nodes.servo_model import ServoConfig

DBC_DIR = Path(__file__).resolve().parents[1] / "firmware_protocol" / "neuron"
N2S = cantools.database.load_file(DBC_DIR / "neuron_neuron_to_spinal.dbc")
_channels = itertools.count()

SPECS = [
    NeuronSpec(1, (ServoConfig(dynamixel_id=3, p_gain=900),), imu=True),
    NeuronSpec(2, (), esc=True),
    NeuronSpec(
        3,
        (
            ServoConfig(initial_position=100, min_position=50, max_position=3000),
            ServoConfig(send_data_flag=False, profile_velocity=40),
            ServoConfig(time_constant=0.02, current_per_tick=7.5, temperature=300),
            ServoConfig(initial_position=4095, goal_current=-20),
        ),
        plant_driven=True,
    ),
    NeuronSpec(7, (ServoConfig(), ServoConfig(dynamixel_id=9)), esc=False, reboot_ms=30),
]


class Bank:
    """The boards as one bank on an in-process channel; a Spinal bus on it sends frames and
    collects the replies."""

    def __init__(self, specs: list[NeuronSpec]) -> None:
        n = next(_channels)
        self.spinal = InProcessBus(f"bank_{n}")
        self.bank = NeuronBankNode(InProcessBus(f"bank_{n}"), specs)

    def send(self, msg: can.Message) -> None:
        self.spinal.send(msg)

    def tick(self, now: float) -> list[tuple[int, bytes]]:
        self.bank.tick(now)
        return [(m.arbitration_id, bytes(m.data)) for m in drain(self.spinal)]

    def close(self) -> None:
        self.bank.close()
        self.spinal.shutdown()


def _view_state(v) -> dict:
    st = v.state()
    return {
        "slave_id": st["slave_id"],
        "flash_slave_id": st["flash_slave_id"],
        "imu_send_flag": st["imu_send_flag"],
        "esc": (v.esc.held_value, v.esc.stopped, v.esc.value),
        "changes": v.change_count,
        "connected": st["connected"],
        "rx": (st["rx_count"], st["rx_filtered"], st["rx_errors"], st["rx_kinds"], st["reboots"]),
        "tx": (v.tx_count, v.tx_errors),
        "servos": [
            (
                s["position"],
                s["velocity"],
                s["goal"],
                s["goal_current"],
                s["torque_enable"],
                s["send_goal_position"],
                s["homing_offset"],
                s["round_offset"],
                s["present_position"],
                s["current"],
                s["moving"],
                *(
                    s["config"][k]
                    for k in (
                        "p_gain",
                        "i_gain",
                        "d_gain",
                        "profile_velocity",
                        "current_limit",
                        "send_data_flag",
                        "external_encoder_flag",
                        "joint_resolution",
                        "servo_resolution",
                    )
                ),
            )
            for s in st["servos"]
        ],
    }


@pytest.fixture
def rig():
    t = Bank(SPECS)
    yield t
    t.close()


def std(can_id: int, data: bytes = b"", **kw) -> can.Message:
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False, **kw)


def words(values: list[int], flags: list[bool]) -> bytes:
    return b"".join(
        struct.pack("<H", (int(f) << 15) | (v & 0x7FFF)) for v, f in zip(values, flags, strict=True)
    )


def pwm(values: list[int]) -> bytes:
    word = 0
    for slot, v in enumerate(values):
        word |= v << (10 * (slot % 3) + 32 * (slot // 3))
    return word.to_bytes(8, "little")


# Payload lengths of the board-config sub-commands (1 + fields, fact sheet sec. 2.5).
BOARD_DLC = {0: 2, 1: 2, 2: 6, 3: 8, 4: 4, 5: 3, 6: 4, 7: 1, 8: 2, 9: 3, 10: 6, 11: 6, 12: 3}


def random_frame(rng: random.Random) -> can.Message:
    """Mostly plausible Spinal frames, a good share of them malformed."""
    slave = rng.choice([1, 2, 3, 7, 15, 15, rng.randrange(16)])
    r = rng.random()
    if r < 0.15:
        vals = [rng.randrange(1001) for _ in range(6)]
        data = bytearray(pwm(vals))
        if rng.random() < 0.2:
            data[3] |= rng.choice([0x40, 0x80])  # reserved bits 30-31
        if rng.random() < 0.1:
            data = data[: rng.randrange(9)]
        return std(rng.randrange(2) << 4 | 0xF, bytes(data))
    if r < 0.35:
        n = rng.choice([0, 1, 2, 4, rng.randrange(6)])
        data = words(
            [rng.randrange(-(1 << 14), 1 << 14) for _ in range(n)],
            [rng.random() < 0.6 for _ in range(n)],
        )
        if rng.random() < 0.1:
            data += bytes([rng.randrange(256)])
        return std(0x200 | rng.choice([0, 1]) << 4 | slave, data)
    if r < 0.45:
        # Direction mixes: enum / config requests and responses, servo states, IMU.
        can_id, dlc = rng.choice(
            [
                (0x700, 0),
                (0x710, 0),
                (0x710, 5),
                (0x730, 8),
                (0x740, 8),
                (0x220, 8),
                (0x230, 8),
                (0x100, 6),
                (0x120, 6),
                (0x130, 6),
                (0x200, 8),
                (0x750, 0),
            ]
        )
        data = bytes(
            rng.randrange(4) if rng.random() < 0.7 else rng.randrange(256)
            for _ in range(dlc + rng.choice([0, 0, 0, 1, -1]) if dlc else 0)
        )
        return std(can_id | slave, data)
    if r < 0.7:
        cmd = rng.choice([*range(13), rng.randrange(256)])
        dlc = BOARD_DLC.get(cmd, 8) if rng.random() < 0.8 else rng.randrange(9)
        body = [rng.choice([0, 1, rng.randrange(4), rng.randrange(256)]) for _ in range(dlc)]
        if cmd == 0 and dlc >= 2 and rng.random() < 0.5:
            body[1] = rng.choice([1, 2, 3, 7])  # slave-id changes that collide
        data = bytes([cmd & 0xFF, *body[1:]]) if dlc else b""
        return std(0x720 | slave, data)
    if r < 0.8:
        return std(rng.choice([0x70F, 0x710 | slave, 0x710 | slave]))
    if r < 0.9:
        return std(rng.randrange(0x800), bytes(rng.randrange(256) for _ in range(rng.randrange(9))))
    kind = rng.randrange(5)
    if kind == 0:
        return can.Message(arbitration_id=rng.randrange(1 << 29), data=b"\x01", is_extended_id=True)
    if kind == 1:
        return std(0x210 | slave, b"", is_remote_frame=True, dlc=2)
    if kind == 2:
        return std(0x0F, b"", is_error_frame=True)
    if kind == 3:
        return std(0x70F, bytes(12), is_fd=True)
    return std(0x1000 | slave, b"")  # an 11-bit frame whose id does not fit 11 bits


#: SHA-256 of every reply frame and every board's state after each step of the random
#: streams below (golden: the Python per-board mirror and the Rust bank gave these same bytes
#: when both existed; any change of the firmware's behaviour on these streams changes them).
RANDOM_STREAM_DIGESTS = {
    0: "065f82fbcba9c065c1264e68e7eed305ae45b4ac123bc19fda55234376a7be93",
    1: "70f6d0e71fccdd9f3b6e585806796700dd96bc1ff486a3b39dc24d44a424e20d",
    2: "5806b29a903c8e4a9dad8268621d063b03f55e7b89e4ffd3c989989526b13577",
    3: "d53d568b6c54b7bcef3b63feb8978fdf5a3a0f1a536887683a45c05ad5b3f9a5",
    4: "47a683059fde246ce3abc6f0a0cbb9f1061c31a98a6bc7f6cfc0647d12813c0b",
    5: "c55aa225cb33bc7304b9c649761ee1f5e58534e8e731d01aed09ddce49723488",
}


@pytest.mark.parametrize("seed", range(6))
def test_random_streams_keep_their_golden_replies(rig, seed):
    rng = random.Random(seed)
    now = 0.0
    sent = 0
    digest = hashlib.sha256()
    for _step in range(700):
        for _ in range(rng.choice([0, 1, 1, 2, 3, 6])):
            rig.send(random_frame(rng))
        if rng.random() < 0.05:
            # Plant feedback on the plant-driven board (slave 3, bank index 2).
            q = [rng.uniform(-40000, 40000) for _ in range(4)]
            rig.bank.boards[2].set_present_positions(q)
        if rng.random() < 0.03:
            g = [rng.uniform(-40, 40) for _ in range(3)]
            rig.bank.boards[0].set_imu(gyro=g, acc=g[::-1], mag=[v * 10 for v in g])
        now += 0.001 if rng.random() < 0.97 else rng.choice([0.0, 0.05, 0.15, 0.3])
        rs = rig.tick(now)
        sent += len(rs)
        digest.update(repr(rs).encode())
        digest.update(repr([_view_state(v) for v in rig.bank.boards]).encode())
    errors = sum((v.rx_errors for v in rig.bank.boards), start=Counter())
    # The stream must have exercised the paths it claims to.
    assert sent > 100
    for reason in ("dlc", "range", "unknown_id", "not_standard_id", "direction"):
        assert errors[reason] > 0, reason
    assert digest.hexdigest() == RANDOM_STREAM_DIGESTS[seed]


def test_bad_frames_are_counted_by_reason(rig):
    frames = [
        std(0x201, words([5], [True]) + b"\x00"),  # DLC 3: dlc
        std(0x00F, pwm([0] * 6)[:7]),  # PWM DLC 7: dlc
        std(0x00F, (1 << 31).to_bytes(8, "little")),  # reserved bit 31
        std(0x00F, pwm([1001, 0, 0, 0, 0, 0])),  # value above 1000: range
        can.Message(arbitration_id=0x201, data=b"\x00\x00", is_extended_id=True),
        std(0x201, b"", is_remote_frame=True, dlc=2),
        std(0x00F, b"", is_error_frame=True),
        std(0x70F, bytes(9), is_fd=True),
        std(0x721, bytes([2, 9, 0, 0, 0, 0])),  # homing offset for servo 9: range
        std(0x727, bytes([2, 1, 0, 0, 0, 0])),  # servo 1 of a 2-servo board: fine
        std(0x721, bytes([2, 1, 0, 0, 0, 0])),  # servo 1 of a 1-servo board: servo_index
        std(0x203, words([1, 2], [True, True])),  # 2 words for 4 servos: servo_count
        std(0x121, bytes(6)),  # an IMU sample sent to a Neuron: direction
        std(0x501, b""),  # device 5: unknown_id
    ]
    for f in frames:
        rig.send(f)
    rs = rig.tick(0.001)
    b1, b2, b3, b7 = (v.rx_errors for v in rig.bank.boards)
    # Independent expectation (fact sheet + the mirror's documented reasons).
    assert b1 == {
        "dlc": 2,
        "unknown_id": 1,
        "reserved_bits": 1,
        "range": 2,
        "not_standard_id": 1,
        "remote": 1,
        "error_frame": 1,
        "fd": 1,
        "servo_index": 1,
        "direction": 1,
    }
    assert b3["servo_count"] == 1 and b3["dlc"] == 1 and b7.get("servo_index") is None
    assert b2["fd"] == 1 and b2["not_standard_id"] == 1  # counted before the id filter
    assert rig.bank.boards[0].rx_filtered == 2  # 0x727 and 0x203 are not for slave 1
    # Reply of the accepted board config (0x727): INITIAL_CONFIG_0 + 2 x (1, 2, 3).
    assert [i for i, _ in rs] == [0x717, 0x727, 0x737, 0x747, 0x727, 0x737, 0x747]


def test_enumeration_and_config_replies_decode_with_the_dbc(rig):
    rig.send(std(0x70F))
    rig.send(std(0x713))
    rs = rig.tick(0.001)
    ids = [i for i, _ in rs]
    # Every board answers in bank order; board 3 handles both of its frames before board 7.
    assert ids == [0x701, 0x702, 0x703, 0x713, *[0x723, 0x733, 0x743] * 4, 0x707]
    decoded = [N2S.decode_message(i, d, decode_choices=False, scaling=False) for i, d in rs[3:16]]
    assert 4 in decoded[0].values()  # servo_num
    assert len(decoded) == 13
    # INITIAL_CONFIG_2 of servo 0 on board 3: index 0, position 100, flags send_data only.
    ic2 = next(d for i, d in rs if i == 0x733 and d[0] == 0)
    assert struct.unpack("<BhHHB", ic2) == (0, 100, 0, 1193, 1)
    ic3 = next(d for i, d in rs if i == 0x743 and d[0] == 3)
    assert struct.unpack("<BBhhh", ic3) == (3, 0, -20, 4096, 4096)


def test_watchdog_board_config_and_reboot(rig):
    t = 0.0

    def step(*frames: can.Message, dt: float = 0.001) -> list:
        nonlocal t
        for f in frames:
            rig.send(f)
        t += dt
        return rig.tick(t)

    step(std(0x00F, pwm([100, 200, 300, 0, 0, 0])))
    assert [v.esc.value for v in rig.bank.boards] == [100, 200, 300, 0]
    step(dt=0.100)  # exactly 100 ms since the last frame: still running
    assert rig.bank.boards[0].esc.value == 100
    step(dt=0.001)  # 101 ms: watchdog
    assert [v.esc.value for v in rig.bank.boards] == [0, 0, 0, 0]
    assert not rig.bank.boards[0].connected
    step(std(0x00F, pwm([100, 200, 300, 0, 0, 0])))
    assert rig.bank.boards[1].esc.value == 200
    # Torque on for board 7's servos, then goals with the handshake ack.
    step(std(0x217, words([0, 0], [True, True])))
    rs = step(std(0x207, words([1000, 1500], [False, True])))
    states = [d for i, d in rs if i in (0x207, 0x217)]
    assert [struct.unpack("<hBBhBx", d)[2] & 4 for d in states] == [4, 0]  # servo 0 pending
    assert rig.bank.boards[3].servo_goals() == [2048, 1500]
    # BOARD_CONFIG: PID gains of servo 1 on board 7, answered with the full config set.
    rs = step(std(0x727, bytes([3, 1, 0x10, 0x27, 5, 0, 6, 0])))
    ic1 = [struct.unpack("<BBHHH", d) for i, d in rs if i == 0x727]
    assert ic1[1] == (1, 9, 10000, 5, 6)
    # SET_SLAVE_ID 7 -> 8, then REBOOT: deaf for 30 ms, then answers as slave 8.
    step(std(0x727, bytes([0, 8])))
    step(std(0x727, bytes([7])))
    assert rig.bank.boards[3].state()["rebooting"]
    assert rig.bank.boards[3].servos[1].torque_enable is False
    for _ in range(29):
        step(std(0x70F))
    assert rig.bank.boards[3].slave_id == 7
    step()
    assert rig.bank.boards[3].slave_id == 8 and rig.bank.boards[3].reboots == 1
    rs = step(std(0x70F))
    assert 0x708 in [i for i, _ in rs]


def test_slave_id_collision_boards_hear_each_other(rig):
    """Board 2 renamed to 1 after a reboot: both answer slave-1 frames and each hears the
    other's replies as the shared bus delivers them."""
    t = 0.0
    for frames in ([std(0x722, bytes([0, 1]))], [std(0x722, bytes([7]))]):
        for f in frames:
            rig.send(f)
        t += 0.001
        rig.tick(t)
    for k in range(150):
        rig.send(std(0x201, words([k], [True])) if k % 2 else std(0x711))
        t += 0.001
        rig.tick(t)
    renamed = rig.bank.boards[1]
    assert renamed.slave_id == 1
    # Deaf for its 100 ms reboot, then 25 angle frames from Spinal, plus board 1's 8-byte
    # servo states (same id 0x201) read as angle frames, and its IMU samples rejected for
    # their direction.
    assert renamed.rx_kinds["servo_target_angle"] > 25 + 20
    assert renamed.rx_errors["direction"] > 0


def test_bank_rejects_bad_setup_with_named_errors():
    from rdm import _rdm

    with pytest.raises(_rdm.NeuronBankError, match="slave_id 2 given twice"):
        NeuronBankNode(InProcessBus("bank_bad"), [NeuronSpec(2), NeuronSpec(2)]).close()
    with pytest.raises(_rdm.NeuronBankError, match=r"boards\[0\].servos\[0\].p_gain"):
        NeuronBankNode(InProcessBus("bank_bad2"), [NeuronSpec(1, (ServoConfig(p_gain=70000),))])
    bank = NeuronBankNode(InProcessBus("bank_bad3"), [NeuronSpec(1, (ServoConfig(),))])
    with pytest.raises(_rdm.NeuronBankError, match="not finite"):
        bank.boards[0].set_present_positions([float("nan")])
    with pytest.raises(_rdm.NeuronBankError, match="now must be finite"):
        bank.tick(float("inf"))
    bank.close()
