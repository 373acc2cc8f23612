"""Capture time index (``rdm.link.capture_index.read_capture_index``): the ``.idx`` file
beside a UART or Leptrino capture, read by ``rdm decode RUN --mcap``.

Input: the capture's size (little-endian u32, masked to 24 bits: up to 16 MiB, written as a
sparse file) then the index file's bytes.

Checks: the reader either raises :class:`CaptureIndexError` or returns exactly the records
of the file, read here with ``struct`` (times never decreasing, end offsets strictly
increasing from above 0, the last one the capture's size unless ``partial_ok``), and
``time_ns_of`` gives each byte the time of the first record ending after it (a linear
search here) and refuses offsets outside the indexed bytes.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable

from fuzz_targets.base import BadFrameAccepted, Target, WrongCount
from fuzz_targets.neuron import _scratch
from rdm.link.capture_index import MAGIC, CaptureIndex, CaptureIndexError, read_capture_index


def _records(body: bytes) -> list[tuple[int, int]] | None:
    """The records of an index body, or None when they break a rule of the format."""
    if len(body) % 16:
        return None
    out = [struct.unpack_from("<qQ", body, k) for k in range(0, len(body), 16)]
    for k, (ns, end) in enumerate(out):
        if end <= (out[k - 1][1] if k else 0) or (k and ns < out[k - 1][0]):
            return None
    return out


def _check_index(index: CaptureIndex, records: list[tuple[int, int]], where: str) -> None:
    if list(zip(index.times_ns, index.ends, strict=True)) != records:
        raise WrongCount(f"{where}: read {len(index.ends)} records, the file has {len(records)}")
    size = records[-1][1] if records else 0
    probes = (
        {0, size - 1, size, -1}
        | {end for _, end in records[:4]}
        | {end - 1 for _, end in records[:4]}
    )
    for offset in sorted(probes):
        want = next((ns for ns, end in records if end > offset), None) if offset >= 0 else None
        try:
            got = index.time_ns_of(offset)
        except CaptureIndexError:
            got = None
        if got != want:
            raise WrongCount(f"{where}: byte {offset} timed {got}, the records say {want}")


def check(data: bytes) -> None:
    """Read the index ``data`` stands for, whole and with ``partial_ok``."""
    if len(data) < 4:
        return
    size = int.from_bytes(data[:4], "little") & 0xFFFFFF
    idx = data[4:]
    capture = _scratch() / "capture.bin"
    with open(capture, "wb") as fh:
        fh.truncate(size)
    (_scratch() / "capture.bin.idx").write_bytes(idx)
    records = _records(idx[8:]) if idx[:8] == MAGIC else None
    for partial in (False, True):
        try:
            index = read_capture_index(capture, partial_ok=partial)
        except CaptureIndexError:
            index = None
        size_ok = records is not None and (partial or (records[-1][1] if records else 0) == size)
        if index is None:
            if size_ok:
                raise WrongCount(f"partial_ok={partial}: a valid index of {size} bytes refused")
            continue
        if not size_ok or records is None:
            raise BadFrameAccepted(f"partial_ok={partial}: an index breaking the format read")
        _check_index(index, records, f"partial_ok={partial}")


def _file(size: int, records: list[tuple[int, int]]) -> bytes:
    body = b"".join(struct.pack("<qQ", ns, end) for ns, end in records)
    return (size & 0xFFFFFF).to_bytes(4, "little") + MAGIC + body


def seeds() -> Iterable[bytes]:
    """Indexes as ``TimedCaptureFile`` writes them (microsecond-rounded times, one record
    per write) and as a killed run leaves them, plus broken ones."""
    yield _file(0, [])
    yield _file(10, [(1_000_000, 4), (1_000_000, 10)])
    writes = [(k * 1_000_000, 23 * (k + 1)) for k in range(1, 30)]
    yield _file(23 * 29, writes)
    yield _file(23 * 20, writes)  # the capture lost its last buffer
    yield _file(5, [(-(2**63), 5)])
    yield _file(8, [(5, 4), (4, 8)])  # back in time
    yield _file(8, [(5, 8), (6, 8)])  # offset does not advance
    yield _file(8, [(5, 8)])[:-3]  # truncated
    yield b"\x08\x00\x00\x00RDMCIDX0" + bytes(16)


TARGETS = [
    Target("capture_index", check, seeds,
           about="rdm.link.capture_index.read_capture_index, CaptureIndex.time_ns_of"),
]  # fmt: skip
