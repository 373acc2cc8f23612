"""What the sub-commands write: an output path the user named, and JSON on stdout.

:func:`check_output_path` is the one check of a file path given on the command line
(``rdm plan --out``, ``rdm plant --export``, ``rdm bench --json``, ``rdm decode --mcap``):
its folder exists and takes new files, and the path is not a symbolic link, a folder or any
other non-regular file. :func:`output_file` is the same check as an argparse type, so a bad
path is refused while the arguments are parsed, before any work (argparse's message then
names the option). The write itself goes through :func:`rdm.output_files.open_output`
(``O_NOFOLLOW``), which catches a link planted between the check and the write.

:func:`json_text` is every ``--json`` output: ``json.dumps(..., allow_nan=False)``, so what
``rdm`` prints is valid JSON (RFC 8259 has no NaN or Infinity).
"""

from __future__ import annotations

import argparse
import json
import os
import stat
import tempfile
from pathlib import Path
from typing import Any


class OutputPathError(ValueError):
    """An output path that cannot or must not be written; the message names the path."""


def check_output_path(path: str | os.PathLike[str], option: str | None = None) -> Path:
    """``path`` as a :class:`Path` if a file can be written there, else
    :class:`OutputPathError` whose message starts with ``option`` (when given) and the path.

    Rules: a non-empty path; not a symbolic link; an existing target is a regular file; the
    parent folder exists, is a folder and takes a new file (tried by making and removing a
    temporary file in it, which also catches read-only and pseudo file systems such as
    ``/proc``, where permissions alone do not tell)."""
    text = os.fspath(path)
    where = f"{option} {text!r}" if option else repr(text)
    if not text:
        raise OutputPathError(f"{option or 'output path'}: an empty path")
    p = Path(text)
    try:
        st = os.lstat(p)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise OutputPathError(f"{where}: {exc.strerror}") from None
    if st is not None:
        if stat.S_ISLNK(st.st_mode):
            raise OutputPathError(f"{where}: a symbolic link; rdm writes no file through one")
        if stat.S_ISDIR(st.st_mode):
            raise OutputPathError(f"{where}: a folder, not a file")
        if not stat.S_ISREG(st.st_mode):
            raise OutputPathError(f"{where}: not a regular file (a device, FIFO or socket)")
    parent = p.parent
    if not parent.is_dir():
        why = "does not exist" if not parent.exists() else "is not a folder"
        raise OutputPathError(f"{where}: the folder {str(parent)!r} {why}")
    try:
        fd, probe = tempfile.mkstemp(prefix=".rdm-write-check-", dir=parent)
    except OSError as exc:
        raise OutputPathError(
            f"{where}: the folder {str(parent)!r} does not take new files ({exc.strerror})"
        ) from None
    os.close(fd)
    os.unlink(probe)
    if st is not None and not os.access(p, os.W_OK):
        raise OutputPathError(f"{where}: the file is not writable")
    return p


def output_file(text: str) -> Path:
    """argparse type of an output file option (:func:`check_output_path`)."""
    try:
        return check_output_path(text)
    except OutputPathError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def output_file_or_stdout(text: str) -> str:
    """argparse type: ``-`` (standard output) or an output file (:func:`output_file`)."""
    return text if text == "-" else str(output_file(text))


def json_text(value: Any, **kwargs: Any) -> str:
    """``json.dumps(value, allow_nan=False, **kwargs)``: valid JSON or ``ValueError`` (the
    caller decides whether a non-finite number is an error, :func:`non_finite_paths`, or null,
    :func:`nulled`; both from :mod:`rdm.json_values`)."""
    return json.dumps(value, allow_nan=False, **kwargs)
