"""Values made ready for JSON: RFC 8259 has no NaN or Infinity, so a number that is not
finite is written as null (:func:`nulled`) or found and reported (:func:`non_finite_paths`).
Every JSON document ``rdm`` writes for a user (``--json`` outputs, ``summary.json``) goes
through ``json.dumps(..., allow_nan=False)`` after one of the two."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any


def nulled(value: Any) -> Any:
    """``value`` with every NaN or infinite float replaced by None (JSON null); mappings get
    string keys, tuples become lists and numpy arrays and scalars their Python values."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): nulled(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [nulled(v) for v in value]
    if hasattr(value, "tolist"):
        return nulled(value.tolist())
    return value


def non_finite_paths(value: Any, where: str = "") -> list[str]:
    """The paths (``cog[2]``, ``a.b``) of every NaN or infinite float in ``value``."""
    if isinstance(value, float):
        return [] if math.isfinite(value) else [where or "value"]
    if isinstance(value, Mapping):
        return [
            p
            for k, v in value.items()
            for p in non_finite_paths(v, f"{where}.{k}" if where else str(k))
        ]
    if isinstance(value, (list, tuple)):
        return [p for i, v in enumerate(value) for p in non_finite_paths(v, f"{where}[{i}]")]
    if hasattr(value, "tolist"):
        return non_finite_paths(value.tolist(), where)
    return []
