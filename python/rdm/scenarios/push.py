"""``push``: an external force at the end effector, pushed and pulled in x, y, z, in flight and
perched (paper Sec. VII-C-1, Figs. 11-12, Tables VIII-IX).

One run, built on the perching scenario's phases (:class:`rdm.scenarios.perching.PerchingScript`):

1. boot, arm, climb at q = 0;
2. **flight stage**: hovering with the arm straight (q = 0) on ``FLIGHT_GAINS``, a quiet
   window (the no-push baseline), then the end effector is pushed and pulled along its x, y,
   z axes in turn;
3. fold in flight to the hanging posture ``PERCH_POSTURE``, approach, perch, settle, then
   a joint motion to the push posture ``PERCHED_POSTURE`` (end effector 0.2 m below the
   plate instead of 1.02 m);
4. **perched stage**: the same quiet window and the same push/pull sequence, with the
   perched magnitudes (the perching QP's foot-wrench filter at ``PERCHED_CUTOFF_HZ``).

The force and its profile: :mod:`rdm.scenarios.push_plan`. Nothing in the stack measures or
compensates it: the onboard node sees only the foot sensor, the IMU and the mocap.

Metrics from ground truth: foot (root) position standard deviation x, y, z over the push
sequence vs Table IX; the mean |F_ee| per axis seen by MuJoCo's end-effector force sensor vs
Table VIII; perched: contact kept, slip, ZMP inside the plate, friction usage.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from rdm.sim import Metric
from rdm.sim.plots import plot_panels, plot_zmp

from .common import (
    ScenarioResult,
    finish,
    observed,
    run_stack,
    sim_stack_options,
    truth_arrays,
)
from .perching import (
    EDGE_MM,
    MU,
    PERCH_PARAMS,
    PERCH_POSTURE,
    PLATE_HALF,
    PerchingScript,
    onboard_config,
)
from .push_plan import (
    AXES,
    DEFAULT_PLAN,
    EE_BODY,
    EE_SENSOR,
    FLIGHT_GAINS,
    FLIGHT_SCALE,
    PAPER_FLIGHT_FORCE_AVG,
    PAPER_FLIGHT_FORCE_PEAK,
    PAPER_FOOT_STD_FLIGHT,
    PAPER_FOOT_STD_PERCHED,
    PAPER_PERCHED_FORCE_AVG,
    PAPER_PERCHED_FORCE_PEAK,
    PERCHED_CUTOFF_HZ,
    PERCHED_POSTURE,
    PERCHED_SCALE,
    PERCHED_SCALE_BEYOND_CEILING,
    PROFILE_MEAN_ABS,
    PROFILE_PEAK,
    PushPlan,
    StageLog,
    profile,
    stage_windows,
)
from .stack import Stack, build_stack

#: the plan's names, re-exported: ``push.PushPlan``, ``push.stage_windows``, Table VIII ...
__all__ = [
    "AXES",
    "DEFAULT_DURATION",
    "DEFAULT_PLAN",
    "EE_BODY",
    "EE_SENSOR",
    "FLIGHT_GAINS",
    "FLIGHT_SCALE",
    "MU",
    "PAPER_FLIGHT_FORCE_AVG",
    "PAPER_FLIGHT_FORCE_PEAK",
    "PAPER_FOOT_STD_FLIGHT",
    "PAPER_FOOT_STD_PERCHED",
    "PAPER_PERCHED_FORCE_AVG",
    "PAPER_PERCHED_FORCE_PEAK",
    "PERCHED_CUTOFF_HZ",
    "PERCHED_POSTURE",
    "PERCHED_SCALE",
    "PERCHED_SCALE_BEYOND_CEILING",
    "PERCH_PARAMS",
    "PLATE_HALF",
    "PROFILE_MEAN_ABS",
    "PROFILE_PEAK",
    "PushPlan",
    "PushScript",
    "StageLog",
    "StagedPerchingScript",
    "analyse",
    "metrics_of",
    "plot",
    "profile",
    "run",
    "stage_windows",
]


class StagedPerchingScript(PerchingScript):
    """The perching scenario's phase machine with two inserted stages: ``flight_stage_s``
    seconds of hovering in the hanging posture after the fold (before the approach), and
    ``perched_stage_s`` seconds once perched and settled. Subclasses act in
    :meth:`flight_tick` / :meth:`perched_tick` (``s`` = seconds into the stage)."""

    def __init__(
        self,
        flight_stage_s: float,
        perched_stage_s: float,
        motion=None,
        flight_after: str = "reconfigure",
    ) -> None:
        # a 0.5 s "motion" to the posture it is already in: the perched stage starts at "hold"
        super().__init__(motion=motion or ((0.5, PERCH_POSTURE),))
        if flight_after not in ("climb", "reconfigure"):
            raise ValueError(f"flight_after={flight_after!r}: 'climb' or 'reconfigure'")
        self.flight_after = flight_after
        self.flight_stage_s = flight_stage_s
        self.perched_stage_s = perched_stage_s
        self.t_flight_stage: float | None = None
        self.t_perched_stage: float | None = None
        self.t_done = 0.0

    def __call__(self, stack: Stack, now: float) -> None:
        if self.flight_after == "climb":  # the tick on which the climb ramp arrives
            r = self.ramp
            ready = r is not None and bool(
                np.linalg.norm(r.goal - r.position) <= r.speed * (now - self._last) + 1e-9
            )
        else:
            ready = now > self.t_phase_end + 1.0
        if (
            self.phase == self.flight_after
            and self.t_flight_stage is None
            and self.flight_stage_s > 0
            and ready
        ):
            self.phase = "flight_stage"
            self.t_flight_stage = now
        if self.phase == "flight_stage":
            assert self.ramp is not None
            self.ramp.step(now - self._last)
            self._last = now
            s = now - self.t_flight_stage
            if s > self.flight_stage_s:
                self.flight_end(stack, now)
                self.phase = self.flight_after  # the parent goes on from there
            else:
                self.flight_tick(stack, now, s)
            return
        super().__call__(stack, now)
        if self.phase == "hold":
            if self.t_perched_stage is None:
                self.t_perched_stage = now
            s = now - self.t_perched_stage
            if s <= self.perched_stage_s:
                self.perched_tick(stack, now, s)
            else:
                self.perched_end(stack, now)
                self.phase = "done"
                self.t_done = now
        elif self.phase == "done" and now > self.t_done + 0.5:
            stack.loop.stop()  # nothing left to do: end the run

    def flight_tick(self, stack: Stack, now: float, s: float) -> None:
        assert self.ramp is not None
        stack.onboard.set_target(self.ramp.position, 0.0, self.ramp.velocity)

    def flight_end(self, stack: Stack, now: float) -> None:
        pass

    def perched_tick(self, stack: Stack, now: float, s: float) -> None:
        pass

    def perched_end(self, stack: Stack, now: float) -> None:
        pass


class PushScript(StagedPerchingScript):
    """Applies the push profile of ``plan`` at the end effector in both stages."""

    def __init__(self, plan: PushPlan) -> None:
        motion = None
        if plan.perched_posture is not None:
            motion = ((plan.posture_s, tuple(plan.perched_posture)),)
        super().__init__(
            plan.flight_stage_s() if plan.flight else 0.0,
            plan.stage_s(),
            motion=motion,
            flight_after=plan.flight_after,
        )
        self.plan = plan
        self.logs = {"flight": StageLog(), "perched": StageLog()}
        self._hover_z: float | None = None

    def _push(self, stack: Stack, now: float, s: float, stage: str) -> None:
        f_ee = self.plan.stage_force(s, stage)
        plant = stack.plant
        rot = plant.data.xmat[plant.model.body(EE_BODY).id].reshape(3, 3)
        plant.apply_body_wrench(EE_BODY, force=rot @ f_ee)
        force, torque = plant.wrench_ideal(EE_SENSOR)
        log = self.logs[stage]
        log.t.append(now)
        log.applied.append(f_ee)
        log.sensor_force.append(force)
        log.sensor_torque.append(torque)
        control = stack.onboard.control
        log.perch_thrust.append(np.array(control.perch_thrust, dtype=float))
        log.perch_counts.append({k: v for k, v in control.counts.items() if k.startswith("perch_")})

    def flight_tick(self, stack: Stack, now: float, s: float) -> None:
        p, ramp = self.plan, self.ramp
        assert ramp is not None
        speed = p.flight_drop / max(p.move_s - 0.5, 0.1)
        if self._hover_z is None:  # go down, then push, then back up
            stack.onboard.control.set_position_gains(p.flight_gains)
            self._hover_z = float(ramp.position[2])
            ramp.set_goal(ramp.position - [0.0, 0.0, p.flight_drop], speed)
        elif s > p.move_s + p.stage_s() and ramp.goal[2] < self._hover_z:
            ramp.set_goal(np.array([*ramp.position[:2], self._hover_z]), speed)
        super().flight_tick(stack, now, s)
        if p.move_s <= s <= p.move_s + p.stage_s():
            self._push(stack, now, s - p.move_s, "flight")

    def flight_end(self, stack: Stack, now: float) -> None:
        stack.plant.apply_body_wrench(EE_BODY)  # zero: removed
        stack.onboard.control.set_position_gains(self.phase_gains(stack))

    def perched_tick(self, stack: Stack, now: float, s: float) -> None:
        self._push(stack, now, s, "perched")

    def perched_end(self, stack: Stack, now: float) -> None:
        stack.plant.apply_body_wrench(EE_BODY)


def _in(t: np.ndarray, w: tuple[float, float]) -> np.ndarray:
    return (t >= w[0]) & (t <= w[1])


def analyse(stack: Stack, script: PushScript) -> dict[str, Any]:
    """Foot-position scatter, end-effector forces and contact outcome per stage (truth)."""
    plan = script.plan
    a = truth_arrays(stack)
    t = a["t"]
    out: dict[str, Any] = {"truth": a}
    t_fl = None if script.t_flight_stage is None else script.t_flight_stage + plan.move_s
    for stage, t0 in (("flight", t_fl), ("perched", script.t_perched_stage)):
        w = stage_windows(plan, t0)
        log = script.logs[stage].arrays()
        if w is None or log["t"].size == 0:
            out[stage] = None
            continue
        pushes, quiet = _in(t, w["pushes"]), _in(t, w["quiet"])
        if not (pushes.any() and quiet.any()):  # the run ended before the stage
            out[stage] = None
            continue
        foot = a["foot"]
        r: dict[str, Any] = {
            "windows": w,
            "log": log,
            "foot_std": np.std(foot[pushes], axis=0),
            "foot_std_quiet": np.std(foot[quiet], axis=0),
            "foot_excursion": np.max(np.linalg.norm(foot[pushes] - foot[quiet].mean(0), axis=1)),
            "foot_excursion_quiet": np.max(
                np.linalg.norm(foot[quiet] - foot[quiet].mean(0), axis=1)
            ),
            "force_mean_abs": np.full(3, np.nan),
            "force_peak": np.full(3, np.nan),
            "applied_mean_abs": np.full(3, np.nan),
            "torque_mean_abs": np.full(3, np.nan),
            "torque_peak": np.full(3, np.nan),
        }
        for ax, aw in w["axes"].items():
            m = _in(log["t"], aw)
            if not m.any():  # the run ended before this push
                continue
            r["force_mean_abs"][ax] = np.mean(np.abs(log["force"][m, ax]))
            r["force_peak"][ax] = np.max(np.abs(log["force"][m, ax]))
            r["applied_mean_abs"][ax] = np.mean(np.abs(log["applied"][m, ax]))
            r["torque_mean_abs"][ax] = np.mean(np.abs(log["torque"][m, ax]))
            r["torque_peak"][ax] = np.max(np.abs(log["torque"][m, ax]))
        if stage == "perched":
            fz = a["force"][pushes, 2]
            slip = a["slip"][pushes]
            zmp = a["zmp"][pushes]
            with np.errstate(invalid="ignore", divide="ignore"):
                cone = np.hypot(a["force"][pushes, 0], a["force"][pushes, 1]) / (MU[0] * fz)
                yaw = np.abs(a["torque"][pushes, 2]) / (MU[2] * fz)
                margin = np.minimum(
                    PLATE_HALF[0] - np.abs(zmp[:, 0]), PLATE_HALF[1] - np.abs(zmp[:, 1])
                )
            r.update(
                contact_kept=float(np.mean(a["contact"][pushes])),
                slip_mm=float(np.max(np.linalg.norm(slip - slip[0], axis=1)) * 1e3),
                slip_yaw_deg=float(
                    np.degrees(
                        np.ptp(
                            [g.foot_slip_yaw for g, p in zip(stack.truth, pushes, strict=True) if p]
                        )
                    )
                ),
                edge_fraction=float(np.mean(~(margin * 1e3 > EDGE_MM))),
                zmp_margin_mm=float(np.nanmin(margin) * 1e3)
                if np.isfinite(margin).any()
                else np.nan,
                cone_max=float(np.nanmax(cone)) if np.isfinite(cone).any() else np.nan,
                yaw_use_max=float(np.nanmax(yaw)) if np.isfinite(yaw).any() else np.nan,
                fz_min=float(np.min(fz)),
                fz_max=float(np.max(fz)),
                fz_quiet=float(np.mean(a["force"][quiet, 2])),
            )
            on = _in(log["t"], w["pushes"])
            counts = script.logs[stage].perch_counts
            idx = np.flatnonzero(on)
            if idx.size:
                first, last = counts[idx[0]], counts[idx[-1]]
                r["qp_status"] = {
                    k[len("perch_") :]: last.get(k, 0) - first.get(k, 0)
                    for k in last
                    if last.get(k, 0) - first.get(k, 0) > 0
                }
                lam = log["perch_thrust"][on].sum(axis=1)
                r["perch_thrust_quiet"] = float(
                    np.mean(log["perch_thrust"][_in(log["t"], w["quiet"])].sum(axis=1))
                )
                r["perch_thrust_max"] = float(lam.max())
        out[stage] = r
    return out


def metrics_of(res: dict[str, Any], plan: PushPlan) -> list[Metric]:
    ms: list[Metric] = []
    nan = float("nan")
    for stage, paper_std, paper_avg, paper_peak in (
        ("flight", PAPER_FOOT_STD_FLIGHT, PAPER_FLIGHT_FORCE_AVG, PAPER_FLIGHT_FORCE_PEAK),
        ("perched", PAPER_FOOT_STD_PERCHED, PAPER_PERCHED_FORCE_AVG, PAPER_PERCHED_FORCE_PEAK),
    ):
        r = res.get(stage)
        if stage == "flight" and not plan.flight:
            continue
        for k, ax in enumerate(AXES):
            ms.append(
                Metric(
                    f"{stage}: foot position std {ax} (pushes)",
                    float(r["foot_std"][k]) if r else nan,
                    paper_std[k],
                    "m",
                    "info",
                )
            )
        for k, ax in enumerate(AXES):
            ms.append(
                Metric(
                    f"{stage}: foot position std {ax} (quiet, no push)",
                    float(r["foot_std_quiet"][k]) if r else nan,
                    None,
                    "m",
                    "info",
                )
            )
        for k in plan.axes:
            ax = AXES[k]
            ms.append(
                Metric(
                    f"{stage}: mean |F_ee,{ax}| (EE sensor, {ax} push)",
                    float(r["force_mean_abs"][k]) if r else nan,
                    paper_avg[k],
                    "N",
                    "info",
                )
            )
            ms.append(
                Metric(
                    f"{stage}: peak |F_ee,{ax}| (EE sensor)",
                    float(r["force_peak"][k]) if r else nan,
                    paper_peak[k],
                    "N",
                    "info",
                )
            )
    r = res.get("perched")
    if plan.flight:
        fl = res.get("flight")
        ms.append(
            Metric(
                "flight: max foot excursion, pushes / quiet",
                float(fl["foot_excursion"] / max(fl["foot_excursion_quiet"], 1e-6)) if fl else nan,
                None,
                "ratio",
                "min",
                limit=2.0,
            )
        )
    ms += [
        Metric(
            "perched: foot contact kept while pushed",
            r["contact_kept"] if r else nan,
            1.0,
            "fraction",
            "min",
            limit=1.0,
        ),
        Metric(
            "perched: foot slip while pushed", r["slip_mm"] if r else nan, None, "mm", "max", 1.0
        ),
        Metric(
            "perched: foot yaw slip while pushed",
            r["slip_yaw_deg"] if r else nan,
            None,
            "deg",
            "info",
        ),
        Metric(
            "perched: min ZMP margin to the plate edge",
            r["zmp_margin_mm"] if r else nan,
            None,
            "mm",
            "min",
            limit=-1e-3,
        ),
        Metric(
            "perched: max friction-cone usage", r["cone_max"] if r else nan, None, "", "max", 1.0
        ),
        Metric("perched: max yaw-friction usage", r["yaw_use_max"] if r else nan, None, "", "info"),
        Metric(
            f"perched: time with the ZMP on the plate edge (< {EDGE_MM:g} mm) while pushed",
            r["edge_fraction"] if r else nan,
            None,
            "fraction",
            "info",
        ),
        Metric("perched: min foot normal force", r["fz_min"] if r else nan, None, "N", "info"),
        Metric(
            "perched: max lambda_perch sum while pushed",
            r.get("perch_thrust_max", nan) if r else nan,
            None,
            "N",
            "info",
        ),
    ]
    return ms


def plot(stack: Stack, res: dict[str, Any]) -> None:
    a = res["truth"]
    t = a["t"]
    for stage, fig in (("flight", "Fig. 11"), ("perched", "Fig. 12")):
        r = res.get(stage)
        if r is None:
            continue
        log = r["log"]
        lt = log["t"]
        span = (t >= lt[0]) & (t <= lt[-1])
        foot = a["foot"][span]
        panels = [
            (
                "(A) applied force (end-effector frame)",
                {f"F{ax}": log["applied"][:, k] for k, ax in enumerate(AXES)},
                "N",
            ),
            (
                "(B) end-effector force (MuJoCo EE sensor)",
                {f"F{ax}": log["force"][:, k] for k, ax in enumerate(AXES)},
                "N",
            ),
            (
                "(C) end-effector moment (MuJoCo EE sensor)",
                {f"M{ax}": log["torque"][:, k] for k, ax in enumerate(AXES)},
                "N m",
            ),
        ]
        plot_panels(
            stack.folder.plot(f"push_{stage}_ee_wrench"),
            lt,
            panels,
            title=f"push, {stage}: end-effector wrench ({fig} B, C)",
        )
        tail = [
            (
                "foot position - mean (truth)",
                {ax: foot[:, k] - foot[:, k].mean() for k, ax in enumerate(AXES)},
                "m",
            )
        ]
        if stage == "perched":
            f, m = a["force"][span], a["torque"][span]
            tail = [
                (
                    "(D) rotor thrust (truth)",
                    {f"rotor{i + 1}": a["thrust"][span, i] for i in range(4)},
                    "N",
                ),
                ("(E) foot force (truth)", {f"F{ax}": f[:, k] for k, ax in enumerate(AXES)}, "N"),
                (
                    "(F) foot moment (truth)",
                    {f"M{ax}": m[:, k] for k, ax in enumerate(AXES)},
                    "N m",
                ),
                ("(G) foot ZMP", {"x": a["zmp"][span, 0], "y": a["zmp"][span, 1]}, "m"),
                *[(f"(H) {p[0]}", p[1], p[2]) for p in tail],
            ]
            plot_zmp(
                stack.folder.plot("push_perched_zmp"),
                a["zmp"][span],
                (2 * PLATE_HALF[0], 2 * PLATE_HALF[1]),
                title="push, perched: foot ZMP (Fig. 12 G)",
            )
        else:
            tail = [("(D) " + tail[0][0], tail[0][1], tail[0][2])]
        plot_panels(
            stack.folder.plot(f"push_{stage}_foot"),
            t[span],
            tail,
            title=f"push, {stage}: the root under the pushes ({fig})",
        )


#: upper bound of a run [s]; the run stops 0.5 s after the perched stage (~56 s by default)
DEFAULT_DURATION = 65.0


def run(
    base: str | Path,
    duration: float | None = None,
    seed: int = 0,
    uart: str = "inproc",
    speed: float | None = None,
    plan: PushPlan | None = None,
    log: bool = True,
    plots: bool = True,
    observer: Callable[[Stack, float], None] | None = None,
    robot: str = "rdm",
    name: str = "push",
    metrics: Callable[[dict[str, Any], PushPlan], list[Metric]] = metrics_of,
    facts: dict[str, Any] | None = None,
) -> ScenarioResult:
    """Run the scenario: it stops 0.5 s after the perched stage, or at ``duration``;
    ``observer(stack, now)``, if given, is called after the script on each of its ticks.
    A variant (``push-paper-forces``) gives its ``robot`` (a shipped name or the path of a
    robot TOML), its ``name``, its ``metrics`` rows and extra ``facts``."""
    plan = plan or DEFAULT_PLAN
    hold = (
        {}
        if plan.rp_integration_hold_rate == "default"
        else {"rp_integration_hold_rate": plan.rp_integration_hold_rate}
    )
    onboard = onboard_config(
        perch_params={**PERCH_PARAMS, **plan.perch_params},
        perch_cutoff_hz=plan.perch_cutoff_hz,
        **hold,
    )
    opts = sim_stack_options(seed, uart, speed=speed, log=log, onboard=onboard, robot=robot)
    script = PushScript(plan)
    stack = build_stack(name, base, opts, observed(script, observer))
    wall = run_stack(stack, DEFAULT_DURATION if duration is None else duration)
    seconds = stack.plant.time
    res = analyse(stack, script)
    if plots:
        plot(stack, res)
    facts = {
        **(facts or {}),
        "plan": asdict(plan),
        "t_flight_stage": script.t_flight_stage,
        "t_perch": script.t_perch,
        "t_perched_stage": script.t_perched_stage,
        "final_phase": script.phase,
        "profile_peak_over_mean": PROFILE_PEAK / PROFILE_MEAN_ABS,
    }
    for stage in ("flight", "perched"):
        r = res.get(stage)
        if r:
            facts[stage] = {
                k: (v.tolist() if isinstance(v, np.ndarray) else v)
                for k, v in r.items()
                if k not in ("log", "windows")
            }
    result = ScenarioResult(name, stack, metrics(res, plan), facts)
    result.analysis = res  # type: ignore[attr-defined]
    result.script = script  # type: ignore[attr-defined]
    return finish(result, seconds, wall)
