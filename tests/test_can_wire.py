"""The Rust CanWire (master <-> Neuron bank without python-can) against the in-process
python-can channel with ``CandumpCapture``: the same candump bytes, the same master and board
state, at every tick, whichever link carries the frames; the full hover stack writes the same
logs on either; another python-can endpoint on a wired channel is refused."""

from __future__ import annotations

import hashlib
import itertools
from pathlib import Path

import pytest
from hover_run_files import hover_run_files

from rdm.link.can import open_can
from rdm.link.can_wire import CanWireError, CanWireLink, WireCandump
from rdm.link.inproc_can import InProcessBus, SimClock, add_tap, remove_tap, set_channel_clock
from rdm.nodes.can_master import SERVO_FIELDS, CanMaster, MasterState
from rdm.nodes.neuron_bank import NeuronBankNode, NeuronSpec
from rdm.nodes.servo_model import ServoConfig
from rdm.protocol import neuron as nr
from rdm.sim import CandumpCapture

_channels = itertools.count()


def _specs() -> list[NeuronSpec]:
    cfg = [ServoConfig(dynamixel_id=10 + i, send_data_flag=i != 1) for i in range(3)]
    return [
        NeuronSpec(1, tuple(cfg[:2]), imu=True),
        NeuronSpec(2, tuple(cfg[:1])),
        NeuronSpec(3, tuple(cfg)),
        NeuronSpec(4),
    ]


class Rig:
    """A Neuron bank and a CAN master ticked bank-first each ms (the stack's node order)."""

    def __init__(self, tmp: Path, wired: bool) -> None:
        self.channel = f"canwire_rig_{next(_channels)}"
        self.clock = SimClock()
        self.path = tmp / f"{'wire' if wired else 'bus'}.log"
        if wired:
            link = CanWireLink(self.channel)
            set_channel_clock(self.channel, self.clock)
            self.bank = NeuronBankNode(link, _specs())
            self.master = CanMaster(link, boot_delay_ms=3)
            self.capture = WireCandump(self.path, link)
        else:
            self.bank = NeuronBankNode(open_can(f"inproc:{self.channel}"), _specs())
            self.master = CanMaster(open_can(f"inproc:{self.channel}"), boot_delay_ms=3)
            set_channel_clock(self.channel, self.clock)
            self.capture = CandumpCapture(self.path, channel=self.channel)

    def tick(self, t_ms: int) -> None:
        self.clock.now = t_ms / 1000
        self.bank.tick(t_ms / 1000)
        self.master.tick_ms(t_ms)

    def close(self) -> bytes:
        self.capture.close()
        self.master.close()
        self.bank.close()
        return self.path.read_bytes()


def _observed(m) -> tuple:
    return (
        m.state,
        m.motor_number,
        m.uav_model,
        m.rx_count,
        list(m.rx_errors.items()),
        list(m.rx_kinds.items()),
        m.tx_count,
        m.connected,
        {k: tuple(getattr(e, f) for f in SERVO_FIELDS) for k, e in m.servo_states.items()},
        m.imu,
        [(e.stamp_ms, e.text) for e in m.pop_events()],
    )


def test_wire_equals_python_bus_and_candump(tmp_path):
    """Boot, enumeration, config, handshake, duties, torque, board configs + reboot, late
    ticks (10 ms replay: several frames per tick in each direction) and an IMU board: the
    same candump bytes and the same master / board state every ms."""
    bus, wire = Rig(tmp_path, wired=False), Rig(tmp_path, wired=True)
    rigs = (bus, wire)
    t = 0
    try:
        while t < 9000:
            for r in rigs:
                m = r.master
                if m.state is MasterState.RUNNING:
                    if t % 5 == 0:
                        m.set_motor_duties([0.5 + ((t // 5 + k) % 50) / 100 for k in range(4)])
                    if t == 1700:
                        m.set_servo_torque(3, 2, True)
                        m.set_servo_targets({(1, 0): 321, (3, 2): -77})
                        m.set_servo_current(1, 1, 12)
                    if t == 2000:
                        m.configure_board(nr.SetSendDataFlag(3, 0, False))
                        m.configure_board(nr.Reboot(2))
                r.tick(t)
            assert _observed(bus.master) == _observed(wire.master), t
            for a, b in zip(bus.bank.boards, wire.bank.boards, strict=True):
                assert a.state() == b.state(), (t, a.name)
                assert a.tx_count == b.tx_count, (t, a.name)
            t += 23 if t in (3000, 3100, 7000) else 1
        assert bus.master.state is MasterState.RUNNING
    finally:
        # Each rig has its own channel name (it is in every line): compared as "can0".
        logs = [r.close().replace(r.channel.encode(), b"can0") for r in rigs]
    assert logs[0] == logs[1]
    assert logs[0].count(b"\n") > 5000  # (4 s of it are the two board-config pauses)
    assert b" 722#07 R" in logs[0]  # the reboot went out


class _CountingBus(InProcessBus):
    """An in-process bus that counts the frames it accepts (the send count the master's
    ``tx_count`` must match, taken from the bus, not from the master)."""

    def __init__(self, channel: str) -> None:
        super().__init__(channel)
        self.sent = 0

    def send_standard(self, can_id: int, data: bytes) -> None:
        super().send_standard(can_id, data)
        self.sent += 1


def test_tx_count_and_pending_events_are_the_cores(tmp_path):
    """``tx_count`` equals the frames the python-can bus accepted (``count_sent``) and, on
    the wire, the same count (``tick_wire``'s own); the pending events are exactly the ones
    ``pop_events`` then returns, every ms of a boot and run."""
    bus, wire = Rig(tmp_path, wired=False), Rig(tmp_path, wired=True)
    counting = _CountingBus(bus.channel)
    bus.master.bus.shutdown()
    bus.master.bus = counting
    popped = 0
    try:
        for t in range(2500):
            for r in (bus, wire):
                r.tick(t)
                m = r.master
                pending = m._pending_events
                events = m.pop_events()
                assert len(events) == pending and m._pending_events == 0, (t, events)
                popped += len(events)
            assert bus.master.tx_count == counting.sent == wire.master.tx_count, t
        assert bus.master.state is MasterState.RUNNING
        assert counting.sent > 1000 and popped >= 2  # the frames and each "running" event
    finally:
        for r in (bus, wire):
            r.close()


def test_other_endpoint_on_a_wired_channel_is_refused(tmp_path):
    """A python-can bus or a tap joining the channel: CanWireError at the next master tick
    (the wire would not deliver to it)."""
    link = CanWireLink(f"canwire_alone_{next(_channels)}")
    master = CanMaster(link, boot_delay_ms=0)
    master.tick_ms(0)
    intruder = open_can(f"inproc:{link.channel}")
    with pytest.raises(CanWireError, match="1 other bus"):
        master.tick_ms(1)
    intruder.shutdown()
    master.tick_ms(2)

    def tap(_msg):
        return None

    add_tap(link.channel, tap)
    with pytest.raises(CanWireError, match="1 tap"):
        master.tick_ms(3)
    remove_tap(link.channel, tap)
    master.close()


_run_hover = hover_run_files


def test_hover_stack_on_the_wire_is_byte_identical(tmp_path):
    """4 simulated s from power-on: the wired stack (default) and the stack on an in-process
    python-can channel write the same can.log, signals.mcap and UART bytes."""
    ref = _run_hover(tmp_path / "ref", "ref", 4.0, can_wire=False)
    wired = _run_hover(tmp_path / "wire", "wire", 4.0)
    assert {"can.log", "signals.mcap"} <= set(ref)
    assert sorted(ref) == sorted(wired)
    for name in ref:
        assert hashlib.sha256(wired[name]).hexdigest() == hashlib.sha256(ref[name]).hexdigest()
    assert ref["can.log"].count(b"\n") > 4000
