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


#: Name -> recogniser (exception, input, signal) -> bool of each known open finding.
MATCHERS: dict[str, Any] = {}

#: The known open findings; none is open (the closed ones are in docs/fuzzing.md, "Findings").
KNOWN: list[Known] = []


def classify(target: str, exc: BaseException | None, data: bytes, signal: int | None) -> str:
    """The name of the known finding this is, or "" for a new one."""
    for known in KNOWN:
        if known.target == target and known.matches(exc, data, signal):
            return known.name
    return ""
