"""Findings that are known and open, recognised so that a campaign counts them and goes
on (every other exception stops the target as a crash). Each entry names where it is
reported; ``tests/test_fuzz_short.py`` holds a strict ``xfail`` regression test per entry
with the committed reproducer from ``fuzz/regressions/``, which starts to fail (XPASS)
the day the owner's fix lands, so the entry is then removed here.
"""

from __future__ import annotations

import traceback
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


def _ground_t(exc: BaseException | None, data: bytes, signal: int | None) -> bool:
    if not isinstance(exc, OverflowError) or "int too large to convert to float" not in str(exc):
        return False
    frames = traceback.extract_tb(exc.__traceback__)
    return any(f.filename.endswith(("ground/auth.py", "ground/commands.py")) for f in frames)


def nesting_depth(text: bytes) -> int:
    """Deepest element nesting of XML-ish ``text``: ``<name`` opens, ``</`` and ``/>``
    close (a plain count: comments and attribute values are not special-cased)."""
    depth = best = 0
    end = -1  # the first '>' at or after the current '<' (one pass over the text)
    k = text.find(b"<")
    while k >= 0:
        nxt = text[k + 1 : k + 2]
        if nxt == b"/":
            depth -= 1
        elif nxt and nxt not in b"!?":
            depth += 1
            best = max(best, depth)
        if 0 <= end < k:
            end = -1
        if end < 0:
            end = text.find(b">", k)
            if end < 0:
                end = len(text) + 1  # none left: no '/>' closes
        if end <= len(text) and text[end - 1 : end] == b"/":
            depth -= 1
        k = text.find(b"<", k + 1)
    return best


def _urdf_deep(exc: BaseException | None, data: bytes, signal: int | None) -> bool:
    if signal is None:
        return False
    from fuzz_targets.description import split

    return nesting_depth(split(data)[0].encode()) >= 1000


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
