"""The benchmark cases, kept in a registry (:data:`CASES`) so more can be added.

A :class:`Case` is a group of measurements on one problem: the core timed inside Rust
(``rdm._rdm.time_*``: ``std::time::Instant`` around each call, GIL released), the same
computation through the public Python API (``time.perf_counter_ns`` around each call,
garbage collector paused as ``timeit`` does), and peers run in the same process on the
same problems. Each measurement carries its budget, its targets and whether they are met.
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rdm.bench import peers as peer_mod
from rdm.bench import scenarios as sc
from rdm.bench.statistics import Summary, summarize_ns

SPINAL_BUDGET_US = 1e6 / sc.SPINAL_RATE_HZ  # 200 Hz: 5 ms
TICK_BUDGET_US = 1e6 / sc.TICK_RATE_HZ  # 40 Hz: 25 ms


@dataclass
class PeerResult:
    """A peer's figures, or why it was skipped."""

    name: str
    summary: Summary | None = None
    failures: int = 0
    max_error: float = 0.0
    error_kind: str = ""
    settings: dict[str, Any] = field(default_factory=dict)
    failure_statuses: dict[str, int] = field(default_factory=dict)
    skipped: str | None = None


@dataclass
class Target:
    """One target of a measurement: ``kind`` is ``median_us``/``p999_us`` (upper limits)
    or ``speedup_vs:<peer>`` / ``faster_than:<peer>`` (lower limit on peer median / ours)."""

    kind: str
    limit: float
    value: float | None = None
    met: bool | None = None


@dataclass
class Measurement:
    """One timed run of our code (Rust-side or through Python) with its peers."""

    name: str
    title: str
    summary: Summary
    budget_us: float
    failures: int
    targets: list[Target]
    peers: dict[str, PeerResult]
    notes: list[str] = field(default_factory=list)

    @property
    def fraction_of_budget(self) -> float:
        """Median as a fraction of the budget."""
        return self.summary.median_us / self.budget_us

    def evaluate_targets(self) -> None:
        """Fill each target's value and whether it is met (None if a peer was skipped)."""
        for t in self.targets:
            if t.kind in ("median_us", "p999_us"):
                t.value = getattr(self.summary, t.kind)
                t.met = t.value <= t.limit
                continue
            peer = self.peers.get(t.kind.split(":", 1)[1])
            if peer is None or peer.summary is None:
                t.value, t.met = None, None
                continue
            t.value = peer.summary.median_us / self.summary.median_us
            t.met = t.value >= t.limit


@dataclass
class Context:
    """Run parameters handed to every case."""

    iterations: int | None  # None: each case's default
    quick: bool
    progress: Callable[[str], None]

    def count(self, default: int) -> int:
        """Iterations for a measurement whose full-run default is ``default``."""
        if self.iterations is not None:
            return self.iterations
        return max(default // 10, 10) if self.quick else default

    def peer_count(self, default: int) -> int:
        """Iterations for a peer (never more than our own measurement's)."""
        if self.iterations is not None:
            return min(self.iterations, default)
        return max(default // 10, 10) if self.quick else default


@dataclass(frozen=True)
class Case:
    """A registered group of measurements."""

    name: str
    title: str
    run: Callable[[Context], list[Measurement]]
    measurements: tuple[str, ...]
    peers: tuple[str, ...]


CASES: dict[str, Case] = {}


def register(case: Case) -> Case:
    """Add a case to the registry (names must be unique)."""
    if case.name in CASES:
        raise ValueError(f"benchmark case {case.name!r} registered twice")
    CASES[case.name] = case
    return case


@contextmanager
def gc_paused() -> Iterator[None]:
    """Pause the cyclic garbage collector for a Python timing loop (as ``timeit`` does)."""
    enabled = gc.isenabled()
    gc.collect()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def skipped_peers(names: tuple[str, ...], module: str) -> dict[str, PeerResult] | None:
    """Skipped entries for ``names`` if ``module`` is missing, else None."""
    ok, why = peer_mod.availability(module)
    if ok:
        return None
    return {n: PeerResult(n, skipped=why) for n in names}


def peer_result(name: str, run: peer_mod.PeerRun) -> PeerResult:
    """Figures of a finished peer run (failed calls have no duration and are left out)."""
    ns = run.ns[run.ns > 0]
    return PeerResult(
        name=name,
        summary=summarize_ns(ns if ns.size else np.zeros(1)),
        failures=run.failures,
        max_error=run.max_error,
        error_kind=run.error_kind,
        settings=run.settings,
        failure_statuses=dict(run.failure_statuses),
    )


# --- 200 Hz Spinal step -------------------------------------------------------------------


def run_spinal(ctx: Context) -> list[Measurement]:
    """Spinal step timed inside Rust and through Python on the same input stream."""
    from rdm import _rdm

    n = ctx.count(100_000)
    si = sc.spinal_inputs(n)
    ctx.progress(f"spinal_step: {n} steps inside Rust")
    rust = _rdm.time_spinal_steps(
        si.gains,
        si.pinv,
        si.inertia,
        si.now,
        si.gyro,
        si.acc,
        si.mag,
        si.voltage,
        si.command_every,
        si.command_angles,
        si.command_base_thrust,
        sc.SPINAL_RATE_HZ,
        0.0,
    )
    ctx.progress(f"spinal_step: {n} steps through Python")
    py_ns, py_invalid = time_spinal_python(si)
    common = dict(budget_us=SPINAL_BUDGET_US, peers={})
    notes = ["armed, integrating, 4 rotors; command every 5 steps (untimed)"]
    return [
        Measurement(
            "spinal_step_rust",
            "200 Hz Spinal step (estimator + attitude control + PWM), inside Rust",
            summarize_ns(rust["ns"]),
            failures=int(rust["invalid"]),
            targets=[Target("median_us", 2.0)],
            notes=notes,
            **common,
        ),
        Measurement(
            "spinal_step_python",
            "200 Hz Spinal step through Python (SpinalStep.step)",
            summarize_ns(py_ns),
            failures=py_invalid,
            targets=[Target("median_us", 5.0)],
            notes=notes,
            **common,
        ),
    ]


def time_spinal_python(si: sc.SpinalInputs) -> tuple[np.ndarray, int]:
    """Per-call ns of the ordinary ``SpinalStep.step`` binding over the same inputs."""
    s = sc.python_spinal(si)
    n = len(si.now)
    args = list(
        zip(si.now.tolist(), si.gyro.tolist(), si.acc.tolist(), si.mag.tolist(), strict=True)
    )
    angles, base = list(si.command_angles), si.command_base_thrust
    ns = np.zeros(n, dtype=np.int64)
    invalid = 0
    clock = time.perf_counter_ns
    with gc_paused():
        for k, (now, gyro, acc, mag) in enumerate(args):
            if k % si.command_every == 0:
                s.four_axis_command(angles, base, now)
            t0 = clock()
            out = s.step(now, gyro, acc, mag, si.voltage)
            ns[k] = clock() - t0
            invalid += out.status == "invalid_input"
    return ns, invalid


# --- LQI synthesis ------------------------------------------------------------------------


def run_lqi(ctx: Context) -> list[Measurement]:
    """LQI synthesis along the joint trajectory, warm (40 Hz sequence) and cold, inside
    Rust and through Python; scipy's CARE on the same (Ā, B̄, Q, R) as the peer."""
    from rdm import _rdm

    n = ctx.count(20_000)
    li = sc.lqi_inputs(n)
    out: list[Measurement] = []
    peers = run_lqi_peers(ctx, li)
    for warm in (True, False):
        mode = "warm" if warm else "cold"
        ctx.progress(f"lqi_{mode}: {n} syntheses inside Rust")
        rust = _rdm.time_lqi_synthesis(li.masses, li.inertias, li.allocations, warm)
        ctx.progress(f"lqi_{mode}: {n} syntheses through Python")
        py_ns, py_failures = time_lqi_python(li, warm)
        detail = (
            "warm: one synthesizer along the trajectory (Kleinman from the previous tick's K)"
            if warm
            else "cold: warm start forgotten before every call (sign function)"
        )
        notes = [detail, f"fell back to cold: {rust['fell_back']}"] if warm else [detail]
        targets = [Target("median_us", 100.0), Target("speedup_vs:scipy_care", 5.0)]
        out.append(
            Measurement(
                f"lqi_{mode}_rust",
                f"LQI gain synthesis ({mode}), 12 states x 4 rotors, inside Rust",
                summarize_ns(rust["ns"]),
                TICK_BUDGET_US,
                int(rust["failures"]),
                targets,
                peers,
                notes,
            )
        )
        out.append(
            Measurement(
                f"lqi_{mode}_python",
                f"LQI gain synthesis ({mode}) through Python (LqiSynthesizer.synthesize)",
                summarize_ns(py_ns),
                TICK_BUDGET_US,
                py_failures,
                [Target("median_us", 100.0), Target("speedup_vs:scipy_care", 5.0)],
                peers,
                [detail],
            )
        )
    return out


def time_lqi_python(li: sc.LqiInputs, warm: bool) -> tuple[np.ndarray, int]:
    """Per-call ns of ``rdm.control.lqi.LqiSynthesizer.synthesize``."""
    from rdm.control.lqi import CareSolveError, LqiSynthesisError, LqiSynthesizer

    synth = LqiSynthesizer()
    n = len(li.masses)
    ns = np.zeros(n, dtype=np.int64)
    failures = 0
    clock = time.perf_counter_ns
    with gc_paused():
        for k in range(n):
            if not warm:
                synth.reset()
            mass, inertia, alloc = float(li.masses[k]), li.inertias[k], li.allocations[k]
            t0 = clock()
            try:
                synth.synthesize(mass, inertia, alloc)
            except (CareSolveError, LqiSynthesisError):
                failures += 1
            ns[k] = clock() - t0
    return ns, failures


def run_lqi_peers(ctx: Context, li: sc.LqiInputs) -> dict[str, PeerResult]:
    """scipy's ``solve_continuous_are`` + K on the first configurations of the sequence."""
    skipped = skipped_peers(("scipy_care",), "scipy")
    if skipped is not None:
        ctx.progress("lqi: scipy missing, peer skipped")
        return skipped
    from rdm import _rdm
    from rdm.control.lqi import TABLE_V_Q, TABLE_V_R

    m = ctx.peer_count(2_000)
    q, r = np.diag(TABLE_V_Q), np.diag(TABLE_V_R)
    problems = []
    for k in range(m):
        a, b = _rdm.augmented_system(float(li.masses[k]), li.inertias[k], li.allocations[k])
        problems.append((a, b, q, r))
    reference = _rdm.time_lqi_synthesis(li.masses[:m], li.inertias[:m], li.allocations[:m], False)
    ctx.progress(f"lqi: {m} scipy solve_continuous_are + K")
    run = peer_mod.run_scipy_care(problems, reference["k"])
    return {"scipy_care": peer_result("scipy_care", run)}


# --- 40 Hz onboard tick -------------------------------------------------------------------


def run_tick(ctx: Context) -> list[Measurement]:
    """Position step + perching controller tick, inside Rust and through Python with the
    default active-set solver, and through Python with ``solver="clarabel"``; OSQP and
    Clarabel's wheel on the QPs of the Python run."""
    from rdm import _rdm

    n = ctx.count(100_000)
    ti = sc.tick_inputs(n)
    ctx.progress(f"tick_40hz: {n} ticks inside Rust")
    rust = _rdm.time_onboard_ticks(
        ti.position,
        ti.velocity,
        ti.target_position,
        ti.target_velocity,
        ti.target_yaw,
        ti.link_rotations,
        ti.dt,
        ti.foot_wrench,
        ti.foot_allocation,
        ti.allocation,
        ti.mass,
        ti.initial_thrust,
    )
    m = ctx.peer_count(5_000)
    ctx.progress(f"tick_40hz: {n} ticks through Python")
    py_ns, py_failures, problems = time_tick_python(ti, collect=m)
    ctx.progress(f"tick_40hz: {n} ticks through Python, solver=clarabel")
    cl_ns, cl_failures, _ = time_tick_python(ti, collect=0, solver="clarabel")
    peers = run_tick_peers(ctx, problems)
    notes = [
        "position step (eqs. 30-36) + perching tick (filter + eq. 49; default solver: dense "
        "active set on the reduced QP, Clarabel as fallback; docs/perch.md)",
        "perched default robot, joint trajectory, scripted foot wrench (docs/bench.md)",
    ]
    return [
        Measurement(
            "tick_40hz_rust",
            "40 Hz onboard tick (position + perching QP, active set), inside Rust",
            summarize_ns(rust["ns"]),
            TICK_BUDGET_US,
            int(rust["failures"]),
            [
                Target("median_us", 20.0),
                Target("p999_us", 100.0),
                Target("faster_than:osqp_setup_solve", 1.0),
            ],
            peers,
            notes,
        ),
        Measurement(
            "tick_40hz_python",
            "40 Hz onboard tick through Python (PositionController.step + PerchController.tick)",
            summarize_ns(py_ns),
            TICK_BUDGET_US,
            py_failures,
            [Target("faster_than:osqp_setup_solve", 1.0)],
            peers,
            notes,
        ),
        Measurement(
            "tick_40hz_python_clarabel",
            "40 Hz onboard tick through Python, perching QP on Clarabel (solver='clarabel')",
            summarize_ns(cl_ns),
            TICK_BUDGET_US,
            cl_failures,
            [Target("faster_than:osqp_setup_solve", 1.0)],
            peers,
            notes,
        ),
    ]


def time_tick_python(
    ti: sc.TickInputs, collect: int, solver: str = "active_set"
) -> tuple[np.ndarray, int, list[peer_mod.QpData]]:
    """Per-call ns of the public Python tick with the perching ``solver``; the QPs of the
    first ``collect`` ticks are read back (untimed) with ``problem_data()`` for the peers."""
    from rdm.control.perch import PerchController
    from rdm.control.position import PositionControlError, PositionController

    position, perch = PositionController(), PerchController(solver=solver)
    perch.reset(ti.initial_thrust)
    n = len(ti.target_yaw)
    ns = np.zeros(n, dtype=np.int64)
    failures = 0
    problems: list[peer_mod.QpData] = []
    clock = time.perf_counter_ns
    with gc_paused():
        for k in range(n):
            args = (
                ti.position[k],
                ti.velocity[k],
                ti.target_position[k],
                ti.target_velocity[k],
                float(ti.target_yaw[k]),
                ti.link_rotations[k],
                ti.dt,
            )
            wrench, foot, alloc = ti.foot_wrench[k], ti.foot_allocation[k], ti.allocation[k]
            t0 = clock()
            try:
                position.step(*args)
            except PositionControlError:
                failures += 1
            result = perch.tick(wrench, foot, alloc, ti.mass)
            ns[k] = clock() - t0
            failures += not result.ok
            if k < collect:
                p = perch.problem_data()
                problems.append(
                    peer_mod.QpData(
                        p.P,
                        p.q,
                        p.A,
                        p.b,
                        p.zero_cone,
                        p.nonnegative_cone,
                        p.variable_scale,
                        result.thrust,
                    )
                )
    return ns, failures, problems


def run_tick_peers(ctx: Context, problems: list[peer_mod.QpData]) -> dict[str, PeerResult]:
    """OSQP (defaults and tight) and Clarabel's wheel, setup+solve and update+solve."""
    out: dict[str, PeerResult] = {}
    osqp_names = tuple(
        f"{variant}_{mode}"
        for variant in peer_mod.OSQP_VARIANTS
        for mode in ("setup_solve", "update_solve")
    )
    skipped = skipped_peers(osqp_names, "osqp")
    if skipped is not None:
        out.update(skipped)
    else:
        for variant, settings in peer_mod.OSQP_VARIANTS.items():
            for mode in ("setup_solve", "update_solve"):
                name = f"{variant}_{mode}"
                ctx.progress(f"tick_40hz: {len(problems)} QPs with {name}")
                out[name] = peer_result(
                    name, peer_mod.run_osqp(problems, settings, mode == "update_solve")
                )
    clarabel_names = ("clarabel_py_setup_solve", "clarabel_py_update_solve")
    skipped = skipped_peers(clarabel_names, "clarabel")
    if skipped is not None:
        out.update(skipped)
    else:
        for name in clarabel_names:
            ctx.progress(f"tick_40hz: {len(problems)} QPs with {name}")
            out[name] = peer_result(
                name, peer_mod.run_clarabel(problems, update=name.endswith("update_solve"))
            )
    return out


register(
    Case(
        "spinal_step",
        "200 Hz Spinal step",
        run_spinal,
        ("spinal_step_rust", "spinal_step_python"),
        (),
    )
)
register(
    Case(
        "lqi",
        "LQI gain synthesis",
        run_lqi,
        ("lqi_warm_rust", "lqi_warm_python", "lqi_cold_rust", "lqi_cold_python"),
        ("scipy_care",),
    )
)
TICK_PEERS = (
    *(f"{v}_{m}" for v in peer_mod.OSQP_VARIANTS for m in ("setup_solve", "update_solve")),
    "clarabel_py_setup_solve",
    "clarabel_py_update_solve",
)
register(
    Case(
        "tick_40hz",
        "40 Hz onboard tick",
        run_tick,
        ("tick_40hz_rust", "tick_40hz_python", "tick_40hz_python_clarabel"),
        TICK_PEERS,
    )
)
