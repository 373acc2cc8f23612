"""Where ``model.opt.disableflags`` lives in the compiled model's memory.

The lockstep kernel sets ``mjDSBL_SENSOR`` before every step and clears it after
(:class:`~rdm.plant.plant.Plant`'s ``lazy_sensors``). Through the bindings' property that is
three attribute accesses a step, ~2k instructions, about half of what the skipped sensor
passes save (cachegrind, docs/plant.md "Lazy sensors"). With the field's address the kernel
reads and writes the int directly.

The bindings do not publish field offsets, so :func:`disableflags_address` finds the field by
probing: it writes distinct values through the property and keeps the one int32 of the
model's first bytes that follows all of them, then checks the other direction (a write
through the address reads back through the property). Anything but exactly one such int is
``None``, and the kernel keeps the property.
"""

from __future__ import annotations

import ctypes

import mujoco
import numpy as np

#: Bytes of the model struct searched (mjModel's sizes and options lie well inside them,
#: and the struct itself is several times larger); the kernel takes no address outside.
SEARCH_BYTES = 2048
_PROBES = (0x2A5A5A5, 0x1234567, 0x6ED0C0B)


def disableflags_address(model: mujoco.MjModel) -> int | None:
    """The address of ``model.opt.disableflags`` (an int32), or None when the probe does not
    find exactly one; the flags are unchanged afterwards."""
    base = getattr(model, "_address", None)
    if not isinstance(base, int) or base == 0:
        return None
    words = np.frombuffer((ctypes.c_int32 * (SEARCH_BYTES // 4)).from_address(base), dtype=np.int32)
    opt = model.opt
    old = int(opt.disableflags)
    try:
        hits: set[int] | None = None
        for value in (*_PROBES, old):
            opt.disableflags = value
            found = set(np.flatnonzero(words == value).tolist())
            hits = found if hits is None else hits & found
        if hits is None or len(hits) != 1:
            return None
        (index,) = hits
        words[index] = _PROBES[0]  # the other direction: the property reads the write
        if int(opt.disableflags) != _PROBES[0]:
            return None
        return base + 4 * index
    finally:
        opt.disableflags = old
