"""The real-time loop's measurements: fixed-bin histograms against numpy, the late-tick rule
on a fake clock, and UART writes that never block the loop (a pty whose reader does not read).
"""

from __future__ import annotations

import os
import select
import threading

import numpy as np
import pytest

from rdm.link.serial import open_pty_pair
from rdm.nodes.base import run_realtime
from rdm.nodes.loop_timing import BIN_S, RANGE_S, Histogram, LoopTiming


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_histogram_quantiles_bracket_numpy_nearest_rank(seed: int) -> None:
    rng = np.random.default_rng(seed)
    # a 25 ms period with jitter, a few long outliers (some past the bins), some zeros
    x = np.concatenate(
        [
            rng.normal(0.025, 0.002, 3000).clip(0.0),
            rng.exponential(0.03, 50),
            rng.uniform(RANGE_S, 2 * RANGE_S, 3),
            np.zeros(5),
        ]
    )
    rng.shuffle(x)
    h = Histogram()
    for v in x:
        h.add(float(v))
    assert h.n == x.size
    assert h.max == x.max()
    assert h.overflow == int(np.sum(x >= RANGE_S))
    for q in (0.0, 0.01, 0.5, 0.9, 0.99, 0.999, 1.0):
        exact = float(np.percentile(x, 100 * q, method="inverted_cdf"))
        got = h.quantile(q)
        if exact >= RANGE_S:
            assert got == x.max()
        else:  # the upper edge of the bin holding the nearest-rank sample
            assert exact <= got < exact + BIN_S + 1e-12, (q, exact, got)


def test_histogram_memory_is_fixed_and_bad_quantiles_are_refused() -> None:
    h = Histogram(bin_s=0.001, range_s=0.01)
    assert len(h.counts) == 10
    for v in (-1.0, 0.0, 0.0099, 0.5):
        h.add(v)
    assert len(h.counts) == 10
    assert h.counts[0] == 2 and h.counts[9] == 1 and h.overflow == 1
    with pytest.raises(ValueError, match="q="):
        h.quantile(1.5)
    with pytest.raises(ValueError, match="no samples"):
        Histogram().quantile(0.5)


class FakeClock:
    """Time advances only when the loop sleeps or a node's tick spends it."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t += s


class CostlyNode:
    """Ticks every 25 ms; tick k spends ``costs[k]`` seconds of the fake clock."""

    name = "control"
    period = 0.025

    def __init__(self, clock: FakeClock, costs: list[float]) -> None:
        self.clock, self.costs, self.k = clock, costs, 0

    def tick(self, now: float) -> None:
        self.clock.t += self.costs[self.k] if self.k < len(self.costs) else 0.0
        self.k += 1


def test_a_tick_is_late_past_the_tolerance_not_only_after_a_whole_period() -> None:
    clock = FakeClock()
    # tick 0 runs 26.5 ms: tick 1 (due 25 ms) starts 1.5 ms late (within 2 ms);
    # tick 1 runs 28.5 ms: tick 2 (due 50 ms) starts 55 ms, 5 ms late (late, no overrun);
    # tick 2 runs 2 ms; the schedule is kept, ticks 3.. start on time.
    node = CostlyNode(clock, [0.0265, 0.0285, 0.002])
    timing = LoopTiming(node.period, late_tolerance=0.002)
    stats = run_realtime(
        [node], duration=0.2, clock=clock, sleep=clock.sleep, timing={"control": timing}
    )
    assert stats.overruns["control"] == 0
    assert timing.late == 1
    starts = [0.0, 0.0265, 0.055, 0.075, 0.1, 0.125, 0.15, 0.175]
    periods = np.diff(starts)
    assert stats.ticks["control"] == len(starts) == timing.tick.n
    assert timing.period_hist.n == len(periods)
    assert timing.lateness.max == pytest.approx(0.005)
    assert timing.jitter.max == pytest.approx(np.abs(periods - 0.025).max())
    assert timing.tick.max == pytest.approx(0.0285)
    status = timing.status()
    assert status["late"] == 1 and status["late_tolerance_ms"] == 2.0
    assert status["tick"]["max_ms"] == pytest.approx(28.5)


def test_the_tolerance_is_a_strict_bound_and_validated() -> None:
    timing = LoopTiming(0.025, late_tolerance=0.002)
    timing.record(due=0.0, start=0.0015, end=0.002)
    timing.record(due=0.025, start=0.0269, end=0.027)  # 1.9 ms: on time
    timing.record(due=0.05, start=0.0521, end=0.053)  # 2.1 ms: late
    assert timing.late == 1
    for bad in (-0.001, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="late_tolerance_s"):
            LoopTiming(0.025, late_tolerance=bad)


class Writer:
    """Writes ``size`` bytes of the tick's number each tick to ``link``."""

    name = "writer"
    period = 0.025

    def __init__(self, link, size: int) -> None:
        self.link, self.size, self.k = link, size, 0
        self.accepted: list[bytes] = []

    def tick(self, now: float) -> None:
        chunk = bytes([self.k % 251]) * self.size
        self.k += 1
        self.link.read_available()
        if self.link.write(chunk) == len(chunk):
            self.accepted.append(chunk)


def test_writes_to_a_pty_nobody_reads_never_block_the_loop() -> None:
    slave, master = open_pty_pair()  # the node writes the master; the slave is never read
    try:
        master.nonblocking_writes(backlog_limit=8192)
        clock = FakeClock()
        node = Writer(master, 2000)
        timing = LoopTiming(node.period)
        result: dict = {}

        def loop() -> None:
            result["stats"] = run_realtime(
                [node], duration=10.0, clock=clock, sleep=clock.sleep, timing={"writer": timing}
            )

        thread = threading.Thread(target=loop, daemon=True)
        thread.start()
        thread.join(timeout=120)  # a blocking write would hang here for good
        assert not thread.is_alive()
        assert result["stats"].ticks["writer"] == 400  # every period kept
        assert timing.late == 0
        # the kernel's buffer is full: a write of one byte more would have had to wait
        with pytest.raises(BlockingIOError):
            os.write(master.port.fd, b"x")
        assert master.dropped_writes == 400 - len(node.accepted) > 0
        assert master.dropped_bytes == 2000 * master.dropped_writes
        assert len(master.backlog) <= 8192
        # what the reader finally gets, then the backlog: the accepted chunks whole, in order
        expected = b"".join(node.accepted)
        got = bytearray()
        while len(got) < len(expected):
            master.read_available()  # hands over more of the backlog
            readable, _, _ = select.select([slave.port.fd], [], [], 5.0)
            if not readable:
                break
            got += os.read(slave.port.fd, 65536)
        assert not master.backlog
        assert bytes(got) == expected
    finally:
        slave.close()


def test_nonblocking_writes_need_a_descriptor_and_a_positive_limit() -> None:
    from rdm.link.serial import open_serial

    loop = open_serial("loop://")
    with pytest.raises(ValueError, match="descriptor"):
        loop.nonblocking_writes()
    slave, _master = open_pty_pair()
    with pytest.raises(ValueError, match="backlog_limit"):
        slave.nonblocking_writes(0)
    slave.close()
    loop.close()


class _OversleepingClock:
    """A fake monotonic clock: each read costs ``read_s``; ``sleep(d)`` returns ``late_s``
    after ``d`` (the OS's wake-up latency)."""

    def __init__(self, read_s: float, late_s: float) -> None:
        self.t, self.read_s, self.late_s = 0.0, read_s, late_s
        self.sleeps: list[float] = []

    def clock(self) -> float:
        self.t += self.read_s
        return self.t

    def sleep(self, d: float) -> None:
        self.sleeps.append(d)
        self.t += d + self.late_s


class _Recorder:
    name, period = "rec", 0.025

    def __init__(self) -> None:
        self.at: list[float] = []

    def tick(self, now: float) -> None:
        self.at.append(now)


def _lateness(spin: float) -> tuple[np.ndarray, _OversleepingClock]:
    fake, node = _OversleepingClock(read_s=1e-6, late_s=7e-4), _Recorder()
    run_realtime([node], duration=0.5, clock=fake.clock, sleep=fake.sleep, spin=spin)
    due = np.arange(len(node.at)) * node.period
    return np.asarray(node.at) - due, fake


def test_spin_starts_each_tick_at_its_due_time_despite_a_late_wake_up() -> None:
    late_sleeping, _ = _lateness(spin=0.0)
    late_spinning, fake = _lateness(spin=1e-3)
    assert len(late_sleeping) == len(late_spinning) == 20
    # sleeping through the wait: every tick after the first starts the wake-up latency late
    assert late_sleeping[1:].min() >= 7e-4
    # polling the last 1 ms: within a few clock reads of the due time
    assert late_spinning.min() >= 0.0 and late_spinning.max() <= 5e-6
    # and the sleep before the poll leaves the spin margin: due - now - spin each time
    assert fake.sleeps and all(0.023 < d < 0.024 for d in fake.sleeps)


def test_a_wake_up_later_than_the_spin_margin_is_not_hidden() -> None:
    fake, node = _OversleepingClock(read_s=1e-6, late_s=2e-3), _Recorder()
    run_realtime([node], duration=0.3, clock=fake.clock, sleep=fake.sleep, spin=1e-3)
    late = np.asarray(node.at[1:]) - np.arange(1, len(node.at)) * node.period
    assert late.min() >= 1e-3 - 1e-5  # 2 ms late wake-up, 1 ms of it covered by the spin


@pytest.mark.parametrize("spin", [-1e-3, float("nan"), float("inf")])
def test_spin_is_validated(spin: float) -> None:
    with pytest.raises(ValueError, match="spin"):
        run_realtime([_Recorder()], duration=0.1, spin=spin)
