"""The Spinal mirror's idle ms and its UART pump (docs/spinal.md, "In the simulated stack").

* ``ClientSession.idle_window``: a session that skips ``spin`` on byte-less ms inside the
  window gives the same events, output bytes, counters and clock as one that spins every ms,
  on random streams (handshake, time answers, noise, corrupt and cut frames, long silences
  past the 2.5 s time request and the 11 s sync loss); the window's edges.
* ``source_inbox`` / ``UartPump.inbox``: found only under known pure wrappers; while it is
  empty a read returns ``b""`` and changes no counter (link cut or not).
* ``UartPump.send``: every byte handed over is written, queued or counted discarded, and
  the peer receives the written bytes in order (in-process pipe with a peer that goes away
  and a port that fails; a pty whose reader is late).
"""

from __future__ import annotations

import random

import numpy as np
import pytest

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


def test_uart_pump_writes_queues_or_discards_every_byte() -> None:
    rng = np.random.default_rng(11)
    sends = [rng.bytes(int(rng.integers(0, 3000))) for _ in range(200)]
    dev, host = open_inproc_uart()
    pump = UartPump(dev, max_pending=4096)
    received = bytearray()
    handed = 0
    for k, data in enumerate(sends):
        if k == 60:
            host.link.closed = True  # nobody listening: writes take 0 bytes, queue grows
        if k == 120:
            host.link.closed = False
        if k == 150:
            dev.link.closed = True  # the port itself fails: counted write errors
        if k == 180:
            dev.link.closed = False
        pump.send(data)
        handed += len(data)
        received += host.read_available()
        assert pump.bytes_out + pump.bytes_discarded + len(pump.pending) == handed, k
        assert pump.bytes_out == len(received), k
        if k < 60:  # an open line, nothing queued: every byte arrives, in order
            assert bytes(received) == b"".join(sends[: k + 1]) and not pump.pending
    assert pump.bytes_discarded > 0 and pump.write_errors > 0  # discards and errors ran


def test_uart_pump_on_a_pty_loses_and_reorders_nothing() -> None:
    """The fd path with partial writes (a peer that reads late): how much the kernel takes is
    timing-dependent, so the bytes read are checked against the bytes sent."""
    import os
    import tty

    class PtyEnd:
        """The device end of a pty as UartPump sees a serial link."""

        def __init__(self, fd: int) -> None:
            self.port = self
            self.fd = fd

        def fileno(self) -> int:
            return self.fd

        def read_available(self) -> bytes:
            return b""

    def drain(fd: int, into: bytearray) -> None:
        while True:
            try:
                chunk = os.read(fd, 65536)
            except (BlockingIOError, OSError):
                return
            if not chunk:
                return
            into += chunk

    rng = np.random.default_rng(5)
    sends = [rng.bytes(int(rng.integers(1, 2500))) for _ in range(60)]
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(slave, False)
    os.set_blocking(master, False)
    pump = UartPump(PtyEnd(slave), max_pending=1 << 20)
    received, held = bytearray(), 0
    try:
        for k, data in enumerate(sends):
            pump.send(data)  # the peer reads only every 20 sends: partial writes
            held = max(held, len(pump.pending))
            if k % 20 == 19:
                drain(master, received)
        for _ in range(1000):
            if not pump.pending:
                break
            pump.pump()
            drain(master, received)
        drain(master, received)
    finally:
        os.close(master)
        os.close(slave)
    assert bytes(received) == b"".join(sends)
    assert pump.bytes_out == len(received) and pump.write_errors == 0
    assert held > 0  # the queue held a remainder at some point
