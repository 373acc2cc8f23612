"""PNG figure helpers in the manner of the paper's Figs. 9-13 (matplotlib, Agg backend).

* :func:`plot_panels` - stacked time series panels sharing the time axis (joint angles, rotor
  thrusts, foot wrench: Figs. 10-13);
* :func:`plot_tracking_errors` - per-axis tracking errors with a +-band (Fig. 9 (B), (C));
* :func:`plot_zmp` - the centre of pressure inside the foot plate (Fig. 12 (E)).

Each checks its inputs at once and returns the path it writes. matplotlib is imported on
first use, with the Agg backend, so nothing needs a display. Inside
:func:`rdm.sim.plot_worker.plots_in_background` the drawing happens in a worker process on
another core and the file appears when :meth:`~rdm.sim.plot_worker.PlotWorker.wait` returns;
elsewhere it is written before the function returns.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rdm.output_files import open_output
from rdm.sim.plot_worker import active_worker, pyplot

Panel = tuple[str, Mapping[str, Sequence[float]], str]  # (title, {label: values}, y label)


def plot_panels(
    path: str | os.PathLike[str],
    t: Sequence[float],
    panels: Sequence[Panel],
    *,
    title: str = "",
    xlabel: str = "time [s]",
    dpi: int = 110,
) -> Path:
    """One panel per ``(title, {label: values}, ylabel)``, stacked, shared time axis."""
    if not panels:
        raise ValueError("plot_panels: no panels")
    t = np.asarray(t, dtype=float)
    checked = []
    for ptitle, series, ylabel in panels:
        arrays = {}
        for label, values in series.items():
            v = np.asarray(values, dtype=float)
            if v.shape != t.shape:
                raise ValueError(f"plot_panels: {label!r} has {v.shape} values, time {t.shape}")
            arrays[label] = v
        checked.append((ptitle, arrays, ylabel))
    return _render(draw_panels, path, t, checked, title, xlabel, dpi)


def draw_panels(
    out: Path,
    t: np.ndarray,
    panels: list[tuple[str, dict[str, np.ndarray], str]],
    title: str,
    xlabel: str,
    dpi: int,
) -> None:
    """Draw :func:`plot_panels`' checked inputs into ``out``."""
    plt = pyplot()
    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(7.0, 2.2 * len(panels)))
    axes = np.atleast_1d(axes)
    for ax, (ptitle, series, ylabel) in zip(axes, panels, strict=True):
        for label, v in series.items():
            ax.plot(t, v, label=label, linewidth=1.0)
        ax.set_title(ptitle, fontsize=9)
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
        if len(series) > 1:
            ax.legend(fontsize=7, ncol=min(len(series), 5), loc="upper right")
    axes[-1].set_xlabel(xlabel)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    _save(fig, out, dpi)
    plt.close(fig)


def plot_tracking_errors(
    path: str | os.PathLike[str],
    t: Sequence[float],
    errors: np.ndarray,
    labels: Sequence[str],
    *,
    band: float | None = None,
    ylabel: str = "error",
    title: str = "",
) -> Path:
    """Errors ``(n, k)`` over time, one line per column, with a dashed +-``band``."""
    errors = np.asarray(errors, dtype=float)
    if errors.ndim != 2 or errors.shape[1] != len(labels):
        raise ValueError(f"plot_tracking_errors: errors {errors.shape} vs {len(labels)} labels")
    t = np.asarray(t, dtype=float)
    return _render(draw_tracking_errors, path, t, errors, list(labels), band, ylabel, title)


def draw_tracking_errors(
    out: Path,
    t: np.ndarray,
    errors: np.ndarray,
    labels: list[str],
    band: float | None,
    ylabel: str,
    title: str,
) -> None:
    """Draw :func:`plot_tracking_errors`' checked inputs into ``out``."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.0, 2.8))
    for i, label in enumerate(labels):
        ax.plot(t, errors[:, i], label=label, linewidth=1.0)
    if band is not None:
        for y in (band, -band):
            ax.axhline(y, color="k", linestyle="--", linewidth=0.8)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, ncol=len(labels))
    if title:
        ax.set_title(title)
    fig.tight_layout()
    _save(fig, out, 110)
    plt.close(fig)


def plot_zmp(
    path: str | os.PathLike[str],
    zmp_xy: np.ndarray,
    plate_size: tuple[float, float],
    *,
    title: str = "ZMP in the foot plate",
) -> Path:
    """Centre-of-pressure trace ``(n, 2)`` [m] inside the plate rectangle (NaN rows skipped)."""
    zmp = np.asarray(zmp_xy, dtype=float)
    if zmp.ndim != 2 or zmp.shape[1] != 2:
        raise ValueError(f"plot_zmp: zmp_xy must be (n, 2), got {zmp.shape}")
    size = (float(plate_size[0]), float(plate_size[1]))
    return _render(draw_zmp, path, zmp, size, title)


def draw_zmp(out: Path, zmp: np.ndarray, plate_size: tuple[float, float], title: str) -> None:
    """Draw :func:`plot_zmp`'s checked inputs into ``out``."""
    plt = pyplot()
    ok = np.all(np.isfinite(zmp), axis=1)
    hx, hy = plate_size[0] / 2, plate_size[1] / 2
    fig, ax = plt.subplots(figsize=(4.0, 4.0))
    ax.plot([-hx, hx, hx, -hx, -hx], [-hy, -hy, hy, hy, -hy], "k-", linewidth=1.0, label="plate")
    ax.plot(zmp[ok, 0], zmp[ok, 1], ".", markersize=2, label="ZMP")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    _save(fig, out, 110)
    plt.close(fig)


def _save(fig: Any, out: str | os.PathLike[str], dpi: int) -> None:
    """Write ``fig`` to ``out`` (format from the suffix, PNG without one), never through a
    symbolic link (:func:`rdm.output_files.open_output`)."""
    out = Path(out)
    with open_output(out, "wb") as f:
        fig.savefig(f, dpi=dpi, format=out.suffix[1:].lower() or "png")


def _render(draw: Any, path: str | os.PathLike[str], *args: Any) -> Path:
    """``draw(out, *args)`` here, or in the background worker when one is active."""
    out = Path(path)
    worker = active_worker()
    if worker is not None:
        worker.submit(draw, out, *args)
    else:
        draw(out, *args)
    return out
