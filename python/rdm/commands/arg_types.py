"""argparse value types shared by the sub-commands: a bad value is an argparse error (a
message and exit 2), never a traceback from deep inside a run."""

from __future__ import annotations

import argparse
import math


def positive_finite(text: str) -> float:
    """A finite number > 0 (seconds, scales, rates)."""
    try:
        v = float(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: not a number") from exc
    if not (v > 0 and math.isfinite(v)):
        raise argparse.ArgumentTypeError(f"{text!r} must be finite and > 0")
    return v


def seed(text: str) -> int:
    """A random seed: an integer >= 0 (numpy's seeds)."""
    try:
        v = int(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: not an integer") from exc
    if v < 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be >= 0 (numpy's seeds)")
    return v
