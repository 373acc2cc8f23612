"""The fault campaign: every mission fault over many seeds (``rdm sim mission --fault all
--seeds N``).

Each fault of :data:`rdm.scenarios.mission.FAULTS` runs as the mission's quick form (take
off, go to, land; the perched faults perch first) once per seed, on any
``concurrent.futures.Executor`` (:func:`rdm.scenarios.seed_sweep.sweep`). Per fault the
campaign counts the runs, the safe ends (disarmed on the floor or held perched, tilt never
above 30 deg in flight, no duty above ``motor_info``'s maximum: the mission's own record),
the detections (the monitor or counter that shows the node noticed, ``mission._DETECTED_BY``),
the time from the fault to the node monitor's trip (the safe state of a perched fault: held)
and the time from the fault to touchdown.
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from typing import Any

import numpy as np

from rdm.json_values import nulled

from .seed_sweep import RunOutcome, sweep


def fault_runs(
    fault: str,
    base: str | os.PathLike[str],
    seeds: Sequence[int],
    executor: Executor | None = None,
    progress: Callable[[RunOutcome], None] | None = None,
    replace: bool = False,
) -> list[RunOutcome]:
    """The quick mission with ``fault`` once per seed."""
    from .mission import DEFAULT_DURATION, PERCHED_FAULTS, QUICK_DURATION

    perched = fault in PERCHED_FAULTS
    duration = DEFAULT_DURATION if perched else QUICK_DURATION
    extra = {"fault": fault, "quick": not perched}
    return sweep("mission", base, seeds, duration, extra, executor, progress, replace)


def fault_row(fault: str, outcomes: Sequence[RunOutcome]) -> dict[str, Any]:
    """One fault's line of the campaign from its runs' mission records."""
    records = [o.summary["mission"] for o in outcomes if o.summary is not None]
    to_safe = [
        r["touchdown_s"] - r["fault_at_s"]
        for r in records
        if r["outcome"] == "landed" and r["touchdown_s"] is not None and r["fault_at_s"]
    ]
    to_detection = [
        r["detected_at_s"] - r["fault_at_s"]
        for r in records
        if r.get("detected_at_s") is not None and r["fault_at_s"] is not None
    ]
    detected = [r["fault_detected"] for r in records if r["fault_detected"] is not None]
    return nulled(
        {
            "fault": fault,
            "runs": len(outcomes),
            "completed": len(records),
            "safe": sum(1 for r in records if r["safe"]),
            "detected": sum(1 for d in detected if d) if detected else None,
            "outcomes": dict(Counter(r["outcome"] for r in records)),
            "max_tilt_deg": max((r["max_tilt_deg"] for r in records), default=None),
            "fault_to_touchdown_s": {
                "median": float(np.median(to_safe)) if to_safe else None,
                "max": float(max(to_safe)) if to_safe else None,
            },
            "fault_to_detection_s": {
                "median": float(np.median(to_detection)) if to_detection else None,
                "max": float(max(to_detection)) if to_detection else None,
            },
            "failed_runs": [{"seed": o.seed, "error": o.error} for o in outcomes if o.error],
            "unsafe_seeds": [
                o.seed
                for o in outcomes
                if o.summary is not None and not o.summary["mission"]["safe"]
            ],
        }
    )


def _num(v: float | None, fmt: str = "{:.1f}") -> str:
    return "-" if v is None else fmt.format(v)


def format_campaign(rows: Sequence[dict[str, Any]]) -> str:
    """Columns: fault, runs, safe, detected, outcomes, max tilt, fault -> detection (a node
    monitor's trip), fault -> touchdown."""
    header = (
        "fault",
        "runs",
        "safe",
        "detected",
        "outcomes",
        "max tilt deg",
        "to detection s",
        "to touchdown s",
    )
    lines = [
        (
            r["fault"],
            str(r["runs"]),
            str(r["safe"]),
            "-" if r["detected"] is None else str(r["detected"]),
            " ".join(f"{k} {v}" for k, v in sorted(r["outcomes"].items())),
            _num(r["max_tilt_deg"]),
            f"{_num(r['fault_to_detection_s']['median'], '{:.2f}')} "
            f"(max {_num(r['fault_to_detection_s']['max'], '{:.2f}')})",
            f"{_num(r['fault_to_touchdown_s']['median'])} "
            f"(max {_num(r['fault_to_touchdown_s']['max'])})",
        )
        for r in rows
    ]
    widths = [max(len(x[i]) for x in [header, *lines]) for i in range(len(header))]
    fmt = "  ".join(f"{{:{'<' if i in (0, 4) else '>'}{w}}}" for i, w in enumerate(widths))
    out = [fmt.format(*header), "  ".join("-" * w for w in widths)]
    out += [fmt.format(*x) for x in lines]
    for r in rows:
        out += [f"{r['fault']} seed {f['seed']}: {f['error']}" for f in r["failed_runs"]]
    return "\n".join(out)
