"""argparse value types shared by the sub-commands: a bad value is an argparse error (a
message and exit 2), never a traceback from deep inside a run."""

from __future__ import annotations

import argparse
import math
import re


def finite(text: str) -> float:
    """A finite number (heights, offsets)."""
    try:
        v = float(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: not a number") from exc
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"{text!r} must be finite")
    return v


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


def finite_list(text: str) -> list[float]:
    """A comma-separated list of finite numbers (``--q 0.5,-0.5,0``); the message names the
    0-based index of a value that is not a number or not finite."""
    values = []
    for i, item in enumerate(text.split(",")):
        try:
            v = float(item)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(
                f"{text!r}: value [{i}] {item.strip()!r} is not a number "
                "(a comma-separated list of numbers)"
            ) from exc
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(
                f"{text!r}: value [{i}] {item.strip()!r} is not finite"
            )
        values.append(v)
    return values


def positive_int(text: str) -> int:
    """An integer >= 1 (counts of workers, iterations)."""
    try:
        v = int(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: not an integer") from exc
    if v < 1:
        raise argparse.ArgumentTypeError(f"{text!r} must be >= 1")
    return v


def accept_negative_values(parser: argparse.ArgumentParser) -> None:
    """Let an option's value start with a minus and a digit (``--q -0.5,0,1``): such a word
    is read as a value, not as an unknown option. Python 3.13's argparse reads it so by
    itself (its pattern is ``-\\.?\\d``); earlier versions take only a single number.
    ASSUMPTION: argparse keeps the pattern in ``_negative_number_matcher`` (3.8-3.13);
    tests/test_cli_bad_input.py runs ``rdm model --q -0.5,...`` to catch a change."""
    parser._negative_number_matcher = re.compile(r"^-\.?\d")
