"""``rdm bench``: latency of the real-time core against its 200 Hz / 40 Hz budgets and peers.

* :mod:`rdm.bench.statistics`: median, p99, p99.9, max of per-call nanoseconds.
* :mod:`rdm.bench.scenarios`: deterministic inputs from the default robot.
* :mod:`rdm.bench.cases`: the case registry (:data:`~rdm.bench.cases.CASES`).
* :mod:`rdm.bench.lockstep`: the full stack in lockstep against 20x real time.
* :mod:`rdm.bench.decode`: ``rdm decode`` throughput and peak memory on large captures.
* :mod:`rdm.bench.onboard_loop`: ``rdm onboard`` as a process, its command-period jitter.
* :mod:`rdm.bench.peers`: scipy / OSQP / Clarabel-wheel peers (optional ``rdm[bench]``).
* :mod:`rdm.bench.report`: text report and the ``rdm.bench/1`` JSON schema.
* :func:`run_benchmarks`: run selected cases and return the JSON document.
"""

from __future__ import annotations

from rdm.bench.runner import run_benchmarks

__all__ = ["run_benchmarks"]

from rdm.bench import decode as _decode  # noqa: F401  (registers the "decode" case)
from rdm.bench import lockstep as _lockstep  # noqa: F401  (registers the "lockstep" case)
from rdm.bench import onboard_loop as _onboard_loop  # noqa: F401  (the "onboard-loop" case)
