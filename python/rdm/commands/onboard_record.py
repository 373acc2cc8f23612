"""``rdm onboard``'s flight recorder options (docs/onboard.md, "Flight recorder and replay").

``--record DIR`` (default ``runs/onboard-<UTC time>``), ``--no-record``, ``--replace``,
``--record-max-mb``: :func:`open_recorder` prepares the folder and attaches a
:class:`rdm.nodes.flight_recorder.FlightRecorder` to the node, :func:`record_datagrams` adds
what reaches the ground link to its journal; :class:`SignalLog` writes the
node's status and the loop's timing histograms into each segment's ``signals.mcap`` when the
``mcap`` package (the ``sim`` extra) is installed; :func:`write_loop_timing` writes the
histograms at the end into ``loop_timing.json`` beside the segments (with or without it).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import time
from pathlib import Path
from typing import Any

from rdm.model import RobotSource
from rdm.nodes.flight_recorder import DEFAULT_MAX_MB, FlightRecorder, record_node
from rdm.nodes.loop_timing import LoopTiming
from rdm.output_files import write_atomic

#: Seconds between two status records in ``signals.mcap``.
SIGNAL_PERIOD_S = 0.1
#: Seconds between two ``/onboard/loop_timing`` records (whole histograms, cumulative from
#: the start; each segment's file also ends with one).
LOOP_TIMING_PERIOD_S = 1.0
#: Topic of the loop's histograms in ``signals.mcap``.
LOOP_TIMING_TOPIC = "/onboard/loop_timing"
#: The loop's histograms at the end, beside the segments.
LOOP_TIMING_FILE = "loop_timing.json"


def add_record_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--record",
        default=None,
        metavar="DIR",
        help="flight recorder folder: every UART and foot-sensor byte and every input, for "
        "rdm replay (default runs/onboard-<UTC time>)",
    )
    parser.add_argument("--no-record", action="store_true", help="record nothing")
    parser.add_argument(
        "--replace", action="store_true", help="empty a non-empty --record folder first"
    )
    parser.add_argument(
        "--record-max-mb",
        type=float,
        default=DEFAULT_MAX_MB,
        help=f"bound of the recording; the oldest segments go first (default {DEFAULT_MAX_MB:g})",
    )


def _default_folder() -> Path:
    """``runs/onboard-<UTC YYYYmmddTHHMMSSZ>``, with ``-2``, ``-3`` ... when taken."""
    stem = Path("runs") / f"onboard-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}"
    path, k = stem, 1
    while path.exists() or path.is_symlink():
        k += 1
        path = stem.with_name(f"{stem.name}-{k}")
    return path


def open_recorder(
    args: argparse.Namespace, node: Any, source: RobotSource
) -> FlightRecorder | None:
    """The recorder of ``node`` (built for the description ``source`` and ``--config``) as
    the options ask (None with ``--no-record``); ValueError (a folder refused, a bad bound)
    names the option and the rule."""
    if args.no_record:
        if args.record is not None:
            raise ValueError("--record and --no-record exclude each other")
        return None
    mb = args.record_max_mb
    if not (math.isfinite(mb) and mb > 0):
        raise ValueError(f"--record-max-mb {mb}: must be a finite number > 0")
    folder = Path(args.record) if args.record is not None else _default_folder()
    recorder = record_node(
        node,
        folder,
        source,
        config_file=args.config,
        replace=args.replace,
        max_bytes=max(1, int(mb * 1e6)),
    )
    print(f"rdm onboard: recording into {folder}", flush=True)
    return recorder


def record_datagrams(port: Any, recorder: FlightRecorder) -> None:
    """Journal every datagram the ground link ``port`` (:class:`rdm.ground.port.GroundPort`)
    takes, before it is handled: its bytes (hex), sender and node time, accepted or not. A
    replay skips these lines; the node calls they caused are journaled after them."""
    handle = port.handle

    def recorded(data: bytes, addr: Any, now: float) -> Any:
        sender = f"{addr[0]}:{addr[1]}" if isinstance(addr, tuple) and len(addr) >= 2 else None
        recorder.note({"datagram": bytes(data).hex(), "from": sender, "t": now})
        return handle(data, addr, now)

    port.handle = recorded


#: Modules of an extra that the recorder looks for (never imports unless found): with
#: ``mcap`` each segment also gets a ``signals.mcap``.
OPTIONAL_PROBES = ("mcap",)


def mcap_available() -> bool:
    """Whether the ``mcap`` package (``sim`` extra) is installed. A finder that refuses the
    name (an import hook, a broken install) counts as not installed."""
    try:
        return importlib.util.find_spec("mcap") is not None
    except (ImportError, ValueError):
        return False


class SignalLog:
    """A node writing the onboard node's status (``/onboard/status``, as ``rdm sim`` logs
    it) into the recorder's present segment's ``signals.mcap``, and with ``timing`` the
    loop's whole histograms (:data:`LOOP_TIMING_TOPIC`, :meth:`LoopTiming.histograms`)
    every :data:`LOOP_TIMING_PERIOD_S` and as the file's last record: finished when the
    segment closes, a new file in the next; its bytes counted in the segment's size."""

    name = "onboard_signals"

    def __init__(
        self, node: Any, recorder: FlightRecorder, timing: LoopTiming | None = None
    ) -> None:
        self.node, self.recorder, self.timing = node, recorder, timing
        self.period = SIGNAL_PERIOD_S
        self._logger: Any = None
        self._size = 0
        self._now = 0.0
        self._timing_due = 0.0
        recorder.segment_closing.append(lambda _segment: self.close())

    def tick(self, now: float) -> None:
        seg = self.recorder.segment
        if self._logger is None:
            from rdm.sim.mcap_log import McapLogger

            self._logger = McapLogger(seg.folder / "signals.mcap")
            self._size = 0
        self._now = now
        self._logger.log_json("/onboard/status", now, self.node.status())
        if self.timing is not None and now >= self._timing_due:
            self._logger.log_json(LOOP_TIMING_TOPIC, now, _as_arrays(self.timing.histograms()))
            self._timing_due = now + LOOP_TIMING_PERIOD_S
        size = os.path.getsize(self._logger.path)
        seg.size += size - self._size
        self._size = size

    def close(self) -> None:
        """Finish the present file (its last record: the histograms as they are now)."""
        if self._logger is not None:
            if self.timing is not None:
                doc = _as_arrays(self.timing.histograms())
                self._logger.log_json(LOOP_TIMING_TOPIC, self._now, doc)
            self._logger.finish()
            self._logger = None


def _as_arrays(histograms: dict[str, Any]) -> dict[str, Any]:
    """``histograms`` with each ``[bin, count]`` list as an integer array: the same JSON, which
    the MCAP logger writes in one call instead of a walk over every pair (about 2 ms less
    per record for a few hundred bins)."""
    import numpy as np

    out = dict(histograms)
    for name in LoopTiming.NAMES:
        h = dict(out[name])
        h["counts"] = np.array(h["counts"], dtype=np.int64).reshape(-1, 2)
        out[name] = h
    return out


def write_loop_timing(recorder: FlightRecorder, timing: LoopTiming) -> None:
    """``loop_timing.json`` in the recording: the whole histograms when the loop ended
    (:meth:`LoopTiming.histograms`) and their summary as the status prints it."""
    doc = {"histograms": timing.histograms(), "status": timing.status()}
    write_atomic(recorder.root / LOOP_TIMING_FILE, json.dumps(doc, indent=1) + "\n")
