"""``tracking``: end-effector pose tracking in flight vs perched (paper Sec. VII-C-2, Fig. 13,
Table X).

One run, built on the perching scenario's phases (the stages of
:class:`rdm.scenarios.push.StagedPerchingScript`): climb, fold in flight to the hanging
posture, then

1. **flight stage**: hovering in the hanging posture, the joints follow a planned joint path
   (``MOTION``, feed-forward through :meth:`OnboardNode.set_trajectory`, as the paper's
   "joint angles are determined by a feed-forward motion planner") while the root is held by
   the position/attitude feedback: the CoG setpoint is streamed so that the *planned*
   configuration puts the root at a fixed point, ``p_cog,ref(t) = p_root,ref +
   cog_in_foot(q_plan(t))`` (the flight scenario's reference);
2. approach, perch, settle; **perched stage**: the same joint path with the root on the
   ceiling (the perching scenario's own "motion" phase).

Error definition (both stages alike). The end-effector target is where the planned
configuration puts the end effector with the root where it was when the motion started:
``T_ee,ref(t) = T_root(t0) T_foot->ee(q_plan(t))`` (``rdm.model`` forward kinematics, root
pose = true foot pose averaged over the 0.5 s before the motion). Position error = true EE
position (MuJoCo) - target; attitude error = ZYX roll/pitch/yaw of the true EE frame minus the
target's (wrapped). RMSE over the motion and 1 s after it, beside Table X.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rdm.model import Robot
from rdm.sim import Metric
from rdm.sim.plots import plot_panels, plot_tracking_errors

from .common import ScenarioResult, finish, sim_onboard_config, sim_stack_options, truth_arrays
from .perching import PERCH_PARAMS, PERCH_POSTURE, PERCHED_MOTION, POSITION_GAINS, joint_path
from .push import StagedPerchingScript
from .stack import Stack, build_stack

AXES = ("x", "y", "z")
ANGLES = ("roll", "pitch", "yaw")
#: Table X: end-effector RMSE x, y, z [m], roll, pitch, yaw [rad]; flight and perched.
PAPER_RMSE_FLIGHT = (0.0552, 0.0759, 0.0688, 0.0019, 0.0003, 0.0004)
PAPER_RMSE_PERCHED = (0.00320, 0.0286, 0.0191, 0.0002, 0.0001, 0.0005)
#: The joint path (duration [s], q1..q6 goal) segments, from and back to ``PERCH_POSTURE``:
#: the perching scenario's arm pitch and yaw sweeps (ASSUMPTION: Fig. 13's motion is not given).
MOTION = PERCHED_MOTION
AFTER_S = 1.0  # s after the motion inside the error window
PRE_S = 0.5  # s before the motion over which the root pose is averaged


def _ends_at_posture(motion) -> tuple:
    """The motion, with a return segment to ``PERCH_POSTURE`` if it ends elsewhere (the flight
    stage must leave the robot in the posture the approach starts from)."""
    motion = tuple(motion)
    if not motion or not np.allclose(motion[-1][1], PERCH_POSTURE):
        motion = (*motion, (3.0, PERCH_POSTURE))
    return motion


def _frames(robot: Robot, q: np.ndarray) -> dict[str, np.ndarray]:
    fr = robot.evaluate(q)["frames"]
    return {k: np.asarray(fr[k], dtype=float) for k in ("foot", "cog", "end_effector")}


def plan_at(points: list[tuple[float, np.ndarray]], t: np.ndarray) -> np.ndarray:
    """Planned full q at times ``t``: linear between the samples, held outside (as the node)."""
    times = np.array([p[0] for p in points])
    qs = np.array([p[1] for p in points])
    return np.column_stack([np.interp(t, times, qs[:, j]) for j in range(qs.shape[1])])


class TrackingScript(StagedPerchingScript):
    """Flight stage: the joint path with the root held by streaming the CoG setpoint; perched
    stage: the parent's motion phase does the same path, then 0.5 s of hold."""

    def __init__(self, motion, robot: Robot) -> None:
        self.track_motion = _ends_at_posture(motion)
        self.motion_s = sum(d for d, _ in self.track_motion)
        super().__init__(self.motion_s + AFTER_S + 0.5, 0.5, motion=self.track_motion)
        self.robot = robot
        self.flight_plan: list[tuple[float, np.ndarray]] = []
        self.perched_plan: list[tuple[float, np.ndarray]] = []
        self._cog_in_foot: np.ndarray | None = None
        self._root_ref: np.ndarray | None = None

    def flight_tick(self, stack: Stack, now: float, s: float) -> None:
        assert self.ramp is not None
        if not self.flight_plan:
            start = now + PRE_S  # the root pose is averaged over the first PRE_S
            n_q = stack.onboard.robot.n_q
            head, _ = joint_path(start, np.array(PERCH_POSTURE), self.track_motion, n_q)
            self.flight_plan = [(now, head[0][1]), *head]
            stack.onboard.set_trajectory(self.flight_plan)
            cogs = []
            for _, q in self.flight_plan:
                f = _frames(self.robot, q)
                cogs.append(f["cog"][:3, 3] - f["foot"][:3, 3])
            self._cog_in_foot = np.array(cogs)
            self._root_ref = self.ramp.position - self._cog_in_foot[0]
        assert self._cog_in_foot is not None and self._root_ref is not None
        times = np.array([p[0] for p in self.flight_plan])
        c = self._cog_in_foot
        pos = self._root_ref + np.array([np.interp(now, times, c[:, k]) for k in range(3)])
        k = int(np.clip(np.searchsorted(times, now) - 1, 0, len(times) - 2))
        vel = (c[k + 1] - c[k]) / (times[k + 1] - times[k]) if times[0] <= now < times[-1] else 0
        stack.onboard.set_target(pos, 0.0, np.zeros(3) + vel)

    def perched_tick(self, stack: Stack, now: float, s: float) -> None:
        if not self.perched_plan:
            self.perched_plan = list(self.q_plan)


@dataclass
class StageErrors:
    t: np.ndarray
    pos_err: np.ndarray  # (n, 3) [m]
    att_err: np.ndarray  # (n, 3) [rad]
    pos_rmse: np.ndarray
    att_rmse: np.ndarray
    pos_max: np.ndarray
    att_max: np.ndarray
    root_std: np.ndarray  # true foot position std over the window [m]


def _zyx(rot: np.ndarray) -> np.ndarray:
    """ZYX roll, pitch, yaw of (n, 3, 3) rotation matrices."""
    roll = np.arctan2(rot[:, 2, 1], rot[:, 2, 2])
    pitch = np.arcsin(np.clip(-rot[:, 2, 0], -1, 1))
    yaw = np.arctan2(rot[:, 1, 0], rot[:, 0, 0])
    return np.stack([roll, pitch, yaw], axis=1)


def _quat_to_mat(q: np.ndarray) -> np.ndarray:
    """(n, 4) (w, x, y, z) unit quaternions -> (n, 3, 3)."""
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def stage_errors(
    stack: Stack, robot: Robot, plan: list[tuple[float, np.ndarray]], motion_s: float
) -> StageErrors | None:
    """End-effector errors against the planned pose over [motion start, end + AFTER_S]."""
    if not plan:
        return None
    a = truth_arrays(stack)
    t = a["t"]
    t0 = plan[-1][0] - motion_s  # first sample of the motion itself
    pre = (t >= t0 - PRE_S) & (t < t0)
    win = (t >= t0) & (t <= t0 + motion_s + AFTER_S)
    if not pre.any() or not win.any():
        return None
    root_p = a["foot"][pre].mean(axis=0)
    root_r = _quat_to_mat(a["quat"][pre][-1:])[0]
    q = plan_at(plan, t[win])
    p_ref = np.zeros((q.shape[0], 3))
    r_ref = np.zeros((q.shape[0], 3, 3))
    for i, qi in enumerate(q):
        f = _frames(robot, qi)
        rel = np.linalg.solve(f["foot"], f["end_effector"])  # foot -> EE
        p_ref[i] = root_p + root_r @ rel[:3, 3]
        r_ref[i] = root_r @ rel[:3, :3]
    ee_q = np.array([g.end_effector_quaternion for g, w in zip(stack.truth, win, strict=True) if w])
    pos_err = a["ee"][win] - p_ref
    att_err = _zyx(_quat_to_mat(ee_q)) - _zyx(r_ref)
    att_err = (att_err + np.pi) % (2 * np.pi) - np.pi
    return StageErrors(
        t=t[win],
        pos_err=pos_err,
        att_err=att_err,
        pos_rmse=np.sqrt(np.mean(pos_err**2, axis=0)),
        att_rmse=np.sqrt(np.mean(att_err**2, axis=0)),
        pos_max=np.abs(pos_err).max(axis=0),
        att_max=np.abs(att_err).max(axis=0),
        root_std=np.std(a["foot"][win], axis=0),
    )


def metrics_of(errs: dict[str, StageErrors | None]) -> list[Metric]:
    nan = float("nan")
    ms: list[Metric] = []
    for stage, paper in (("flight", PAPER_RMSE_FLIGHT), ("perched", PAPER_RMSE_PERCHED)):
        e = errs[stage]
        for k, ax in enumerate(AXES):
            ms.append(
                Metric(
                    f"{stage}: end-effector position RMSE {ax}",
                    float(e.pos_rmse[k]) if e else nan,
                    paper[k],
                    "m",
                    "info",
                )
            )
        for k, ax in enumerate(ANGLES):
            ms.append(
                Metric(
                    f"{stage}: end-effector attitude RMSE {ax}",
                    float(e.att_rmse[k]) if e else nan,
                    paper[3 + k],
                    "rad",
                    "info",
                )
            )
        ms.append(
            Metric(
                f"{stage}: max |EE position error|",
                float(e.pos_max.max()) if e else nan,
                0.1 if stage == "flight" else 0.05,
                "m",
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
            band=0.05,
            ylabel="m",
            title=f"end-effector position error {label} (Fig. 13)",
        )
        plot_tracking_errors(
            stack.folder.plot(f"tracking_{stage}_attitude_error"),
            e.t,
            e.att_err,
            list(ANGLES),
            band=0.1,
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
        title="tracking: the same joint path in flight, then perched",
    )


#: upper bound of a run [s]; the run stops 1 s after the perched motion (~38 s by default)
DEFAULT_DURATION = 50.0


def run(
    base: str | Path,
    duration: float | None = None,
    seed: int = 0,
    uart: str = "inproc",
    speed: float | None = None,
    motion=MOTION,
    log: bool = True,
    plots: bool = True,
) -> ScenarioResult:
    """Run the scenario: it stops after the perched stage, or at ``duration``."""
    onboard = sim_onboard_config(
        position_gains=dict(POSITION_GAINS), perch_params=dict(PERCH_PARAMS)
    )
    opts = sim_stack_options(seed, uart, speed=speed, log=log, onboard=onboard)
    robot = Robot.default()
    script = TrackingScript(motion, robot)
    stack = build_stack("tracking", base, opts, script)
    t0 = time.perf_counter()
    try:
        stack.loop.run(DEFAULT_DURATION if duration is None else duration)
    finally:
        stack.close()
    seconds = stack.plant.time
    wall = time.perf_counter() - t0
    errs = {
        "flight": stage_errors(stack, robot, script.flight_plan, script.motion_s),
        "perched": stage_errors(stack, robot, script.perched_plan, script.motion_s),
    }
    if plots:
        plot(stack, errs)
    facts: dict[str, Any] = {
        "motion": [list(map(float, [d, *g])) for d, g in script.track_motion],
        "t_flight_stage": script.t_flight_stage,
        "t_perch": script.t_perch,
        "final_phase": script.phase,
    }
    for stage, e in errs.items():
        if e is not None:
            facts[stage] = {
                "pos_rmse": e.pos_rmse.tolist(),
                "att_rmse": e.att_rmse.tolist(),
                "pos_max": e.pos_max.tolist(),
                "att_max": e.att_max.tolist(),
                "root_std": e.root_std.tolist(),
            }
    result = ScenarioResult("tracking", stack, metrics_of(errs), facts)
    result.errors = errs  # type: ignore[attr-defined]
    result.script = script  # type: ignore[attr-defined]
    return finish(result, seconds, wall)
