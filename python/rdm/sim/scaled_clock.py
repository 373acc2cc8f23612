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

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from rdm.nodes.base import Node

#: A tick due within this many simulated seconds counts as due (float rounding).
_DUE_SLACK = 1e-7


@dataclass(frozen=True)
class ScaledClock:
    """Simulated time = (``monotonic`` - ``epoch``) * ``scale`` (s); shared across processes."""

    epoch: float
    scale: float
    monotonic: Callable[[], float] = time.monotonic

    def __post_init__(self) -> None:
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"ScaledClock: scale {self.scale!r} must be a positive number")
        if not math.isfinite(self.epoch):
            raise ValueError(f"ScaledClock: epoch {self.epoch!r} must be finite")

    def now(self) -> float:
        """Simulated seconds since the epoch (negative before it)."""
        return (self.monotonic() - self.epoch) * self.scale

    def sleep(self, sim_seconds: float) -> None:
        """Sleep ``sim_seconds`` of simulated time (nothing if <= 0)."""
        if sim_seconds > 0:
            time.sleep(sim_seconds / self.scale)

    def wait_for_epoch(self) -> None:
        """Block until simulated time 0."""
        left = self.epoch - self.monotonic()
        if left > 0:
            time.sleep(left)


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


def run_scaled(nodes: Sequence[Node], clock: ScaledClock, end: float) -> DeadlineStats:
    """Tick ``nodes`` on ``clock`` from simulated time 0 until ``end``; return the stats.

    A node's k-th tick is due at ``k * period``; it is passed that scheduled time (as a
    firmware timer interrupt would stamp it) when it runs within one period of it. A tick that
    starts more than one period late is an overrun: the node is passed the clock's time, its
    missed ticks are dropped and its schedule re-phased (no burst of catch-up ticks). Nodes due
    at the same instant tick in list order.
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
    wall0 = time.monotonic()
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
        wait = min(min(due), end) - clock.now()
        clock.sleep(wait)
        now = clock.now()
    stats.wall_s = time.monotonic() - wall0
    stats.end_time = now
    return stats
