"""``rdm decode``: decode a capture file into one line per message.

Formats (a registry: name -> decoder; the extensions of each name are
:mod:`rdm.protocol.capture_formats`'):

* ``uart``: raw bytes of the Spinal <-> PC rosserial link (:mod:`rdm.protocol.rosserial.capture`);
* ``candump``: a ``candump -L`` log of the Spinal <-> Neuron CAN bus (``rdm.protocol.neuron``);
* ``leptrino``: a raw Leptrino force/torque sensor capture (``rdm.protocol.leptrino``).

With ``--mcap OUT`` the capture, or every capture of a run folder, is written as an MCAP log
instead, each message at the simulated time it crossed its wire (:mod:`rdm.sim.wire_mcap`).

The CAN and Leptrino decoders live in other modules and are imported only when asked for.

Decoding streams: a capture is read in chunks of :data:`CHUNK_BYTES`, each record is written
as soon as its frame is complete, and the summary is counted on the way, so memory does not
grow with the capture. A run of OK Leptrino samples comes from the decoder as one numpy batch
(:class:`rdm.protocol.leptrino_capture.ForceRun`) and is written by
:func:`rdm.commands.decode_lines.force_run_lines`: the lines :func:`format_record` and the JSON
form give its records one by one.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rdm.commands.decode_lines import force_run_lines
from rdm.commands.output import check_output_path, json_text
from rdm.json_values import nulled
from rdm.protocol import capture_formats
from rdm.protocol.capture_formats import EXTENSIONS, detect_format, read_chunks

Records = Iterator[Any]  # dicts, and ForceRun batches from the Leptrino decoder

#: Bytes read from a UART capture at a time (read when called, so a test can shrink it).
CHUNK_BYTES = capture_formats.CHUNK_BYTES
#: Leptrino chunks are larger: its decoder keeps events only between frame starts.
LEPTRINO_CHUNK_BYTES = 1 << 18


class DecoderUnavailable(RuntimeError):
    """A format whose decoder module is not part of this installation."""


@dataclass(frozen=True)
class CaptureFormat:
    """One entry of the format registry."""

    name: str
    extensions: tuple[str, ...]
    decode: Callable[[Path, argparse.Namespace], Records]
    help: str


class LayoutError(ValueError):
    """A ``--layout`` file that cannot be read or is not a slot layout."""


def load_checked_layout(path: Path | None) -> dict[str, Any]:
    """The slot layout at ``path`` (default: the shipped one), checked: readable JSON, an
    object whose ``subscribers`` and ``publishers`` are lists of rows with an integer
    ``id``, string ``name`` and ``kind``, and a ``type`` the Spinal message registry knows.
    :class:`LayoutError` names the file and what is wrong."""
    from rdm.protocol.rosserial.capture import load_layout
    from rdm.protocol.rosserial.registry import spinal_registry

    where = f"--layout {str(path)!r}"
    try:
        layout = load_layout(path)
    except OSError as exc:
        raise LayoutError(f"{where}: {exc.strerror or exc}") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise LayoutError(f"{where}: not JSON ({exc})") from None
    if not isinstance(layout, dict):
        raise LayoutError(f"{where}: not a JSON object")
    registry = spinal_registry()
    for key in ("subscribers", "publishers"):
        rows = layout.get(key)
        if not isinstance(rows, list):
            raise LayoutError(f"{where}: {key!r} must be a list of slot rows")
        for i, row in enumerate(rows):
            ok = (
                isinstance(row, dict)
                and type(row.get("id")) is int
                and isinstance(row.get("name"), str)
                and isinstance(row.get("kind"), str)
                and isinstance(row.get("type"), str)
            )
            if not ok:
                raise LayoutError(
                    f"{where}: {key}[{i}] must have an integer id and string name, type, kind"
                )
            if not (registry.has_msg(row["type"]) or registry.has_srv(row["type"])):
                raise LayoutError(f"{where}: {key}[{i}]: unknown message type {row['type']!r}")
    return layout


def _decode_uart(path: Path, args: argparse.Namespace) -> Records:
    from rdm.protocol.rosserial.capture import decode_uart

    layout = None if args.no_layout else load_checked_layout(args.layout)
    return decode_uart(read_chunks(path, CHUNK_BYTES), layout=layout)


def _lazy(module: str, function: str) -> Callable[..., Records]:
    try:
        mod = importlib.import_module(module)
        return getattr(mod, function)
    except (ImportError, AttributeError) as exc:
        raise DecoderUnavailable(
            f"the decoder {module}.{function} is not available in this installation ({exc})"
        ) from exc


def _decode_candump(path: Path, args: argparse.Namespace) -> Records:
    # Vector ASCII by its suffix; candump -L lines for any other name (--format candump)
    syntax = "asc" if path.suffix.lower() == ".asc" else "log"
    return _lazy("rdm.protocol.neuron", "decode_candump")(path, syntax=syntax)


def _decode_leptrino(path: Path, args: argparse.Namespace) -> Records:
    """The frames, then one bad record ``discarded: N bytes outside any frame`` when the
    parser skipped bytes that belong to no frame (garbage between frames is counted)."""
    _lazy("rdm.protocol.leptrino", "decode_leptrino")
    decode = _lazy("rdm.protocol.leptrino_capture", "iter_leptrino_records")
    parser = _lazy("rdm.protocol.leptrino", "LeptrinoStreamParser")()
    yield from decode(read_chunks(path, LEPTRINO_CHUNK_BYTES), parser=parser)
    if parser.discarded_bytes:
        n = parser.discarded_bytes
        yield {
            "offset": None,
            "kind": None,
            "ok": False,
            "error": f"discarded: {n} bytes outside any frame",
            "discarded_bytes": n,
        }


FORMATS: dict[str, CaptureFormat] = {
    f.name: f
    for f in (
        CaptureFormat("uart", EXTENSIONS["uart"], _decode_uart, "rosserial UART bytes"),
        CaptureFormat("candump", EXTENSIONS["candump"], _decode_candump, "candump -L or ASC log"),
        CaptureFormat("leptrino", EXTENSIONS["leptrino"], _decode_leptrino, "Leptrino bytes"),
    )
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``rdm decode``."""
    parser.add_argument(
        "capture", type=Path, help="capture file (with --mcap: or a run folder of rdm sim)"
    )
    parser.add_argument(
        "--format",
        choices=sorted(FORMATS),
        help="capture format (default: from the extension: "
        + "; ".join(f"{f.name}: {' '.join(f.extensions)}" for f in FORMATS.values())
        + ")",
    )
    parser.add_argument("--json", action="store_true", help="emit one JSON object per line")
    parser.add_argument(
        "--layout", type=Path, help="uart: slot layout JSON for ids without a handshake"
    )
    parser.add_argument(
        "--no-layout", action="store_true", help="uart: name topics only from TopicInfo records"
    )
    parser.add_argument(
        "--mcap",
        type=Path,
        metavar="OUT",
        help="write the messages to the MCAP file OUT, each at the time it crossed its wire "
        "(UART/Leptrino captures need the .idx time index rdm sim writes beside them)",
    )


def bad_reason(rec: dict[str, Any]) -> str:
    """Why a record is bad, in one word for the summary: its kind (``skipped``), else the
    head of its error text (``syntax`` of "syntax: bad data field"), else ``unknown``."""
    kind = rec.get("kind")
    if kind and kind != "bad_frame":
        return str(kind)
    error = rec.get("error")
    if error:
        return str(error).split(":", 1)[0].strip() or "unknown"
    return "unknown"


def _json_line(rec: dict[str, Any]) -> str:
    """One record as valid JSON: a value that is not a finite number is null."""
    try:
        return json_text(rec, default=str)
    except ValueError:
        return json_text(nulled(rec), default=str)


def _where(rec: dict[str, Any]) -> str:
    if "offset" in rec:
        return f"@{rec['offset']}"
    if "line" in rec:
        return f"line {rec['line']}"
    return "?"


def format_record(rec: dict[str, Any]) -> str:
    """One human-readable line for a decoded record."""
    if not rec.get("ok", False):
        detail = {k: v for k, v in rec.items() if k not in ("offset", "line", "ok", "error")}
        return f"{_where(rec)} BAD {rec.get('error')} {json.dumps(detail, default=str)}"
    if "fields" in rec and "topic_id" in rec:
        topic = rec.get("topic") or rec.get("kind")
        fields = json.dumps(rec["fields"], separators=(",", ":"), default=str)
        return (
            f"{_where(rec)} {rec['kind']} id={rec['topic_id']} {topic} [{rec.get('type')}] {fields}"
        )
    rest = {k: v for k, v in rec.items() if k not in ("offset", "line", "ok", "error", "kind")}
    return f"{_where(rec)} {rec.get('kind')} {json.dumps(rest, separators=(',', ':'), default=str)}"


def _one_of(out: Path, inputs: list[Path]) -> Path | None:
    """The input that ``out`` is (the same file, by any name), or None."""
    if not out.exists():
        return None
    for p in inputs:
        try:
            if p.exists() and os.path.samefile(out, p):
                return p
        except OSError:
            continue
    return None


def _run_mcap(args: argparse.Namespace) -> int:
    from rdm.link.capture_index import index_path
    from rdm.sim.wire_mcap import WireMcapError, run_captures, write_wire_mcap

    try:
        out = check_output_path(args.mcap, "--mcap")
    except ValueError as exc:
        print(f"rdm decode: {exc}", file=sys.stderr)
        return 2
    path: Path = args.capture
    if path.is_dir():
        captures = run_captures(path)
        if not captures:
            print(f"rdm decode: {path} holds no can.log or uart/*_tx* capture", file=sys.stderr)
            return 2
    elif path.is_file():
        if detect_format(path) is None:
            print(
                f"rdm decode: cannot tell the format of {path} from its extension "
                "(--mcap reads it from the name)",
                file=sys.stderr,
            )
            return 2
        if detect_format(path) != "candump" and not index_path(path).is_file():
            print(
                f"rdm decode: {path} has no time index beside it ({index_path(path).name}); "
                "rdm sim writes one with every UART and Leptrino capture",
                file=sys.stderr,
            )
            return 2
        captures = [path]
    else:
        print(f"rdm decode: no such file or folder: {path}", file=sys.stderr)
        return 2
    inputs = [*captures, *(index_path(c) for c in captures)]
    same = _one_of(out, inputs)
    if same is not None:
        print(
            f"rdm decode: --mcap {str(args.mcap)!r} is the input {str(same)!r}; "
            "the output must be another file (e.g. RUN/wire.mcap)",
            file=sys.stderr,
        )
        return 2
    try:
        report = write_wire_mcap(captures, out)
    except (WireMcapError, OSError) as exc:
        print(f"rdm decode: {exc}", file=sys.stderr)
        return 2
    for topic, n in sorted(report.messages.items()):
        print(f"{n:8d}  {topic}")
    for line in report.warnings():
        print(f"rdm decode: {line}", file=sys.stderr)
    print(report.summary(), file=sys.stderr)
    return 0


def run(args: argparse.Namespace) -> int:
    """Decode ``args.capture``; exit code 0 on success, 2 on usage or availability errors."""
    if args.mcap is not None:
        return _run_mcap(args)
    path: Path = args.capture
    if path.is_dir():
        print(f"rdm decode: {path} is a folder; --mcap OUT converts a run folder", file=sys.stderr)
        return 2
    if not path.exists():
        print(f"rdm decode: no such file: {path}", file=sys.stderr)
        return 2
    name = args.format or detect_format(path)
    if name is None:
        print(
            f"rdm decode: cannot tell the format of {path} from its extension; use --format",
            file=sys.stderr,
        )
        return 2
    if not path.is_file():
        print(f"rdm decode: {path} is not a regular file", file=sys.stderr)
        return 2
    if name == "uart" and not args.no_layout:
        try:
            load_checked_layout(args.layout)  # a bad --layout is refused before any output
        except LayoutError as exc:
            print(f"rdm decode: {exc}", file=sys.stderr)
            return 2
    counts: Counter[str] = Counter()
    write = sys.stdout.write
    line = _json_line if args.json else format_record
    try:
        for rec in FORMATS[name].decode(path, args):
            if rec.__class__ is not dict:  # a batch of OK Leptrino samples
                counts["ok"] += len(rec)
                write(force_run_lines(rec, args.json))
                continue
            if rec.get("ok"):
                counts["ok"] += 1
            else:
                counts["bad"] += 1
                counts[f"bad:{bad_reason(rec)}"] += 1
            write(line(rec) + "\n")
    except DecoderUnavailable as exc:
        print(f"rdm decode: {name}: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        raise  # the reader went away: rdm.cli ends quietly
    except OSError as exc:  # the capture could not be read
        print(f"rdm decode: {path}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    bad = {k[4:]: v for k, v in counts.items() if k.startswith("bad:")}
    sys.stdout.flush()  # keep the summary after the records when both go to one terminal
    print(f"{name}: {counts['ok']} records decoded, {counts['bad']} bad {bad}", file=sys.stderr)
    return 0
