"""Planner results: a reached ``Trajectory`` or an ``Unreachable`` one naming the
constraint that blocked progress."""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rdm.output_files import open_output


@dataclass
class Trajectory:
    """zeta per step (row 0 = start) with the predicted loads and margins at each state.

    ``thrusts`` [N] are the static distribution (docs/planner.md), ``torques`` [N m] eq.
    (61), ``rho`` eq. (65), ``clearance`` [m] the smallest shape clearance (eq. 67) and
    ``airflow`` [m] the smallest rotor airflow clearance (eq. 68).
    """

    zeta: np.ndarray
    thrusts: np.ndarray
    torques: np.ndarray
    rho: np.ndarray
    clearance: np.ndarray
    airflow: np.ndarray
    ee_position: np.ndarray
    error: np.ndarray
    target: tuple[float, ...]
    mode: str
    binding: list[str | None] = field(default_factory=list)
    reached: bool = True
    blocking: str | None = None

    @property
    def final_error(self) -> float:
        """End-effector position error at the last state [m]."""
        return float(self.error[-1])

    @property
    def steps(self) -> int:
        """Number of planner steps taken."""
        return len(self.zeta) - 1

    def to_json(self) -> dict:
        """A JSON-ready dict."""
        return {
            "mode": self.mode,
            "target": list(self.target),
            "reached": self.reached,
            "blocking": self.blocking,
            "final_error": self.final_error,
            "zeta": self.zeta.tolist(),
            "thrusts": self.thrusts.tolist(),
            "torques": self.torques.tolist(),
            "rho": self.rho.tolist(),
            "clearance": self.clearance.tolist(),
            "airflow": self.airflow.tolist(),
            "ee_position": self.ee_position.tolist(),
            "error": self.error.tolist(),
            "binding": self.binding,
        }

    def save(self, path: str | Path) -> None:
        """Write ``.json`` (everything; ValueError for a non-finite value) or ``.csv`` (one row
        per step), never through a symbolic link (:func:`rdm.output_files.open_output`)."""
        path = Path(path)
        if path.suffix == ".json":
            text = json.dumps(self.to_json(), indent=1, allow_nan=False)  # valid JSON or raise
            with open_output(path, "w", encoding="utf-8") as f:
                f.write(text)
            return
        n_z, n_t, n_l = self.zeta.shape[1], self.torques.shape[1], self.thrusts.shape[1]
        header = (
            ["step"]
            + [f"zeta{i}" for i in range(n_z)]
            + [f"thrust{i + 1}" for i in range(n_l)]
            + [f"tau{i + 1}" for i in range(n_t)]
            + ["rho", "clearance", "airflow", "ee_x", "ee_y", "ee_z", "error", "binding"]
        )
        with open_output(path, "w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow(header)
            for k in range(len(self.zeta)):
                w.writerow(
                    [k, *self.zeta[k], *self.thrusts[k], *self.torques[k], self.rho[k],
                     self.clearance[k], self.airflow[k], *self.ee_position[k], self.error[k],
                     self.binding[k] if k < len(self.binding) else ""]
                )  # fmt: skip

    def plot(self, path: str | Path) -> None:
        """Save a PNG: end-effector path (x-z), error, thrusts, torques."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(2, 2, figsize=(10, 7))
        ax[0, 0].plot(self.ee_position[:, 0], self.ee_position[:, 2], ".-", ms=2)
        ax[0, 0].plot(self.target[0], self.target[2], "r*", ms=12)
        ax[0, 0].set(xlabel="x [m]", ylabel="z [m]", title="end-effector path", aspect="equal")
        ax[0, 1].semilogy(np.maximum(self.error, 1e-6))
        ax[0, 1].set(xlabel="step", ylabel="position error [m]")
        ax[1, 0].plot(self.thrusts)
        ax[1, 0].set(xlabel="step", ylabel="thrust [N]", title="static thrusts")
        ax[1, 1].plot(self.torques[:, :6])
        ax[1, 1].set(xlabel="step", ylabel="torque [N m]", title="joint torques q1..q6")
        status = "reached" if self.reached else f"unreachable ({self.blocking})"
        fig.suptitle(f"{self.mode} plan to {tuple(round(t, 3) for t in self.target)}: {status}")
        fig.tight_layout()
        fmt = Path(path).suffix[1:].lower() or "png"
        try:
            if fmt not in fig.canvas.get_supported_filetypes():
                raise ValueError(f"matplotlib writes no {fmt!r} files (png, pdf, svg, ...)")
            with open_output(path, "wb") as f:
                fig.savefig(f, dpi=100, format=fmt)
        finally:
            plt.close(fig)


@dataclass
class Unreachable(Trajectory):
    """A plan that stalled: ``blocking`` names the constraint family whose rows carried
    the largest dual when progress stopped (``joint_limit``, ``joint_torque``,
    ``rotor_thrust``, ``stability``, ``collision``, ``airflow``), or ``qp_failed``."""

    reached: bool = False
