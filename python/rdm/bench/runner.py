"""Run the registered cases and assemble the report document."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from rdm.bench import cases as case_mod
from rdm.bench.machine import cpu_ticks, load_average, machine_info, steal_share
from rdm.bench.report import to_json


def select_cases(only: Sequence[str] | None) -> list[case_mod.Case]:
    """Cases named by group (``lqi``) or by measurement (``lqi_warm_rust``); all if None.

    Raises ``ValueError`` naming the valid choices for an unknown name.
    """
    if not only:
        return list(case_mod.CASES.values())
    chosen: list[case_mod.Case] = []
    for name in only:
        match = [c for c in case_mod.CASES.values() if name == c.name or name in c.measurements]
        if not match:
            valid = sorted(
                [*case_mod.CASES, *(m for c in case_mod.CASES.values() for m in c.measurements)]
            )
            raise ValueError(f"unknown case {name!r}; choose from {', '.join(valid)}")
        for c in match:
            if c not in chosen:
                chosen.append(c)
    return chosen


def timer_overhead() -> dict[str, float]:
    """Median cost of one timer pair in Rust (``Instant``) and Python (``perf_counter_ns``)."""
    from rdm import _rdm

    rust = np.asarray(_rdm.time_timer_overhead(10_000))
    clock = time.perf_counter_ns
    py = np.empty(10_000, dtype=np.int64)
    for i in range(py.size):
        t0 = clock()
        py[i] = clock() - t0
    return {"rust_median_ns": float(np.median(rust)), "python_median_ns": float(np.median(py))}


def stderr_progress(total: int) -> Callable[[int, str], None]:
    """``[k/total] message`` lines on stderr."""

    def report(k: int, message: str) -> None:
        print(f"[{k}/{total}] {message}", file=sys.stderr, flush=True)

    return report


def run_benchmarks(
    only: Sequence[str] | None = None,
    iterations: int | None = None,
    quick: bool = False,
    command: str = "rdm bench",
    blas_pinned: bool = False,
    progress: Callable[[int, str], None] | None = None,
) -> dict[str, Any]:
    """Run the selected cases; returns the ``rdm.bench/1`` document (see report.py)."""
    if iterations is not None and iterations < 1:
        raise ValueError("`iterations` must be >= 1")
    selected = select_cases(only)
    total = len(selected)
    show = progress or stderr_progress(total)
    machine = machine_info(blas_pinned)
    overhead = timer_overhead()
    results: list[tuple[str, case_mod.Measurement]] = []
    for k, case in enumerate(selected, start=1):
        show(k, f"{case.name}: {case.title}")
        ctx = case_mod.Context(
            iterations=iterations,
            quick=quick,
            progress=lambda msg, k=k: show(k, msg),
        )
        for m in case.run(ctx):
            m.evaluate_targets()
            results.append((case.name, m))
    machine["load_average_end"] = load_average()
    machine["cpu_steal_share"] = steal_share(machine.pop("cpu_ticks_start"), cpu_ticks())
    return to_json(results, machine, command, overhead)
