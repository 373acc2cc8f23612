"""A shared, scaled wall clock for nodes that run as separate processes.

Every process of a process-level run gets the same ``epoch`` (a ``time.monotonic()`` value:
``CLOCK_MONOTONIC`` is one clock for the whole machine) and the same ``scale`` (simulated
seconds per wall second, e.g. 0.05 = 20 wall s per simulated s). Simulated time is then
``(monotonic() - epoch) * scale`` in every process, so the control loops keep their rates in
simulated time however slow the machine is (the vcan VM runs Python ~16x slower than the host).

:func:`run_scaled` ticks nodes on that clock, each at its own period, and measures how late
each tick starts (deadline overruns are reported, never asserted).
"""

from __future__ import annotations

import contextlib
import math
import mmap
import os
import select
import socket
import struct
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from rdm.nodes.base import Node

#: A tick due within this many simulated seconds counts as due (float rounding).
_DUE_SLACK = 1e-7


class SharedTimes:
    """A few float64 slots in a memory-mapped file shared by the processes of a run: slot 0
    is the time the robot process has produced its outputs for (the *gate* of the
    controllers' :class:`ScaledClock`), slots 1.. the time up to which each controller process
    has run all its due ticks (the robot waits for them before its next tick). Put the file
    on a RAM file system (the default temp dir; in the vcan VM that is a tmpfs)."""

    _FMT = struct.Struct("<d")

    def __init__(
        self, path: str | os.PathLike[str], slots: int, init: Sequence[float] | None = None
    ) -> None:
        size = self._FMT.size * slots
        fd = os.open(path, os.O_RDWR | (os.O_CREAT if init is not None else 0), 0o600)
        try:
            if init is not None:
                os.ftruncate(fd, size)
                os.pwrite(fd, struct.pack(f"<{slots}d", *init), 0)
            self._map = mmap.mmap(fd, size)
        finally:
            os.close(fd)
        self.slots = slots

    def set(self, slot: int, t: float) -> None:
        self._FMT.pack_into(self._map, 8 * slot, t)

    def get(self, slot: int) -> float:
        return self._FMT.unpack_from(self._map, 8 * slot)[0]

    def close(self) -> None:
        self._map.close()


class WakeSocket:
    """A wake-up line between processes (Unix datagram socket, abstract namespace): a process
    that waits for another's progress blocks in :meth:`wait` instead of polling, and the other
    calls :meth:`notify` after it made progress. A full queue means a wake is pending already."""

    def __init__(self, token: str, name: str) -> None:
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(f"\0rdm-{token}-wake-{name}")
        self.sock.setblocking(False)
        self._out = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self._out.setblocking(False)
        self.token = token

    def wait(self, timeout: float) -> None:
        """Block until a wake arrives or ``timeout`` wall seconds pass; drain the wakes."""
        if timeout > 0:
            select.select([self.sock], [], [], timeout)
        while True:
            try:
                self.sock.recv(16)
            except BlockingIOError:
                return

    def notify(self, name: str) -> None:
        """Wake the process waiting on ``name`` (lost wakes are harmless: it re-checks)."""
        with contextlib.suppress(OSError):
            self._out.sendto(b"w", f"\0rdm-{self.token}-wake-{name}")

    def close(self) -> None:
        self.sock.close()
        self._out.close()


@dataclass(frozen=True)
class ScaledClock:
    """Simulated time = (``monotonic`` - ``epoch``) * ``scale`` (s); shared across processes.

    With a ``gate`` (a function returning the physics time reached, e.g.
    :meth:`SharedTime.get`) the clock never runs more than ``gate_slack`` ahead of it: when
    the physics process cannot keep up with the scaled wall clock the controllers wait for it
    instead of flying a plant that lags (the run slows down; rates stay right in simulated
    time). Without a gate it is a pure scaled wall clock.
    """

    epoch: float
    scale: float
    monotonic: Callable[[], float] = time.monotonic
    sleeper: Callable[[float], None] = time.sleep
    gate: Callable[[], float] | None = None
    gate_slack: float = 0.001
    #: Longest wall sleep while the gate holds the clock (the gate moves when another
    #: process works, not with the wall clock): a poll, or a block in ``waiter``.
    gate_poll_s: float = 0.0005
    #: ``waiter(wall_s)``: block until the gate may have moved (a :class:`WakeSocket`'s wait)
    #: or ``wall_s`` passed; None = sleep ``gate_poll_s`` and poll.
    waiter: Callable[[float], None] | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"ScaledClock: scale {self.scale!r} must be a positive number")
        if not math.isfinite(self.epoch):
            raise ValueError(f"ScaledClock: epoch {self.epoch!r} must be finite")

    def wall_now(self) -> float:
        """Simulated seconds since the epoch on the scaled wall clock alone (no gate)."""
        return (self.monotonic() - self.epoch) * self.scale

    def now(self) -> float:
        """Simulated seconds since the epoch (negative before it), held back by the gate."""
        t = (self.monotonic() - self.epoch) * self.scale
        if self.gate is not None:
            return min(t, self.gate() + self.gate_slack)
        return t

    def sleep(self, sim_seconds: float) -> None:
        """Sleep ``sim_seconds`` of simulated time at the wall rate (nothing if <= 0); with a
        gate the clock may have advanced less: callers re-check :meth:`now`."""
        if sim_seconds <= 0:
            return
        wall = sim_seconds / self.scale
        if self.gate is not None and self.gate() + self.gate_slack < self.wall_now():
            if self.waiter is not None:
                self.waiter(wall)
                return
            wall = min(wall, self.gate_poll_s)
        self.sleeper(wall)

    def wait_for_epoch(self) -> None:
        """Block until simulated time 0."""
        left = self.epoch - self.monotonic()
        if left > 0:
            self.sleeper(left)


@dataclass
class DeadlineStats:
    """Per node: ticks run, ticks started more than one period late (missed ticks were dropped
    and the schedule re-phased: ``overruns``), and the worst / mean start lateness [sim s]."""

    ticks: dict[str, int] = field(default_factory=dict)
    overruns: dict[str, int] = field(default_factory=dict)
    max_late_s: dict[str, float] = field(default_factory=dict)
    sum_late_s: dict[str, float] = field(default_factory=dict)
    wall_s: float = 0.0
    end_time: float = 0.0

    def as_dict(self) -> dict[str, dict[str, float]]:
        """``{node: {ticks, overruns, max_late_ms, mean_late_ms}}`` (simulated ms)."""
        out: dict[str, dict[str, float]] = {}
        for name, n in self.ticks.items():
            out[name] = {
                "ticks": n,
                "overruns": self.overruns.get(name, 0),
                "max_late_ms": round(1e3 * self.max_late_s.get(name, 0.0), 3),
                "mean_late_ms": round(1e3 * self.sum_late_s.get(name, 0.0) / n, 3) if n else 0.0,
            }
        return out


def run_scaled(
    nodes: Sequence[Node],
    clock: ScaledClock,
    end: float,
    progress: Callable[[float], None] | None = None,
) -> DeadlineStats:
    """Tick ``nodes`` on ``clock`` from simulated time 0 until ``end``; return the stats.

    A node's k-th tick is due at ``k * period``; it is passed that scheduled time (as a
    firmware timer interrupt would stamp it) when it runs within one period of it. A tick that
    starts more than one period late is an overrun: the node is passed the clock's time, its
    missed ticks are dropped and its schedule re-phased (no burst of catch-up ticks). Nodes due
    at the same instant tick in list order. ``progress(t)`` is told after every pass that all
    ticks due at or before ``t`` have run (``inf`` at the end).
    """
    if not nodes:
        raise ValueError("run_scaled: no nodes given")
    for node in nodes:
        p = node.period
        if not (isinstance(p, (int, float)) and math.isfinite(p) and p > 0):
            raise ValueError(f"run_scaled: node {node.name!r} period {p!r} invalid")
    names = [n.name for n in nodes]
    stats = DeadlineStats(
        {n: 0 for n in names},
        {n: 0 for n in names},
        {n: 0.0 for n in names},
        {n: 0.0 for n in names},
    )
    clock.wait_for_epoch()
    wall0 = clock.monotonic()
    due = [0.0] * len(nodes)
    now = clock.now()
    while now < end:
        for i, node in enumerate(nodes):
            if now < due[i] - _DUE_SLACK:
                continue
            late = now - due[i]
            name = node.name
            if late > node.period:
                stats.overruns[name] += 1
                node.tick(now)
                due[i] = now + node.period
            else:
                node.tick(due[i])
                due[i] += node.period
            stats.ticks[name] += 1
            stats.sum_late_s[name] += max(late, 0.0)
            if late > stats.max_late_s[name]:
                stats.max_late_s[name] = late
            now = clock.now()
        if progress is not None:
            progress(min(due) - 2 * _DUE_SLACK)
        wait = min(min(due), end) - clock.now()
        clock.sleep(wait)
        now = clock.now()
    if progress is not None:
        progress(math.inf)
    stats.wall_s = clock.monotonic() - wall0
    stats.end_time = now
    return stats
