"""The files a flight recording keeps to rebuild its node (docs/onboard.md, "Flight recorder
and replay"): the robot description's URDF and TOML and, when the node was configured from
one, the configuration file.

:func:`store_sources` copies their texts into the recording's root (``robot.urdf``,
``robot.toml``, ``config.toml``) and returns the journal header's ``files`` entry: per file
its SHA-256, its size and its origin (``shipped:<name>/<file>`` or the absolute path it was
read from). :func:`load_sources` reads the copies back for ``rdm replay``, refuses a copy
whose SHA-256 is not the header's, and says in a note when the origin changed since the
recording (a file edited, moved or deleted, a shipped description of another package
version): the replay uses the recorded copy either way. Rotation never deletes these files
(they sit beside the segments); their bytes count in the recording's bound.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from rdm.model import SHIPPED_ORIGIN, RobotSource, sha256_text, shipped_robot_files
from rdm.output_files import open_output

ROBOT_URDF = "robot.urdf"
ROBOT_TOML = "robot.toml"
CONFIG_TOML = "config.toml"


class SourceError(ValueError):
    """A stored copy that is missing, unreadable or not the content the header names."""


def source_texts(
    robot: RobotSource, config_file: str | os.PathLike[str] | None
) -> dict[str, tuple[str, str]]:
    """``{stored name: (text, origin)}`` of ``robot``'s description and ``config_file`` (read
    now; OSError names the file)."""
    files = {
        ROBOT_URDF: (robot.urdf, robot.urdf_origin),
        ROBOT_TOML: (robot.toml, robot.toml_origin),
    }
    if config_file is not None:
        path = Path(config_file).absolute()
        files[CONFIG_TOML] = (path.read_text(encoding="utf-8"), str(path))
    return files


def stored_bytes(files: dict[str, tuple[str, str]]) -> int:
    """Bytes the copies of ``files`` take on disk."""
    return sum(len(text.encode("utf-8")) for text, _ in files.values())


def store_sources(root: Path, files: dict[str, tuple[str, str]]) -> dict[str, Any]:
    """Write each text into ``root`` (a new file, no link followed); the header's ``files``."""
    header: dict[str, Any] = {}
    for name, (text, origin) in files.items():
        data = text.encode("utf-8")
        with open_output(root / name, "wb", exclusive=True) as f:
            f.write(data)
        header[name] = {"sha256": sha256_text(text), "bytes": len(data), "origin": origin}
    return header


def _current_text(origin: str) -> str | None:
    """The text at ``origin`` today (None: gone or unreadable)."""
    try:
        if origin.startswith(SHIPPED_ORIGIN):
            name, _, file = origin[len(SHIPPED_ORIGIN) :].partition("/")
            with shipped_robot_files(name) as (urdf, toml):
                path = urdf if file.endswith(".urdf") else toml
                return path.read_text(encoding="utf-8")
        return Path(origin).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError, ValueError):
        return None


def origin_note(name: str, entry: dict[str, Any]) -> str | None:
    """A note when the origin of the stored ``name`` no longer holds the recorded content."""
    origin = str(entry.get("origin", ""))
    if not origin:
        return None
    now = _current_text(origin)
    if now is None:
        return f"{origin} is gone (moved or deleted); the recorded copy {name} is used"
    sha = sha256_text(now)
    if sha == entry["sha256"]:
        return None
    what = "differs in this package version" if origin.startswith(SHIPPED_ORIGIN) else "was edited"
    return (
        f"{origin} {what} since the recording (sha256 {entry['sha256'][:12]} recorded, "
        f"{sha[:12]} now); the recorded copy {name} is used"
    )


def load_sources(root: Path, files: dict[str, Any]) -> tuple[dict[str, str], list[str]]:
    """(texts by stored name, notes): each copy in ``root`` checked against the header's
    SHA-256 (SourceError names the file), a note per origin that changed (:func:`origin_note`)."""
    texts: dict[str, str] = {}
    notes: list[str] = []
    for name, entry in files.items():
        path = root / name
        if name not in (ROBOT_URDF, ROBOT_TOML, CONFIG_TOML) or not isinstance(entry, dict):
            raise SourceError(f"{path}: not a file a recording stores")
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise SourceError(f"{path}: the recorded copy cannot be read ({exc})") from None
        if sha256_text(text) != entry.get("sha256"):
            raise SourceError(f"{path}: the recorded copy's sha256 is not the header's (damaged)")
        texts[name] = text
        note = origin_note(name, entry)
        if note is not None:
            notes.append(note)
    return texts, notes
