"""Replay of a flight recording (:mod:`rdm.nodes.flight_recorder`) through a fresh onboard
node: ``rdm replay RUN``.

The node is built from the journal's header (the recorded copies of its robot description,
its configuration), its links are :class:`ReplayLink` ends that hand it, read by read, the
bytes it read in flight (each read as long as the journal says), and the journal's inputs
are called and its ticks ticked at their recorded times, in their recorded order. What the
node writes is compared byte for byte with what it wrote in flight: :func:`replay` reports,
per link, the first differing byte offset and its time. A node that reads no clock of its
own writes the same bytes.

A replay starts at the flight's start: the recorder stores the node's inputs, not its state,
so a recording whose first segments rotation deleted is refused in one line that names the
first segment kept (docs/onboard.md, "Flight recorder and replay", on why a later segment
cannot start a replay).
"""

from __future__ import annotations

import bisect
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rdm.link.capture_index import CaptureIndexError, read_capture_index
from rdm.nodes.flight_recorder import (
    INCOMPLETE,
    INPUT_METHODS,
    JOURNAL,
    JOURNAL_FORMAT,
    JOURNAL_VERSION,
    LINKS,
    capture_name,
    config_document,
    decode_value,
    segment_name,
)

#: Journal versions a replay reads (1: the robot named by a shipped name only).
READ_VERSIONS = (1, JOURNAL_VERSION)


class ReplayError(ValueError):
    """A recording that cannot be replayed (missing segment, bad journal); names the file."""


def _segment_indexes(root: Path) -> list[int]:
    """Indexes of the ``segNNNN`` folders in ``root``, in order."""
    return sorted(
        int(p.name[3:]) for p in root.glob("seg[0-9][0-9][0-9][0-9]") if p.name[3:].isdigit()
    )


def find_recording(path: str | Path) -> Path:
    """The recording folder ``path`` names: a recorder folder (``seg0000/``) or a run folder
    that holds one in ``onboard/`` (``rdm sim --record-onboard``). ReplayError (one line) when
    rotation deleted the first segments: it names the first segment kept."""
    p = Path(path)
    for root in (p, p / "onboard"):
        if (root / segment_name(0) / JOURNAL).is_file():
            return root
        kept = _segment_indexes(root) if root.is_dir() else []
        if kept:
            raise ReplayError(
                f"{root}: cannot replay exactly: rotation deleted {segment_name(0)}.."
                f"{segment_name(kept[0] - 1)} and the first segment kept is "
                f"{segment_name(kept[0])}; a replay starts at the flight's start (the node's "
                "state at a later segment is not recorded)"
            )
    raise ReplayError(f"{p}: holds no flight recording ({segment_name(0)}/{JOURNAL})")


def _segments(root: Path) -> list[Path]:
    """Every segment from ``seg0000`` on; ReplayError when one in between is missing."""
    out: list[Path] = []
    while (root / segment_name(len(out)) / JOURNAL).is_file():
        out.append(root / segment_name(len(out)))
    later = [k for k in _segment_indexes(root) if k > len(out)]
    if later:
        raise ReplayError(
            f"{root}: {segment_name(len(out))}/{JOURNAL} is missing, {segment_name(later[0])} "
            "follows it; a replay needs every segment in order"
        )
    return out


def _journal(segment: Path) -> tuple[dict[str, Any], list[dict[str, Any]], bool]:
    """(header, entries, cut): a last line without its newline (a killed recorder) is
    dropped and reported as ``cut``."""
    path = segment / JOURNAL
    text = path.read_text(encoding="utf-8")
    lines = text.split("\n")
    cut = lines[-1] != ""
    lines = lines[:-1]
    entries = []
    for k, line in enumerate(lines, 1):
        try:
            entries.append(json.loads(line))
        except json.JSONDecodeError as exc:
            raise ReplayError(f"{path}: line {k} is not JSON ({exc.msg})") from None
    if not entries or entries[0].get("format") != JOURNAL_FORMAT:
        raise ReplayError(f"{path}: line 1 is not a {JOURNAL_FORMAT} header")
    if entries[0].get("version") not in READ_VERSIONS:
        raise ReplayError(
            f"{path}: version {entries[0].get('version')!r}, expected one of "
            f"{', '.join(map(str, READ_VERSIONS))}"
        )
    return entries[0], entries[1:], cut


class ReplayLink:
    """The node's end of a link in replay: reads give the recorded bytes, writes are kept."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.data = b""
        self.pos = 0
        self.results: dict[str, list[Any]] = {"r": [], "w": []}
        self.written = bytearray()
        #: (end offset, node time) of each replayed write
        self.index: list[tuple[int, float]] = []
        self.now = 0.0
        self.short = False
        self.unexpected = 0

    def _next(self, kind: str) -> Any:
        results = self.results[kind]
        if not results:
            self.unexpected += 1
            return None
        return results.pop(0)

    def read_available(self) -> bytes:
        n = self._next("r")
        if n == "E":
            raise OSError(f"{self.name}: recorded read error")
        if not n:
            return b""
        chunk = self.data[self.pos : self.pos + n]
        self.pos += n
        if len(chunk) < n:
            self.short = True
        return chunk

    def write(self, data: bytes) -> int:
        self.written += data
        self.index.append((len(self.written), self.now))
        n = self._next("w")
        if n == "E":
            raise OSError(f"{self.name}: recorded write error")
        return len(data) if n is None else int(n)


@dataclass
class Stream:
    """One link's written bytes: in flight and in replay."""

    recorded: bytes = b""
    #: (time ns, end offset) of the recorded writes, over all segments
    recorded_index: list[tuple[int, int]] = field(default_factory=list)


def _first_difference(a: bytes, b: bytes) -> int | None:
    n = min(len(a), len(b))
    if a[:n] != b[:n]:
        lo, hi = 0, n  # bisect on the prefix: one compare per halving
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if a[lo:mid] != b[lo:mid]:
                hi = mid
            else:
                lo = mid
        return lo
    return None if len(a) == len(b) else n


def _robot(header: dict[str, Any], root: Path) -> tuple[Any, list[str]]:
    """The robot of the header (the recorded description copies; a version-1 header: the
    shipped robot it names) and the notes on the copies' origins."""
    from rdm.model import Robot
    from rdm.nodes.recording_sources import ROBOT_TOML, ROBOT_URDF, load_sources

    files = header.get("files")
    if files is None:
        return Robot.shipped(str(header.get("robot", "rdm"))), []
    if not isinstance(files, dict) or not {ROBOT_URDF, ROBOT_TOML} <= set(files):
        raise ValueError(f"files must name {ROBOT_URDF} and {ROBOT_TOML}")
    texts, notes = load_sources(root, files)
    robot = Robot.from_strs(
        texts[ROBOT_URDF], texts[ROBOT_TOML], str(root / ROBOT_URDF), str(root / ROBOT_TOML)
    )
    return robot, notes


def _build_node(
    header: dict[str, Any], links: dict[str, ReplayLink], where: Path, root: Path
) -> tuple[Any, list[str]]:
    """The node the header describes and the notes on its files."""
    from rdm.nodes.onboard import OnboardNode
    from rdm.nodes.onboard_config_file import parse_onboard

    try:
        robot, notes = _robot(header, root)
        config = parse_onboard(header["config"], where).config
    except (KeyError, ValueError, OSError) as exc:
        raise ReplayError(f"{where}: header: {exc}") from None
    if config_document(config) != header["config"]:
        raise ReplayError(f"{where}: header: the configuration does not read back the same")
    try:
        node = OnboardNode(links["spinal"], links.get("leptrino_foot"), robot, config=config)
    except ValueError as exc:
        raise ReplayError(f"{where}: header: the node cannot be built: {exc}") from None
    return node, notes


def _apply(entry: dict[str, Any], node: Any, links: dict[str, ReplayLink]) -> str:
    """Replay one journal entry; its kind (``call``, ``tick``, ``close``, ``note`` or
    ``io``)."""
    if "note" in entry:  # what arrived at the ground link: its effect is the calls after it
        return "note"
    if "call" in entry:
        name = entry["call"]
        if name not in INPUT_METHODS or "unrecordable" in entry:
            why = entry.get("unrecordable", "not an input method")
            raise ReplayError(f"call {name!r} cannot be replayed ({why})")
        getattr(node, name)(*decode_value(entry["args"]), **decode_value(entry["kwargs"]))
        return "call"
    for kind in ("r", "w"):
        recorded = entry.get(kind, {})
        for n, link in links.items():
            link.results[kind] = list(recorded.get(n, ()))
    if "tick" in entry:
        now = decode_value(entry["tick"])
        for link in links.values():
            link.now = now if isinstance(now, float) and math.isfinite(now) else link.now
        node.tick(now)
        return "tick"
    if "close" in entry:
        node.close()
        return "close"
    return "io"


def replay(path: str | Path) -> dict[str, Any]:
    """Replay the recording at ``path`` (:func:`find_recording`); the report (JSON-ready):
    ``identical``, ``notes`` (a robot or configuration file changed since the recording:
    the recorded copy was used), per link the recorded and replayed byte counts and
    ``first_difference`` (``offset``, its recorded and replayed time in s, the two bytes),
    ticks and calls, ``truncated`` (the files end early: the bytes both hold are compared)
    and ``incomplete`` (the recording's ``INCOMPLETE`` marker is there)."""
    root = find_recording(path)
    segments = _segments(root)
    header, _, _ = _journal(segments[0])
    names = [n for n in header.get("links", ["spinal"]) if n in LINKS]
    if "spinal" not in names:
        raise ReplayError(f"{segments[0] / JOURNAL}: header: links must include spinal")
    links = {n: ReplayLink(n) for n in names}
    node, notes = _build_node(header, links, segments[0] / JOURNAL, root)
    streams = {n: Stream() for n in names}
    ticks = calls = 0
    cut = short = False
    for seg in segments:
        seg_header, entries, seg_cut = _journal(seg)
        if seg_header.get("ticks_before") != ticks:
            raise ReplayError(
                f"{seg / JOURNAL}: starts after tick {seg_header.get('ticks_before')}"
                f", the segments before hold {ticks}"
            )
        cut |= seg_cut
        for n in names:
            dev = seg / capture_name(n, "device_tx")
            host = seg / capture_name(n, "host_tx")
            try:
                links[n].data, links[n].pos = dev.read_bytes(), 0
                out = host.read_bytes()
                idx = read_capture_index(host, partial_ok=True)
            except (OSError, CaptureIndexError) as exc:
                raise ReplayError(f"{seg}: {exc}") from None
            s = streams[n]
            base = len(s.recorded)
            s.recorded += out
            s.recorded_index += [(t, base + e) for t, e in zip(idx.times_ns, idx.ends, strict=True)]
        for line, entry in enumerate(entries, 2):
            try:
                kind = _apply(entry, node, links)
            except (KeyError, TypeError, ValueError, AttributeError) as exc:
                raise ReplayError(f"{seg / JOURNAL}: line {line}: {exc}") from None
            ticks += int(kind == "tick")
            calls += int(kind == "call")
            short |= any(link.short for link in links.values())
            if short:
                break
        if short:
            break
    report_streams = {}
    identical = True
    for n in names:
        rec, rep = streams[n].recorded, bytes(links[n].written)
        if short or cut:  # the flight's files end early: compare what both hold
            rep = rep[: len(rec)]
            rec = rec[: len(rep)]
        k = _first_difference(rec, rep)
        identical &= k is None
        diff = None
        if k is not None:
            diff = {
                "offset": k,
                "recorded_time_s": _time_at(streams[n].recorded_index, k),
                "replayed_time_s": _time_at([(int(t * 1e9), e) for e, t in links[n].index], k),
                "recorded": rec[k] if k < len(rec) else None,
                "replayed": rep[k] if k < len(rep) else None,
            }
        report_streams[n] = {
            "recorded_bytes": len(streams[n].recorded),
            "replayed_bytes": len(links[n].written),
            "first_difference": diff,
            "unexpected_io": links[n].unexpected,
        }
    return {
        "run": str(root),
        "identical": identical,
        "segments": len(segments),
        "ticks": ticks,
        "calls": calls,
        "truncated": short or cut,
        "incomplete": (root / INCOMPLETE).exists(),
        "notes": notes,
        "streams": report_streams,
    }


def _time_at(index: list[tuple[int, int]], offset: int) -> float | None:
    """Time (s) of the write that carried byte ``offset`` (None past the last write)."""
    ends = [e for _, e in index]
    k = bisect.bisect_right(ends, offset)
    if k >= len(index):
        return None
    return index[k][0] / 1e9
