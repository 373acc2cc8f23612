"""The Rust CAN master (``RustCanMaster``) against the Python ``CanMaster`` (the independent
reference): the same scripted Neuron traffic and commands, on separate buses, must give the
same sent frames (id and bytes, per millisecond) and the same state and counters after every
tick; the full hover stack writes the same logs with either master."""

from __future__ import annotations

import hashlib
import itertools
import random
from pathlib import Path

import can
import pytest
from hover_run_files import hover_run_files

from rdm import _rdm
from rdm.link.can import open_can
from rdm.link.inproc_can import InProcessBus
from rdm.nodes.base import drain
from rdm.nodes.can_master import CanMaster, MasterState
from rdm.nodes.can_master_rust import SERVO_FIELDS, RustCanMaster
from rdm.protocol import neuron as nr

_channels = itertools.count()
SLAVES = (1, 2, 3)


def _state(m) -> dict:
    """Everything observable of a master (same attribute interface for both)."""
    return {
        "state": m.state,
        "motor_number": m.motor_number,
        "uav_model": m.uav_model,
        "rx_count": m.rx_count,
        "rx_errors": list(m.rx_errors.items()),  # insertion order shows in the status log
        "rx_kinds": list(m.rx_kinds.items()),
        "tx": (m.tx_count, m.tx_errors),
        "connected": m.connected,
        "slaves": m.slaves,
        "neurons": [
            (
                n.slave,
                n.servo_num,
                n.imu_send_flag,
                n.ttl_rs485_mixed,
                n.pulley_skip_thresh,
                n.configured,
                len(n.servos),
            )
            for n in m.neurons
        ],
        "servos": {
            k: tuple(getattr(e, f) for f in SERVO_FIELDS) for k, e in m.servo_states.items()
        },
        "imu": m.imu,
        "events": [(e.stamp_ms, e.level, e.text) for e in m.events],
    }


class Pair:
    """A Python and a Rust master, each alone on its own channel with a driver bus."""

    def __init__(self, kind: str = "inproc", boot_delay_ms: int = 20) -> None:
        self.buses: list[can.BusABC] = []
        self.masters = []
        self.drivers = []
        for cls in (CanMaster, RustCanMaster):
            ch = f"canwire_test_{next(_channels)}"
            spec = f"{kind}:{ch}"
            self.masters.append(cls(self._open(spec), boot_delay_ms=boot_delay_ms))
            self.drivers.append(self._open(spec))
        self.py, self.rs = self.masters

    def _open(self, spec: str) -> can.BusABC:
        bus = open_can(spec)
        self.buses.append(bus)
        return bus

    def inject(self, messages: list[can.Message]) -> None:
        for drv in self.drivers:
            for m in messages:
                drv.send(m)

    def tick(self, t: int) -> list[tuple[int, bytes]]:
        sent = []
        for m, drv in zip(self.masters, self.drivers, strict=True):
            m.tick_ms(t)
            sent.append([(x.arbitration_id, bytes(x.data)) for x in drain(drv)])
        assert sent[0] == sent[1], t
        return sent[0]

    def check(self, where: object) -> None:
        assert _state(self.py) == _state(self.rs), where

    def both(self, method: str, *args) -> None:
        """Call a command on both; both must raise the same error type and text, or none."""
        outcomes = []
        for m in self.masters:
            try:
                getattr(m, method)(*args)
                outcomes.append(None)
            except (ValueError, KeyError, TypeError) as exc:
                outcomes.append((type(exc), str(exc)))
        assert outcomes[0] == outcomes[1], (method, args)

    def close(self) -> None:
        for b in self.buses:
            b.shutdown()


def msg(can_id: int, data: bytes, **flags) -> can.Message:
    return can.Message(arbitration_id=can_id, data=data, is_extended_id=False, **flags)


def good_replies(rng: random.Random, slave: int) -> list[can.Message]:
    """Valid Neuron -> Spinal frames of ``slave`` (config, states with handshake bits, IMU)."""
    index = rng.randrange(4)
    frames: list[nr.NeuronFrame] = [
        nr.InitialConfig0(slave, rng.randrange(5), rng.random() < 0.5, False, rng.randrange(99)),
        nr.InitialConfig1(slave, index, rng.randrange(250), 800, 0, 20),
        nr.InitialConfig2(
            slave,
            index,
            rng.randrange(-32768, 32768),
            rng.randrange(100),
            rng.randrange(2000),
            rng.random() < 0.6,
            rng.random() < 0.2,
        ),
        nr.InitialConfig3(slave, index, rng.randrange(256), 7, 4096, 4096),
        nr.ImuFrame(slave, nr.ImuMessage(rng.randrange(3)), *rng.sample(range(-9000, 9000), 3)),
    ]
    for _ in range(3):
        frames.append(
            nr.ServoState(
                slave,
                rng.randrange(4),
                rng.randrange(-32768, 32768),
                rng.randrange(256),
                rng.random() < 0.05,
                rng.random() < 0.5,
                rng.random() < 0.2,
                rng.randrange(-500, 500),
                rng.randrange(3),
            )
        )
    return [msg(f.can_id, f.encode()) for f in rng.sample(frames, rng.randrange(1, 4))]


def bad_replies(rng: random.Random) -> list[can.Message]:
    """Corrupt / wrong-length / unknown / Spinal-direction / non-classic frames."""
    choice = rng.randrange(12)
    if choice == 0:  # any id, any length up to 8 (every decoder branch, reason ranking)
        n = rng.randrange(9)
        return [msg(rng.randrange(0x800), bytes(rng.randrange(256) for _ in range(n)))]
    if choice == 1:  # initializer ids with small payloads (board-config / config-0 readings)
        can_id = 0x700 | (rng.randrange(5) << 4) | rng.randrange(16)
        n = rng.randrange(9)
        data = bytes([rng.randrange(14)] + [rng.randrange(3) for _ in range(n)])[: max(n, 0)]
        return [msg(can_id, data)]
    if choice == 2:
        return [msg(0x200 | rng.randrange(64), bytes(rng.randrange(256) for _ in range(8)))]
    if choice == 3:
        return [can.Message(arbitration_id=0x12345, data=b"\x01", is_extended_id=True)]
    if choice == 4:
        return [msg(0x701, b"", is_remote_frame=True)]
    if choice == 5:
        return [can.Message(is_error_frame=True, arbitration_id=0x20000080, is_extended_id=True)]
    if choice == 6:
        return [msg(0x211, bytes(12), is_fd=True)]
    if choice == 7:  # 11-bit flag but id above 0x7FF; a classic frame with 9 bytes
        return [msg(0x9FF, bytes(8)), msg(0x211, bytes(9))]
    if choice == 8:  # Spinal's own frames heard back (direction)
        f = rng.choice([nr.EnumRequest(), nr.InitialConfigRequest(2), nr.SetSlaveId(1, 3)])
        return [msg(f.can_id, f.encode())]
    if choice == 9:  # unknown slave (valid frame)
        f = nr.ServoState(9, 0, 5, 30, False, False, False, 0, 0)
        return [msg(f.can_id, f.encode()), msg(0x709, b"")]
    if choice == 10:  # PWM ids (reserved bits, range, direction)
        data = bytes(rng.randrange(256) for _ in range(8))
        return [msg(0x00F | (rng.randrange(2) << 4), data)]
    return [msg(0x7F3, b"")]  # device 7, message 15: unknown id


def _commands(rng: random.Random, pair: Pair) -> None:
    """Random commands to both masters (same validation errors expected)."""
    n = pair.py.motor_number
    r = rng.random()
    if r < 0.3:
        duties = [rng.choice([0.5, 0.75, 1.0, rng.uniform(0.5, 1.0)]) for _ in range(n)]
        if rng.random() < 0.1:
            duties.append(0.6)  # wrong count
        if rng.random() < 0.1 and duties:
            duties[0] = rng.choice([float("nan"), 1.2, 0.4])
        pair.both("set_motor_duties", duties)
    elif r < 0.45:
        slave, index = rng.choice((*SLAVES, 7)), rng.randrange(5)
        value = rng.choice([rng.randrange(-16384, 16384), 20000, 1.5])
        pair.both("set_servo_targets", {(slave, index): value})
    elif r < 0.55:
        pair.both("set_servo_torque", rng.choice(SLAVES), rng.randrange(4), rng.random() < 0.7)
    elif r < 0.6:
        pair.both("set_servo_current", rng.choice(SLAVES), rng.randrange(4), rng.randrange(-99, 99))
    elif r < 0.63:
        slave = rng.choice(SLAVES)
        frame = rng.choice(
            [nr.Reboot(slave), nr.SetSendDataFlag(slave, 0, False), nr.SetImuSendFlag(slave, True)]
        )
        pair.both("configure_board", frame)
    elif r < 0.64:
        pair.both("configure_board", nr.EnumRequest())  # TypeError on both


@pytest.mark.parametrize("seed", range(5))
def test_random_traffic_same_frames_and_state(seed):
    """~4 s of scripted Neuron replies (valid, corrupt, unknown, non-classic), commands, board
    configs and reboots, time jumps (catch-up, repeated and older ms), silences
    (disconnect events): every ms the same frames and the same observable state."""
    rng = random.Random(seed)
    pair = Pair()
    try:
        t = 0
        while t < 4000:
            if 20 <= t < 220:  # enumeration window: the Neurons answer (plus strays)
                pair.inject([msg(0x700 | s, b"") for s in SLAVES if rng.random() < 0.05])
            silent = 1500 <= t < 1800 and seed % 2 == 0
            if not silent and rng.random() < 0.7:
                batch = []
                for _ in range(rng.randrange(1, 4)):
                    batch += good_replies(rng, rng.choice(SLAVES))
                if rng.random() < 0.3:
                    batch += bad_replies(rng)
                pair.inject(batch)
            if pair.py.state is MasterState.RUNNING and rng.random() < 0.2:
                _commands(rng, pair)
            pair.tick(t)
            pair.check(t)
            step = rng.choices([1, 2, 7, 37, 0, -5], [90, 3, 2, 1, 2, 2])[0]
            t += step if t + step >= 0 else 1
        assert pair.py.state is MasterState.RUNNING
        assert pair.py.rx_count > 2000
        assert sum(pair.py.rx_errors.values()) > 100
    finally:
        pair.close()


def test_named_cases_boot_handshake_board_config_reboot_disconnect():
    """A deterministic run: enumeration of 2 Neurons, config, handshake (goal report taken,
    ack bit), force-off, board config + 2000 ms pause, reboot re-request after 5000 ms, a
    disconnect logged once per second, a 50 ms time jump replaying only 10 ms."""
    pair = Pair(boot_delay_ms=5)
    try:
        sent: dict[int, list] = {}

        def run(t0: int, t1: int, replies=None) -> None:
            for t in range(t0, t1):
                if replies is not None:
                    pair.inject(replies(t))
                sent[t] = pair.tick(t)
                pair.check(t)

        run(0, 6)
        pair.inject([msg(0x702, b""), msg(0x701, b"")])
        run(6, 210)  # enumeration ends at 205
        config = [
            nr.InitialConfig0(1, 2, True, False, 3),
            nr.InitialConfig2(1, 0, 100, 1, 2, True, False),
            nr.InitialConfig2(1, 1, -50, 1, 2, False, False),
            nr.InitialConfig0(2, 1, False, False, 0),
            nr.InitialConfig2(2, 0, 7, 1, 2, True, False),
        ]
        pair.inject([msg(f.can_id, f.encode()) for f in config])
        run(210, 900)  # 2 x 200 ms config + 2 x 100 ms IMU init
        assert pair.py.state is MasterState.RUNNING
        assert pair.rs.uav_model is None  # 1 gimbal servo on 2 Neurons: no model
        report = nr.ServoState(1, 0, 1234, 30, False, False, True, 0, 0)
        pair.inject([msg(report.can_id, report.encode())])
        pair.both("set_servo_torque", 1, 0, True)
        run(900, 910, lambda t: [msg(0x700 | 1, b"")])  # keep-alive frames
        assert pair.rs.servo(1, 0).goal_valid and pair.rs.servo(1, 0).goal_position == 1234
        off = nr.ServoState(1, 0, 1234, 30, True, False, False, 0, 0)
        pair.inject([msg(off.can_id, off.encode())])
        pair.both("set_servo_torque", 1, 0, True)  # refused while forced off
        run(910, 920)
        pair.both("configure_board", nr.Reboot(2))
        run(920, 8000, lambda t: [] if 3000 <= t < 5500 else [msg(0x701, b"")] * (t % 3 == 0))
        reboot_t = next(t for t, s in sent.items() if (0x722, b"\x07") in s)
        assert not any(s for t, s in sent.items() if reboot_t < t < reboot_t + 2000)
        assert (0x712, b"") in sent[reboot_t + 5000]
        texts = [e.text for e in pair.rs.events]
        assert 2 <= texts.count("CAN disconnected!!") <= 3  # 2.5 s silent, once per second
        for m in pair.masters:
            m.tick_ms(8050)  # 50 ms jump: only the last 10 ms are replayed
        pair.check("jump")
    finally:
        pair.close()


def test_virtual_bus_without_send_standard():
    """python-can's own virtual bus (no ``send_standard``): the same frames and counters."""
    rng = random.Random(11)
    pair = Pair("virtual", boot_delay_ms=0)
    try:
        for t in range(1600):  # running from ~1100 ms (3 Neurons)
            if t < 200:
                pair.inject([msg(0x700 | s, b"") for s in SLAVES if rng.random() < 0.1])
            bad = bad_replies(rng) if t > 200 else []
            pair.inject(good_replies(rng, rng.choice(SLAVES)) + bad)
            pair.tick(t)
            pair.check(t)
        assert pair.py.state is MasterState.RUNNING and pair.py.tx_count > 300
    finally:
        pair.close()


def test_core_errors_are_typed():
    core = _rdm.CanMaster(0, 0)
    with pytest.raises(_rdm.CanMasterError, match=r"duties: 1 values"):
        core.set_motor_duties([0.5])
    with pytest.raises(_rdm.CanMasterError, match="no servo 0 on Neuron 1"):
        core.set_servo_target(1, 0, 5)
    with pytest.raises(_rdm.CanMasterError, match="payload > 8"):
        core.configure_board(0x712, bytes(9))
    with pytest.raises(_rdm.CanMasterError, match="out of range"):
        core.servo(0, 0)
    master = RustCanMaster(InProcessBus("canwire_errors"))
    with pytest.raises(KeyError, match="no servo 1 on Neuron 3"):
        master.servo(3, 1)
    master.close()


def _run_hover(tmp_path: Path, backend: str, seconds: float) -> dict[str, bytes]:
    return hover_run_files(tmp_path, backend, seconds, master_backend=backend)


def test_hover_stack_logs_are_byte_identical(tmp_path):
    """4 simulated s from power-on (boot, enumeration, config, arming, take-off): can.log,
    signals.mcap and every UART capture are the same bytes with either master."""
    py = _run_hover(tmp_path / "py", "python", 4.0)
    rs = _run_hover(tmp_path / "rs", "rust", 4.0)
    assert {"can.log", "signals.mcap"} <= set(py)
    assert sorted(py) == sorted(rs)
    for name in py:
        assert hashlib.sha256(rs[name]).hexdigest() == hashlib.sha256(py[name]).hexdigest(), name
    assert py["can.log"].count(b"\n") > 4000


def test_jump_to_the_end_of_time_matches_the_reference():
    """Times near the i64 limits (the reference's ints are unbounded): same phase, no hang."""
    pair = Pair(boot_delay_ms=0)
    try:
        pair.tick(0)
        pair.inject([msg(0x701, b"")])
        for t in (1, 2**63 - 1, 2**63 - 1, -(2**63)):
            pair.tick(t)
            pair.check(t)
        assert pair.rs.state is MasterState.CONFIGURING and pair.rs.slaves == [1]
    finally:
        pair.close()
