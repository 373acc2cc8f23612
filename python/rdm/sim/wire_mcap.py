"""Every wire message of a run as an MCAP log: ``rdm decode RUN --mcap wire.mcap``.

A run folder keeps the wires as their real bytes (``can.log``, ``uart/*.bin``, ``uart/*.lep``),
which is what a port dump of the robot holds. This module decodes them and writes one MCAP with
a channel per message kind, each message at the simulated time it crossed its wire:

* ``/wire/can/<kind>`` (JSON): the Neuron bus, one message per CAN frame at its candump stamp,
  the frame's id, bytes and decoded fields (``rdm.protocol.neuron``);
* ``/wire/<link>/<direction>/<topic>`` (ROS1 with the full ``.msg`` definition, as
  ``signals.mcap``'s Spinal channels): the rosserial link, one message per frame, the payload
  as it was on the wire (rosserial payloads are ROS1 serialisations). ``link`` is the capture's
  stem (``spinal``), ``direction`` ``device_tx`` (what Spinal sent) or ``host_tx`` (what the
  PC sent, timed when Spinal read it); rosserial's own frames (handshake, time sync, log)
  are under ``<link>/<direction>/rosserial/``; a frame with no message type (a topic
  request) is JSON;
* ``/wire/leptrino_foot/<direction>/<kind>`` (JSON): the foot sensor's frames and the host's
  commands;
* ``.../errors`` (JSON): every bad frame, skipped run of bytes or undecodable payload, with its
  offset or line and bytes, so nothing on a wire is left out.

UART and Leptrino captures are timed by the index beside each (:mod:`rdm.link.capture_index`);
a capture without one is skipped and named in the report. A capture and index of a run killed
before it closed them may disagree in length (each file loses its own unwritten buffer): the
messages are all kept, those past the index at its last time, and the report names the
capture (``partial``). Decoding runs in Python: about 10 s for the ~110k CAN frames of a 40 s run.

Memory does not grow with the captures: each is read in chunks
(:func:`rdm.protocol.capture_formats.read_chunks`) and decoded lazily, and the captures' message
streams are merged by time (:func:`heapq.merge`, equal times in the order the captures are
given) as they are written. Each capture is in time order as written (candump stamps ascend,
an index's times ascend with the offset); a message earlier than its capture's previous one is
still written, at its own time (MCAP readers order by time), and counted (``out_of_order``).
"""

from __future__ import annotations

import heapq
import os
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rdm.link.capture_index import CaptureIndex, CaptureIndexError, read_capture_index, time_ns
from rdm.protocol.capture_formats import detect_format, known_extensions, read_chunks
from rdm.sim.mcap_log import McapLogger

#: Record keys that say where a record came from or whether it decoded, not what it holds.
_BOOKKEEPING = frozenset({"ok", "error", "offset", "line", "timestamp", "channel", "raw"})


#: rosserial's own frames (handshake, time sync, log), under ``<link>/<direction>/rosserial/``.
_ROSSERIAL_KINDS = frozenset({"topic_info", "topic_request", "tx_stop", "time", "log"})


class WireMcapError(ValueError):
    """A capture that cannot be converted (unknown format, index that does not fit)."""


@dataclass
class WireMcapReport:
    """What :func:`write_wire_mcap` wrote and what it could not."""

    path: Path
    #: messages per MCAP topic
    messages: Counter[str] = field(default_factory=Counter)
    #: bad records per capture file name
    errors: Counter[str] = field(default_factory=Counter)
    #: captures left out and why
    skipped: list[tuple[Path, str]] = field(default_factory=list)
    #: captures whose index covers other than all their bytes: (capture, indexed, size);
    #: records past the index are timed at its last entry
    partial: list[tuple[Path, int, int]] = field(default_factory=list)
    #: messages earlier than the previous one of the same capture, per capture file name
    out_of_order: Counter[str] = field(default_factory=Counter)

    @property
    def total(self) -> int:
        return sum(self.messages.values())

    def warnings(self) -> list[str]:
        """One line per capture left out or with an index of another length."""
        lines = [f"left out {capture}: {why}" for capture, why in self.skipped]
        lines += [
            f"{capture}: its index covers {indexed} of {size} bytes (a run that did not close "
            "its files?); messages past it are timed at its last entry"
            for capture, indexed, size in self.partial
        ]
        lines += [
            f"{name}: {n} messages earlier than the one before them (written at their own time)"
            for name, n in self.out_of_order.items()
        ]
        return lines

    def summary(self) -> str:
        """The one-line result: messages, channels, bad records, where."""
        return (
            f"{self.path.name}: {self.total} messages on {len(self.messages)} channels, "
            f"bad records {dict(self.errors)} ({self.path})"
        )


@dataclass(frozen=True)
class _Message:
    ns: int
    topic: str
    ros1_type: str | None  # a ROS1 payload of this type, else ``values`` as JSON
    payload: bytes
    values: dict[str, Any]


def run_captures(run: str | os.PathLike[str]) -> list[Path]:
    """The wire captures of a run folder: ``can.log`` and every ``uart/*_tx*`` capture."""
    root = Path(run)
    found = [root / "can.log"] if (root / "can.log").is_file() else []
    uart = root / "uart"
    if uart.is_dir():
        found += sorted(
            p
            for p in uart.iterdir()
            if p.is_file() and p.suffix in (".bin", ".lep") and "_tx." in p.name
        )
    return found


def _kind_of(path: Path) -> str:
    """The capture's format by its extension, as ``rdm decode`` tells it."""
    kind = detect_format(path)
    if kind is None:
        raise WireMcapError(f"{path}: not a capture rdm decode knows ({known_extensions()})")
    return kind


def _link_topic(path: Path) -> str:
    """``spinal.device_tx.bin`` -> ``/wire/spinal/device_tx``."""
    parts = path.name.split(".")
    if len(parts) >= 3:
        return f"/wire/{parts[0]}/{parts[1]}"
    return f"/wire/{path.stem}"


def _values(rec: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in rec.items() if k not in _BOOKKEEPING}


def _error_values(rec: dict[str, Any]) -> dict[str, Any]:
    where = {k: rec[k] for k in ("offset", "line") if k in rec}
    rest = {k: v for k, v in rec.items() if k not in ("offset", "line", "ok", "raw")}
    return {**where, **rest, "error": str(rec.get("error"))}


def _candump_messages(path: Path, report: WireMcapReport) -> Iterator[_Message]:
    from rdm.protocol.neuron import decode_candump

    for rec in decode_candump(path):
        ns = time_ns(float(rec.get("timestamp") or 0.0))
        if rec.get("ok"):
            yield _Message(ns, f"/wire/can/{rec['kind']}", None, b"", _values(rec))
        else:
            report.errors[path.name] += 1
            yield _Message(ns, "/wire/can/errors", None, b"", _error_values(rec))


def _indexed_messages(
    path: Path, records: Iterator[dict[str, Any]], index: CaptureIndex, report: WireMcapReport
) -> Iterator[_Message]:
    from rdm.protocol.rosserial.registry import spinal_registry

    base = _link_topic(path)
    registry = spinal_registry()
    last_ns = index.times_ns[-1] if index.times_ns else 0
    for rec in records:
        offset = int(rec["offset"])
        # past the index (a run killed before it flushed): the index's last time
        ns = index.time_ns_of(offset) if offset < index.size else last_ns
        if not rec.get("ok"):
            report.errors[path.name] += 1
            yield _Message(ns, f"{base}/errors", None, b"", _error_values(rec))
            continue
        name = rec.get("topic") or rec.get("kind") or "message"
        if rec.get("kind") in _ROSSERIAL_KINDS:
            name = f"rosserial/{rec.get('topic') or rec['kind']}"
        type_name = rec.get("type")
        raw = rec.get("raw")
        if raw is not None and type_name and registry.has_msg(type_name):
            yield _Message(ns, f"{base}/{name}", type_name, bytes(raw), {})
        else:
            yield _Message(ns, f"{base}/{name}", None, b"", _values(rec))


def _capture_messages(path: Path, report: WireMcapReport) -> Iterator[_Message] | None:
    kind = _kind_of(path)
    if kind == "candump":
        return _candump_messages(path, report)
    try:
        index = read_capture_index(path, partial_ok=True)
    except FileNotFoundError:
        report.skipped.append((path, "no time index beside it (<capture>.idx)"))
        return None
    except CaptureIndexError as exc:
        raise WireMcapError(str(exc)) from exc
    size = path.stat().st_size
    if index.size != size:
        report.partial.append((path, index.size, size))
    if kind == "uart":
        from rdm.protocol.rosserial.capture import decode_uart, load_layout

        records = decode_uart(read_chunks(path), layout=load_layout(None), raw=True)
    else:
        records = _leptrino_records(path, from_sensor=".host_tx." not in path.name)
    return _indexed_messages(path, records, index, report)


def _leptrino_records(path: Path, from_sensor: bool) -> Iterator[dict[str, Any]]:
    """The Leptrino capture's records, read in chunks through one stream parser."""
    from rdm.protocol.leptrino import LeptrinoStreamParser, decode_leptrino

    parser = LeptrinoStreamParser()
    for chunk in read_chunks(path):
        yield from decode_leptrino(chunk, from_sensor=from_sensor, parser=parser)


def _in_order(
    messages: Iterator[_Message], name: str, report: WireMcapReport
) -> Iterator[_Message]:
    """``messages`` unchanged, each one earlier than its predecessor counted."""
    last = None
    for m in messages:
        if last is not None and m.ns < last:
            report.out_of_order[name] += 1
        last = m.ns
        yield m


def write_wire_mcap(
    captures: Sequence[str | os.PathLike[str]], out: str | os.PathLike[str]
) -> WireMcapReport:
    """Decode ``captures`` and write their messages, in time order, to the MCAP ``out``.

    Raises :class:`WireMcapError` for a file that is no capture or an index that does not fit
    its capture (nothing is written then); bad frames inside a capture go to its ``errors``
    channel and are counted in the report.
    """
    report = WireMcapReport(Path(out))
    streams = []
    for capture in captures:
        found = _capture_messages(Path(capture), report)
        if found is not None:
            streams.append(_in_order(found, Path(capture).name, report))
    # equal times keep the order of the captures as given (merge breaks ties by stream)
    messages = heapq.merge(*streams, key=lambda m: m.ns)
    log = McapLogger(out)
    try:
        for m in messages:
            t = m.ns * 1e-9
            if m.ros1_type is not None:
                log.log_ros1(m.topic, m.ros1_type, t, m.payload)
            else:
                log.log_json(m.topic, t, m.values)
            report.messages[m.topic] += 1
    finally:
        log.finish()
    return report
