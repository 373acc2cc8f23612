"""Test-side helper: every file a short hover stack writes, for byte-for-byte comparisons of
two stack options (Neuron backend, CAN master backend, CAN wire, collision gate, lazy
sensors)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

T = TypeVar("T")


def hover_run_files(tmp_path: Path, name: str, seconds: float, **options) -> dict[str, bytes]:
    """Run the hover stack (seed 0, in-process UART, as fast as possible) with ``options``
    over ``sim_stack_options`` for ``seconds`` from power-on; its run folder's files by
    relative path."""
    return hover_run(tmp_path, name, seconds, None, **options)[0]


def hover_run(
    tmp_path: Path,
    name: str,
    seconds: float,
    inspect: Callable[[Any], T] | None,
    **options,
) -> tuple[dict[str, bytes], T | None]:
    """:func:`hover_run_files`, and ``inspect(stack)`` after the run, before the stack is
    closed (its plant's state, a part's counters)."""
    from rdm.scenarios.common import sim_stack_options
    from rdm.scenarios.hover import HOVER_Z, make_script
    from rdm.scenarios.stack import build_stack

    opts = sim_stack_options(0, "inproc", speed=None, **options)
    stack = build_stack(name, tmp_path, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))
    try:
        stack.loop.run(seconds)
        seen = None if inspect is None else inspect(stack)
    finally:
        stack.close()
    root = Path(stack.folder.root)
    files = {
        str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
    }
    return files, seen
