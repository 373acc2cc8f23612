"""Findings that are known and open, recognised so that a campaign counts them and goes
on (every other exception stops the target as a crash). Each entry names where it is
reported; ``tests/test_fuzz_short.py`` holds a strict ``xfail`` regression test per entry
with the committed reproducer from ``fuzz/regressions/``, which starts to fail (XPASS)
the day the owner's fix lands, so the entry is then removed here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Known:
    """A known open finding: ``name``, where it lives, and how it is recognised."""

    name: str
    target: str
    where: str
    status: str

    def matches(self, exc: BaseException | None, data: bytes, signal: int | None) -> bool:
        return MATCHERS[self.name](exc, data, signal)


def _model_nan(exc: BaseException | None, data: bytes, signal: int | None) -> bool:
    from fuzz_targets.base import NonFinite

    return isinstance(exc, NonFinite) and "evaluate(0)" in str(exc)


MATCHERS: dict[str, Any] = {
    "model-huge-origin-nan": _model_nan,
}

KNOWN = [
    Known(
        "model-huge-origin-nan",
        "description",
        "rdm_core model: a URDF origin or mass near the double's limit (xyz='0 -1e308 0') is "
        "accepted (finite), and evaluate(q = 0) returns NaN inertia / infinite CoG",
        "open: issue 28 item 9 (the description loader's checks)",
    ),
]


def classify(target: str, exc: BaseException | None, data: bytes, signal: int | None) -> str:
    """The name of the known finding this is, or "" for a new one."""
    for known in KNOWN:
        if known.target == target and known.matches(exc, data, signal):
            return known.name
    return ""
