"""Metrics beside the paper's values: a table printer and a JSON summary.

A :class:`Metric` holds our value, the paper's (None when the paper gives none), the unit and
a pass rule: ``max`` (ours <= limit), ``min`` (ours >= limit) or ``near`` (|ours - paper| <=
tol). ``limit`` defaults to the paper's value.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

from rdm.json_values import nulled
from rdm.output_files import write_atomic


@dataclass(frozen=True)
class Metric:
    name: str
    ours: float
    paper: float | None = None
    unit: str = ""
    rule: str = "max"  # "max", "min", "near" or "info" (no verdict)
    limit: float | None = None
    tol: float = 0.0

    def __post_init__(self) -> None:
        if self.rule not in ("max", "min", "near", "info"):
            raise ValueError(f"Metric {self.name!r}: rule {self.rule!r} not max/min/near/info")

    @property
    def passed(self) -> bool | None:
        """True/False, or None when there is nothing to compare with."""
        if self.rule == "info" or not math.isfinite(self.ours):
            return None if self.rule == "info" else False
        bound = self.limit if self.limit is not None else self.paper
        if bound is None:
            return None
        if self.rule == "max":
            return self.ours <= bound
        if self.rule == "min":
            return self.ours >= bound
        return abs(self.ours - bound) <= self.tol


def _num(v: float | None) -> str:
    if v is None:
        return "-"
    if not math.isfinite(v):
        return str(v)
    return f"{v:.4g}"


def format_metrics_table(metrics: Sequence[Metric]) -> str:
    """Columns: metric, paper, ours, unit, pass."""
    header = ("metric", "paper", "ours", "unit", "pass")
    rows = [
        (
            m.name,
            _num(m.paper),
            _num(m.ours),
            m.unit,
            {True: "yes", False: "NO", None: "-"}[m.passed],
        )
        for m in metrics
    ]
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(5)]
    line = "  ".join(f"{{:{'<' if i in (0, 3) else '>'}{w}}}" for i, w in enumerate(widths))
    out = [line.format(*header), "  ".join("-" * w for w in widths)]
    out += [line.format(*r) for r in rows]
    return "\n".join(out)


def summary_dict(metrics: Sequence[Metric], **facts: Any) -> dict[str, Any]:
    """The JSON summary: ``metrics`` (with ``passed``), ``all_passed`` and any run facts."""
    rows = [{**asdict(m), "passed": m.passed} for m in metrics]
    verdicts = [r["passed"] for r in rows if r["passed"] is not None]
    return nulled({"metrics": rows, "all_passed": all(verdicts), **facts})


def write_summary(path: str | os.PathLike[str], metrics: Sequence[Metric], **facts: Any) -> dict:
    """Write :func:`summary_dict` as JSON (sorted keys, NaN as null); returns the dict."""
    doc = summary_dict(metrics, **facts)
    write_atomic(path, json.dumps(doc, indent=2, sort_keys=True, allow_nan=False) + "\n")
    return doc
