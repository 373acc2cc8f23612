"""``rdm decode``: decode a capture file into one line per message.

Formats (a registry: name -> file extensions and decoder):

* ``uart``: raw bytes of the Spinal <-> PC rosserial link (:mod:`rdm.protocol.rosserial.capture`);
* ``candump``: a ``candump -l`` log of the Spinal <-> Neuron CAN bus (``rdm.protocol.neuron``);
* ``leptrino``: a raw Leptrino force/torque sensor capture (``rdm.protocol.leptrino``).

With ``--mcap OUT`` the capture, or every capture of a run folder, is written as an MCAP log
instead, each message at the simulated time it crossed its wire (:mod:`rdm.sim.wire_mcap`).

The CAN and Leptrino decoders live in other modules and are imported only when asked for.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

Records = Iterator[dict[str, Any]]


class DecoderUnavailable(RuntimeError):
    """A format whose decoder module is not part of this installation."""


@dataclass(frozen=True)
class CaptureFormat:
    """One entry of the format registry."""

    name: str
    extensions: tuple[str, ...]
    decode: Callable[[Path, argparse.Namespace], Records]
    help: str


def _decode_uart(path: Path, args: argparse.Namespace) -> Records:
    from rdm.protocol.rosserial.capture import decode_uart, load_layout

    layout = None if args.no_layout else load_layout(args.layout)
    return decode_uart(path.read_bytes(), layout=layout)


def _lazy(module: str, function: str) -> Callable[..., Records]:
    try:
        mod = importlib.import_module(module)
        return getattr(mod, function)
    except (ImportError, AttributeError) as exc:
        raise DecoderUnavailable(
            f"the decoder {module}.{function} is not available in this installation ({exc})"
        ) from exc


def _decode_candump(path: Path, args: argparse.Namespace) -> Records:
    return _lazy("rdm.protocol.neuron", "decode_candump")(path)


def _decode_leptrino(path: Path, args: argparse.Namespace) -> Records:
    return _lazy("rdm.protocol.leptrino", "decode_leptrino")(path.read_bytes())


FORMATS: dict[str, CaptureFormat] = {
    f.name: f
    for f in (
        CaptureFormat(
            "uart", (".bin", ".raw", ".uart", ".cap"), _decode_uart, "rosserial UART bytes"
        ),
        CaptureFormat("candump", (".log", ".candump"), _decode_candump, "candump -l log"),
        CaptureFormat("leptrino", (".lep", ".leptrino"), _decode_leptrino, "Leptrino bytes"),
    )
}


def detect_format(path: Path) -> str | None:
    """The format whose extensions include the file's suffix, or None."""
    suffix = path.suffix.lower()
    for fmt in FORMATS.values():
        if suffix in fmt.extensions:
            return fmt.name
    return None


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


def _run_mcap(args: argparse.Namespace) -> int:
    from rdm.sim.capture_index import index_path
    from rdm.sim.wire_mcap import WireMcapError, run_captures, write_wire_mcap

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
    try:
        report = write_wire_mcap(captures, args.mcap)
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
    name = args.format or detect_format(path)
    if name is None:
        print(
            f"rdm decode: cannot tell the format of {path} from its extension; use --format",
            file=sys.stderr,
        )
        return 2
    if not path.is_file():
        print(f"rdm decode: no such file: {path}", file=sys.stderr)
        return 2
    counts: Counter[str] = Counter()
    try:
        for rec in FORMATS[name].decode(path, args):
            counts["ok" if rec.get("ok") else "bad"] += 1
            if not rec.get("ok"):
                key = rec.get("error") if rec.get("kind") == "bad_frame" else rec.get("kind")
                counts[f"bad:{key}"] += 1
            if args.json:
                print(json.dumps(rec, default=str))
            else:
                print(format_record(rec))
    except DecoderUnavailable as exc:
        print(f"rdm decode: {name}: {exc}", file=sys.stderr)
        return 2
    bad = {k[4:]: v for k, v in counts.items() if k.startswith("bad:")}
    sys.stdout.flush()  # keep the summary after the records when both go to one terminal
    print(f"{name}: {counts['ok']} records decoded, {counts['bad']} bad {bad}", file=sys.stderr)
    return 0
