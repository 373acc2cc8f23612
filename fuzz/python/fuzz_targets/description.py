"""Robot description loading through the bindings (``rdm._rdm.Robot.from_strs``, what
``rdm.model.Robot`` and every ``--urdf/--toml`` option call): the URDF reader (Rust
roxmltree) and the TOML reader, then a first evaluation.

Input: the same format as the Rust target ``description`` (``fuzz/src/description.rs``):
byte 0x00 + ``n_hi n_lo k`` repeats the last ``k`` bytes ``n`` more times (text capped at
256 KiB), byte 0x01 separates URDF from TOML, invalid UTF-8 is replaced.

The reader is native code: a stack overflow kills the process, so the engines run this
target in a child process per batch and report a child that dies as a crash with the input
it was reading (``isolated=True``).

Checks: a rejection is a ``DescriptionError`` whose message starts with the file it is
about; an accepted description has a finite mass and evaluates at q = 0 to finite numbers
(or refuses with ``ModelError``).
"""

from __future__ import annotations

import random
from collections.abc import Iterable
from typing import Any

import numpy as np

from fuzz_targets.base import NonFinite, Target, all_finite
from rdm import _rdm
from rdm.descriptions import build_description
from rdm.model import DescriptionError, ModelError

MAX_TEXT = 1 << 18
SEPARATOR = 1
#: Numbers the generator writes over one number of a description.
EXTREMES = (b"1e308", b"-1e308", b"nan", b"inf", b"0", b"-0", b"1e-320", b"4.9e-324",
            b"17976931348623157e292", b"99999999999999999999")  # fmt: skip


def expand(data: bytes) -> bytes:
    """The text an input stands for (``rdm_fuzz::description::expand``)."""
    out = bytearray()
    i = 0
    while i < len(data) and len(out) < MAX_TEXT:
        j = data.find(0, i)
        if j < 0:
            j = len(data)
        out += data[i : min(j, i + MAX_TEXT - len(out))]
        if j == len(data) or len(out) >= MAX_TEXT or j + 4 > len(data):
            break
        n, k = data[j + 1] << 8 | data[j + 2], min(data[j + 3], len(out))
        i = j + 4
        if k:
            out += bytes(out[-k:]) * min(n, (MAX_TEXT - len(out)) // k)
    return bytes(out)


def split(data: bytes) -> tuple[str, str]:
    """The URDF and TOML texts of an input."""
    text = expand(data)
    urdf, _, toml = text.partition(bytes([SEPARATOR]))
    return urdf.decode("utf-8", "replace"), toml.decode("utf-8", "replace")


def _as_lists(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, dict):
        return {k: _as_lists(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_as_lists(v) for v in value]
    return value


def check(data: bytes) -> None:
    """Load the description ``data`` stands for and evaluate it once."""
    urdf, toml = split(data)
    try:
        robot = _rdm.Robot.from_strs(urdf, toml, "fuzz.urdf", "fuzz.toml")
    except DescriptionError as exc:
        if not str(exc).startswith(("fuzz.urdf", "fuzz.toml")):
            raise AssertionError(f"error names no file: {exc}") from None
        return
    all_finite(robot.mass, "mass")
    try:
        out = robot.evaluate(np.zeros(robot.n_q))
    except ModelError:
        return
    if out.get("zmp_degenerate"):  # no aerial ZMP to give: its fields are not numbers
        out = {k: v for k, v in out.items() if k not in ("aerial_zmp", "zmp_margin")}
    try:
        all_finite(_as_lists(out), "evaluate(0)")
    except NonFinite as exc:
        raise NonFinite(f"accepted description: {exc}") from None


def seeds() -> Iterable[bytes]:
    """The shipped RDM and RCM and the Table II arm-unit variants (URDF, 0x01, TOML)."""
    sep = bytes([SEPARATOR])
    for layout, position in (("rdm", 1.0), ("rcm", 1.0), ("rdm", 0.0), ("rdm", 0.5)):
        desc = build_description(layout, position)
        yield desc.urdf.encode() + sep + desc.toml.encode()


def generate(rng: random.Random) -> bytes:
    """Structure-aware inputs: a shipped description with one element nested ``n`` deep
    (written with the repeat macro), or with a number or a TOML value replaced by an
    extreme one."""
    base = rng.choice(list(seeds()))
    urdf, _, toml = base.partition(bytes([SEPARATOR]))
    kind = rng.randrange(3)
    if kind == 0:
        depth = rng.choice((10, 100, 1000, 3000, 10_000, 20_000, 40_000))
        tag = rng.choice((b"<a>", b"<link>", b"<inertial>", b"<x/><y>"))
        at = rng.randrange(len(urdf))
        nest = tag + bytes([0, (depth - 1) >> 8 & 0xFF, (depth - 1) & 0xFF, len(tag)])
        return urdf[:at] + nest + urdf[at:] + bytes([SEPARATOR]) + toml
    extreme = rng.choice(EXTREMES)
    text = bytearray(urdf if kind == 1 else toml)
    digits = [k for k, b in enumerate(text) if 0x30 <= b <= 0x39]
    if digits:
        at = rng.choice(digits)
        end = at
        while end < len(text) and chr(text[end]) in "0123456789.e-+":
            end += 1
        text[at:end] = extreme
    return bytes(text) + bytes([SEPARATOR]) + toml if kind == 1 else urdf + b"\x01" + bytes(text)


TARGETS = [
    Target("description", check, seeds, generate, isolated=True,
           about="rdm._rdm.Robot.from_strs (URDF via roxmltree, TOML) and Robot.evaluate"),
]  # fmt: skip
