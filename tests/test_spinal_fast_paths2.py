"""The Spinal mirror's idle-ms fast path (docs/spinal.md, "In the simulated stack") against its
plain path.

* ``ClientSession.idle_window``: a session that skips ``spin`` on byte-less ms inside the
  window gives the same events, output bytes, counters and clock as one that spins every ms,
  on random streams (handshake, time answers, noise, corrupt and cut frames, long silences
  past the 2.5 s time request and the 11 s sync loss).
* ``source_inbox`` / ``UartPump.inbox``: found only under known pure wrappers; while it is
  empty a read returns ``b""`` and changes no counter (link cut or not).
* ``CanMaster.tick_wire_steady`` against ``tick_wire`` on twin masters and wires: same
  results every ms, same log lines, through boot, the disable event and log drains.
* The whole hover stack with the fast tick on and off, 5 s with a UART cut: same bytes in
  every log, same counters.
"""

from __future__ import annotations

import random
import tempfile
from pathlib import Path

import numpy as np
import pytest

from rdm import _rdm
from rdm.link.tapped_link import TappedLink
from rdm.link.uart_pipe import InProcessUartEnd, open_inproc_uart
from rdm.nodes.spinal_uart import UartPump, source_inbox
from rdm.protocol.rosserial import constants as C
from rdm.protocol.rosserial.client import ClientSession
from rdm.protocol.rosserial.framing import encode_frame


def _time_answer(session: ClientSession, secs: int, nsecs: int) -> bytes:
    codec = session.registry.msg("std_msgs/Time")
    from rdm.protocol.rosserial.codec import RosTime

    return encode_frame(C.TopicId.TIME, codec.encode(codec.new(data=RosTime(secs, nsecs))))


def _chunks(rng: random.Random, session: ClientSession) -> bytes:
    """One random burst of wire bytes from the PC side."""
    kind = rng.random()
    if kind < 0.15:
        return encode_frame(C.TopicId.PUBLISHER, b"")  # topic request -> configured
    if kind < 0.35:
        return _time_answer(session, rng.randrange(1 << 20), rng.randrange(10**9))
    if kind < 0.5:
        frame = encode_frame(100 + rng.randrange(30), bytes(rng.randrange(256) for _ in range(12)))
        return frame[: rng.randrange(1, len(frame))]  # cut: the parser waits, times out
    if kind < 0.6:
        return bytes([0xFF, 0xFE]) + bytes(rng.randrange(256) for _ in range(6))  # bad version
    if kind < 0.75:
        frame = bytearray(_time_answer(session, 1, 2))
        frame[rng.randrange(len(frame))] ^= 1 << rng.randrange(8)  # corrupt
        return bytes(frame)
    if kind < 0.85:
        return encode_frame(C.TopicId.TX_STOP, b"")
    return bytes(rng.randrange(256) for _ in range(rng.randrange(1, 20)))


def _state(s: ClientSession) -> tuple:
    return (
        s.configured,
        dict(s.counts),
        dict(s.parser.counts),
        s.take_output(),
        repr(s.now(1 << 20)),
    )


@pytest.mark.parametrize("seed", range(6))
def test_idle_window_skip_equals_spinning_every_ms(seed: int) -> None:
    rng = random.Random(seed)
    every, skipping = ClientSession.from_layout(), ClientSession.from_layout()
    lo = hi = 0
    events_every: list[str] = []
    events_skip: list[str] = []
    t = rng.randrange(0, 1 << 31)
    skipped = 0
    for _ in range(600):
        data = _chunks(rng, every) if rng.random() < 0.3 else b""
        events_every += [repr(e) for e in every.spin(data, t)]
        if data or not lo <= t < hi:
            events_skip += [repr(e) for e in skipping.spin(data, t)]
            lo, hi = skipping.idle_window()
        else:
            skipped += 1
        assert events_every == events_skip, t
        if rng.random() < 0.3:
            assert _state(every) == _state(skipping)
        # mostly 1 ms; sometimes a jump past the 2.5 s time request or the 11 s sync loss
        t += rng.choice((1, 1, 1, 2, 5, 19, 21, 2499, 2501, 10999, 11001, 20000))
    assert _state(every) == _state(skipping)
    assert skipped > 50  # the skip was exercised
    assert every.counts["sync_lost"] + every.counts.get("tx_frames", 0) > 0


def test_idle_window_edges() -> None:
    s = ClientSession.from_layout()
    assert s.idle_window()[0] < 0 < s.idle_window()[1]  # unconfigured: no deadline
    s.spin(encode_frame(C.TopicId.PUBLISHER, b""), 1000)
    assert s.configured
    lo, hi = s.idle_window()
    assert (lo, hi) == (1000, 1000 + min(C.SYNC_LOSS_MS, C.TIME_REQUEST_INTERVAL_MS) + 1)
    s.take_output()
    assert s.spin(b"", hi - 1) == [] and s.take_output() == b""
    s.spin(b"", hi)  # the first ms outside: the time request goes out
    assert s.take_output() != b""
    s.spin(bytes([0xFF, 0xFE, 0x01]), hi + 1)  # part of a frame: no window
    assert s.idle_window() == (0, 0)


def test_source_inbox_only_under_pure_wrappers() -> None:
    from rdm.scenarios.stack import DroppableLink

    dev, host = open_inproc_uart()
    end = dev.link
    assert isinstance(end, InProcessUartEnd)
    assert source_inbox(end) is end.inbox
    assert source_inbox(dev) is end.inbox
    cut = DroppableLink(dev)
    assert source_inbox(cut) is end.inbox

    class Other:  # an unknown wrapper: its read may have effects
        def __init__(self, link):
            self.link = link

        def read_available(self) -> bytes:
            return self.link.read_available()

    assert source_inbox(Other(dev)) is None
    assert source_inbox(TappedLink(Other(end))) is None
    assert source_inbox(object()) is None

    pump = UartPump(cut)
    assert pump.inbox is end.inbox
    for dropped in (False, True):
        cut.dropped = dropped
        before = (pump.bytes_in, pump.read_errors, dev.rx_bytes, cut.bytes_lost)
        assert not pump.inbox and pump.read() == b""
        assert (pump.bytes_in, pump.read_errors, dev.rx_bytes, cut.bytes_lost) == before
        host.write(b"\x01\x02")
        assert pump.inbox  # bytes waiting: a read is not a no-op
        assert pump.read() == (b"" if dropped else b"\x01\x02")
        assert cut.bytes_lost == (2 if dropped else 0)
    pump.link = Other(dev)
    assert pump.inbox is None  # follows the link


def test_tick_wire_steady_equals_tick_wire() -> None:
    masters = [_rdm.CanMaster(50, 0), _rdm.CanMaster(50, 0)]
    wires = [_rdm.CanWire(), _rdm.CanWire()]
    rng = random.Random(3)
    drain_at = 7
    steady_seen = minus_seen = 0
    t = 0
    for _ in range(3000):
        stamp = t / 1000.0 + rng.random() * 1e-4
        plain = masters[0].tick_wire(t, stamp, wires[0])
        got = masters[1].tick_wire_steady(t, stamp, wires[1], drain_at)
        assert masters[1].last_wire_tick == plain
        state, events, sent, logged = plain
        if state == 3 and events == 0 and logged < drain_at:
            assert got == sent
            steady_seen += 1
        else:
            assert got == -1
            minus_seen += 1
        if events:
            assert masters[0].pop_events() == masters[1].pop_events()
        if logged >= drain_at or rng.random() < 0.01:
            assert wires[0].drain_log("can0") == wires[1].drain_log("can0")
        if rng.random() < 0.05:
            masters[0].set_motor_duties([])
            masters[1].set_motor_duties([])
        t += rng.choice((1, 1, 1, 2, 7, 40, 0))
    assert minus_seen > 0
    assert (masters[0].state_index, masters[0].rx_count) == (
        masters[1].state_index,
        masters[1].rx_count,
    )
    assert wires[0].frames == wires[1].frames > 0
    del steady_seen  # no Neuron answers here: the master never runs (the stack test does)


TICKS = 5200  # boot, running, a UART cut and its restore, several wire log drains


def _run(base: str, fast: bool) -> tuple[dict[str, bytes], dict, int]:
    from rdm.scenarios.common import sim_stack_options
    from rdm.scenarios.hover import HOVER_Z, make_script
    from rdm.scenarios.stack import build_stack

    opts = sim_stack_options(0, "inproc", speed=None)
    stack = build_stack("fastpaths2", base, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))
    spinal = stack.spinal
    spinal._fast = fast
    spinal.servos._fast = fast
    spinal.master.fast = fast
    spinal.uart.fast = fast
    skipped = 0
    if fast:  # count the idle ms the fast tick does not spin
        inner = spinal._receive
        calls = [0]

        def counting(now_ms: int) -> None:
            calls[0] += 1
            inner(now_ms)

        spinal._receive = counting
    stack.loop.run_ticks(3000)
    stack.spinal_link.dropped = True
    stack.loop.run_ticks(700)
    stack.spinal_link.dropped = False
    stack.loop.run_ticks(TICKS - 3700)
    if fast:
        skipped = TICKS - calls[0]
    diag = spinal.diagnostics()
    diag["tx_count"] = spinal.master.tx_count
    diag["frames"] = spinal.master.wire.wire.frames
    stack.close()
    paths = sorted(p for p in Path(base).rglob("*") if p.is_file())
    files = {str(p.relative_to(base)): p.read_bytes() for p in paths}
    return files, diag, skipped


def test_stack_bytes_and_counters_equal_fast_and_plain_tick() -> None:
    with tempfile.TemporaryDirectory() as a, tempfile.TemporaryDirectory() as b:
        fast_files, fast_diag, skipped = _run(a, True)
        plain_files, plain_diag, _ = _run(b, False)
    assert fast_diag == plain_diag
    assert skipped > TICKS // 2  # most ms were idle and took the fast tick
    assert fast_diag["frames"] > 8192  # the wire log was drained on the way
    assert sorted(fast_files) == sorted(plain_files)
    for name in fast_files:
        assert fast_files[name] == plain_files[name], name
