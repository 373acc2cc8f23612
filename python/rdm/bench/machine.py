"""Machine and software facts recorded with every run (the host is shared and noisy)."""

from __future__ import annotations

import os
import platform
import sys
from importlib import metadata
from typing import Any

#: Thread-count variables pinned to 1 before numpy loads (OpenBLAS threads make scipy's
#: CARE tail ~30x worse on a 2-core box, performance-anchors sec. 2.1).
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def cpu_model() -> str:
    """CPU model name from /proc/cpuinfo, else ``platform.processor()``."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def load_average() -> list[float] | None:
    """1, 5 and 15 minute load averages (None where the OS has none)."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except (OSError, AttributeError):
        return None


def cpu_ticks() -> list[int] | None:
    """The host's CPU time counters since boot, in clock ticks: the first line of
    ``/proc/stat`` (user, nice, system, idle, iowait, irq, softirq, steal); None where absent."""
    try:
        with open("/proc/stat", encoding="ascii") as f:
            fields = f.readline().split()
    except OSError:
        return None
    if len(fields) < 9 or fields[0] != "cpu":
        return None
    try:
        return [int(v) for v in fields[1:9]]
    except ValueError:
        return None


def steal_share(start: list[int] | None, end: list[int] | None) -> float | None:
    """Between two :func:`cpu_ticks` readings, the share of the CPU time this VM's CPUs
    wanted (everything but idle and iowait) that the hypervisor gave to other guests (steal):
    on a shared host, why one hour's figures are slower than another's. None without both
    readings or when no CPU time was wanted."""
    if start is None or end is None or len(start) != 8 or len(end) != 8:
        return None
    delta = [b - a for a, b in zip(start, end, strict=True)]
    if min(delta) < 0:
        return None
    wanted = sum(delta) - delta[3] - delta[4]
    return delta[7] / wanted if wanted > 0 else None


def package_version(name: str) -> str | None:
    """Installed version of a distribution, None if absent."""
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def machine_info(blas_pinned: bool) -> dict[str, Any]:
    """Everything a reader needs to judge the figures (load at start is filled here)."""
    from rdm import _rdm

    return {
        "cpu_model": cpu_model(),
        "logical_cores": os.cpu_count(),
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "versions": {
            name: package_version(name) for name in ("rdm", "numpy", "scipy", "osqp", "clarabel")
        },
        "wheel_build_profile": _rdm.bench_build_profile(),
        "thread_env": {v: os.environ.get(v) for v in THREAD_VARIABLES},
        "blas_threads_pinned_before_numpy": blas_pinned,
        "load_average_start": load_average(),
        "load_average_end": None,
        "cpu_ticks_start": cpu_ticks(),
        #: filled at the end of the run (:func:`steal_share`)
        "cpu_steal_share": None,
    }
