"""The run folder of one simulation: ``runs/<scenario>-seed<seed>/`` (or ``-<timestamp>``).

Layout (names are fixed so tools and docs can rely on them)::

    runs/<scenario>-seed<seed>/
        signals.mcap        ground truth, the onboard PC's status and controller signals
                            (Foxglove / PlotJuggler)
        wire.mcap           with --wire-mcap: every wire message at its time (rdm.sim.wire_mcap)
        can.log             candump -L capture of the Neuron bus (rdm decode can.log)
        uart/               raw UART byte captures (*.bin rosserial, *.lep Leptrino), each with
                            its time index *.idx (rdm.link.capture_index)
        plots/              PNG figures
        metrics.txt         the metrics table
        summary.json        metrics + run facts (seed, duration, speed, counters)
        INCOMPLETE          present while the run has not finished (written when the folder
                            is made, removed once summary.json is in place; an interrupted or
                            crashed run keeps it, with the reason when one is known)

A run folder is made empty: an existing non-empty folder is refused unless the caller asks
to replace it (``replace=True``, ``rdm sim --replace``; :func:`run_folders`), and then its
content is removed first without following any symbolic link in it (a link is unlinked,
never its target). Every file in it is opened with ``O_NOFOLLOW``
(:func:`rdm.output_files.open_output`); ``summary.json`` and ``metrics.txt`` are written
atomically (:func:`rdm.output_files.write_atomic`).
"""

from __future__ import annotations

import os
import re
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path

from rdm.output_files import OutputFolderError, open_output, prepare_empty_folder, write_atomic

_NAME = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")

#: Name of the marker file of a run that has not finished.
INCOMPLETE = "INCOMPLETE"
_INCOMPLETE_TEXT = "this run has not finished: summary.json is written when it does\n"


class RunFolderError(ValueError):
    """A run folder that cannot be used as asked (not empty, a symbolic link, a file)."""


@dataclass
class _Scope:
    replace: bool
    created: list[RunFolder]


_SCOPE: ContextVar[_Scope | None] = ContextVar("rdm_run_folders", default=None)


@contextmanager
def run_folders(*, replace: bool = False) -> Iterator[list[RunFolder]]:
    """Inside the block, :meth:`RunFolder.create` replaces an existing run folder when
    ``replace`` (else refuses a non-empty one) and records every folder it makes in the
    yielded list (``rdm sim`` marks them incomplete when it is interrupted)."""
    scope = _Scope(replace, [])
    token = _SCOPE.set(scope)
    try:
        yield scope.created
    finally:
        _SCOPE.reset(token)


def _prepare(root: Path, replace: bool) -> None:
    """Make ``root`` an empty real folder, or raise :class:`RunFolderError`."""
    try:
        prepare_empty_folder(root, replace, f"run folder {root}")
    except OutputFolderError as exc:
        hint = " (or choose another --out or --seed)" if "not empty" in str(exc) else ""
        raise RunFolderError(f"{exc}{hint}") from None


@dataclass(frozen=True)
class RunFolder:
    """Paths of one run; :meth:`create` makes the directories."""

    root: Path

    @classmethod
    def create(
        cls,
        scenario: str,
        *,
        base: str | os.PathLike[str] = "runs",
        seed: int | None = None,
        stamp: str | None = None,
        replace: bool | None = None,
    ) -> RunFolder:
        """``<base>/<scenario>-seed<seed>`` when a seed is given (reproducible runs keep one
        folder per seed), else ``<base>/<scenario>-<stamp or local time YYYYmmdd-HHMMSS>``.

        The folder is made empty and marked :data:`INCOMPLETE`. An existing non-empty folder
        (or a symbolic link or file in its place) raises :class:`RunFolderError` unless
        ``replace`` (default: that of the enclosing :func:`run_folders`, else False); then its
        content is removed first, following no symbolic link."""
        if not _NAME.match(scenario):
            raise ValueError(f"RunFolder: scenario {scenario!r} must match {_NAME.pattern}")
        if seed is not None:
            suffix = f"seed{int(seed)}"
        else:
            suffix = stamp or time.strftime("%Y%m%d-%H%M%S")
            if not _NAME.match(suffix):
                raise ValueError(f"RunFolder: stamp {suffix!r} must match {_NAME.pattern}")
        root = Path(base) / f"{scenario}-{suffix}"
        scope = _SCOPE.get()
        if replace is None:
            replace = scope is not None and scope.replace
        _prepare(root, replace)
        folder = cls(root)
        with open_output(folder.incomplete, "w", exclusive=True, encoding="utf-8") as f:
            f.write(_INCOMPLETE_TEXT)
        for d in (folder.uart_dir, folder.plots_dir):
            d.mkdir()
        if scope is not None:
            scope.created.append(folder)
        return folder

    @property
    def incomplete(self) -> Path:
        """The marker of a run that has not finished (:data:`INCOMPLETE`)."""
        return self.root / INCOMPLETE

    def mark_complete(self) -> None:
        """Remove the :data:`INCOMPLETE` marker (once ``summary.json`` is written)."""
        with suppress(FileNotFoundError):
            os.unlink(self.incomplete)

    def mark_incomplete(self, reason: str) -> None:
        """(Re)write the :data:`INCOMPLETE` marker with ``reason`` (an interrupted run)."""
        write_atomic(self.incomplete, f"this run did not finish: {reason}\n")

    @property
    def mcap(self) -> Path:
        return self.root / "signals.mcap"

    @property
    def wire_mcap(self) -> Path:
        return self.root / "wire.mcap"

    @property
    def candump(self) -> Path:
        return self.root / "can.log"

    @property
    def uart_dir(self) -> Path:
        return self.root / "uart"

    @property
    def plots_dir(self) -> Path:
        return self.root / "plots"

    @property
    def metrics_txt(self) -> Path:
        return self.root / "metrics.txt"

    @property
    def summary_json(self) -> Path:
        return self.root / "summary.json"

    def plot(self, name: str) -> Path:
        """Path of a PNG in ``plots/``."""
        return self.plots_dir / (name if name.endswith(".png") else f"{name}.png")
