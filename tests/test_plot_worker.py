"""The figures of ``rdm sim`` drawn in a worker process (rdm.sim.plot_worker): the same
pixels as in this process, inputs checked in the caller, drawing errors raised by ``wait``."""

from __future__ import annotations

import os
import signal
import time

import matplotlib.image as mpimg
import numpy as np
import pytest

from rdm.sim.plot_worker import active_worker, plots_in_background
from rdm.sim.plots import plot_panels, plot_tracking_errors, plot_zmp


def _figures(folder) -> list:
    """Three figures, one of each kind, into ``folder``; returns their paths."""
    t = np.linspace(0.0, 3.0, 301)
    rng = np.random.default_rng(7)
    walk = np.cumsum(rng.normal(size=(t.size, 3)), axis=0)
    zmp = np.c_[0.01 * np.sin(t), 0.02 * np.cos(3 * t)]
    zmp[10] = np.nan
    return [
        plot_panels(
            folder / "panels.png",
            t,
            [("walk", {"a": walk[:, 0], "b": walk[:, 1]}, "m"), ("c", {"c": walk[:, 2]}, "N")],
            title="three walks",
        ),
        plot_tracking_errors(folder / "errors.png", t, walk * 1e-3, ["x", "y", "z"], band=0.01),
        plot_zmp(folder / "zmp.png", zmp, (0.1, 0.15)),
    ]


def test_the_worker_draws_the_pixels_this_process_draws(tmp_path):
    here, there = tmp_path / "here", tmp_path / "there"
    here.mkdir()
    there.mkdir()
    local = _figures(here)
    with plots_in_background() as worker:
        assert worker is not None and active_worker() is worker
        # drawn in another process: that process's id is not ours
        assert worker._pool.submit(os.getpid).result() != os.getpid()
        remote = _figures(there)
        drawn = worker.wait()
    assert active_worker() is None
    assert drawn == remote
    for a, b in zip(local, remote, strict=True):
        assert a.name == b.name
        pa, pb = mpimg.imread(a), mpimg.imread(b)
        assert pa.shape == pb.shape and pa.shape[0] > 100
        np.testing.assert_array_equal(pa, pb)


def test_bad_inputs_raise_in_the_caller_and_nothing_is_queued(tmp_path):
    t = np.linspace(0.0, 1.0, 11)
    with plots_in_background() as worker:
        assert worker is not None
        with pytest.raises(ValueError, match="has"):
            plot_panels(tmp_path / "a.png", t, [("x", {"short": t[:5]}, "")])
        with pytest.raises(ValueError, match="labels"):
            plot_tracking_errors(tmp_path / "b.png", t, np.c_[t, t], ["x"])
        with pytest.raises(ValueError, match=r"\(n, 2\)"):
            plot_zmp(tmp_path / "c.png", np.zeros((4, 3)), (0.1, 0.1))
        assert worker.wait() == []
    assert list(tmp_path.iterdir()) == []


def test_a_drawing_error_is_raised_by_wait_after_the_other_figures(tmp_path):
    t = np.linspace(0.0, 1.0, 11)
    panel = [("x", {"x": t}, "m")]
    with plots_in_background() as worker:
        assert worker is not None
        plot_panels(tmp_path / "missing-folder" / "a.png", t, panel)
        plot_panels(tmp_path / "b.png", t, panel)
        with pytest.raises(FileNotFoundError):
            worker.wait()
    assert (tmp_path / "b.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not (tmp_path / "missing-folder").exists()


def test_leaving_the_context_waits_for_the_figures(tmp_path):
    with plots_in_background():
        path = _figures(tmp_path)[0]
    assert mpimg.imread(path).shape[0] > 100


def test_without_the_context_the_figure_is_written_before_return(tmp_path):
    assert active_worker() is None
    path = _figures(tmp_path)[0]
    assert path.stat().st_size > 0


def test_figures_a_dead_worker_left_are_drawn_here(tmp_path):
    t = np.linspace(0.0, 1.0, 11)
    panel = [("x", {"x": t}, "m")]
    with plots_in_background() as worker:
        assert worker is not None
        pid = worker._pool.submit(os.getpid).result()
        worker._pool.submit(time.sleep, 30)  # holds the worker: the figures stay queued
        paths = [plot_panels(tmp_path / f"{k}.png", t, panel) for k in range(2)]
        os.kill(pid, signal.SIGKILL)
        assert worker.wait() == paths
        assert worker.redrawn == 2
        # the pool is broken now: a later figure is drawn here as well
        late = plot_panels(tmp_path / "late.png", t, panel)
        assert worker.wait() == [*paths, late] and worker.redrawn == 3
    for p in (*paths, late):
        assert mpimg.imread(p).shape[0] > 100


def test_a_queued_figure_shows_its_inputs_as_they_were_when_queued(tmp_path):
    t = np.linspace(0.0, 1.0, 101)
    values = np.sin(6 * t)
    expected = plot_panels(tmp_path / "expected.png", t, [("x", {"x": values.copy()}, "m")])
    with plots_in_background() as worker:
        assert worker is not None
        # the worker sleeps and its call queue (one more item) is full: the figure's call
        # waits in the executor as a Python object, where a later change to the caller's
        # buffer would show if the inputs were not pickled when queued
        for _ in range(3):
            worker._pool.submit(time.sleep, 0.4)
        queued = plot_panels(tmp_path / "queued.png", t, [("x", {"x": values}, "m")])
        values[:] = 0.0  # the caller reuses its buffer
        worker.wait()
    np.testing.assert_array_equal(mpimg.imread(queued), mpimg.imread(expected))
