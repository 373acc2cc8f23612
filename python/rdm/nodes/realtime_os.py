"""Operating-system settings for a real-time loop: SCHED_FIFO priority, CPU affinity,
``mlockall`` and ``gc.freeze`` (``rdm onboard --rt-priority N --cpu K --mlock --gc-freeze``).

Each is optional. :func:`apply_realtime_options` applies the ones asked for, in the order
affinity, priority, memory lock, garbage-collector freeze, and returns what is in effect (for
the node's status). When the OS refuses one it raises :class:`RealtimeOptionError` whose
message is one line naming the option, the OS's reason and what grants it; what was applied
before stays applied (the caller exits).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import os
from typing import Any

#: ``mlockall`` flags (Linux ``<sys/mman.h>``): lock what is mapped now and what will be.
MCL_CURRENT = 1
MCL_FUTURE = 2


class RealtimeOptionError(ValueError):
    """A real-time option the OS refused or that is out of range (one-line message)."""


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc)


def set_affinity(cpu: int) -> list[int]:
    """Pin this process to CPU ``cpu``; the CPUs it may run on afterwards."""
    if not isinstance(cpu, int) or cpu < 0:
        raise RealtimeOptionError(f"--cpu {cpu!r}: must be an integer >= 0")
    allowed = sorted(os.sched_getaffinity(0))
    try:
        os.sched_setaffinity(0, {cpu})
    except OSError as exc:
        raise RealtimeOptionError(
            f"--cpu {cpu}: the OS refused the CPU affinity ({_reason(exc)}); "
            f"this process may run on CPUs {allowed}"
        ) from None
    return sorted(os.sched_getaffinity(0))


def set_fifo_priority(priority: int) -> int:
    """Run this process under SCHED_FIFO at ``priority``; the priority in effect."""
    low, high = os.sched_get_priority_min(os.SCHED_FIFO), os.sched_get_priority_max(os.SCHED_FIFO)
    if not isinstance(priority, int) or not low <= priority <= high:
        raise RealtimeOptionError(f"--rt-priority {priority!r}: must be an integer {low}..{high}")
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        raise RealtimeOptionError(
            f"--rt-priority {priority}: the OS refused SCHED_FIFO ({_reason(exc)}); it needs "
            "CAP_SYS_NICE or an rtprio limit (limits.conf, or LimitRTPRIO= in a systemd unit)"
        ) from None
    return os.sched_getparam(0).sched_priority


def lock_memory() -> None:
    """``mlockall(MCL_CURRENT | MCL_FUTURE)``: no page of this process is swapped out."""
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
        err = ctypes.get_errno()
        raise RealtimeOptionError(
            f"--mlock: the OS refused mlockall ({os.strerror(err)}); it needs CAP_IPC_LOCK or "
            "a memlock limit (limits.conf, or LimitMEMLOCK=infinity in a systemd unit)"
        )


def apply_realtime_options(
    rt_priority: int | None = None,
    cpu: int | None = None,
    mlock: bool = False,
    gc_freeze: bool = False,
) -> dict[str, Any]:
    """Apply the options asked for (see the module doc); the status of each:
    ``{"rt_priority": N | None, "cpus": [...], "mlock": bool, "gc_freeze": bool}``."""
    status: dict[str, Any] = {
        "rt_priority": None,
        "cpus": None,
        "mlock": False,
        "gc_freeze": False,
    }
    if cpu is not None:
        status["cpus"] = set_affinity(cpu)
    if rt_priority is not None:
        status["rt_priority"] = set_fifo_priority(rt_priority)
    if mlock:
        lock_memory()
        status["mlock"] = True
    if gc_freeze:
        gc.collect()
        gc.freeze()  # what exists now is never scanned again: shorter collections in the loop
        status["gc_freeze"] = True
    return status
