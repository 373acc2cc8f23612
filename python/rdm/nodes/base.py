"""The pattern every node shares (Neuron mirror, CAN master, Spinal mirror, onboard node, plant).

A node

* never reads a wall clock: the caller passes the time in, ``tick(now)`` in seconds since the
  node's epoch (a lockstep scheduler passes simulated time, :func:`run_realtime` passes
  ``time.monotonic()`` minus its start);
* owns the ports it was given at construction (a python-can ``BusABC``, a serial port ...) and
  never blocks on them: each tick it drains whatever is pending (:func:`drain`), acts, sends;
* has a ``name`` (for logs) and a ``period`` (seconds between ticks it wants).

The same node object therefore runs in lockstep (one process, simulated clock, deterministic)
and in real time (own process, real or virtual ports) without change.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import can

if TYPE_CHECKING:
    from rdm.nodes.loop_timing import LoopTiming

#: Upper bound of frames taken from one port in one tick, so a flooded bus cannot stall a node.
MAX_FRAMES_PER_TICK = 10_000
#: A tick due within this many seconds counts as due (clock rounding must not spin the loop).
_DUE_SLACK = 1e-7


@runtime_checkable
class Node(Protocol):
    """What a scheduler needs from a node."""

    name: str
    #: Seconds between two ticks the node wants (0.001 for a 1 kHz firmware task).
    period: float

    def tick(self, now: float) -> None:
        """Advance to time ``now`` (seconds, monotonic, never decreasing); drain ports; send."""
        ...


def to_ms(now: float) -> int:
    """Seconds to whole milliseconds (floor), robust to float sums like ``0.001 * 3``."""
    return math.floor(now * 1000.0 + 1e-6)


def drain(bus: can.BusABC, limit: int = MAX_FRAMES_PER_TICK) -> Iterator[can.Message]:
    """Every frame pending on ``bus`` right now, without blocking (``recv(timeout=0)`` loop)."""
    for _ in range(limit):
        msg = bus.recv(timeout=0)
        if msg is None:
            return
        yield msg


@dataclass
class RealtimeStats:
    """What :func:`run_realtime` did: ticks per node, late ticks re-phased, wall time run."""

    ticks: dict[str, int] = field(default_factory=dict)
    #: Ticks that came more than one period late (the schedule was re-phased, not caught up).
    overruns: dict[str, int] = field(default_factory=dict)
    #: Node time of the last loop pass (``start_time`` + wall seconds run).
    end_time: float = 0.0


def run_realtime(
    nodes: Sequence[Node],
    duration: float | None = None,
    stop: threading.Event | None = None,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
    start_time: float = 0.0,
    timing: Mapping[str, LoopTiming] | None = None,
    spin: float = 0.0,
) -> RealtimeStats:
    """Tick ``nodes`` on the wall clock, each at its own ``period``, until ``duration`` seconds
    have passed or ``stop`` is set. Times passed to ``tick`` start at ``start_time`` (node
    time must never go back: to resume nodes, pass the previous run's ``end_time``).

    A node that falls more than one period behind is re-phased (its missed ticks are dropped,
    counted in ``overruns``) rather than ticked in a burst. Nodes due at the same instant tick
    in list order. Signal handling is the caller's job: set ``stop`` from the handler.

    ``timing``: per node name, a :class:`~rdm.nodes.loop_timing.LoopTiming` that records each
    of that node's ticks (when it was due, when it started and ended on ``clock``); the
    caller reads it while the loop runs (a status node) and after.

    ``spin``: the last ``spin`` seconds before the next due tick are waited by polling
    ``clock`` instead of sleeping through them, so the tick starts within a clock read of its
    due time rather than after the OS's wake-up latency (one CPU stays busy for ``spin`` of
    every period). ``0`` sleeps the whole wait.
    """
    if not nodes:
        raise ValueError("run_realtime: no nodes given")
    for node in nodes:
        if not (isinstance(node.period, (int, float)) and math.isfinite(node.period)):
            raise ValueError(f"run_realtime: node {node.name!r} period {node.period!r} invalid")
        if node.period <= 0:
            raise ValueError(f"run_realtime: node {node.name!r} period must be > 0")
    if not (math.isfinite(spin) and spin >= 0.0):
        raise ValueError(f"run_realtime: spin {spin!r} must be finite and >= 0")
    stop = stop or threading.Event()
    stats = RealtimeStats({n.name: 0 for n in nodes}, {n.name: 0 for n in nodes})
    due = [0.0] * len(nodes)
    timed = [None if timing is None else timing.get(n.name) for n in nodes]
    start = clock()
    now = 0.0
    while not stop.is_set():
        now = clock() - start
        if duration is not None and now >= duration:
            break
        for i, node in enumerate(nodes):
            if now >= due[i] - _DUE_SLACK:
                record = timed[i]
                if record is None:
                    node.tick(start_time + now)
                else:
                    began = clock() - start
                    node.tick(start_time + now)
                    record.record(due[i], began, clock() - start)
                stats.ticks[node.name] += 1
                due[i] += node.period
                if now - due[i] > node.period:
                    stats.overruns[node.name] += 1
                    due[i] = now + node.period
        target = min(due) if duration is None else min(min(due), duration)
        wait = target - (clock() - start)
        if wait > spin:
            sleep(wait - spin)
        if spin > 0.0:  # ends when the clock reaches the target (or at a stop)
            while clock() - start < target - _DUE_SLACK and not stop.is_set():
                pass
    stats.end_time = start_time + now
    return stats
