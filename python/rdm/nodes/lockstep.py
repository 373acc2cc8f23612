"""Lockstep scheduler: one simulated clock drives the physics and every node (PX4-style lockstep).

Time advances in base ticks of ``dt`` (1 ms = the 1 kHz physics rate). At base tick ``k`` the
simulated time is exactly ``k * dt`` (a product, never a running sum, so no drift) and:

1. the simulated clock is set to ``t = k * dt`` (the in-process CAN channels stamp with it);
2. every node due at ``k`` is ticked with ``t``, **in the order the nodes were given** (a fixed,
   deterministic order: put the plant bridge first, then firmware mirrors, then the PC side,
   then sensor streamers and loggers);
3. *barriers* (objects with ``settle()``, e.g. pty pairs whose kernel delivery is asynchronous)
   are settled, so every byte written in this tick is readable in the next one;
4. the physics (any object with ``step()``) advances one step, to ``(k + 1) * dt``.

A node's period must be a whole multiple of ``dt`` (checked): a 40 Hz onboard node ticks every
25th base tick, a 200 Hz Spinal every 5th, CAN master and Neuron mirrors every tick. An optional
per-node offset (base ticks) staggers nodes of the same rate.

Speed: ``speed=None`` runs as fast as possible; ``speed=x`` paces the loop so simulated time
runs at ``x`` times the wall clock (sleeping when ahead; never skipping ticks when behind: in
lockstep a slow step slows the simulation, it never changes it). The wall clock is read only
here, for pacing and progress reports; nodes see only simulated time. Same seed, same inputs,
same bytes.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

from rdm import _rdm
from rdm.link.inproc_can import SimClock, set_channel_clock

from .base import Node


class Physics(Protocol):
    """What the scheduler needs from a physics engine (e.g. :class:`rdm.plant.Plant`)."""

    def step(self, n: int = 1) -> None: ...


class Barrier(Protocol):
    """Something that must settle before the next tick (e.g. a pty pair)."""

    def settle(self) -> None: ...


@dataclass(frozen=True)
class Progress:
    """What the progress callback receives."""

    sim_time: float  # simulated seconds reached
    wall_time: float  # wall seconds since run() started
    ticks: int  # base ticks done in total
    real_time_factor: float  # simulated seconds per wall second in this run() so far


@dataclass
class LockstepStats:
    """Per-node tick counts and the wall time spent in each node, the physics and barriers."""

    ticks: dict[str, int] = field(default_factory=dict)
    wall_s: dict[str, float] = field(default_factory=dict)
    base_ticks: int = 0
    sim_time: float = 0.0
    wall_time: float = 0.0

    @property
    def real_time_factor(self) -> float:
        return self.sim_time / self.wall_time if self.wall_time > 0 else math.inf


@dataclass
class _Entry:
    node: Node
    every: int
    offset: int


def _due_count(k0: int, k1: int, every: int, offset: int) -> int:
    """How many k in [k0, k1) have ``k % every == offset``."""

    def upto(k: int) -> int:  # count in [0, k)
        return (k - offset + every - 1) // every if k > offset else 0

    return upto(k1) - upto(k0)


class Lockstep:
    """Deterministic lockstep loop over ``nodes`` (list order = tick order) and ``physics``.

    Args:
        nodes: objects with ``name``, ``period`` (seconds) and ``tick(now)``.
        physics: stepped once per base tick after the nodes (None: no physics).
        dt: base tick [s] (the physics step).
        speed: None = as fast as possible; a positive float = real-time factor to pace to.
        can_channels: in-process CAN channel names whose frame timestamps follow this clock.
        barriers: objects whose ``settle()`` runs after the nodes of every tick.
        offsets: optional base-tick offset per node name (0 <= offset < node's tick interval).
        progress: ``progress(Progress)`` every ``progress_every`` simulated seconds.
        profile: measure wall time per node (two ``perf_counter`` calls per tick and node).
        wall_clock, sleep: injectable for tests (used only for pacing and progress).
    """

    def __init__(
        self,
        nodes: Sequence[Node],
        *,
        physics: Physics | None = None,
        dt: float = 0.001,
        speed: float | None = None,
        can_channels: Sequence[str] = (),
        barriers: Sequence[Barrier] = (),
        offsets: dict[str, int] | None = None,
        progress: Callable[[Progress], None] | None = None,
        progress_every: float = 1.0,
        profile: bool = False,
        wall_clock: Callable[[], float] = time.perf_counter,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"Lockstep: dt {dt!r} must be a positive finite number")
        if speed is not None and not (math.isfinite(speed) and speed > 0):
            raise ValueError(f"Lockstep: speed {speed!r} must be None or a positive number")
        if not (math.isfinite(progress_every) and progress_every > 0):
            raise ValueError(f"Lockstep: progress_every {progress_every!r} must be > 0")
        self.dt = float(dt)
        self.physics = physics
        self.speed = speed
        self.barriers = list(barriers)
        self.progress = progress
        self.progress_every = progress_every
        self.profile = profile
        self._wall = wall_clock
        self._sleep = sleep
        self.clock = SimClock(0.0)
        for name in can_channels:
            set_channel_clock(name, self.clock)
        self.k = 0
        self._entries: list[_Entry] = []
        self.stats = LockstepStats()
        self._stop = False
        #: The stop request as the Rust loop reads it (set and cleared with ``_stop``).
        self.stop_flag = _rdm.StopFlag()
        #: A :class:`rdm._rdm.LockstepKernel` running the unpaced loop in Rust
        #: (``rdm.nodes.lockstep_kernel.attach_kernel``); None: the Python loop.
        self.kernel = None
        offsets = dict(offsets or {})
        names = set()
        for node in nodes:
            self._entries.append(self._entry(node, offsets.pop(node.name, 0)))
            if node.name in names:
                raise ValueError(f"Lockstep: two nodes named {node.name!r}")
            names.add(node.name)
        if offsets:
            raise ValueError(f"Lockstep: offsets for unknown nodes {sorted(offsets)}")
        self.stats.ticks = {e.node.name: 0 for e in self._entries}
        self.stats.wall_s = {e.node.name: 0.0 for e in self._entries}
        self.stats.wall_s["<physics>"] = 0.0
        self.stats.wall_s["<barriers>"] = 0.0
        # Precomputed schedule: for each residue of k modulo the lcm of intervals, who ticks.
        self._schedule = self._build_schedule()

    def _entry(self, node: Node, offset: int) -> _Entry:
        period = getattr(node, "period", None)
        name = getattr(node, "name", None)
        if not isinstance(name, str) or not callable(getattr(node, "tick", None)):
            raise TypeError(f"Lockstep: {node!r} is not a node (name, period, tick)")
        if not (isinstance(period, (int, float)) and math.isfinite(period) and period > 0):
            raise ValueError(f"Lockstep: node {name!r} period {period!r} must be > 0")
        every = round(period / self.dt)
        if every < 1 or abs(every * self.dt - period) > 1e-9 * max(1.0, period):
            raise ValueError(
                f"Lockstep: node {name!r} period {period!r} s is not a whole multiple of "
                f"dt {self.dt!r} s"
            )
        if not isinstance(offset, int) or not 0 <= offset < every:
            raise ValueError(f"Lockstep: node {name!r} offset {offset!r} not in 0..{every - 1}")
        return _Entry(node, every, offset)

    def _build_schedule(self) -> list[list[_Entry]]:
        cycle = 1
        for e in self._entries:
            cycle = cycle * e.every // math.gcd(cycle, e.every)
        if cycle > 100_000:  # unusual periods: fall back to checking every entry each tick
            return []
        return [[e for e in self._entries if r % e.every == e.offset] for r in range(cycle)]

    # ------------------------------------------------------------------ running
    @property
    def time(self) -> float:
        """Simulated time of the next tick (seconds)."""
        return self.k * self.dt

    @property
    def nodes(self) -> list[Node]:
        return [e.node for e in self._entries]

    def stop(self) -> None:
        """Stop the current :meth:`run` after the tick in progress (callable from a node)."""
        self._stop = True
        self.stop_flag.set()

    def step(self) -> None:
        """One base tick: due nodes in order, barriers, one physics step."""
        k = self.k
        t = k * self.dt
        self.clock.now = t
        sched = self._schedule
        due = (
            sched[k % len(sched)]
            if sched
            else [e for e in self._entries if k % e.every == e.offset]
        )
        ticks = self.stats.ticks
        if self.profile:
            wall = self.stats.wall_s
            clock = time.perf_counter
            for e in due:
                t0 = clock()
                e.node.tick(t)
                wall[e.node.name] += clock() - t0
                ticks[e.node.name] += 1
            t0 = clock()
            for b in self.barriers:
                b.settle()
            t1 = clock()
            if self.physics is not None:
                self.physics.step(1)
            wall["<barriers>"] += t1 - t0
            wall["<physics>"] += clock() - t1
        else:
            for e in due:
                e.node.tick(t)
                ticks[e.node.name] += 1
            for b in self.barriers:
                b.settle()
            if self.physics is not None:
                self.physics.step(1)
        self.k = k + 1
        self.stats.base_ticks += 1
        self.stats.sim_time = self.k * self.dt

    def run(self, duration: float) -> LockstepStats:
        """Advance ``duration`` simulated seconds (rounded to whole ticks); returns the stats."""
        if not (math.isfinite(duration) and duration >= 0):
            raise ValueError(f"Lockstep.run: duration {duration!r} must be >= 0")
        return self.run_ticks(round(duration / self.dt))

    def run_until(self, sim_time: float) -> LockstepStats:
        """Advance until the next tick would be at ``sim_time`` or later."""
        return self.run_ticks(max(0, math.ceil(sim_time / self.dt - 1e-9) - self.k))

    def run_ticks(self, n: int) -> LockstepStats:
        """Advance ``n`` base ticks (fewer if :meth:`stop` is called)."""
        self._stop = False
        self.stop_flag.clear()
        wall0 = self._wall()
        sim0 = self.time
        next_report = sim0 + self.progress_every
        if self.speed is None and self.progress is None and not self.profile and self._schedule:
            if self.kernel is not None and not self.barriers:
                self._run_kernel(int(n))
            else:
                self._run_fast(int(n))
            self.stats.wall_time += self._wall() - wall0
            return self.stats
        for _ in range(int(n)):
            self.step()
            sim = self.time
            if self.speed is not None:
                ahead = (sim - sim0) / self.speed - (self._wall() - wall0)
                if ahead > 0:
                    self._sleep(ahead)
            if self.progress is not None and sim >= next_report - 1e-12:
                next_report += self.progress_every
                self.progress(self._progress(sim, sim0, wall0))
            if self._stop:
                break
        elapsed = self._wall() - wall0
        self.stats.wall_time += elapsed
        return self.stats

    def _run_fast(self, n: int) -> None:
        """:meth:`step` ``n`` times with everything hoisted out of the loop (no pacing, no
        progress, no profile): the same ticks in the same order. Per-node tick counts are
        added once at the end (stopping early counts only the ticks that ran)."""
        sched = [[e.node.tick for e in slot] for slot in self._schedule]
        cycle = len(sched)
        barriers = [b.settle for b in self.barriers]
        physics = self.physics.step if self.physics is not None else None
        clock = self.clock
        dt = self.dt
        k0 = k = self.k
        try:
            for _ in range(n):
                t = k * dt
                clock.now = t
                for tick in sched[k % cycle]:
                    tick(t)
                for settle in barriers:
                    settle()
                if physics is not None:
                    physics(1)
                k += 1
                self.k = k
                if self._stop:
                    break
        finally:
            self._count(k0, k)

    def _run_kernel(self, n: int) -> None:
        """:meth:`_run_fast` through :attr:`kernel` (the same ticks in the same order). The
        nodes' ``tick`` attributes are read now, as :meth:`_run_fast` reads them: a node
        whose ``tick`` was replaced (a wrapper) runs the replacement, never its fast path."""
        k0 = self.k
        nodes = [e.node for e in self._entries]
        ticks = [node.tick for node in nodes]
        own = [
            getattr(tick, "__func__", None) is getattr(type(node), "tick", None)
            for node, tick in zip(nodes, ticks, strict=True)
        ]
        try:
            self.kernel.run(k0, n, ticks, own)
        finally:
            self._count(k0, self.kernel.k)

    def _count(self, k0: int, k: int) -> None:
        """Per-node tick counts and totals after the base ticks ``k0 .. k-1`` ran."""
        self.k = k
        ticks = self.stats.ticks
        for e in self._entries:
            ticks[e.node.name] += _due_count(k0, k, e.every, e.offset)
        self.stats.base_ticks += k - k0
        self.stats.sim_time = k * self.dt

    def _progress(self, sim: float, sim0: float, wall0: float) -> Progress:
        wall = self._wall() - wall0
        rtf = (sim - sim0) / wall if wall > 0 else math.inf
        return Progress(sim, wall, self.k, rtf)

    def profile_table(self) -> str:
        """Wall time per node / physics / barriers (needs ``profile=True``), largest first."""
        total = sum(self.stats.wall_s.values()) or 1.0
        rows = sorted(self.stats.wall_s.items(), key=lambda kv: -kv[1])
        lines = [f"{'part':<24} {'wall s':>9} {'share':>6} {'ticks':>8}"]
        for name, wall in rows:
            n = self.stats.ticks.get(name, self.stats.base_ticks)
            lines.append(f"{name:<24} {wall:9.3f} {wall / total:6.1%} {n:8d}")
        return "\n".join(lines)
