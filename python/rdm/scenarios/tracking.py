"""``tracking``: end-effector pose tracking in flight vs perched (paper Sec. VII-C-2, Fig. 13,
Table X), with the Sec. V planner in front of the position controller (Fig. 6).

The paper moves the joints by a feed-forward planner while the root (base link) is held by
the real-time position/attitude feedback, once flying and once perched, and compares the
end-effector pose errors (Table X). One run, built on the perching scenario's phase machine
(:class:`rdm.scenarios.push.StagedPerchingScript`, ``perching.py`` unchanged):

1. boot, arm, climb at q = 0 (as ``perching-hanging``);
2. **flight stage** (arm straight, q = 0, the posture Fig. 9 starts its change from): settle,
   then the joints follow the stage's planned path (:mod:`rdm.scenarios.tracking_plan`:
   ``rdm.planner`` in flight mode to where Fig. 9 (A)'s end configuration puts the end
   effector, held, retraced) through :meth:`OnboardNode.set_trajectory` at 40 Hz, while the
   CoG setpoint is streamed so that the *planned* configuration keeps the root at a fixed
   point, ``p_cog,ref(t) = p_root,ref + cog_in_foot(q_plan(t))`` (the flight scenario's
   reference);
3. fold to the hanging posture, approach, perch, settle (as ``perching-hanging``);
4. **perched stage**: the planner in perched mode from ``PERCH_POSTURE`` to the end effector
   of Fig. 10's arm pose, the root on the ceiling, the setpoint held (as ``perching-hanging``).

``motion=`` (joint offsets from each stage's base posture, the same in both stages) replaces
the planned paths by hand-chosen ones (the flight-envelope study of docs/scenarios.md).

Error definition (both stages alike). The end-effector target is where the planned
configuration puts the end effector with the root where it was just before the motion:
``T_ee,ref(t) = T_root(t0) T_foot->ee(q_plan(t))`` (``rdm.model`` forward kinematics; root =
true foot pose, position averaged over the ``PRE_S`` before the motion, orientation at t0).
Position error = true end-effector position (MuJoCo) - target (world axes); attitude error =
the rotation vector of ``R_true R_ref^T`` (world axes; for small errors the roll, pitch, yaw
errors, without the ZYX gimbal singularity). RMSE over the motion and ``AFTER_S`` after it.

Resolution floor. The servo goals cross the wire as encoder counts (``servo/target_states``,
1.53 mrad for a Dynamixel X), so even ideal servos, on their goals at once and without sag,
put the end effector at the plan rounded to counts. ``StageErrors.att_floor_rmse`` /
``pos_floor_rmse`` are the RMSE of that pose against the plan, over the same window and axes
(docs/scenarios.md). Real joints are not on their goals, so a run can land below this floor
by chance (a sag that cancels part of a rounding), not by a margin the rounding leaves open.
"""

from __future__ import annotations

from dataclasses import asdict, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from rdm.model import Robot
from rdm.nodes.onboard_config import ServoMap
from rdm.sim import Metric
from rdm.sim.plots import plot_panels, plot_tracking_errors

if TYPE_CHECKING:
    from scipy.spatial.transform import Rotation

    from rdm.plant.servo import ServoParams

from .common import (
    ScenarioResult,
    finish,
    run_stack,
    scenario_servo_lead,
    sim_stack_options,
    truth_arrays,
)
from .perching import HANGING_FLIGHT_GAINS, PERCH_POSTURE, joint_path, onboard_config
from .push import StagedPerchingScript
from .servo_lag import joint_lags
from .stack import Stack, build_stack
from .tracking_margins import StageErrors, execution_metrics, stage_execution
from .tracking_plan import StagePath, StagePlan, plan_arrays, plan_at, stage_path

AXES = ("x", "y", "z")
ANGLES = ("roll", "pitch", "yaw")
#: Table X: end-effector RMSE x, y, z [m], roll, pitch, yaw [rad]; flight and perched.
PAPER_RMSE_FLIGHT = (0.0552, 0.0759, 0.0688, 0.0019, 0.0003, 0.0004)
PAPER_RMSE_PERCHED = (0.00320, 0.0286, 0.0191, 0.0002, 0.0001, 0.0005)
#: Sec. VII-C-2: perched errors "generally less than 0.05 m and 0.1 rad" (Fig. 13 (B)).
PAPER_PERCHED_BAND = (0.05, 0.1)
FLIGHT_POSTURE = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
#: Base posture of the flight stage: "straight" (q = 0, after the climb; the default) or
#: "hanging" (``PERCH_POSTURE``, after the fold; the flying hanging robot is lightly damped).
FLIGHT_POSTURES = {"straight": FLIGHT_POSTURE, "hanging": PERCH_POSTURE}
#: Position gains of the hanging posture's flight stage: ``perching.HANGING_FLIGHT_GAINS``
#: (the configured y PID and Table V's x PID are linearly unstable there; docs/scenarios.md).
#: The straight posture keeps the run's configuration (None).
FLIGHT_STAGE_GAINS: dict[str, dict | None] = {"straight": None, "hanging": HANGING_FLIGHT_GAINS}
#: Hand-chosen joint offsets for ``run(motion=...)`` (the default run plans its paths):
#: (duration [s], q1..q6 offset from the stage's base posture) segments, back to zero offset
#: at the end; a slow arm pitch/yaw sweep (the flight-envelope study of docs/scenarios.md).
MOTION: tuple[tuple[float, tuple[float, ...]], ...] = (
    (4.0, (0.0, -0.3, 0.2, 0.4, 0.3, 0.0)),
    (4.0, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)),
)
#: s of each stage before its pre-motion window: in flight the climb overshoots ~8 cm in z and
#: settles in ~2.5 s; perched, the contact transient rocks the plate on its edges (roll
#: +-2 deg, seed 1) for up to ~4.5 s after contact (the stage starts ~2 s after contact)
SETTLE_S = 3.0
PRE_S = 0.5  # s before the motion over which the root position is averaged
AFTER_S = 1.0  # s after the motion inside the error window


def _absolute(base: tuple[float, ...], motion) -> list[tuple[float, np.ndarray]]:
    """Offset segments -> absolute joint goals, ending at ``base``."""
    segs = [(float(d), np.asarray(base, float) + np.asarray(dq, float)) for d, dq in motion]
    if not segs or not np.allclose(segs[-1][1], base):
        segs.append((3.0, np.asarray(base, float)))
    return segs


def motion_seconds(motion) -> float:
    return sum(d for d, _ in _absolute(FLIGHT_POSTURE, motion))


def _frames(robot: Robot, q: np.ndarray) -> dict[str, np.ndarray]:
    fr = robot.evaluate(q)["frames"]
    return {k: np.asarray(fr[k], dtype=float) for k in ("foot", "cog", "end_effector")}


#: Planned stage (:data:`rdm.scenarios.tracking_plan.STAGES`) of each flight posture.
FLIGHT_PLAN_STAGE = {"straight": "flight", "hanging": "flight-hanging"}


class TrackingScript(StagedPerchingScript):
    """Flight stage at q = 0 with the CoG setpoint streamed (root held); perched stage in the
    hanging posture with the setpoint held. Same settle time in both; the joint paths are the
    planner's (``motion`` None) or the same hand-chosen offsets in both stages."""

    def __init__(
        self,
        motion,
        robot: Robot,
        flight_posture: str = "straight",
        flight_gains: dict | None = None,
    ) -> None:
        if flight_posture not in FLIGHT_POSTURES:
            raise ValueError(f"flight_posture={flight_posture!r}: one of {list(FLIGHT_POSTURES)}")
        #: position gains of the flight stage (None: the run's configuration), restored after
        self.flight_gains = flight_gains
        self.offsets = None if motion is None else tuple(motion)
        self.paths: dict[str, StagePath] = {}
        if self.offsets is None:
            self.paths = {
                "flight": stage_path(FLIGHT_PLAN_STAGE[flight_posture]),
                "perched": stage_path("perched"),
            }
            seconds = {k: p.duration for k, p in self.paths.items()}
        else:
            seconds = dict.fromkeys(("flight", "perched"), motion_seconds(self.offsets))
        self.flight_posture = flight_posture
        super().__init__(
            SETTLE_S + PRE_S + seconds["flight"] + AFTER_S,
            SETTLE_S + PRE_S + seconds["perched"] + AFTER_S,
            flight_after="climb" if flight_posture == "straight" else "reconfigure",
        )
        self.robot = robot
        self.plans: dict[str, StagePlan] = {}
        self._cog_in_foot: np.ndarray | None = None
        self._root_ref: np.ndarray | None = None

    def _send(self, stack: Stack, stage: str, now: float, start: float, base) -> StagePlan:
        n_q = stack.onboard.robot.n_q
        planned = self.paths.get(stage)
        if planned is None:
            assert self.offsets is not None
            segs = _absolute(base, self.offsets)
            path, end = joint_path(start, np.asarray(base, float), segs, n_q)
        else:  # the planner's samples at 40 Hz from the motion start
            path = [(start + float(t), q) for t, q in zip(planned.times, planned.q, strict=True)]
            end = start + planned.duration
        points = [(now, path[0][1]), *path]  # hold the base posture until the start
        if not stack.onboard.set_trajectory(points):
            raise RuntimeError(f"tracking {stage}: the onboard node refused the joint path")
        plan = StagePlan(points, start, end, planned)
        self.plans[stage] = plan
        return plan

    def flight_tick(self, stack: Stack, now: float, s: float) -> None:
        assert self.ramp is not None
        if "flight" not in self.plans:
            if self.flight_gains is not None:
                stack.onboard.control.set_position_gains(self.flight_gains)
            base = FLIGHT_POSTURES[self.flight_posture]
            plan = self._send(stack, "flight", now, now + SETTLE_S + PRE_S, base)
            cogs = []
            for _, q in plan.points:
                f = _frames(self.robot, q)
                cogs.append(f["cog"][:3, 3] - f["foot"][:3, 3])
            self._cog_in_foot = np.array(cogs)
            self._root_ref = self.ramp.position - self._cog_in_foot[0]
        assert self._cog_in_foot is not None and self._root_ref is not None
        times = np.array([p[0] for p in self.plans["flight"].points])
        c = self._cog_in_foot
        pos = self._root_ref + np.array([np.interp(now, times, c[:, k]) for k in range(3)])
        vel = np.zeros(3)
        if times[0] <= now < times[-1]:
            k = int(np.clip(np.searchsorted(times, now, side="right") - 1, 0, len(times) - 2))
            vel = (c[k + 1] - c[k]) / (times[k + 1] - times[k])
        stack.onboard.set_target(pos, 0.0, vel)

    def flight_end(self, stack: Stack, now: float) -> None:
        if self.flight_gains is not None:  # back to the phase machine's (fold or configured)
            stack.onboard.control.set_position_gains(self.phase_gains(stack))

    def perched_tick(self, stack: Stack, now: float, s: float) -> None:
        if "perched" not in self.plans:
            self._send(stack, "perched", now, now + SETTLE_S + PRE_S, PERCH_POSTURE)


def goal_resolution(q: np.ndarray, servo_map: ServoMap) -> np.ndarray:
    """Joint paths ``q`` (n, n_q) as the servos are told them: each joint's goal in the ticks
    the onboard node writes to ``servo/target_states`` (``ServoMap.to_raw``), back in rad
    (``ServoMap.to_rad``). Joints without a servo stay as they are."""
    out = np.array(q, dtype=float)
    n = min(out.shape[1], servo_map.n_joints)
    to_raw, to_rad = servo_map.to_raw, servo_map.to_rad
    out[:, :n] = [[to_rad(j, to_raw(j, v)) for j, v in enumerate(row[:n])] for row in out.tolist()]
    return out


def ee_targets(
    robot: Robot, root_p: np.ndarray, root_r: np.ndarray, q: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Planned end-effector positions (n, 3) and orientations (n, 3, 3) in the world for the
    planned configurations ``q`` (n, n_q) with the root frame at (root_p, root_r)."""
    p_ref = np.zeros((q.shape[0], 3))
    r_ref = np.zeros((q.shape[0], 3, 3))
    for i, qi in enumerate(q):
        f = _frames(robot, qi)
        rel = np.linalg.solve(f["foot"], f["end_effector"])  # foot -> EE
        p_ref[i] = root_p + root_r @ rel[:3, 3]
        r_ref[i] = root_r @ rel[:3, :3]
    return p_ref, r_ref


def _wxyz_to_rot(q: np.ndarray) -> Rotation:
    # scipy.spatial is imported here, at evaluation, not with the module (0.3 s of start-up)
    from scipy.spatial.transform import Rotation

    q = np.atleast_2d(q)
    return Rotation.from_quat(q[:, [1, 2, 3, 0]])


def stage_errors(stack: Stack, robot: Robot, plan: StagePlan | None) -> StageErrors | None:
    """End-effector errors against the planned pose over [motion start, end + AFTER_S], and
    the floor the servos' goal resolution sets over the same window."""
    if plan is None:
        return None
    a = truth_arrays(stack)
    t = a["t"]
    pre = (t >= plan.t_start - PRE_S) & (t < plan.t_start)
    win = (t >= plan.t_start) & (t <= plan.t_end + AFTER_S)
    if not pre.any() or not win.any():
        return None
    root_p = a["foot"][pre].mean(axis=0)
    root_r = _wxyz_to_rot(a["quat"][pre][-1]).as_matrix()[0]
    q_plan = plan_at(plan.points, t[win])
    p_ref, r_ref = ee_targets(robot, root_p, root_r, q_plan)
    smap = stack.onboard.config.servo_map
    assert smap is not None  # the node fills in the default map
    p_fl, r_fl = ee_targets(robot, root_p, root_r, goal_resolution(q_plan, smap))
    times, qs = plan_arrays(plan.points)
    lags = joint_lags(t[win], a["q"][win, :6], times, qs[:, :6])
    ee_q = np.array([g.end_effector_quaternion for g, w in zip(stack.truth, win, strict=True) if w])
    pos_err = a["ee"][win] - p_ref
    from scipy.spatial.transform import Rotation

    r_ref_inv = Rotation.from_matrix(r_ref).inv()
    att_err = (_wxyz_to_rot(ee_q) * r_ref_inv).as_rotvec()
    att_floor = (Rotation.from_matrix(r_fl) * r_ref_inv).as_rotvec()
    return StageErrors(
        t=t[win],
        pos_err=pos_err,
        att_err=att_err,
        pos_rmse=np.sqrt(np.mean(pos_err**2, axis=0)),
        att_rmse=np.sqrt(np.mean(att_err**2, axis=0)),
        pos_std=np.std(pos_err, axis=0),
        pos_max=np.abs(pos_err).max(axis=0),
        att_max=np.abs(att_err).max(axis=0),
        root_std=np.std(a["foot"][win], axis=0),
        root_p=root_p,
        root_r=root_r,
        joint_lag_s=lags,
        pos_floor_rmse=np.sqrt(np.mean((p_fl - p_ref) ** 2, axis=0)),
        att_floor_rmse=np.sqrt(np.mean(att_floor**2, axis=0)),
    )


def metrics_of(stack: Stack, errs: dict[str, StageErrors | None]) -> list[Metric]:
    nan = float("nan")
    ms: list[Metric] = []
    for stage, paper in (("flight", PAPER_RMSE_FLIGHT), ("perched", PAPER_RMSE_PERCHED)):
        e = errs[stage]
        ms.append(Metric(f"{stage} stage ran", float(e is not None), 1.0, "", "min", limit=1.0))
        for k, ax in enumerate(AXES):
            v = float(e.pos_rmse[k]) if e else nan
            ms.append(Metric(f"{stage}: EE position RMSE {ax}", v, paper[k], "m", "info"))
        for k, ax in enumerate(ANGLES):
            v = float(e.att_rmse[k]) if e else nan
            ms.append(Metric(f"{stage}: EE attitude RMSE {ax}", v, paper[3 + k], "rad", "info"))
        for k, ax in enumerate(ANGLES):
            # ideal servos on their goals: the plan rounded to encoder counts (module doc)
            v = float(e.att_floor_rmse[k]) if e else nan
            name = f"{stage}: EE attitude RMSE {ax}, floor at one encoder count"
            ms.append(Metric(name, v, paper[3 + k], "rad", "info"))
        ms.append(
            Metric(
                f"{stage}: max |EE position error|",
                float(e.pos_max.max()) if e else nan,
                PAPER_PERCHED_BAND[0] if stage == "perched" else None,
                "m",
                "info",
            )
        )
        ms.append(
            Metric(
                f"{stage}: max |EE attitude error|",
                float(e.att_max.max()) if e else nan,
                PAPER_PERCHED_BAND[1] if stage == "perched" else None,
                "rad",
                "info",
            )
        )
        ms.append(
            Metric(
                f"{stage}: root position std (norm)",
                float(np.linalg.norm(e.root_std)) if e else nan,
                None,
                "m",
                "info",
            )
        )
    fl, pe = errs["flight"], errs["perched"]
    ratio = float(np.linalg.norm(pe.pos_rmse) / np.linalg.norm(fl.pos_rmse)) if fl and pe else nan
    ms.append(
        Metric(
            "perched / flight EE position RMSE (norm)",
            ratio,
            float(np.linalg.norm(PAPER_RMSE_PERCHED[:3]) / np.linalg.norm(PAPER_RMSE_FLIGHT[:3])),
            "ratio",
            "max",
            limit=1.0,
        )
    )
    ms.append(
        Metric(
            "Spinal fail-safes",
            float(sum(stack.spinal.counters.failsafes.values())),
            None,
            "",
            "max",
            limit=0.0,
        )
    )
    return ms


def plot(stack: Stack, errs: dict[str, StageErrors | None]) -> None:
    for stage, label in (("flight", "(A) during flight"), ("perched", "(B) during perching")):
        e = errs[stage]
        if e is None:
            continue
        plot_tracking_errors(
            stack.folder.plot(f"tracking_{stage}_position_error"),
            e.t,
            e.pos_err,
            list(AXES),
            band=PAPER_PERCHED_BAND[0],
            ylabel="m",
            title=f"end-effector position error {label} (Fig. 13)",
        )
        plot_tracking_errors(
            stack.folder.plot(f"tracking_{stage}_attitude_error"),
            e.t,
            e.att_err,
            list(ANGLES),
            band=PAPER_PERCHED_BAND[1],
            ylabel="rad",
            title=f"end-effector attitude error {label} (Fig. 13)",
        )
    a = truth_arrays(stack)
    plot_panels(
        stack.folder.plot("tracking_overview"),
        a["t"],
        [
            ("joints q1-q6 (truth)", {f"q{i + 1}": a["q"][:, i] for i in range(6)}, "rad"),
            (
                "end-effector position (truth)",
                {ax: a["ee"][:, k] for k, ax in enumerate(AXES)},
                "m",
            ),
            ("foot position (truth)", {ax: a["foot"][:, k] for k, ax in enumerate(AXES)}, "m"),
            ("rotor thrust (truth)", {f"rotor{i + 1}": a["thrust"][:, i] for i in range(4)}, "N"),
        ],
        title="tracking: planned joint paths in flight (from q = 0), then perched",
    )


#: upper bound of a run [s]; the run stops 0.5 s after the perched stage (~58 s by default)
DEFAULT_DURATION = 75.0


def run(
    base: str | Path,
    duration: float | None = None,
    seed: int = 0,
    uart: str = "inproc",
    speed: float | None = None,
    motion=None,
    log: bool = True,
    plots: bool = True,
    flight_posture: str = "straight",
    flight_gains: dict | str | None = "posture",
    servo_lead_s: float | None = None,
    servo: ServoParams | None = None,
) -> ScenarioResult:
    """Run the scenario: it stops after the perched stage, or at ``duration``.
    ``motion``: None (the planner's paths, :mod:`rdm.scenarios.tracking_plan`) or hand-chosen
    joint offsets, the same in both stages (e.g. :data:`MOTION`).
    ``flight_gains``: position gains of the flight stage ("posture": ``FLIGHT_STAGE_GAINS``
    of ``flight_posture``; None: the run's configuration; a dict: those).
    ``servo_lead_s``: feed-forward lead of the servo goals (None: the scenarios' identified
    lead, ``common.scenario_servo_lead()``; 0: the plan at its own time, as the paper's
    planner sends it; docs/scenarios.md).
    ``servo``: the simulated joint servos (None: ``StackOptions.servo``, kp 150 N m/rad);
    e.g. stiffer ones show how much of the perched error is their static sag."""
    if servo_lead_s is None:
        servo_lead_s = scenario_servo_lead()
    onboard = onboard_config(servo_lead_s=servo_lead_s)
    opts = sim_stack_options(seed, uart, speed=speed, log=log, onboard=onboard)
    if servo is not None:
        opts = replace(opts, servo=servo)
    robot = Robot.default()
    if flight_gains == "posture":
        flight_gains = FLIGHT_STAGE_GAINS.get(flight_posture)
    if isinstance(flight_gains, str):
        raise ValueError(f"flight_gains={flight_gains!r}: 'posture', None or a dict")
    script = TrackingScript(motion, robot, flight_posture, flight_gains)
    stack = build_stack("tracking", base, opts, script)
    wall = run_stack(stack, DEFAULT_DURATION if duration is None else duration)
    seconds = stack.plant.time
    errs = {s: stage_errors(stack, robot, script.plans.get(s)) for s in ("flight", "perched")}
    if plots:
        plot(stack, errs)
    offsets = script.offsets
    facts: dict[str, Any] = {
        "joint_path": "planner" if offsets is None else "offsets",
        "motion_offsets": None
        if offsets is None
        else [list(map(float, [d, *g])) for d, g in offsets],
        "flight_posture": flight_posture,
        "t_flight_stage": script.t_flight_stage,
        "t_perch": script.t_perch,
        "t_perched_stage": script.t_perched_stage,
        "final_phase": script.phase,
    }
    if flight_gains is not None:
        facts["flight_gains"] = dict(flight_gains)
    if servo is not None:
        facts["servo"] = asdict(servo)
    for stage, e in errs.items():
        if e is not None:
            facts[stage] = {
                "pos_rmse": e.pos_rmse.tolist(),
                "att_rmse": e.att_rmse.tolist(),
                "pos_std": e.pos_std.tolist(),
                "pos_max": e.pos_max.tolist(),
                "att_max": e.att_max.tolist(),
                "root_std": e.root_std.tolist(),
                # what is left of the joints' lag behind the plan (q1..q6; NaN: not moved)
                "joint_lag_s": e.joint_lag_s.tolist(),
                # ideal servos at the wire's goal resolution (module doc)
                "pos_floor_rmse": e.pos_floor_rmse.tolist(),
                "att_floor_rmse": e.att_floor_rmse.tolist(),
            }
    executed = {}
    for stage, e in errs.items():
        plan = script.plans.get(stage)
        if e is not None and plan is not None:
            executed[stage] = stage_execution(stack, robot, plan, e, AFTER_S)
            facts[stage].update(executed[stage])
    metrics = metrics_of(stack, errs) + execution_metrics(executed)
    result = ScenarioResult("tracking", stack, metrics, facts)
    result.errors = errs  # type: ignore[attr-defined]
    result.script = script  # type: ignore[attr-defined]
    return finish(result, seconds, wall)
