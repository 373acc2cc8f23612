"""The in-process CAN bus against python-can's own ``virtual`` bus (the oracle): the same
scenario on both must give the same deliveries (order, self-reception, filters, message
fields); timestamps must come from the simulated clock. Speed is measured and printed, never
asserted (``pytest -s`` shows it)."""

from __future__ import annotations

import itertools
import time
import uuid

import can
import pytest

from rdm.link import inproc_can
from rdm.link.can import CanSpecError, open_can, parse_can_spec
from rdm.link.inproc_can import InProcessBus, SimClock, set_channel_clock


def _fields(msg: can.Message) -> tuple:
    return (
        msg.arbitration_id,
        msg.is_extended_id,
        msg.is_remote_frame,
        msg.is_error_frame,
        msg.dlc,
        bytes(msg.data),
        msg.is_fd,
        msg.is_rx,
    )


FILTERS = [
    None,
    [{"can_id": 0x100, "can_mask": 0x700}],  # 0x100..0x1FF
    [
        {"can_id": 0x005, "can_mask": 0x00F, "extended": False},
        {"can_id": 0x18DAF100, "can_mask": 0x1FFFFFFF, "extended": True},
    ],
]


def _scenario(make_bus) -> list[list[tuple]]:
    """Three buses (one hears itself, two with filters) exchange a mixed burst of frames."""
    buses = [
        make_bus(receive_own_messages=False, can_filters=FILTERS[0]),
        make_bus(receive_own_messages=True, can_filters=FILTERS[1]),
        make_bus(receive_own_messages=False, can_filters=FILTERS[2]),
    ]
    try:
        frames = []
        for i in range(60):
            frames.append(
                can.Message(
                    arbitration_id=(0x0F5 + 7 * i) & 0x7FF,
                    data=bytes([i, i + 1, i + 2][: i % 4]),
                    is_extended_id=False,
                )
            )
        frames.append(can.Message(arbitration_id=0x18DAF100, data=b"\x01", is_extended_id=True))
        frames.append(
            can.Message(arbitration_id=0x105, is_remote_frame=True, dlc=2, is_extended_id=False)
        )
        for i, msg in enumerate(frames):
            buses[i % 3].send(msg)
        out = []
        for bus in buses:
            got = []
            # A small timeout, not 0: python-can's recv(timeout=0) returns None as soon as the
            # first pending frame fails the filters, even with matching frames queued behind it.
            while (m := bus.recv(timeout=0.005)) is not None:
                got.append(_fields(m))
            out.append(got)
        return out
    finally:
        for b in buses:
            b.shutdown()


def test_same_deliveries_as_python_can_virtual():
    v_name, i_name = f"v{uuid.uuid4().hex}", f"i{uuid.uuid4().hex}"
    virtual = _scenario(lambda **kw: can.Bus(interface="virtual", channel=v_name, **kw))
    inproc = _scenario(lambda **kw: InProcessBus(i_name, **kw))
    assert inproc == virtual
    # the scenario really exercises each behaviour
    assert len(virtual[0]) == 41  # 62 frames minus its own 21, no filter
    assert any(not rx for *_, rx in virtual[1])  # self-reception (is_rx False) on bus 1
    assert virtual[1] and all(f[0] & 0x700 == 0x100 for f in virtual[1])
    assert {f[1] for f in virtual[2]} == {False, True}


def test_order_across_senders_and_no_self_reception():
    name = f"o{uuid.uuid4().hex}"
    a, b, c = (InProcessBus(name) for _ in range(3))
    try:
        seq = [(a, 1), (b, 2), (a, 3), (c, 4), (b, 5)]
        for bus, n in seq:
            bus.send(can.Message(arbitration_id=n, data=b"", is_extended_id=False))
        got = {bus: [] for bus in (a, b, c)}
        for bus in (a, b, c):
            while (m := bus.recv(timeout=0)) is not None:
                got[bus].append(m.arbitration_id)
        for bus in (a, b, c):
            assert got[bus] == [n for sender, n in seq if sender is not bus]
    finally:
        for bus in (a, b, c):
            bus.shutdown()


def test_timestamps_from_sim_clock_and_receiver_copies_independent():
    name = f"t{uuid.uuid4().hex}"
    clock = SimClock(1.25)
    set_channel_clock(name, clock)
    tx, rx1, rx2 = (InProcessBus(name) for _ in range(3))
    try:
        msg = can.Message(arbitration_id=0x10, data=b"\x01\x02", is_extended_id=False)
        tx.send(msg)
        clock.set(1.5)
        msg.data[0] = 0xFF  # the sender reuses its object: frames already sent must not change
        tx.send(msg)
        first, second = rx1.recv(0), rx1.recv(0)
        assert (first.timestamp, second.timestamp) == (1.25, 1.5)
        assert bytes(first.data) == b"\x01\x02" and bytes(second.data) == b"\xff\x02"
        assert first.channel == name and first.is_rx
        assert rx2.recv(0).timestamp == 1.25
        assert inproc_can.channel_frame_count(name) == 2
    finally:
        for bus in (tx, rx1, rx2):
            bus.shutdown()


def test_open_can_inproc_spec_and_closed_bus():
    name = f"s{uuid.uuid4().hex[:20]}"
    assert parse_can_spec(f"inproc:{name}").interface == "inproc"
    with pytest.raises(CanSpecError):
        parse_can_spec("inproc:bad name")
    a = open_can(f"inproc:{name},receive_own_messages=1")
    b = open_can(f"inproc:{name}")
    assert isinstance(a, InProcessBus) and a.receive_own_messages
    a.send(can.Message(arbitration_id=1, is_extended_id=False))
    assert a.recv(0).is_rx is False and b.recv(0).is_rx is True
    b.shutdown()
    with pytest.raises(can.CanOperationError):
        b.send(can.Message(arbitration_id=1, is_extended_id=False))
    a.shutdown()
    a.shutdown()  # idempotent


def test_bounded_queue_drops_oldest_and_blocking_recv_times_out():
    name = f"q{uuid.uuid4().hex}"
    tx, rx = InProcessBus(name), InProcessBus(name, rx_queue_size=2)
    try:
        for n in range(3):
            tx.send(can.Message(arbitration_id=n, is_extended_id=False))
        assert rx.rx_dropped == 1
        assert [rx.recv(0).arbitration_id, rx.recv(0).arbitration_id] == [1, 2]
        t0 = time.monotonic()
        assert rx.recv(timeout=0.01) is None
        assert time.monotonic() - t0 >= 0.009
    finally:
        tx.shutdown()
        rx.shutdown()


def test_tap_sees_every_frame_once():
    name = f"p{uuid.uuid4().hex}"
    seen = []
    inproc_can.add_tap(name, seen.append)
    a, b = InProcessBus(name), InProcessBus(name)
    try:
        for n in range(5):
            (a if n % 2 else b).send(can.Message(arbitration_id=n, is_extended_id=False))
        assert [m.arbitration_id for m in seen] == list(range(5))
    finally:
        inproc_can.remove_tap(name, seen.append)
        a.shutdown()
        b.shutdown()


def _throughput(make, n_receivers: int = 4, frames: int = 4000) -> float:
    buses = [make() for _ in range(n_receivers + 1)]
    try:
        msg = can.Message(arbitration_id=0x10, data=b"\x00" * 8, is_extended_id=False)
        t0 = time.perf_counter()
        for _ in range(frames):
            buses[0].send(msg)
            for b in buses[1:]:
                b.recv(timeout=0)
        return frames / (time.perf_counter() - t0)
    finally:
        for b in buses:
            b.shutdown()


def test_speed_against_virtual_reported():
    v, i = f"v{uuid.uuid4().hex}", f"i{uuid.uuid4().hex}"
    best_v = max(_throughput(lambda: can.Bus(interface="virtual", channel=v)) for _ in range(3))
    best_i = max(_throughput(lambda: InProcessBus(i)) for _ in range(3))
    print(
        f"\n1 sender + 4 receivers, 8-byte frames: virtual {best_v:,.0f} frames/s, "
        f"inproc {best_i:,.0f} frames/s ({best_i / best_v:.1f}x)"
    )
    assert best_v > 0 and best_i > 0


def test_channels_isolated():
    names = [f"c{uuid.uuid4().hex}" for _ in range(2)]
    buses = [InProcessBus(n) for n, _ in itertools.product(names, range(2))]
    try:
        buses[0].send(can.Message(arbitration_id=7, is_extended_id=False))
        assert buses[1].recv(0).arbitration_id == 7
        assert buses[2].recv(0) is None and buses[3].recv(0) is None
    finally:
        for b in buses:
            b.shutdown()
