"""The run folder of one simulation: ``runs/<scenario>-seed<seed>/`` (or ``-<timestamp>``).

Layout (names are fixed so tools and docs can rely on them)::

    runs/<scenario>-seed<seed>/
        signals.mcap        ground truth, the onboard PC's status and controller signals
                            (Foxglove / PlotJuggler)
        wire.mcap           with --wire-mcap: every wire message at its time (rdm.sim.wire_mcap)
        can.log             candump -L capture of the Neuron bus (rdm decode can.log)
        uart/               raw UART byte captures (*.bin rosserial, *.lep Leptrino), each with
                            its time index *.idx (rdm.sim.capture_index)
        plots/              PNG figures
        metrics.txt         the metrics table
        summary.json        metrics + run facts (seed, duration, speed, counters)
"""

from __future__ import annotations

import os
import re
import time
from dataclasses import dataclass
from pathlib import Path

_NAME = re.compile(r"^[A-Za-z0-9_.\-]{1,64}$")


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
        overwrite: bool = True,
    ) -> RunFolder:
        """``<base>/<scenario>-seed<seed>`` when a seed is given (reproducible runs keep one
        folder per seed), else ``<base>/<scenario>-<stamp or local time YYYYmmdd-HHMMSS>``.
        ``overwrite=False`` refuses an existing folder."""
        if not _NAME.match(scenario):
            raise ValueError(f"RunFolder: scenario {scenario!r} must match {_NAME.pattern}")
        if seed is not None:
            suffix = f"seed{int(seed)}"
        else:
            suffix = stamp or time.strftime("%Y%m%d-%H%M%S")
            if not _NAME.match(suffix):
                raise ValueError(f"RunFolder: stamp {suffix!r} must match {_NAME.pattern}")
        root = Path(base) / f"{scenario}-{suffix}"
        if root.exists() and not overwrite:
            raise FileExistsError(f"RunFolder: {root} exists")
        folder = cls(root)
        for d in (root, folder.uart_dir, folder.plots_dir):
            d.mkdir(parents=True, exist_ok=True)
        return folder

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
