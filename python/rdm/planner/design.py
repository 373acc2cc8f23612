"""Design evaluation of Sec. II-A-2/3: reachability (AMR) and feasibility (AMF, eqs. 3-4)
over a grid of end-effector targets, each computed with the planner, in parallel on any
``concurrent.futures.Executor``.

The paper gives AMR in m^2, so the reachable set is evaluated on a 2-D section: the
vertical x-z plane of the foot frame through the foot centre (the plane the arm moves in
when the yaw joints q3, q5 are zero, as drawn in Figs. 3-4), below the ceiling. AMR is the
number of reachable grid cells times the cell area; eq. (4) is integrated over that
section with dA / L^2 (the 2-D analogue of dV / L^3; ASSUMPTION, see docs/planner.md).
"""

from __future__ import annotations

import math
import sys
import time
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field

import numpy as np

from rdm.output_files import open_output
from rdm.planner.core import PlannerSetup, feasible_starts, make_core
from rdm.planner.plan import run_core

#: Representative force F [N] and length L [m] of eq. (4) (Table III).
REPRESENTATIVE_FORCE = 33.5
REPRESENTATIVE_LENGTH = 1.2
#: Grid extent in the foot frame's x-z plane [m] (arm reach 1.05 m plus the q1 offset).
X_RANGE = (-1.2, 1.2)
Z_RANGE = (-1.25, -0.05)
#: Steps allowed per target and start.
MAX_STEPS_PER_TARGET = 400
#: Starts tried per target, nearest end effector first (ASSUMPTION, docs/planner.md).
MAX_STARTS_PER_TARGET = 3


@dataclass
class DesignResult:
    """AMR [m^2], AMF (eq. 4) and the per-point data of one robot."""

    name: str
    resolution: float
    amr: float
    amf: float
    points: np.ndarray  # (N, 2) x, z of every grid point
    reached: np.ndarray  # (N,) bool
    force: np.ndarray  # (N,) F_ee,feasible [N] (0 where unreachable)
    blocking: list[str | None] = field(default_factory=list)
    seconds: float = 0.0

    def to_json(self) -> dict:
        """Summary (no per-point data)."""
        return {
            "name": self.name,
            "resolution": self.resolution,
            "amr_m2": self.amr,
            "amf": self.amf,
            "reachable_points": int(self.reached.sum()),
            "grid_points": len(self.points),
            "mean_feasible_force": float(self.force[self.reached].mean()) if self.reached.any()
            else 0.0,
            "seconds": self.seconds,
        }  # fmt: skip


def grid(resolution: float) -> np.ndarray:
    """Cell centres of the x-z section."""
    xs = np.arange(X_RANGE[0] + resolution / 2, X_RANGE[1], resolution)
    zs = np.arange(Z_RANGE[0] + resolution / 2, Z_RANGE[1], resolution)
    return np.array([(x, z) for z in zs for x in xs])


def _evaluate_chunk(
    setup: PlannerSetup, starts: list[np.ndarray], points: list[tuple[float, float]]
) -> list[tuple]:
    """Worker: plan to every point, trying the starts nearest to it first (differential IK
    is local); feasible force where reached."""
    core = None
    out = []
    anchors = []
    for zeta in starts:
        if core is None:
            core = make_core(setup, zeta)
        else:
            core.set_zeta(zeta)
        anchors.append(np.array(core.end_effector_pose()[0]))
    for x, z in points:
        result = (False, 0.0, "no feasible start")
        target = np.array((x, 0.0, z))
        order = sorted(range(len(starts)), key=lambda i: np.linalg.norm(anchors[i] - target))
        for i in order[:MAX_STARTS_PER_TARGET]:
            core.set_zeta(starts[i])
            traj = run_core(core, tuple(target), setup.mode, max_steps=MAX_STEPS_PER_TARGET)
            if traj.reached:
                f = core.feasible_force()
                result = (True, 0.0 if f is None else f[1], None)
                break
            if result[2] == "no feasible start":
                result = (False, 0.0, traj.blocking)
        out.append(result)
    return out


def evaluate_design(
    setup: PlannerSetup,
    name: str = "robot",
    resolution: float = 0.1,
    executor: Executor | None = None,
    chunk: int = 8,
    progress: bool = True,
) -> DesignResult:
    """AMR and AMF of ``setup``'s robot (perched) on a grid of ``resolution`` metres.

    ``executor``: any ``concurrent.futures.Executor`` (default: a ProcessPoolExecutor over
    all cores), e.g. a Dask ``Client.get_executor()``. Progress goes to stderr.
    """
    t0 = time.perf_counter()
    starts = feasible_starts(setup, step=0.1)
    pts = grid(resolution)
    chunks = [pts[i : i + chunk] for i in range(0, len(pts), chunk)]
    own = executor is None
    ex = ProcessPoolExecutor() if own else executor
    results: list[list[tuple] | None] = [None] * len(chunks)
    try:
        futures = {
            ex.submit(_evaluate_chunk, setup, starts, [tuple(p) for p in c]): i
            for i, c in enumerate(chunks)
        }
        for done, fut in enumerate(as_completed(futures), start=1):
            results[futures[fut]] = fut.result()
            if progress:
                print(
                    f"\r{name}: {done}/{len(chunks)} chunks ({len(pts)} points)",
                    end="", file=sys.stderr, flush=True,
                )  # fmt: skip
    finally:
        if own:
            ex.shutdown()
    if progress:
        print(file=sys.stderr)
    flat = [r for c in results if c for r in c]
    reached = np.array([r[0] for r in flat])
    force = np.array([r[1] for r in flat])
    cell = resolution**2
    amr = float(reached.sum() * cell)
    amf = float((force[reached] / REPRESENTATIVE_FORCE).sum() * cell / REPRESENTATIVE_LENGTH**2)
    return DesignResult(
        name=name, resolution=resolution, amr=amr, amf=amf, points=pts, reached=reached,
        force=force, blocking=[r[2] for r in flat], seconds=time.perf_counter() - t0,
    )  # fmt: skip


#: The paper's values: Table II (AMF by arm-unit position) and Table III.
PAPER_TABLE2 = {"root": 0.0, "middle": 1.5e-2, "end": 3.1e-2}
PAPER_TABLE3 = {"rcm": (1.01, 7.5e-2), "rdm": (2.86, 3.2e-1)}
TABLE2_POSITIONS = {"root": 0.0, "middle": 0.5, "end": 1.0}


def table2_setups() -> dict[str, PlannerSetup]:
    """RDM variants with the arm unit at the root, middle and end of the middle link."""
    from rdm.descriptions import build_description

    out = {}
    for label, frac in TABLE2_POSITIONS.items():
        d = build_description("rdm", arm_unit_position=frac)
        out[label] = PlannerSetup.for_robot((d.urdf, d.toml), "perched")
    return out


def table3_setups() -> dict[str, PlannerSetup]:
    """The shipped RCM and RDM."""
    return {n: PlannerSetup.for_robot(n, "perched") for n in ("rcm", "rdm")}


def run_table(
    which: int, resolution: float, executor: Executor | None = None, progress: bool = True
) -> dict[str, DesignResult]:
    """Evaluate every robot of Table ``which`` (2 or 3)."""
    setups = table2_setups() if which == 2 else table3_setups()
    return {
        n: evaluate_design(s, n, resolution, executor, progress=progress) for n, s in setups.items()
    }


def format_table(which: int, results: dict[str, DesignResult]) -> str:
    """Ours beside the paper's values, with ratios."""
    lines = []
    if which == 2:
        lines.append(f"{'arm unit':<8} {'AMR ours [m2]':>14} {'AMF ours':>10} {'AMF paper':>10}")
        for n, r in results.items():
            lines.append(f"{n:<8} {r.amr:>14.3f} {r.amf:>10.3e} {PAPER_TABLE2[n]:>10.1e}")
    else:
        lines.append(
            f"{'type':<5} {'AMR ours':>9} {'AMR paper':>10} {'AMF ours':>10} {'AMF paper':>10}"
        )
        for n, r in results.items():
            amr_p, amf_p = PAPER_TABLE3[n]
            lines.append(f"{n:<5} {r.amr:>9.3f} {amr_p:>10.2f} {r.amf:>10.3e} {amf_p:>10.1e}")
        if "rcm" in results and "rdm" in results:
            a, b = results["rcm"], results["rdm"]
            ra = b.amr / a.amr if a.amr > 0 else math.inf
            rf = b.amf / a.amf if a.amf > 0 else math.inf
            lines.append(f"RDM/RCM: AMR {ra:.2f}x (paper 2.8x), AMF {rf:.1f}x (paper ~4.3x-40x)")
    res = next(iter(results.values())).resolution if results else 0
    lines.append(f"resolution {res} m; F = {REPRESENTATIVE_FORCE} N, L = {REPRESENTATIVE_LENGTH} m")
    return "\n".join(lines)


def plot_results(results: dict[str, DesignResult], path: str) -> None:
    """Reachable sets coloured by feasible force, like Figs. 3-4 (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(5 * len(results), 3.6), squeeze=False)
    for ax, (name, r) in zip(axes[0], results.items(), strict=True):
        ax.scatter(r.points[~r.reached, 0], r.points[~r.reached, 1], s=4, c="0.85")
        sc = ax.scatter(r.points[r.reached, 0], r.points[r.reached, 1], s=8,
                        c=r.force[r.reached], cmap="viridis", vmin=0)  # fmt: skip
        ax.axhline(0.0, color="k", lw=2)
        ax.plot(0, 0, "ks")
        ax.set(title=f"{name}: AMR {r.amr:.2f} m², AMF {r.amf:.3f}", xlabel="x [m]",
               ylabel="z [m]", aspect="equal")  # fmt: skip
        fig.colorbar(sc, ax=ax, label="F_ee,feasible [N]")
    fig.tight_layout()
    try:
        with open_output(path, "wb") as f:  # never through a symbolic link
            fig.savefig(f, dpi=100, format="png")
    finally:
        plt.close(fig)
