"""Design evaluation of Sec. II-A-2/3: reachability (AMR [m^3]) and feasibility (AMF,
eqs. 3-4) on a 3-D grid, in parallel on any ``concurrent.futures.Executor``.

AMR is the volume of the end-effector positions of every perched configuration the
planner's constraints admit: the joints q1..q5 (pitch and yaw) are swept on a grid of
``joint_step`` radians, the vectoring angles alpha, beta of every configuration are the
planner's (eq. 53's zeta: re-solved so each unit thrusts straight up, Sec. III's horizontal
vectoring apparatus), and a configuration is admitted when its joint torques, rotor thrusts,
stability rho, collision clearances and rotor spacing are inside the planner's forbidden
limits (eqs. 58-68). The end-effector image is voxelised at ``resolution`` metres
(:mod:`rdm.planner.reach`). Each reached voxel's F_ee,feasible is eq. (3) with the
perching controller's authority (:mod:`rdm.planner.perch_force`) at the admitted
configurations nearest to its centre; a voxel where none of them can stay perched is not
reached. AMF = (1 / L^3) sum F_ee,feasible / F dV (eq. 4). q6 (end-effector roll) does not
move the end-effector position and stays 0.
"""

from __future__ import annotations

import itertools
import math
import sys
import time
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np

from rdm import _rdm
from rdm.model import Robot
from rdm.output_files import open_output
from rdm.planner.core import PlannerSetup, make_core
from rdm.planner.perch_force import PerchAuthority, feasible_force
from rdm.planner.reach import grid_image_voxels, voxel_centres, voxel_keys, voxel_volume

#: Representative force F [N] and length L [m] of eq. (4) (Table III).
REPRESENTATIVE_FORCE = 33.5
REPRESENTATIVE_LENGTH = 1.2
#: Default voxel side [m] and joint grid step [rad].
RESOLUTION = 0.1
JOINT_STEP = 0.12
#: Forbidden limits of the planner's dampers (PlannerConfig::new in
#: crates/rdm_core/src/planner/config.rs): rho_F, collision and rotor-spacing d_F, and the
#: joint-limit band zeta_F [rad].
RHO_FORBIDDEN = 1e-4
DISTANCE_FORBIDDEN = 0.01
JOINT_FORBIDDEN = 0.01
#: Admitted configurations tried per voxel for the feasible force, nearest first.
CANDIDATES_PER_VOXEL = 3
#: The swept joints (q1..q5); q1 from 0 (below it the root link tips into the ceiling).
SWEPT = 5


@dataclass
class DesignResult:
    """AMR [m^3], AMF (eq. 4) and the per-voxel data of one robot. ``amr_kinematic``: the
    volume with collisions only; ``amr_admitted``: with every planner limit, before the
    perching test of the feasible force (``amr`` <= ``amr_admitted`` <= ``amr_kinematic``)."""

    name: str
    resolution: float
    joint_step: float
    amr: float
    amf: float
    points: np.ndarray  # (N, 3) centres of the reached voxels [m]
    force: np.ndarray  # (N,) F_ee,feasible [N]
    configurations: int = 0
    admitted: int = 0
    amr_kinematic: float = 0.0
    amr_admitted: float = 0.0
    yaw: bool = True
    seconds: float = 0.0

    def to_json(self) -> dict:
        """Summary (no per-voxel data)."""
        return {
            "name": self.name,
            "resolution_m": self.resolution,
            "joint_step_rad": self.joint_step,
            "amr_m3": self.amr,
            "amf": self.amf,
            "amr_kinematic_m3": self.amr_kinematic,
            "amr_admitted_m3": self.amr_admitted,
            "reached_voxels": len(self.points),
            "configurations": self.configurations,
            "admitted_configurations": self.admitted,
            "mean_feasible_force_n": float(self.force.mean()) if len(self.force) else 0.0,
            "yaw_joints": self.yaw,
            "seconds": self.seconds,
        }


def joint_axes(model: Robot, joint_step: float, yaw: bool = True) -> list[np.ndarray]:
    """Grid values of q1..q5: inside the joint limits by the forbidden band, q1 >= 0;
    the yaw joints q3, q5 at 0 when ``yaw`` is False."""
    lo, hi = np.asarray(model.joint_limits).T
    axes = []
    for i in range(SWEPT):
        a = max(lo[i] + JOINT_FORBIDDEN, 0.0) if i == 0 else lo[i] + JOINT_FORBIDDEN
        b = hi[i] - JOINT_FORBIDDEN
        if i in (2, 4) and not yaw:
            axes.append(np.zeros(1))
            continue
        n = max(2, math.floor((b - a) / joint_step) + 1)
        axes.append(np.linspace(a, b, n))
    return axes


def clear(values: np.ndarray, layout: dict) -> np.ndarray:
    """Rows of ``values`` whose collision clearances and rotor spacing are >= d_F (the
    kinematic part of the constraints: no statics)."""
    v = np.atleast_2d(values)
    ok = np.all(np.isfinite(v), axis=1)
    for key in ("collision", "airflow"):
        c0, nc = layout[key]
        if nc:
            ok &= np.all(v[:, c0 : c0 + nc] >= DISTANCE_FORBIDDEN, axis=1)
    return ok


def admitted(values: np.ndarray, layout: dict, model: Robot) -> np.ndarray:
    """Rows of ``values`` (one planner ``values`` vector per row) inside every forbidden
    limit: |tau| <= stall, thrust in [min, upper], rho >= rho_F, clearances >= d_F."""
    v = np.atleast_2d(values)
    t0, nt = layout["torque"]
    r0, nr = layout["thrust"]
    u0, _ = layout["thrust_upper"]
    stall = np.asarray(model.stall_torques)
    tmin = np.array([r["thrust_min"] for r in model.rotors])
    ok = np.all(np.abs(v[:, t0 : t0 + nt]) <= stall, axis=1)
    thrust = v[:, r0 : r0 + nr]
    ok &= np.all(thrust >= tmin, axis=1) & np.all(thrust <= v[:, u0 : u0 + nr], axis=1)
    ok &= v[:, layout["rho"][0]] >= RHO_FORBIDDEN
    return ok & clear(v, layout)


def _sweep_slab(
    setup: PlannerSetup, q1: float, axes: list[np.ndarray]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Worker: admitted mask, end-effector positions and collision-free mask of the grid
    slab at ``q1``."""
    model = Robot.from_strs(setup.urdf, setup.toml)
    zeta = np.zeros(6 + model.n_q)
    zeta[6] = q1
    core = None
    shape = tuple(len(a) for a in axes)
    n = int(np.prod(shape))
    ok = np.zeros(n, dtype=bool)
    free = np.zeros(n, dtype=bool)
    ee = np.zeros((n, 3), dtype=np.float32)
    batch = 20_000
    values: np.ndarray | None = None
    for i, qs in enumerate(itertools.product(*axes)):
        zeta[7 : 6 + SWEPT] = qs
        try:
            if core is None:  # built at the first configuration it accepts
                core = make_core(setup, zeta)
                values = np.full((batch, len(core.values)), np.nan)
            else:
                core.set_zeta(zeta)
            values[i % batch] = core.values
            ee[i] = core.end_effector_pose()[0]
        except (_rdm.RdmError, ValueError):
            if values is not None:
                values[i % batch] = np.nan
        if core is not None and values is not None and (i % batch == batch - 1 or i == n - 1):
            start = i - i % batch
            ok[start : i + 1] = admitted(values[: i + 1 - start], core.layout, model)
            free[start : i + 1] = clear(values[: i + 1 - start], core.layout)
    return ok.reshape(shape), ee.reshape(*shape, 3), free.reshape(shape)


def _force_chunk(setup: PlannerSetup, work: list[list[np.ndarray]]) -> list[float | None]:
    """Worker: F_ee,feasible of each voxel, the max over its candidate configurations
    (q1..q5), None when none of them can stay perched."""
    model = Robot.from_strs(setup.urdf, setup.toml)
    authority = PerchAuthority.from_controller(model)
    zeta = np.zeros(6 + model.n_q)
    core = None
    out: list[float | None] = []
    for candidates in work:
        best = None
        for qs in candidates:
            zeta[6 : 6 + SWEPT] = qs
            # levels the vectoring units: alpha, beta of zeta
            if core is None:
                core = make_core(setup, zeta)
            else:
                core.set_zeta(zeta)
            r = feasible_force(model, core.zeta[6:], authority)
            if r is not None:
                best = r[1] if best is None else max(best, r[1])
        out.append(best)
    return out


def _candidates(
    keys: np.ndarray, ok: np.ndarray, ee: np.ndarray, q_grid: list[np.ndarray], resolution: float
) -> list[list[np.ndarray]]:
    """For every voxel in ``keys``: up to CANDIDATES_PER_VOXEL admitted configurations whose
    end effector is nearest its centre (searched in the voxel, then its 26 neighbours)."""
    idx = np.argwhere(ok)
    pos = ee[ok].astype(float)
    if len(keys) == 0 or len(pos) == 0:
        return [[] for _ in range(len(keys))]
    own = voxel_keys(pos, resolution)
    lo = np.minimum(own.min(axis=0), keys.min(axis=0)) - 1
    span = np.maximum(own.max(axis=0), keys.max(axis=0)) + 2 - lo

    def code(k: np.ndarray) -> np.ndarray:
        k = k - lo
        return (k[..., 0] * span[1] + k[..., 1]) * span[2] + k[..., 2]

    order = np.argsort(code(own), kind="stable")
    sorted_codes = code(own)[order]
    centres = voxel_centres(keys, resolution)
    offsets = np.array([d for d in itertools.product((-1, 0, 1), repeat=3) if d != (0, 0, 0)])
    starts = np.searchsorted(sorted_codes, code(keys), "left")
    ends = np.searchsorted(sorted_codes, code(keys), "right")
    near = code(keys[:, None, :] + offsets[None])
    n_starts = np.searchsorted(sorted_codes, near, "left")
    n_ends = np.searchsorted(sorted_codes, near, "right")
    cap = 64  # rows looked at per voxel
    work = []
    for v in range(len(keys)):
        rows = order[starts[v] : min(ends[v], starts[v] + cap)]
        if len(rows) < CANDIDATES_PER_VOXEL:
            more = [order[a : min(b, a + cap)] for a, b in zip(n_starts[v], n_ends[v], strict=True)]
            rows = np.concatenate([rows, *more])
        if len(rows) > CANDIDATES_PER_VOXEL:
            dist = np.linalg.norm(pos[rows] - centres[v], axis=1)
            rows = rows[np.argsort(dist, kind="stable")[:CANDIDATES_PER_VOXEL]]
        work.append([np.array([q_grid[a][i] for a, i in enumerate(idx[r])]) for r in rows])
    return work


def evaluate_design(
    setup: PlannerSetup,
    name: str = "robot",
    resolution: float = RESOLUTION,
    executor: Executor | None = None,
    progress: bool = True,
    joint_step: float = JOINT_STEP,
    yaw: bool = True,
    chunk: int = 64,
) -> DesignResult:
    """AMR [m^3] and AMF of ``setup``'s robot (perched) on a 3-D grid of ``resolution``
    metres, the joints swept every ``joint_step`` radians (yaw joints fixed at 0 when
    ``yaw`` is False).

    ``executor``: any ``concurrent.futures.Executor`` (default: a ProcessPoolExecutor over
    all cores), e.g. a Dask ``Client.get_executor()``. Progress goes to stderr.
    """
    t0 = time.perf_counter()
    model = Robot.from_strs(setup.urdf, setup.toml)
    axes = joint_axes(model, joint_step, yaw)
    own = executor is None
    ex = ProcessPoolExecutor() if own else executor

    def say(text: str) -> None:
        if progress:
            print(f"\r{name}: {text}", end="", file=sys.stderr, flush=True)

    try:
        slabs = [ex.submit(_sweep_slab, setup, float(q1), axes[1:]) for q1 in axes[0]]
        parts = []
        for i, fut in enumerate(slabs, start=1):
            parts.append(fut.result())
            say(f"joint grid {i}/{len(slabs)} slabs")
        ok = np.stack([p[0] for p in parts])
        ee = np.stack([p[1] for p in parts])
        kinematic = voxel_volume(
            grid_image_voxels(np.stack([p[2] for p in parts]), ee, resolution), resolution
        )
        del parts
        keys = grid_image_voxels(ok, ee, resolution)
        work = _candidates(keys, ok, ee, axes, resolution)
        chunks = [work[i : i + chunk] for i in range(0, len(work), chunk)]
        futs = [ex.submit(_force_chunk, setup, c) for c in chunks]
        forces: list[float | None] = []
        for i, fut in enumerate(futs, start=1):
            forces += fut.result()
            say(f"feasible force {i}/{len(futs)} chunks ({len(work)} voxels)   ")
    finally:
        if own:
            ex.shutdown()
    if progress:
        print(file=sys.stderr)
    held = np.array([f is not None for f in forces], dtype=bool)
    force = np.array([f for f in forces if f is not None], dtype=float)
    points = voxel_centres(keys, resolution)[held] if len(keys) else np.zeros((0, 3))
    cell = resolution**3
    amr = float(len(force) * cell)
    amf = float((force / REPRESENTATIVE_FORCE).sum() * cell / REPRESENTATIVE_LENGTH**3)
    return DesignResult(
        name=name, resolution=resolution, joint_step=joint_step, amr=amr, amf=amf,
        points=points, force=force, configurations=int(ok.size), admitted=int(ok.sum()),
        amr_kinematic=kinematic, amr_admitted=voxel_volume(keys, resolution), yaw=yaw,
        seconds=time.perf_counter() - t0,
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
    which: int,
    resolution: float = RESOLUTION,
    executor: Executor | None = None,
    progress: bool = True,
    joint_step: float = JOINT_STEP,
) -> dict[str, DesignResult]:
    """Evaluate every robot of Table ``which`` (2 or 3)."""
    setups = table2_setups() if which == 2 else table3_setups()
    return {
        n: evaluate_design(s, n, resolution, executor, progress, joint_step)
        for n, s in setups.items()
    }


def paper_values(which: int, name: str) -> dict[str, float | None]:
    """The paper's AMR [m^3] (Table III only; the paper prints m^2) and AMF for ``name``."""
    if which == 2:
        return {"amr_m3": None, "amf": PAPER_TABLE2.get(name)}
    amr, amf = PAPER_TABLE3.get(name, (None, None))
    return {"amr_m3": amr, "amf": amf}


def table_json(which: int, results: dict[str, DesignResult]) -> dict:
    """``rdm design --json``: ours and the paper's per robot, and the ratios."""
    rows = {}
    for n, r in results.items():
        rows[n] = {"ours": r.to_json(), "paper": paper_values(which, n)}
    out: dict = {"table": which, "robots": rows, "representative_force_n": REPRESENTATIVE_FORCE,
                 "representative_length_m": REPRESENTATIVE_LENGTH}  # fmt: skip
    if which == 3 and {"rcm", "rdm"} <= results.keys():
        a, b = results["rcm"], results["rdm"]
        out["rdm_over_rcm"] = {
            "ours": {"amr": _ratio(b.amr, a.amr), "amf": _ratio(b.amf, a.amf)},
            "paper": {"amr": PAPER_TABLE3["rdm"][0] / PAPER_TABLE3["rcm"][0],
                      "amf": PAPER_TABLE3["rdm"][1] / PAPER_TABLE3["rcm"][1]},
        }  # fmt: skip
    if which == 2 and {"middle", "end"} <= results.keys():
        out["middle_over_end_amf"] = {
            "ours": _ratio(results["middle"].amf, results["end"].amf),
            "paper": PAPER_TABLE2["middle"] / PAPER_TABLE2["end"],
        }
    return out


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 else math.inf


def format_table(which: int, results: dict[str, DesignResult]) -> str:
    """Ours beside the paper's values, with ratios."""
    head = (
        f"{'robot':<7} {'AMR ours':>9} {'AMR paper':>10} {'kinematic':>10} {'admitted':>9} "
        f"{'AMF ours':>9} {'AMF paper':>10} {'mean F':>7}"
    )
    lines = [f"Table {'II' if which == 2 else 'III'} (AMR in m^3)", head]
    for n, r in results.items():
        p = paper_values(which, n)
        amr_p = "-" if p["amr_m3"] is None else f"{p['amr_m3']:.2f}"
        amf_p = "-" if p["amf"] is None else f"{p['amf']:.1e}"
        mean_f = float(r.force.mean()) if len(r.force) else 0.0
        lines.append(
            f"{n:<7} {r.amr:>9.3f} {amr_p:>10} {r.amr_kinematic:>10.3f} {r.amr_admitted:>9.3f} "
            f"{r.amf:>9.3e} {amf_p:>10} {mean_f:>6.2f}N"
        )
    j = table_json(which, results)
    if "rdm_over_rcm" in j:
        o, p = j["rdm_over_rcm"]["ours"], j["rdm_over_rcm"]["paper"]
        lines.append(
            f"RDM/RCM: AMR {o['amr']:.2f}x (paper {p['amr']:.2f}x), AMF {o['amf']:.2f}x "
            f"(paper {p['amf']:.2f}x; its text says about forty)"
        )
    if "middle_over_end_amf" in j:
        m = j["middle_over_end_amf"]
        lines.append(f"middle/end AMF: ours {m['ours']:.2f}, paper {m['paper']:.2f}")
    r0 = next(iter(results.values()), None)
    if r0 is not None:
        lines.append(
            f"voxel {r0.resolution} m, joint step {r0.joint_step} rad; "
            f"F = {REPRESENTATIVE_FORCE} N, L = {REPRESENTATIVE_LENGTH} m; "
            "kinematic = AMR with collisions only; admitted = with every planner limit, "
            "before the perching test"
        )
    return "\n".join(lines)


def plot_results(results: dict[str, DesignResult], path: str) -> None:
    """Reached voxels coloured by feasible force, like Figs. 3-4 (PNG): per robot a 3-D
    view and the x-z projection."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(results)
    fig = plt.figure(figsize=(9, 4 * n))
    for row, (name, r) in enumerate(results.items()):
        ax3 = fig.add_subplot(n, 2, 2 * row + 1, projection="3d")
        ax2 = fig.add_subplot(n, 2, 2 * row + 2)
        p, f = r.points, r.force
        vmax = float(f.max()) if len(f) else 1.0
        ax3.scatter(p[:, 0], p[:, 1], p[:, 2], c=f, s=4, cmap="viridis", vmin=0, vmax=vmax)
        ax3.set(title=f"{name}: AMR {r.amr:.2f} m³, AMF {r.amf:.3f}", xlabel="x [m]",
                ylabel="y [m]", zlabel="z [m]")  # fmt: skip
        sc = ax2.scatter(p[:, 0], p[:, 2], c=f, s=6, cmap="viridis", vmin=0, vmax=vmax)
        ax2.axhline(0.0, color="k", lw=2)
        ax2.set(title="x-z projection", xlabel="x [m]", ylabel="z [m]", aspect="equal")
        fig.colorbar(sc, ax=ax2, label="F_ee,feasible [N]")
    fig.tight_layout()
    try:
        with open_output(path, "wb") as fh:  # never through a symbolic link
            fig.savefig(fh, dpi=100, format="png")
    finally:
        plt.close(fig)
