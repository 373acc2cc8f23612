"""The Leptrino node's wrench input, the candump capture and the in-process CAN send path
against independent references.

The Leptrino node's ``set_wrench`` (vs a numpy clip and saturation count),
the candump line memo (vs python-can's ``CanutilsLogWriter`` on frames stamped by the
simulated clock, several per tick, memo overflow included), the inlined delivery of
``InProcessBus.send_standard`` (vs ``send`` of a ``Message`` with bounded queues that drop)
and the CAN master's bound ``send_standard`` (vs the generic path, closed bus counted).
"""

from __future__ import annotations

import math
import random

import can
import numpy as np
import pytest

from rdm.link.inproc_can import InProcessBus, SimClock, set_channel_clock
from rdm.nodes.can_master import CanMaster
from rdm.nodes.leptrino_sensor import LeptrinoSensorNode
from rdm.sim import candump as candump_mod


class _NullUart:
    def read_available(self) -> bytes:
        return b""

    def write(self, data: bytes) -> int:
        return len(data)

    def close(self) -> None:
        pass


@pytest.mark.parametrize("entry", ["set_wrench", "set_wrench_values"])
def test_set_wrench_equals_a_numpy_clip_and_counts_saturation_alike(entry: str):
    node = LeptrinoSensorNode(_NullUart(), "CFS034CA301U")
    values = entry == "set_wrench_values"  # one 6-tuple (the plant bridge's 1 kHz input)
    lim = np.array(node.limits)
    gen = np.random.default_rng(12)
    saturated = bad = 0
    for k in range(3000):
        kind = k % 6
        w = gen.normal(0, 0.6, 6) * lim
        if kind == 1:
            w = lim * gen.choice([1.0, -1.0, 0.0, -0.0, 1.0 + 1e-12, -(1.0 + 1e-12)], 6)
        elif kind == 2:
            w[gen.integers(6)] = gen.choice([math.nan, math.inf, -math.inf])
        elif kind == 3:
            w = np.round(w)  # whole numbers, passed as Python ints below
        before = node.wrench
        if kind == 3:
            ints = [int(v) for v in w]
            if values:
                node.set_wrench_values(tuple(float(v) for v in ints))
            else:
                node.set_wrench(ints[:3], ints[3:])
            w = np.array(ints, dtype=float)  # int(-0.0) is 0
        elif values:
            node.set_wrench_values(tuple(w.tolist()))
        elif kind == 4:
            node.set_wrench(list(w[:2]), list(w[2:]))  # 2 + 4 values: still six
        else:
            node.set_wrench(w[:3], w[3:])
        if not np.all(np.isfinite(w)):
            bad += 1
            assert node.wrench == before
            continue
        want = np.clip(w, -lim, lim)
        saturated += bool(np.any(np.abs(w) > lim))
        got = np.array(node.wrench, dtype=float)
        assert np.array_equal(got, want) and np.array_equal(np.signbit(got), np.signbit(want))
    if values:
        node.set_wrench_values((1.0, 2.0, 3.0, 4.0, 5.0))  # five values: refused
    else:
        node.set_wrench([1.0, 2.0], [3.0])
    assert node.errors["bad_wrench"] == bad + 1
    assert node.saturated_samples == saturated and saturated > 100


def test_candump_memo_writes_what_python_cans_writer_writes(tmp_path, monkeypatch):
    monkeypatch.setattr(candump_mod, "REST_CACHE_SIZE", 5)  # overflow the memo often
    name = "sensor_candump"
    clock = SimClock(0.0)
    set_channel_clock(name, clock)
    tx = InProcessBus(name)
    rx = InProcessBus(name)
    ours = candump_mod.CandumpCapture(tmp_path / "ours.log", channel=name)
    theirs = can.CanutilsLogWriter(tmp_path / "theirs.log", channel="can0")
    gen = random.Random(3)
    common = [(0x00F, bytes(8)), (0x123, b"\x10\x20"), (0x7FF, b"")]
    try:
        for k in range(2500):
            clock.set(k * 0.001 if k % 400 else -0.0 + k * 0.001)
            for _ in range(gen.randrange(4)):  # 0..3 frames in one tick, same stamp object
                r = gen.random()
                if r < 0.5:
                    can_id, data = gen.choice(common)
                elif r < 0.7:  # a known id with new data (a PWM frame with other duties)
                    can_id, data = 0x00F, bytes([gen.randrange(4)] * 8)
                else:
                    n = gen.randrange(9)
                    can_id, data = gen.randrange(0x800), bytes(gen.randrange(256) for _ in range(n))
                tx.send_standard(can_id, data)
                theirs.on_message_received(rx.recv(timeout=0))
    finally:
        ours.close()
        theirs.stop()
        tx.shutdown()
        rx.shutdown()
    assert ours.frames > 3000
    assert (tmp_path / "ours.log").read_bytes() == (tmp_path / "theirs.log").read_bytes()


def test_send_standard_into_full_queues_drops_as_send_does():
    def fields(m: can.Message) -> tuple:
        return (m.timestamp, m.arbitration_id, bytes(m.data), m.is_rx, m.dlc)

    gen = random.Random(4)
    frames = [(gen.randrange(0x800), bytes(gen.randrange(256) for _ in range(gen.randrange(9))))
              for _ in range(200)]  # fmt: skip
    seen = {}
    for name, standard in (("sensor_q_a", False), ("sensor_q_b", True)):
        tx = InProcessBus(name, receive_own_messages=True, rx_queue_size=7)
        small = InProcessBus(name, rx_queue_size=3)
        big = InProcessBus(name)
        filt = InProcessBus(name, rx_queue_size=2, can_filters=[{"can_id": 0, "can_mask": 0x001}])
        for can_id, data in frames:
            if standard:
                tx.send_standard(can_id, data)
            else:
                tx.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        buses = (tx, small, big, filt)
        seen[standard] = (
            [[fields(m) for m in iter(lambda b=b: b.recv(timeout=0), None)] for b in buses],
            [b.rx_dropped for b in buses],
        )
        for b in buses:
            b.shutdown()
    assert seen[True] == seen[False]
    drops = seen[True][1]
    assert drops[0] > 0 and drops[1] > 0 and drops[2] == 0 and drops[3] > 0
    assert len(seen[True][0][2]) == len(frames)


def test_can_master_sends_through_the_bus_it_holds_and_counts_refusals():
    enum_request = (0x70F, b"")  # the first frame after boot (fact sheet sec. 2.5)
    master = CanMaster(InProcessBus("sensor_master_a"), boot_delay_ms=0)
    listener = InProcessBus("sensor_master_b")
    master.bus = InProcessBus("sensor_master_b")  # the send path follows the bus
    master.tick_ms(0)
    got = listener.recv(timeout=0)
    assert (got.arbitration_id, bytes(got.data)) == enum_request
    assert master.tx_count == 1 and master.tx_errors == 0
    master.bus.shutdown()

    class RefusingBus(InProcessBus):
        """A bus whose controller refuses every frame (python-can's CanOperationError)."""

        def send_standard(self, can_id: int, data: bytes) -> None:
            raise can.CanOperationError("TX refused")

    refused = CanMaster(RefusingBus("sensor_master_c"), boot_delay_ms=0)
    refused.tick_ms(0)  # refused: counted, the node goes on
    assert refused.tx_count == 0 and refused.tx_errors == 1
    refused.close()
    # A python-can bus without send_standard takes the generic path.
    virt_tx = can.Bus(interface="virtual", channel="sensor_virt")
    virt_rx = can.Bus(interface="virtual", channel="sensor_virt")
    generic = CanMaster(virt_tx, boot_delay_ms=0)
    generic.tick_ms(0)
    got = virt_rx.recv(timeout=1.0)
    assert (got.arbitration_id, bytes(got.data), got.is_extended_id) == (*enum_request, False)
    assert generic.tx_count == 1
    for b in (virt_tx, virt_rx, listener):
        b.shutdown()
