"""Every metric of a scenario as a distribution over seeds (``rdm sim SCENARIO --seeds N``).

Seed ``k`` changes what a seed changes in one run (sensor noise, plant randomisation, the
mocap noise; docs/sim.md): each run is the scenario's own ``run`` with its own run folder
(``OUT/SCENARIO-seedK``), executed on any ``concurrent.futures.Executor`` (local processes by
default; a Ray or Dask executor scales the same call out to a cluster, docs/scenarios.md
"Seed sweeps"). For each metric row the sweep reports the paper's value, the median of ours,
the 10th and 90th percentiles, min, max and how many runs passed; a run that fails to finish
is reported with its error and counts as not passed.

The paper reports one run per experiment; the sweep says how far one seed's figure is from
the typical one.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rdm.json_values import nulled

#: Percentiles of the spread.
LOW_PCT, HIGH_PCT = 10, 90


@dataclass(frozen=True)
class RunOutcome:
    """One seed's run: its summary (``summary.json``'s dict) or the error that stopped it."""

    scenario: str
    seed: int
    folder: str | None
    summary: dict[str, Any] | None
    error: str | None = None


@dataclass
class MetricSpread:
    """One metric row over the runs that reported it."""

    name: str
    unit: str
    paper: float | None
    values: list[float] = field(default_factory=list)
    passed: list[bool | None] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        """Paper value, median, percentiles, extremes and pass count (NaN runs excluded
        from the statistics, counted in ``n_nan``)."""
        finite = np.array([v for v in self.values if v is not None and math.isfinite(v)])
        stats: dict[str, Any] = {"median": None, "p10": None, "p90": None, "min": None}
        stats["max"] = None
        if finite.size:
            stats = {
                "median": float(np.median(finite)),
                "p10": float(np.percentile(finite, LOW_PCT)),
                "p90": float(np.percentile(finite, HIGH_PCT)),
                "min": float(finite.min()),
                "max": float(finite.max()),
            }
        verdicts = [p for p in self.passed if p is not None]
        return {
            "name": self.name,
            "unit": self.unit,
            "paper": self.paper,
            "n": len(self.values),
            "n_nan": len(self.values) - int(finite.size),
            **stats,
            "passed": sum(1 for p in verdicts if p),
            "judged": len(verdicts),
            "values": self.values,
        }


def run_seed(
    scenario: str,
    base: str,
    seed: int,
    duration: float | None,
    extra: dict[str, Any],
    replace: bool = False,
) -> RunOutcome:
    """Run one seed of ``scenario`` into ``base`` (in this process); never raises. A
    non-empty run folder is refused unless ``replace`` (as ``rdm sim`` does)."""
    from rdm.scenarios import SCENARIOS
    from rdm.sim.run_folder import run_folders

    sc = SCENARIOS[scenario]
    try:
        if duration is None:  # the scenario's default run (the mission's quick form: its own)
            if scenario == "mission" and extra.get("quick"):
                from rdm.scenarios.mission import QUICK_DURATION

                duration = QUICK_DURATION
            else:
                duration = sc.default_duration
        with run_folders(replace=replace):
            result = sc.run(base, duration=duration, seed=seed, uart="inproc", speed=None, **extra)
        summary = json.loads(Path(result.stack.folder.summary_json).read_text())
        return RunOutcome(scenario, seed, str(result.folder), summary)
    except Exception as exc:  # one failed seed is a row of the report, not a crash
        return RunOutcome(scenario, seed, None, None, f"{type(exc).__name__}: {exc}")


def sweep(
    scenario: str,
    base: str | os.PathLike[str],
    seeds: Sequence[int],
    duration: float | None = None,
    extra: dict[str, Any] | None = None,
    executor: Executor | None = None,
    progress: Any = None,
    replace: bool = False,
) -> list[RunOutcome]:
    """Run ``scenario`` once per seed on ``executor`` (default: a process per core); the
    outcomes in seed order. ``progress(outcome)`` is called as each run ends."""
    calls = [
        (run_seed, scenario, str(base), int(s), duration, dict(extra or {}), replace) for s in seeds
    ]
    return run_calls(calls, executor, progress)


def run_calls(
    calls: Sequence[tuple[Any, ...]],
    executor: Executor | None = None,
    progress: Callable[[Any], None] | None = None,
) -> list[Any]:
    """Each ``(fn, *args)`` of ``calls`` on ``executor`` (default: a process per core); the
    results in call order, ``progress(result)`` as each one is taken."""
    own = executor is None
    ex = ProcessPoolExecutor() if own else executor
    try:
        futures = [ex.submit(*call) for call in calls]
        results = []
        for f in futures:
            result = f.result()
            if progress is not None:
                progress(result)
            results.append(result)
        return results
    finally:
        if own:
            ex.shutdown(cancel_futures=True)


def spreads(outcomes: Sequence[RunOutcome]) -> list[MetricSpread]:
    """The metric rows over the runs, in the order the first run lists them."""
    rows: dict[str, MetricSpread] = {}
    for o in outcomes:
        for m in (o.summary or {}).get("metrics", []):
            row = rows.setdefault(m["name"], MetricSpread(m["name"], m["unit"], m["paper"]))
            ours = m["ours"]
            row.values.append(float("nan") if ours is None else float(ours))
            row.passed.append(m["passed"])
    return list(rows.values())


def report(scenario: str, outcomes: Sequence[RunOutcome]) -> dict[str, Any]:
    """The sweep's JSON document (valid JSON: NaN as null)."""
    return nulled(
        {
            "scenario": scenario,
            "seeds": [o.seed for o in outcomes],
            "runs_completed": sum(1 for o in outcomes if o.summary is not None),
            "runs_all_passed": sum(
                1 for o in outcomes if o.summary is not None and o.summary.get("all_passed")
            ),
            "failed_runs": [{"seed": o.seed, "error": o.error} for o in outcomes if o.error],
            "folders": [o.folder for o in outcomes],
            "metrics": [s.as_dict() for s in spreads(outcomes)],
        }
    )


def _num(v: float | None) -> str:
    return "-" if v is None else f"{v:.4g}"


def format_report(doc: dict[str, Any]) -> str:
    """Columns: metric, paper, median, p10..p90, unit, passed/judged."""
    header = ("metric", "paper", "median", f"p{LOW_PCT}..p{HIGH_PCT}", "unit", "passed")
    rows = [
        (
            m["name"],
            _num(m["paper"]),
            _num(m["median"]),
            f"{_num(m['p10'])}..{_num(m['p90'])}",
            m["unit"],
            f"{m['passed']}/{m['judged']}" if m["judged"] else "-",
        )
        for m in doc["metrics"]
    ]
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(6)]
    line = "  ".join(f"{{:{'<' if i in (0, 4) else '>'}{w}}}" for i, w in enumerate(widths))
    out = [
        f"{doc['scenario']}: {doc['runs_completed']}/{len(doc['seeds'])} runs completed, "
        f"{doc['runs_all_passed']} with every metric passing",
        line.format(*header),
        "  ".join("-" * w for w in widths),
    ]
    out += [line.format(*r) for r in rows]
    out += [f"seed {f['seed']}: {f['error']}" for f in doc["failed_runs"]]
    return "\n".join(out)
