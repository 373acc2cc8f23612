"""The capture formats rdm reads, told apart by the file's extension.

* ``uart``: raw bytes of the Spinal <-> PC rosserial link (:mod:`rdm.protocol.rosserial.capture`);
* ``candump``: a ``candump -L`` (or Vector ASC) log of the Spinal <-> Neuron CAN bus
  (:mod:`rdm.protocol.neuron`);
* ``leptrino``: raw bytes of a Leptrino force/torque sensor link (:mod:`rdm.protocol.leptrino`).

``rdm decode`` (:mod:`rdm.commands.decode`) and the wire MCAP (:mod:`rdm.sim.wire_mcap`) both
name a capture's format with :func:`detect_format`, and read it piece by piece with
:func:`read_chunks` (the decoders take chunks, so memory does not grow with the file).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

#: Format name -> the file extensions (lower case, with the dot) that carry it.
EXTENSIONS: dict[str, tuple[str, ...]] = {
    "uart": (".bin", ".raw", ".uart", ".cap"),
    "candump": (".log", ".candump", ".asc"),
    "leptrino": (".lep", ".leptrino"),
}


def detect_format(path: Path) -> str | None:
    """The format whose extensions include the file's suffix (any case), or None."""
    suffix = path.suffix.lower()
    for name, extensions in EXTENSIONS.items():
        if suffix in extensions:
            return name
    return None


def known_extensions() -> str:
    """Every extension of every format, space-separated (for error messages)."""
    return " ".join(ext for extensions in EXTENSIONS.values() for ext in extensions)


#: Bytes read from a capture at a time (the decoders keep at most a chunk's events).
CHUNK_BYTES = 1 << 14


def read_chunks(path: Path, size: int = CHUNK_BYTES) -> Iterator[bytes]:
    """The bytes of the file at ``path``, ``size`` at a time."""
    with open(path, "rb") as fh:
        while chunk := fh.read(size):
            yield chunk
