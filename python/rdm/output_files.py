"""Output files written without following symbolic links, and replaced atomically.

Every file ``rdm`` writes into a run folder or to a path the user named goes through
:func:`open_output`: the last component of the path is opened with ``O_NOFOLLOW`` (a
symbolic link there is refused, never written through) and must turn out to be a regular
file (a FIFO, a device or a ``/proc`` entry is refused). :func:`write_atomic` writes a whole
file under a temporary name beside it and renames it into place (``os.replace``), so a
reader sees the old file or the new one, never half of one.

ASSUMPTION: a POSIX system with ``O_NOFOLLOW`` (Linux, macOS). The folders on the way to the
file are the caller's: only the file's own name is protected against a link.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import stat
from pathlib import Path
from typing import IO, Any

#: Flags of every output file: write only, never through a symbolic link, not inherited by
#: child processes, and a FIFO without a reader refused at once instead of blocking.
_FLAGS = os.O_WRONLY | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK


class OutputFileError(OSError):
    """An output path that cannot be written safely (a symbolic link, not a regular file)."""


def _open_fd(path: str | os.PathLike[str], flags: int) -> int:
    try:
        fd = os.open(path, flags, 0o666)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise OutputFileError(
                errno.ELOOP, "a symbolic link: rdm writes no file through one", os.fspath(path)
            ) from None
        if exc.errno == errno.ENXIO:
            raise OutputFileError(
                errno.ENXIO, "not a regular file (a FIFO or device)", os.fspath(path)
            ) from None
        raise
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OutputFileError(errno.EINVAL, "not a regular file", os.fspath(path))
        os.set_blocking(fd, True)
    except BaseException:
        os.close(fd)
        raise
    return fd


def open_output(
    path: str | os.PathLike[str],
    mode: str = "wb",
    *,
    exclusive: bool = False,
    **kwargs: Any,
) -> IO[Any]:
    """``open(path, mode)`` for writing (``"w"``/``"wb"``: created or truncated), refusing a
    symbolic link or a non-regular file at ``path`` (:class:`OutputFileError`).
    ``exclusive``: refuse any existing file (``O_EXCL``). ``kwargs`` go to :func:`os.fdopen`
    (encoding, newline, buffering)."""
    if mode not in ("w", "wb"):
        raise ValueError(f"open_output: mode {mode!r} must be 'w' or 'wb'")
    flags = _FLAGS | os.O_CREAT | (os.O_EXCL if exclusive else os.O_TRUNC)
    fd = _open_fd(path, flags)
    try:
        return os.fdopen(fd, mode, **kwargs)
    except BaseException:
        # the file object may already own (and have closed) fd when, say, Ctrl-C arrives
        # inside fdopen: a second close must not replace the exception on its way out
        with contextlib.suppress(OSError):
            os.close(fd)
        raise


def write_atomic(path: str | os.PathLike[str], data: str | bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file beside it and ``os.replace``: the
    file is whole or absent, and a symbolic link at ``path`` is replaced, not followed."""
    path = os.fspath(path)
    folder, name = os.path.split(path)
    tmp = os.path.join(folder, f".{name}.{os.getpid()}.tmp")
    binary = isinstance(data, bytes)
    kwargs = {} if binary else {"encoding": "utf-8"}
    with open_output(tmp, "wb" if binary else "w", exclusive=True, **kwargs) as f:
        try:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        except BaseException:
            os.unlink(tmp)
            raise
    try:
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


class OutputFolderError(ValueError):
    """A folder that cannot be used as asked (not empty, a symbolic link, a file)."""


def prepare_empty_folder(root: Path, replace: bool, name: str) -> None:
    """Make ``root`` an empty real folder. Without ``replace`` a symbolic link, a file or a
    non-empty folder in its place is refused (:class:`OutputFolderError`, the message starting
    with ``name``, e.g. ``"run folder runs/x"``); with it a link or file is removed (never
    what a link points to) and a folder's content is removed without following a link."""
    if root.is_symlink():
        if not replace:
            raise OutputFolderError(
                f"{name} is a symbolic link; rdm writes only into a real folder "
                "(--replace removes the link, never what it points to)"
            )
        os.unlink(root)
    elif root.exists() and not root.is_dir():
        if not replace:
            raise OutputFolderError(f"{name} exists and is not a folder (--replace)")
        os.unlink(root)
    elif root.is_dir() and any(os.scandir(root)):
        if not replace:
            raise OutputFolderError(f"{name} is not empty; --replace removes its content first")
        for entry in os.scandir(root):
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path)  # the fd-based rmtree: links inside are unlinked
            else:
                os.unlink(entry.path)
    root.mkdir(parents=True, exist_ok=True)
