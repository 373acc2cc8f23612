"""The onboard node's flight recorder: every byte of its ports and every input it took, for
``rdm replay`` (docs/onboard.md, "Flight recorder and replay").

:func:`attach_recorder` wraps an :class:`rdm.nodes.onboard.OnboardNode` before it first ticks:
its UART and foot-sensor links become :class:`RecordingLink` ends, and its ``tick``, ``close``
and input methods (:data:`INPUT_METHODS`: mocap, targets, operator commands) are journaled
on the instance. The recording is a folder of segments::

    <folder>/
        INCOMPLETE                  while recording (an interrupted run keeps it)
        summary.json                the recorder's counts, written when it closes
        robot.urdf, robot.toml      the robot description the node was built for
        config.toml                 the configuration file it was given (if one was)
        seg0000/
            journal.jsonl           header line, then one line per input and per tick
            uart/spinal.device_tx.bin         bytes the node read from Spinal   (+ .idx)
            uart/spinal.host_tx.bin           bytes the node wrote to Spinal    (+ .idx)
            uart/leptrino_foot.device_tx.lep  bytes the node read from the foot sensor
            uart/leptrino_foot.host_tx.lep    bytes the node wrote to it
        seg0001/ ...

The captures are the files ``rdm sim`` writes for its UARTs (raw bytes, the time index
``<capture>.idx`` of :mod:`rdm.link.capture_index`, the node's tick time at each read and
write), so ``rdm decode SEGMENT --mcap`` reads a segment as it reads a simulation run.
The journal holds what the captures cannot: each tick's exact time (a float, where the
index keeps microseconds), how many bytes each read returned (and each write took, or an
``OSError``), and each input call with its arguments, in the order they happened. The node
reads no clock of its own (:mod:`rdm.nodes.base`), so these are all its inputs.

The description and configuration copies (:mod:`rdm.nodes.recording_sources`, their
SHA-256 in the header) let a replay rebuild the node after those files moved or changed.

Segments rotate: once a segment holds ``segment_bytes`` the next tick starts another, and the
oldest segments are deleted while the folder (segments and copies) holds more than
``max_bytes``. A replay needs every segment from ``seg0000`` on (the node's state is not
stored, only its inputs).
"""

from __future__ import annotations

import json
import math
import os
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from rdm.link.capture_index import TimedCaptureFile
from rdm.model import RobotSource, robot_source
from rdm.output_files import OutputFolderError, open_output, prepare_empty_folder, write_atomic

#: The node methods an outside caller (ground link, mocap, scenario script) drives it by.
INPUT_METHODS = (
    "set_mocap",
    "set_mocap_pose",
    "set_target",
    "set_joint_targets",
    "set_trajectory",
    "move_joints",
    "request_perch",
    "perch",
    "unperch",
    "arm",
    "disarm",
    "force_landing",
    "takeoff",
    "land",
    "halt",
    "goto",
    "set_gain_profile",
    "use_position_gains",
    "on_ground_lost",
    "on_ground_restored",
)

JOURNAL = "journal.jsonl"
JOURNAL_FORMAT = "rdm-onboard-journal"
#: 2: the header's ``files`` (robot description and configuration copies); a replay reads 1
#: (a shipped robot by name) and 2.
JOURNAL_VERSION = 2
INCOMPLETE = "INCOMPLETE"
SUMMARY = "summary.json"
#: The captured links: name -> file extension (``rdm sim``'s capture names).
LINKS = {"spinal": ".bin", "leptrino_foot": ".lep"}
#: ASSUMPTION: 1024 MB bound the folder (about 3 h of flight at ~100 kB/s of both ports).
DEFAULT_MAX_MB = 1024.0
#: ASSUMPTION: a segment is an eighth of the bound (rotation frees 1/8 at a time).
SEGMENTS_PER_BOUND = 8


class RecorderError(ValueError):
    """A recording folder that cannot be used as asked (not empty, a link, a file)."""


def segment_name(index: int) -> str:
    return f"seg{index:04d}"


def capture_name(link: str, direction: str) -> str:
    """``uart/<link>.<direction><ext>`` inside a segment (direction ``device_tx``: what the
    node read; ``host_tx``: what it wrote)."""
    return f"uart/{link}.{direction}{LINKS[link]}"


# ----------------------------------------------------------------------------- values
def encode_value(value: Any) -> Any:
    """A JSON form of an input argument that :func:`decode_value` turns back into the same
    type and the same float bits (tuples and arrays are tagged)."""
    if isinstance(value, np.generic):
        return {"scalar": encode_value(value.item()), "dtype": value.dtype.str}
    if value is None or isinstance(value, (bool, str, int)):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else {"float": repr(value)}
    if isinstance(value, np.ndarray):
        return {"ndarray": [encode_value(v) for v in value.ravel().tolist()],
                "dtype": value.dtype.str, "shape": list(value.shape)}  # fmt: skip
    if isinstance(value, tuple):
        return {"tuple": [encode_value(v) for v in value]}
    if isinstance(value, list):
        return [encode_value(v) for v in value]
    if isinstance(value, dict) and all(isinstance(k, str) for k in value):
        return {"dict": {k: encode_value(v) for k, v in value.items()}}
    raise TypeError(f"an input argument of type {type(value).__name__} cannot be recorded")


def decode_value(value: Any) -> Any:
    """The inverse of :func:`encode_value`."""
    if isinstance(value, list):
        return [decode_value(v) for v in value]
    if not isinstance(value, dict):
        return value
    if "float" in value:
        return float(value["float"])
    if "ndarray" in value:
        flat = [decode_value(v) for v in value["ndarray"]]
        return np.array(flat, dtype=np.dtype(value["dtype"])).reshape(value["shape"])
    if "scalar" in value:
        return np.dtype(value["dtype"]).type(decode_value(value["scalar"]))
    if "tuple" in value:
        return tuple(decode_value(v) for v in value["tuple"])
    if "dict" in value:
        return {k: decode_value(v) for k, v in value["dict"].items()}
    raise ValueError(f"journal value {value!r} has no known tag")


def _drop_none(doc: Any) -> Any:
    if isinstance(doc, dict):
        return {k: _drop_none(v) for k, v in doc.items() if v is not None}
    if isinstance(doc, list):
        return [_drop_none(v) for v in doc]
    return doc


def config_document(config: Any) -> dict[str, Any]:
    """An ``OnboardConfig`` as the configuration file's document (``None`` fields left out:
    they are the defaults), which :func:`rdm.nodes.onboard_config_file.parse_onboard` reads
    back to an equal configuration (:func:`check_config_document` makes sure)."""
    from rdm.nodes.onboard_config_file import config_json

    return _drop_none(config_json(config))


def check_config_document(config: Any) -> dict[str, Any]:
    """:func:`config_document` of ``config``; RecorderError when it does not read back as an
    equal configuration (a replay could not build the same node)."""
    from rdm.nodes.onboard_config_file import parse_onboard

    doc = config_document(config)
    try:
        back = parse_onboard(doc, "recorder header").config
    except ValueError as exc:
        raise RecorderError(f"the configuration cannot be recorded: {exc}") from None
    if config_document(back) != doc:
        raise RecorderError("the configuration does not read back the same; not recordable")
    return doc


# ----------------------------------------------------------------------------- folder
def prepare_folder(root: Path, replace: bool) -> None:
    """Make ``root`` an empty real folder marked :data:`INCOMPLETE` (the run-folder rules of
    :mod:`rdm.sim.run_folder`: a non-empty folder is refused unless ``replace``, whose content
    is then removed without following a symbolic link; a link in its place is refused)."""
    try:
        prepare_empty_folder(root, replace, f"--record {root}:")
    except OutputFolderError as exc:
        raise RecorderError(str(exc)) from None
    with open_output(root / INCOMPLETE, "w", exclusive=True, encoding="utf-8") as f:
        f.write("this recording has not finished: summary.json is written when it does\n")


class _Segment:
    """One segment's journal and captures."""

    def __init__(self, root: Path, index: int, links: tuple[str, ...], clock: Callable) -> None:
        self.index = index
        self.folder = root / segment_name(index)
        self.folder.mkdir()
        (self.folder / "uart").mkdir()
        self.journal = open_output(self.folder / JOURNAL, "w", encoding="utf-8")
        self.captures: dict[tuple[str, str], TimedCaptureFile] = {}
        for link in links:
            for direction in ("device_tx", "host_tx"):
                path = self.folder / capture_name(link, direction)
                self.captures[link, direction] = TimedCaptureFile(path, clock)
        self.size = 0

    def line(self, entry: dict[str, Any]) -> None:
        text = json.dumps(entry, separators=(",", ":")) + "\n"
        self.journal.write(text)
        self.size += len(text)

    def capture(self, link: str, direction: str, data: bytes) -> None:
        self.captures[link, direction].write(data)
        self.size += len(data) + 16  # the bytes and their index record

    def close(self) -> None:
        self.journal.close()
        for f in self.captures.values():
            f.close()


class FlightRecorder:
    """Journal and captures of one node (see the module doc). ``header``: what a replay
    needs to build the same node (``robot``, ``config``), written at the top of every
    segment. ``max_bytes``/``segment_bytes`` bound the folder."""

    def __init__(
        self,
        root: str | os.PathLike[str],
        header: dict[str, Any],
        links: tuple[str, ...],
        *,
        max_bytes: int = int(DEFAULT_MAX_MB * 1e6),
        segment_bytes: int | None = None,
        reserved_bytes: int = 0,
    ) -> None:
        if max_bytes < 1:
            raise RecorderError(f"max_bytes={max_bytes} must be >= 1")
        if reserved_bytes >= max_bytes:
            raise RecorderError(
                f"max_bytes={max_bytes} must exceed the {reserved_bytes} bytes of the robot "
                "description and configuration copies"
            )
        self.root = Path(root)
        self.header = {"format": JOURNAL_FORMAT, "version": JOURNAL_VERSION, **header}
        self.links = links
        self.max_bytes = max_bytes
        self.segment_bytes = segment_bytes or max(1, max_bytes // SEGMENTS_PER_BOUND)
        #: bytes outside the segments that count in the bound (the copies in the root)
        self.reserved_bytes = reserved_bytes
        self.now = 0.0
        self.ticks = 0
        self.calls = 0
        self.dropped_segments = 0
        self.unrecordable = 0
        self._closed_sizes: list[tuple[int, int]] = []  # (segment index, bytes) kept
        self._entry: dict[str, Any] | None = None
        self._depth = 0
        #: called with a segment before it closes (a writer of other files into it, such as
        #: the signals MCAP, finishes them there): the segment's size is then measured
        self.segment_closing: list[Callable[[_Segment], None]] = []
        self.segment = self._open_segment(0)

    def _open_segment(self, index: int) -> _Segment:
        seg = _Segment(self.root, index, self.links, lambda: self.now)
        seg.line({**self.header, "segment": index, "ticks_before": self.ticks})
        return seg

    # ------------------------------------------------------------------ node events
    def begin(self, kind: str, now: float | None = None) -> None:
        """A tick at ``now`` (or the node's ``close``) starts: its reads and writes follow."""
        if now is not None and math.isfinite(now) and now >= self.now:
            self.now = now
        self._entry = {kind: now if kind == "tick" else True}
        self._depth += 1

    def end(self) -> None:
        """The tick (or close) ended: its journal line, then rotation at the boundary."""
        self._depth -= 1
        entry, self._entry = self._entry, None
        if entry is None:
            return
        if "tick" in entry:
            self.ticks += 1
            if not isinstance(entry["tick"], float) or not math.isfinite(entry["tick"]):
                entry["tick"] = encode_value(entry["tick"])
        self.segment.line(entry)
        if self.segment.size >= self.segment_bytes:
            self._rotate()

    def call(self, name: str, args: tuple, kwargs: dict) -> bool:
        """Journal an input call made from outside the node; False inside a tick or another
        input (the node's own calls are replayed by replaying the outer one)."""
        if self._depth:
            return False
        try:
            entry = {"call": name, "args": encode_value(list(args)),
                     "kwargs": encode_value(kwargs)}  # fmt: skip
        except TypeError as exc:
            self.unrecordable += 1
            entry = {"call": name, "unrecordable": str(exc)}
        self.calls += 1
        self.segment.line(entry)
        return True

    def note(self, entry: dict[str, Any]) -> None:
        """A journal line a replay does not act on (a ground-link datagram as it arrived)."""
        self.segment.line({"note": True, **entry})

    def io(self, link: str, kind: str, data: bytes, result: int | str) -> None:
        """A read (``r``) or write (``w``) on ``link``: the bytes into its capture, the
        result (bytes returned or taken, ``"E"`` for an OSError) into the journal."""
        direction = "device_tx" if kind == "r" else "host_tx"
        if data:
            self.segment.capture(link, direction, data)
        entry = self._entry
        if entry is None:  # outside a tick: its own line, so the journal keeps the order
            self.segment.line({"io": True, kind: {link: [result]}})
            return
        entry.setdefault(kind, {}).setdefault(link, []).append(result)

    # ------------------------------------------------------------------ rotation
    def _close_segment(self) -> int:
        """Close the present segment; its bytes on disk."""
        seg = self.segment
        for closing in self.segment_closing:
            closing(seg)
        seg.close()
        return sum(p.stat().st_size for p in seg.folder.rglob("*") if p.is_file())

    def _rotate(self) -> None:
        old = self.segment
        self._closed_sizes.append((old.index, self._close_segment()))
        self.segment = self._open_segment(old.index + 1)
        while self._closed_sizes and (
            sum(s for _, s in self._closed_sizes) + self.segment.size + self.reserved_bytes
            > self.max_bytes
        ):
            index, _ = self._closed_sizes.pop(0)
            shutil.rmtree(self.root / segment_name(index))
            self.dropped_segments += 1

    def close(self, reason: str | None = None) -> dict[str, Any]:
        """Close the files; write ``summary.json`` and drop :data:`INCOMPLETE` (or, with a
        ``reason``, keep it and say why). Returns the summary."""
        self._close_segment()
        summary = {
            "ticks": self.ticks,
            "calls": self.calls,
            "segments": [i for i, _ in self._closed_sizes] + [self.segment.index],
            "dropped_segments": self.dropped_segments,
            "unrecordable_calls": self.unrecordable,
            "max_bytes": self.max_bytes,
            "segment_bytes": self.segment_bytes,
            "copies_bytes": self.reserved_bytes,
            "replayable": self.dropped_segments == 0 and self.unrecordable == 0,
        }
        write_atomic(self.root / SUMMARY, json.dumps(summary, indent=2) + "\n")
        if reason is None:
            (self.root / INCOMPLETE).unlink(missing_ok=True)
        else:
            write_atomic(self.root / INCOMPLETE, f"this recording did not finish: {reason}\n")
        return summary


class RecordingLink:
    """A byte link end whose reads and writes go to a :class:`FlightRecorder`; every other
    attribute is the wrapped link's."""

    def __init__(self, link: Any, name: str, recorder: FlightRecorder) -> None:
        self.link = link
        self._name = name
        self._recorder = recorder

    def read_available(self) -> bytes:
        try:
            data = self.link.read_available()
        except OSError:
            self._recorder.io(self._name, "r", b"", "E")
            raise
        self._recorder.io(self._name, "r", data, len(data))
        return data

    def write(self, data: bytes) -> int:
        try:
            n = self.link.write(data)
        except OSError:
            self._recorder.io(self._name, "w", bytes(data), "E")
            raise
        n = len(data) if n is None else int(n)
        self._recorder.io(self._name, "w", bytes(data), n)
        return n

    def __getattr__(self, name: str) -> Any:
        return getattr(self.link, name)


def _journaled(recorder: FlightRecorder, name: str, method: Callable) -> Callable:
    def call(*args: Any, **kwargs: Any) -> Any:
        if not recorder.call(name, args, kwargs):
            return method(*args, **kwargs)
        recorder._depth += 1
        try:
            return method(*args, **kwargs)
        finally:
            recorder._depth -= 1

    call.__name__ = name
    return call


def attach_recorder(node: Any, recorder: FlightRecorder) -> None:
    """Record ``node`` (an ``OnboardNode`` that has not ticked) into ``recorder``: its links
    wrapped, its tick, close and :data:`INPUT_METHODS` journaled on the instance (a caller
    that looks them up on the node, as every scheduler and the ground link do, is seen)."""
    node.uart = RecordingLink(node.uart, "spinal", recorder)
    if node.foot is not None:
        node.foot.link = RecordingLink(node.foot.link, "leptrino_foot", recorder)
    tick, close = node.tick, node.close

    def recorded_tick(now: float) -> None:
        recorder.begin("tick", now)
        try:
            tick(now)
        finally:
            recorder.end()

    def recorded_close() -> None:
        recorder.begin("close")
        try:
            close()
        finally:
            recorder.end()

    node.tick, node.close = recorded_tick, recorded_close
    for name in INPUT_METHODS:
        setattr(node, name, _journaled(recorder, name, getattr(node, name)))


def record_node(
    node: Any,
    folder: str | os.PathLike[str],
    robot: str | RobotSource,
    *,
    config_file: str | os.PathLike[str] | None = None,
    replace: bool = False,
    max_bytes: int = int(DEFAULT_MAX_MB * 1e6),
    segment_bytes: int | None = None,
) -> FlightRecorder:
    """Prepare ``folder`` (:func:`prepare_folder`) and record ``node`` into it; the caller
    closes the returned recorder after the node. ``robot``: the description the node was
    built from (a shipped name or a TOML path is read here); ``config_file``: the file its
    configuration came from. Both are copied into the folder for the replay."""
    from rdm.nodes.recording_sources import source_texts, store_sources, stored_bytes

    doc = check_config_document(node.config)
    source = robot if isinstance(robot, RobotSource) else robot_source(robot)
    try:
        files = source_texts(source, config_file)
    except (OSError, UnicodeDecodeError) as exc:
        raise RecorderError(f"--config {config_file}: {exc}") from None
    reserved = stored_bytes(files)
    if reserved >= max_bytes:
        raise RecorderError(
            f"--record-max-mb {max_bytes / 1e6:g}: the bound must exceed the {reserved} bytes "
            "of the robot description and configuration copies"
        )
    root = Path(folder)
    prepare_folder(root, replace)
    links = ("spinal", "leptrino_foot") if node.foot is not None else ("spinal",)
    header = {
        "robot": source.spec,
        "files": store_sources(root, files),
        "config": doc,
        "links": list(links),
    }
    recorder = FlightRecorder(
        root,
        header,
        links,
        max_bytes=max_bytes,
        segment_bytes=segment_bytes,
        reserved_bytes=reserved,
    )
    attach_recorder(node, recorder)
    return recorder
