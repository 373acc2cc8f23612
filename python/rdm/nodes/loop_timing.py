"""Timing of a real-time loop: fixed-bin histograms and the late-tick rule.

:class:`Histogram` counts non-negative durations in bins of equal width, allocated once:
adding a sample never grows memory, so it runs inside the loop for as long as the loop runs.
Its quantiles are nearest-rank (the order statistic numpy's ``percentile`` calls
``method="inverted_cdf"``) to the resolution of one bin: :meth:`Histogram.quantile` returns
the upper edge of the bin that holds that sample, the exact maximum past the last bin.

:class:`LoopTiming` is what :func:`rdm.nodes.base.run_realtime` records for one node: per
tick, the lateness (start minus the time the tick was due), the tick's duration (for the
onboard node: from reading its UART to handing the command to the port), the period between
two tick starts and its jitter ``|period - nominal|``. A tick is counted late when it starts
more than ``late_tolerance`` seconds after it was due (default 2 ms).
"""

from __future__ import annotations

import math
from itertools import compress
from typing import Any

#: Width of every histogram bin [s]: the resolution of the reported quantiles.
BIN_S = 50e-6
#: Range covered by bins [s]; a longer sample counts in the overflow (its maximum is exact).
RANGE_S = 0.2
#: Default lateness after which a tick counts as late [s].
LATE_TOLERANCE_S = 0.002


def check_late_tolerance(seconds: float) -> float:
    """``seconds`` if it is a finite number >= 0, else ValueError naming the rule."""
    if not (isinstance(seconds, (int, float)) and math.isfinite(seconds) and seconds >= 0):
        raise ValueError(f"late_tolerance_s={seconds!r} must be finite and >= 0 s")
    return float(seconds)


class Histogram:
    """Counts of non-negative samples in ``bins`` bins of ``bin_s`` seconds, plus overflow."""

    __slots__ = ("_inv", "bin_s", "counts", "max", "n", "overflow")

    def __init__(self, bin_s: float = BIN_S, range_s: float = RANGE_S) -> None:
        if not (math.isfinite(bin_s) and bin_s > 0 and math.isfinite(range_s) and range_s > 0):
            raise ValueError("Histogram: bin_s and range_s must be finite and > 0")
        self.bin_s = float(bin_s)
        self._inv = 1.0 / self.bin_s
        self.counts = [0] * max(1, math.ceil(range_s / bin_s - 1e-9))
        self.overflow = 0
        self.n = 0
        self.max = 0.0

    def add(self, x: float) -> None:
        """Count one sample (a negative one as 0)."""
        self.n += 1
        if x > self.max:
            self.max = x
        i = int(x * self._inv) if x > 0 else 0
        if i < len(self.counts):
            self.counts[i] += 1
        else:
            self.overflow += 1

    def quantile(self, q: float) -> float:
        """Nearest-rank quantile ``q`` in [0, 1]: the upper edge of the bin holding the
        ``ceil(q n)``-th smallest sample (the first for q = 0), or :attr:`max` if that sample
        is past the bins. ValueError on no samples or ``q`` outside [0, 1]."""
        if self.n == 0:
            raise ValueError("Histogram: no samples")
        if not 0.0 <= q <= 1.0:
            raise ValueError(f"Histogram: quantile q={q!r} must be in [0, 1]")
        rank = max(1, math.ceil(q * self.n - 1e-9))
        seen = 0
        for i, c in enumerate(self.counts):
            seen += c
            if seen >= rank:
                return min((i + 1) * self.bin_s, self.max)
        return self.max

    def counts_json(self) -> dict[str, Any]:
        """The whole histogram, JSON-ready: ``bin_s``, ``bins`` (their number), ``counts`` as
        ``[bin, count]`` pairs of the bins that hold a sample (bin ``i`` holds samples in
        ``[i bin_s, (i + 1) bin_s)``, a negative sample in bin 0), ``overflow`` (samples past
        the last bin), ``n`` and the exact ``max_s``; :meth:`quantile` follows from these."""
        counts = self.counts
        return {
            "bin_s": self.bin_s,
            "bins": len(self.counts),
            "counts": [[i, counts[i]] for i in compress(range(len(counts)), counts)],
            "overflow": self.overflow,
            "n": self.n,
            "max_s": self.max,
        }

    def summary_ms(self) -> dict[str, Any]:
        """``{"n", "p50_ms", "p99_ms", "max_ms"}`` (None figures before a sample)."""
        if self.n == 0:
            return {"n": 0, "p50_ms": None, "p99_ms": None, "max_ms": None}
        return {
            "n": self.n,
            "p50_ms": round(self.quantile(0.5) * 1e3, 3),
            "p99_ms": round(self.quantile(0.99) * 1e3, 3),
            "max_ms": round(self.max * 1e3, 3),
        }


class LoopTiming:
    """One node's loop figures (see the module doc). ``period``: the nominal period [s]."""

    def __init__(self, period: float, late_tolerance: float = LATE_TOLERANCE_S) -> None:
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"LoopTiming: period={period!r} must be finite and > 0")
        self.period = float(period)
        self.late_tolerance = check_late_tolerance(late_tolerance)
        self.tick = Histogram()
        self.lateness = Histogram()
        self.period_hist = Histogram()
        self.jitter = Histogram()
        #: ticks that started more than ``late_tolerance`` after they were due
        self.late = 0
        self._last_start: float | None = None

    def record(self, due: float, start: float, end: float) -> None:
        """One tick due at ``due`` ran from ``start`` to ``end`` (seconds, one clock)."""
        lateness = start - due
        if lateness > self.late_tolerance:
            self.late += 1
        self.lateness.add(lateness)
        self.tick.add(end - start)
        last = self._last_start
        if last is not None:
            period = start - last
            self.period_hist.add(period)
            self.jitter.add(abs(period - self.period))
        self._last_start = start

    #: The histograms by the names :meth:`status` and :meth:`histograms` give them.
    NAMES = ("tick", "lateness", "period", "period_jitter")

    def _by_name(self) -> dict[str, Histogram]:
        hists = (self.tick, self.lateness, self.period_hist, self.jitter)
        return dict(zip(self.NAMES, hists, strict=True))

    def histograms(self) -> dict[str, Any]:
        """Every histogram whole (:meth:`Histogram.counts_json`) with the late count, the
        tolerance and the nominal period [s]: what the flight recorder writes."""
        return {
            "period_s": self.period,
            "late_tolerance_s": self.late_tolerance,
            "late": self.late,
            **{name: h.counts_json() for name, h in self._by_name().items()},
        }

    def status(self) -> dict[str, Any]:
        """JSON-ready figures: late count and tolerance, p50/p99/max of each histogram."""
        return {
            "late": self.late,
            "late_tolerance_ms": round(self.late_tolerance * 1e3, 6),
            "bin_ms": round(BIN_S * 1e3, 6),
            **{name: h.summary_ms() for name, h in self._by_name().items()},
        }
