"""Foot force/torque sensor reader of the onboard node (Leptrino over a UART, fact sheet sec. 5).

Sends DATA_START, de-frames the continuous output with
:class:`rdm.protocol.leptrino.LeptrinoStreamParser`, converts each sample with the sensor's
rated values (raw 10000 = rated; CFS034CA301U: 150/150/300 N, 4/4/4 N m) and keeps the newest
wrench ``[Fx, Fy, Fz, Mx, My, Mz]`` in the sensor frame (= foot frame, see docs/onboard.md).
DATA_START is re-sent when no sample arrived for ``restart_s``. Bad bytes are counted, never
raised.
"""

from __future__ import annotations

import math
import struct
from collections import Counter
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from rdm.protocol import leptrino as lp

#: The six int16 force/moment counts at the start of a sample's body.
_RAW_COUNTS = struct.Struct("<6h")
#: |offset|, |rated| below this keep (raw - offset) * rated / 10000 finite for int16 raw.
_MODERATE = 1e100


class ByteLink(Protocol):
    def read_available(self) -> bytes: ...
    def write(self, data: bytes) -> int: ...


class FootSensorReader:
    """Non-blocking Leptrino host: call :meth:`poll` every tick."""

    def __init__(
        self,
        link: ByteLink,
        model: str = "CFS034CA301U",
        offset: Sequence[float] = (0.0,) * 6,
        restart_s: float = 1.0,
    ) -> None:
        self.link = link
        self.model = lp.MODELS[model]
        self.offset = tuple(float(v) for v in offset)
        self.restart_s = restart_s
        self.parser = lp.LeptrinoStreamParser()
        self.counts: Counter[str] = Counter()
        self.wrench: np.ndarray | None = None
        self.stamp: float | None = None
        self._last_start: float | None = None
        # Every sample of a batch but the newest is only counted (see poll). Exact when offset
        # and rated values are moderate: raw counts are int16, so every wrench is then finite
        # and the per-payload non-finite check can never drop a sample.
        self._skip_older = len(self.offset) == len(self.model.rated) == 6 and all(
            abs(v) < _MODERATE for v in (*self.offset, *self.model.rated)
        )

    def poll(self, now: float) -> None:
        """Read what arrived, keep the newest sample, (re-)send DATA_START when due."""
        try:
            data = self.link.read_available()
        except OSError:
            self.counts["read_error"] += 1
            data = b""
        if data:
            self.counts["bytes"] += len(data)
        newest: bytes | None = None  # a well-formed OK sample not converted yet
        if self._skip_older:
            # the leading run of OK-sample frames de-framed in one Rust call
            # (LeptrinoStreamParser.feed_ok_samples): what the loop below does for each of
            # them (one sample each, newest wins), summed
            count, newest, events = self.parser.feed_ok_samples(data)
            if count:
                self.stamp = now
                self.counts["samples"] += count
        else:
            events = self.parser.feed(data)
        for event in events:
            if event.error is not None:
                self.counts[f"frame_{event.error.reason}"] += 1
                continue
            payload = event.payload or b""
            if self._skip_older and _is_ok_sample(payload):
                # what _handle below does for it: one sample, finite, newest wins
                newest = payload
                self.stamp = now
                self.counts["samples"] += 1
                continue
            if newest is not None:
                self._take(newest)
                newest = None
            self._handle(payload, now)
        if newest is not None:
            self._take(newest)
        quiet_since = self.stamp if self.stamp is not None else self._last_start
        if self._last_start is None or (
            now - max(quiet_since or 0.0, self._last_start) >= self.restart_s
        ):
            self._start(now)

    def _handle(self, payload: bytes, now: float) -> None:
        """One de-framed payload: parse, check, convert, keep."""
        try:
            resp = lp.parse_response(payload)
        except lp.LeptrinoError as exc:
            self.counts[f"payload_{exc.reason}"] += 1
            return
        if resp.result != lp.Result.OK:
            self.counts["result_error"] += 1
            return
        if isinstance(resp, lp.ForceData):
            w = lp.to_wrench(resp.raw, self.model, self.offset)
            if not all(math.isfinite(v) for v in w):
                self.counts["non_finite"] += 1
                return
            self.wrench = np.array(w, dtype=float)
            self.stamp = now
            self.counts["samples"] += 1
        else:
            self.counts["other_responses"] += 1

    def _take(self, payload: bytes) -> None:
        """Convert a sample :func:`_is_ok_sample` accepted (stamp and count already set): its
        six counts are the first fields :func:`~rdm.protocol.leptrino.parse_response` unpacks,
        converted as :func:`~rdm.protocol.leptrino.to_wrench` does."""
        raw = _RAW_COUNTS.unpack_from(payload, lp.HEADER_LEN)
        scale = lp.RAW_AT_RATED
        pairs = zip(raw, self.offset, self.model.rated, strict=True)
        self.wrench = np.array([(r - o) * k / scale for r, o, k in pairs], dtype=float)

    def _start(self, now: float) -> None:
        try:
            self.link.write(lp.start_continuous_output())
            self.counts["start_sent"] += 1
        except OSError:
            self.counts["write_error"] += 1
        self._last_start = now

    def latest(self, now: float, timeout: float) -> np.ndarray | None:
        """The newest wrench if it is at most ``timeout`` old, else None."""
        if self.wrench is None or self.stamp is None or now - self.stamp > timeout:
            return None
        return self.wrench

    def stop(self) -> None:
        try:
            self.link.write(lp.stop_continuous_output())
        except OSError:
            self.counts["write_error"] += 1


#: True when a de-framed payload parses to an OK ForceData (kept under its old name).
_is_ok_sample = lp.is_ok_sample
