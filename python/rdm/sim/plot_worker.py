"""PNG figures drawn in a worker process while the simulation runs on this one.

matplotlib costs ~0.6 s to import and ~1 s to lay out and write one figure of
:func:`rdm.sim.plots.plot_panels`: about as long as the 30 s perching simulation itself on
a 2-core x86_64 machine, and all of it after the simulation. ``rdm sim`` therefore starts one worker
process at launch (:func:`plots_in_background`); it imports matplotlib on the second core
while the single-threaded simulation runs, and draws the figures the scenario hands it
while the main process evaluates metrics and writes the summary. The figures are the same
(same matplotlib, same Agg backend, same inputs: ``tests/test_plot_worker.py`` compares the
pixels).

Inputs are checked in the caller (a bad shape raises there, at once); a drawing error in
the worker is raised by :meth:`PlotWorker.wait`. A worker that cannot start (no process
spawning here) leaves the drawing to the caller's process, as without the context; a worker
that dies (killed, out of memory) has its unfinished figures drawn again in the caller's
process by :meth:`PlotWorker.wait` (counted in ``redrawn``), so no figure is lost.
"""

from __future__ import annotations

import multiprocessing
import pickle
import signal
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import Any

_ACTIVE: ContextVar[PlotWorker | None] = ContextVar("rdm_plot_worker", default=None)


def active_worker() -> PlotWorker | None:
    """The worker of the enclosing :func:`plots_in_background`, if any."""
    return _ACTIVE.get()


def pyplot() -> Any:
    """``matplotlib.pyplot`` with the Agg backend (no display needed), imported on first use."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _warm_up() -> None:
    """Worker initializer: import matplotlib (Agg) before the first figure is asked for."""
    pyplot()


def _ready() -> bool:
    return True


def _draw_snapshot(draw: Callable[..., None], out: Path, snapshot: bytes) -> None:
    """Worker side of :meth:`PlotWorker.submit`: ``draw(out, *inputs)`` of the inputs as
    they were when the figure was queued."""
    draw(out, *pickle.loads(snapshot))


@contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored inside the block (in the main thread; elsewhere no change)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler if old is None else old)


class PlotWorker:
    """One spawned process that draws figures (``draw(out, *args)`` calls) in order."""

    def __init__(self) -> None:
        # spawn, not fork: the parent may hold threads (MCAP writer) and MuJoCo state
        self._pool = ProcessPoolExecutor(
            max_workers=1,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_warm_up,
        )
        # start the process (and its matplotlib import) now, with Ctrl-C ignored: SIGINT to
        # the terminal's process group is the parent's to handle (rdm sim stops the worker),
        # and a process that starts with SIGINT ignored keeps it so (Python installs its
        # KeyboardInterrupt handler only over the default), so no traceback of its own
        with _sigint_ignored():
            self._pool.submit(_ready)
        self._pending: list[tuple[Future | None, Callable[..., None], Path, bytes]] = []
        #: Every figure written so far (by :meth:`wait`), in order.
        self.drawn: list[Path] = []
        #: Figures drawn in this process because the worker had died.
        self.redrawn = 0

    def submit(self, draw: Callable[..., None], out: Path, *args: Any) -> None:
        """Queue ``draw(out, *args)`` (a module-level function and picklable inputs). The
        inputs are pickled here, at once: the figure shows them as they are now, whatever
        the caller does with its arrays afterwards."""
        snapshot = pickle.dumps(args, protocol=pickle.HIGHEST_PROTOCOL)
        try:
            future: Future | None = self._pool.submit(_draw_snapshot, draw, out, snapshot)
        except BrokenProcessPool:
            future = None  # the worker is gone: wait() draws it here
        self._pending.append((future, draw, out, snapshot))

    def wait(self) -> list[Path]:
        """Block until every queued figure is written; returns every written path in order.
        A drawing error is raised here, after the other figures are written; the figures a
        dead worker left are drawn in this process."""
        error: BaseException | None = None
        pending, self._pending = self._pending, []
        for future, draw, out, snapshot in pending:
            try:
                try:
                    if future is None:
                        raise BrokenProcessPool("the plot worker was not running")
                    future.result()
                except BrokenProcessPool:
                    _draw_snapshot(draw, out, snapshot)
                    self.redrawn += 1
                self.drawn.append(out)
            except BaseException as exc:  # re-raised below, after the rest
                error = error or exc
        if error is not None:
            raise error
        return list(self.drawn)

    def close(self) -> None:
        """Stop the process (waits for queued figures; :meth:`wait` first to see errors)."""
        self._pool.shutdown(wait=True, cancel_futures=False)


@contextmanager
def plots_in_background() -> Iterator[PlotWorker | None]:
    """Inside: the ``rdm.sim.plots`` functions queue their figure to a worker process. On a
    normal exit the figures are waited for (errors raised); the worker is always stopped.
    Yields None (figures drawn in this process) when no worker process can be started."""
    try:
        worker: PlotWorker | None = PlotWorker()
    except (OSError, RuntimeError, ImportError):
        worker = None
    token = _ACTIVE.set(worker)
    try:
        yield worker
        if worker is not None:
            worker.wait()
    finally:
        _ACTIVE.reset(token)
        if worker is not None:
            worker.close()
