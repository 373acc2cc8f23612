"""Lockstep scheduler: one simulated clock drives the physics and every node (PX4-style lockstep).

Time advances in base ticks of ``dt`` (1 ms = the 1 kHz physics rate). At base tick ``k`` the
simulated time is exactly ``k * dt`` (a product, never a running sum, so no drift) and:

1. the simulated clock reads ``t = k * dt`` whenever Python code runs in the tick (the
   in-process CAN channels stamp with it);
2. every node due at ``k`` is ticked with ``t``, **in the order the nodes were given** (a fixed,
   deterministic order: put the plant bridge first, then firmware mirrors, then the PC side,
   then sensor streamers and loggers);
3. *barriers* (objects with ``settle()``, e.g. pty pairs whose kernel delivery is asynchronous)
   are settled, so every byte written in this tick is readable in the next one;
4. the physics (any object with ``step()``) advances one step, to ``(k + 1) * dt``.
5. a run (not :meth:`Lockstep.step`) sleeps while ahead of ``speed``, reports ``progress``
   when due, and ends here when :meth:`Lockstep.stop` was called.

A node's period must be a whole multiple of ``dt`` (checked): a 40 Hz onboard node ticks every
25th base tick, a 200 Hz Spinal every 5th, CAN master and Neuron mirrors every tick. An optional
per-node offset (base ticks) staggers nodes of the same rate.

Speed: ``speed=None`` runs as fast as possible; ``speed=x`` paces the loop so simulated time
runs at ``x`` times the wall clock (sleeping when ahead; never skipping ticks when behind: in
lockstep a slow step slows the simulation, it never changes it). The wall clock is read only
by the loop, for pacing and progress reports; nodes see only simulated time. Same seed, same
inputs, same bytes.

The loop itself is :class:`rdm._rdm.LockstepKernel` (Rust; the schedule is
``rdm_core::sim::tick_schedule``); :class:`Lockstep` is its face. Fast parts for the
simulated stack's steady milliseconds attach to it through
:func:`rdm.nodes.lockstep_kernel.attach_kernel`; without them every tick is the node's own
Python ``tick``.
"""

from __future__ import annotations

import math
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
        profile: measure wall time per node, the barriers and the physics.
        wall_clock, sleep: injectable for tests (used only for pacing and progress; None: the
            process's monotonic clock and sleep).
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
        wall_clock: Callable[[], float] | None = None,
        sleep: Callable[[float], None] | None = None,
    ) -> None:
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"Lockstep: dt {dt!r} must be a positive finite number")
        self.physics = physics
        self.barriers = list(barriers)
        self.progress = progress
        self.clock = SimClock(0.0)
        for name in can_channels:
            set_channel_clock(name, self.clock)
        #: The stop request the loop reads after every tick.
        self.stop_flag = _rdm.StopFlag()
        self._dt = float(dt)
        self._speed = speed
        self._tick = _rdm.TickCounter()  # k, readable from inside a tick
        self._nodes = list(nodes)
        offsets = dict(offsets or {})
        names: list[str] = []
        periods: list[float] = []
        offs: list[int] = []
        for node in self._nodes:
            name, period = _check_node(node)
            if name in names:
                raise ValueError(f"Lockstep: two nodes named {name!r}")
            offset = offsets.pop(name, 0)
            if not isinstance(offset, int) or offset < 0:
                raise ValueError(f"Lockstep: node {name!r} offset {offset!r} must be an int >= 0")
            names.append(name)
            periods.append(period)
            offs.append(offset)
        if offsets:
            raise ValueError(f"Lockstep: offsets for unknown nodes {sorted(offsets)}")
        self._names = names
        report = None
        if progress is not None:

            def report(sim: float, wall: float, ticks: int, rtf: float) -> None:
                progress(Progress(sim, wall, ticks, rtf))

        #: The loop (:class:`rdm._rdm.LockstepKernel`).
        self.kernel = _rdm.LockstepKernel(
            float(dt),
            names,
            periods,
            offs,
            [node.tick for node in self._nodes],
            physics.step if physics is not None else None,
            self.clock,
            self.stop_flag,
            self._tick,
            [b.settle for b in self.barriers],
            speed,
            report,
            progress_every,
            profile,
            wall_clock,
            sleep,
        )

    # ------------------------------------------------------------------ running
    @property
    def dt(self) -> float:
        """The base tick [s]."""
        return self._dt

    @property
    def speed(self) -> float | None:
        """The real-time factor runs are paced to (None: as fast as possible)."""
        return self._speed

    @property
    def k(self) -> int:
        """The next base tick (during a tick: the tick in progress)."""
        return self._tick.get()

    @property
    def time(self) -> float:
        """Simulated time of the next tick (seconds)."""
        return self._tick.get() * self._dt

    @property
    def nodes(self) -> list[Node]:
        return list(self._nodes)

    @property
    def profile(self) -> bool:
        """Whether the loop measures wall time per node, the barriers and the physics."""
        return self.kernel.profile

    @profile.setter
    def profile(self, on: bool) -> None:
        self.kernel.profile = on

    def stop(self) -> None:
        """Stop the current :meth:`run` after the tick in progress (callable from a node)."""
        self.stop_flag.set()

    def step(self) -> None:
        """One base tick: due nodes in order, barriers, one physics step (no pacing, no
        progress report)."""
        self._advance(1, paced=False)

    def run(self, duration: float) -> LockstepStats:
        """Advance ``duration`` simulated seconds (rounded to whole ticks); returns the stats."""
        if not (math.isfinite(duration) and duration >= 0):
            raise ValueError(f"Lockstep.run: duration {duration!r} must be >= 0")
        return self.run_ticks(round(duration / self.dt))

    def run_until(self, sim_time: float) -> LockstepStats:
        """Advance until the next tick would be at ``sim_time`` or later."""
        return self.run_ticks(max(0, math.ceil(sim_time / self.dt - 1e-9) - self.k))

    def run_ticks(self, n: int) -> LockstepStats:
        """Advance ``n`` base ticks (fewer if :meth:`stop` is called), paced to ``speed``."""
        self.stop_flag.clear()
        self._advance(int(n), paced=True)
        return self.stats

    def _advance(self, n: int, *, paced: bool) -> None:
        """``n`` base ticks in the kernel. The nodes' ``tick`` attributes are read at each
        call: a node whose ``tick`` was replaced (a wrapper) runs the replacement, never a
        fast part."""
        nodes = self._nodes
        ticks = [node.tick for node in nodes]
        own = [
            getattr(tick, "__func__", None) is getattr(type(node), "tick", None)
            for node, tick in zip(nodes, ticks, strict=True)
        ]
        self.kernel.run(n, ticks, own, paced)

    @property
    def stats(self) -> LockstepStats:
        """Per-node tick counts, wall time per part (with ``profile``), totals."""
        s = self.kernel.stats()
        names = self._names
        ticks = {n: f + p for n, f, p in zip(names, s["fast"], s["python"], strict=True)}
        wall = {
            n: (f + p) * 1e-9 for n, f, p in zip(names, s["fast_ns"], s["python_ns"], strict=True)
        }
        wall["<physics>"] = s["physics_ns"] * 1e-9
        wall["<barriers>"] = s["barriers_ns"] * 1e-9
        return LockstepStats(ticks, wall, s["base_ticks"], self.time, s["wall_time"])

    def profile_table(self) -> str:
        """Wall time per node / physics / barriers (needs ``profile=True``), largest first."""
        stats = self.stats
        total = sum(stats.wall_s.values()) or 1.0
        rows = sorted(stats.wall_s.items(), key=lambda kv: -kv[1])
        lines = [f"{'part':<24} {'wall s':>9} {'share':>6} {'ticks':>8}"]
        for name, wall in rows:
            n = stats.ticks.get(name, stats.base_ticks)
            lines.append(f"{name:<24} {wall:9.3f} {wall / total:6.1%} {n:8d}")
        return "\n".join(lines)


def _check_node(node: object) -> tuple[str, float]:
    """``node``'s name and period, or a one-line error naming what is missing."""
    period = getattr(node, "period", None)
    name = getattr(node, "name", None)
    if not isinstance(name, str) or not callable(getattr(node, "tick", None)):
        raise TypeError(f"Lockstep: {node!r} is not a node (name, period, tick)")
    if not isinstance(period, (int, float)) or isinstance(period, bool):
        raise ValueError(f"Lockstep: node {name!r} period {period!r} must be a number > 0")
    return name, float(period)
