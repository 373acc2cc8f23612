"""``flight``: configuration change during flight (paper Sec. VII-A, Fig. 9, Table VI).

Take-off along a ramped setpoint, hover, then move the joints q1..q6 from 0 to
``Q_TARGET`` (Fig. 9 (A)) while flying, hold, and compare the root (foot-frame) tracking
errors with Table VI. The end-effector scatter while hovering with the final configuration
is reported beside Table X's flight column.

Reference. The onboard node controls the CoG (mocap gives it the CoG), but the paper
reports the errors of the root p_foot / eta_foot. The CoG moves in the foot frame when q
changes (about -0.05 / +0.035 / -0.16 m in x / y / z for Fig. 9's change), so the scenario
fixes a root target pose (foot origin ``foot_target``, level, yaw 0) and commands the CoG
setpoint that puts the foot there at the *planned* q(t):
``p_cog,ref(t) = p_foot,ref + cog_in_foot(q_ref(t))`` (eq. (6)'s CoG through the model, foot
axes = CoG-frame axes), with its time derivative as the velocity feed-forward. The metrics
are the errors of the true foot frame (MuJoCo ``base_position`` / ``base_quaternion``)
against that fixed root pose, over the configuration-change window (change start to the
end of the hold).

Joint path: a quintic (minimum-jerk) joint-space trajectory sampled into
:meth:`OnboardNode.set_trajectory` (the node interpolates linearly between the samples and
sends servo targets at 40 Hz). The differential-kinematics planner (:mod:`rdm.planner`)
plans towards an end-effector target under perching constraints; Fig. 9 prescribes joint
angles, so it is not used here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from rdm.model import Robot
from rdm.nodes.onboard_config import OnboardConfig
from rdm.sim import Metric
from rdm.sim.plots import plot_panels, plot_tracking_errors

from .common import (
    ScenarioResult,
    finish,
    roll_pitch,
    run_stack,
    scenario_servo_lead,
    sim_stack_options,
    truth_arrays,
)
from .stack import Stack, build_stack, quaternion_yaw

#: Fig. 9 (A): the joints between links go from 0 to this [rad].
Q_TARGET = (0.5, -0.5, 0.2, 0.8, 0.6, 0.0)
#: Table VI: root position RMSE x, y, z [m] and attitude RMSE roll, pitch, yaw [rad].
PAPER_POSITION_RMSE = (0.057, 0.033, 0.012)
PAPER_ATTITUDE_RMSE = (0.017, 0.036, 0.039)
#: Sec. VII-A: "position and attitude errors became less than +-0.1 m and +-0.05 rad".
PAPER_POSITION_BAND = 0.1
PAPER_ATTITUDE_BAND = 0.05
#: Table X, flight column: end-effector position RMSE x, y, z [m].
PAPER_EE_RMSE_FLIGHT = (0.0552, 0.0759, 0.0688)
#: Joint angles must reach the target within this [rad] (servo error under gravity load).
JOINT_TOLERANCE = 0.05
AXES = ("x", "y", "z")
ANGLES = ("roll", "pitch", "yaw")


@dataclass(frozen=True)
class FlightPlan:
    """Timeline and targets of the scenario (all scenario-level choices, see docs)."""

    arm_at: float = 1.5  # s: the CAN master runs from ~1.4 s
    takeoff_s: float = 3.0  # minimum-jerk climb of the CoG setpoint
    hover_s: float = 2.5  # settle before the change
    change_s: float = 8.0  # duration of the joint trajectory (x error grows with q1 rate)
    hold_s: float = 4.0  # hover with the final configuration
    #: Root (foot origin) target in the world [m]; the CoG hangs ~0.05-0.2 m below it.
    foot_target: tuple[float, float, float] = (0.0, 0.0, 0.8)
    q_target: tuple[float, ...] = Q_TARGET
    trajectory_samples: int = 60

    @property
    def change_start(self) -> float:
        return self.arm_at + self.takeoff_s + self.hover_s

    @property
    def change_end(self) -> float:
        return self.change_start + self.change_s

    @property
    def duration(self) -> float:
        return self.change_end + self.hold_s


DEFAULT_PLAN = FlightPlan()
DEFAULT_DURATION = DEFAULT_PLAN.duration


def min_jerk(s: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Quintic time scaling 10 s^3 - 15 s^4 + 6 s^5 and its derivative d/ds, s in [0, 1]."""
    s = np.clip(np.asarray(s, dtype=float), 0.0, 1.0)
    return s**3 * (10 - 15 * s + 6 * s**2), 30 * s**2 * (1 - s) ** 2


class Reference:
    """The planned joint path and the root / CoG references it implies (model ``robot``)."""

    def __init__(self, plan: FlightPlan, robot: Robot, cog_at_rest: np.ndarray) -> None:
        self.plan = plan
        self.robot = robot
        self.n_q = robot.n_q
        self.q_target = np.asarray(plan.q_target, dtype=float)
        self.foot = np.asarray(plan.foot_target, dtype=float)
        grid = np.linspace(0.0, 1.0, 101)
        # CoG in the foot frame along the path (vectoring joints at 0: they do not move the
        # CoG of the model by more than their own small offsets, and the flight controller
        # sets them anyway)
        self._grid = grid
        self._cog_in_foot = np.array([self.cog_in_foot(self.full_q(g)) for g in grid])
        self.cog_start = self.foot + self._cog_in_foot[0]
        self.cog_at_rest = np.asarray(cog_at_rest, dtype=float)

    def full_q(self, fraction: float) -> np.ndarray:
        """joint_order vector at path fraction ``fraction`` of the change (vectoring = 0)."""
        q = np.zeros(self.n_q)
        q[: self.q_target.size] = fraction * self.q_target
        return q

    def cog_in_foot(self, q: np.ndarray) -> np.ndarray:
        """CoG position in the foot frame at q (model frames with the foot at the origin)."""
        frames = self.robot.evaluate(q)["frames"]
        return (
            np.asarray(frames["cog"], dtype=float)[:3, 3]
            - np.asarray(frames["foot"], dtype=float)[:3, 3]
        )

    def ee_in_foot(self, q: np.ndarray) -> np.ndarray:
        frames = self.robot.evaluate(q)["frames"]
        return (
            np.asarray(frames["end_effector"], dtype=float)[:3, 3]
            - np.asarray(frames["foot"], dtype=float)[:3, 3]
        )

    def fraction(self, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Path fraction and its time derivative [1/s] at time(s) t."""
        p = self.plan
        s, ds = min_jerk((np.asarray(t, dtype=float) - p.change_start) / p.change_s)
        return s, ds / p.change_s

    def q_ref(self, t: np.ndarray | float) -> np.ndarray:
        """Planned q1..q6 at time(s) t, shape (..., 6)."""
        s, _ = self.fraction(t)
        return np.multiply.outer(s, self.q_target)

    def trajectory_points(self) -> list[tuple[float, np.ndarray]]:
        """(node time, full q) samples of the joint path for ``OnboardNode.set_trajectory``."""
        p = self.plan
        times = np.linspace(p.change_start, p.change_end, p.trajectory_samples)
        s, _ = self.fraction(times)
        return [(float(t), self.full_q(float(f))) for t, f in zip(times, s, strict=True)]

    def cog_setpoint(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """CoG position and velocity setpoint at t: take-off ramp, then the CoG of the
        planned configuration under the fixed root target."""
        p = self.plan
        if t < p.arm_at + p.takeoff_s:
            s, ds = min_jerk((t - p.arm_at) / p.takeoff_s)
            d = self.cog_start - self.cog_at_rest
            return self.cog_at_rest + float(s) * d, float(ds) / p.takeoff_s * d
        s, ds_dt = self.fraction(t)
        s, ds_dt = float(s), float(ds_dt)
        offs = np.array([np.interp(s, self._grid, self._cog_in_foot[:, k]) for k in range(3)])
        slope = np.gradient(self._cog_in_foot, self._grid, axis=0)
        dv = np.array([np.interp(s, self._grid, slope[:, k]) for k in range(3)])
        return self.foot + offs, dv * ds_dt


@dataclass
class FlightScript:
    """Arms at ``plan.arm_at``, loads the joint trajectory and streams the CoG setpoint.
    (Spinal's ``desire_coordinate``, the IMU link -> CoG frame rotation that q1 changes, is
    sent by the onboard node itself, ``OnboardConfig.send_desire_coordinate``.)"""

    ref: Reference
    armed: bool = False

    def __call__(self, stack: Stack, now: float) -> None:
        p = self.ref.plan
        if now < p.arm_at:
            return
        pos, vel = self.ref.cog_setpoint(now)
        stack.onboard.set_target(pos, 0.0, vel)
        if not self.armed:
            self.armed = True
            stack.onboard.set_trajectory(self.ref.trajectory_points())
            stack.onboard.arm()


def rotor_margins(robot: Robot, q_target: np.ndarray, n: int = 21) -> dict[str, Any]:
    """Hover thrusts along the straight joint path with every rotor's thrust vertical (the
    vectoring angles found by least squares, as eqs. (33)-(36) do at zero lateral demand),
    from the model's Q-bar (eq. (9)): the static per-rotor margin to ``thrust_max``."""
    from scipy.optimize import least_squares

    limits = np.array([r["thrust_max"] for r in robot.rotors], dtype=float)
    names = list(robot.joint_names)
    vec = [names.index(u[k]) for u in robot.vectoring_units for k in ("roll_joint", "pitch_joint")]
    ab = np.zeros(len(vec))
    worst = np.zeros(robot.n_rotors)
    fractions = np.linspace(0.0, 1.0, n)
    for f in fractions:
        q = np.zeros(robot.n_q)
        q[: q_target.size] = f * q_target

        def residual(x: np.ndarray, q: np.ndarray = q) -> np.ndarray:
            qq = q.copy()
            qq[vec] = x
            d = np.asarray(robot.evaluate(qq)["rotor_directions"], dtype=float)
            return (d - [0.0, 0.0, 1.0]).ravel()

        ab = least_squares(residual, ab).x
        q[vec] = ab
        o = robot.evaluate(q)
        hover = np.linalg.solve(
            np.asarray(o["allocation_bar"], dtype=float), [o["mass"] * 9.80665, 0.0, 0.0, 0.0]
        )
        worst = np.maximum(worst, hover)
    return {
        "max_hover_thrust": worst.tolist(),
        "min_margin": float(np.min(limits - worst)),
        "thrust_max": limits.tolist(),
    }


def _rms(x: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(x**2, axis=0)) if len(x) else np.full(x.shape[1:], np.nan)


def _absmax(x: np.ndarray) -> np.ndarray:
    return np.abs(x).max(axis=0) if len(x) else np.full(x.shape[1:], np.nan)


def analyse(stack: Stack, ref: Reference) -> dict[str, Any]:
    """Root errors, joint outcome, thrusts and the end-effector scatter from ground truth."""
    p = ref.plan
    a = truth_arrays(stack)
    t = a["t"]
    rp = roll_pitch(a["quat"])
    yaw = np.array([quaternion_yaw(q) for q in a["quat"]])
    att = np.column_stack([rp, yaw])
    pos_err = a["foot"] - ref.foot
    q_ref = ref.q_ref(t)
    window = (t >= p.change_start) & (t <= p.duration)
    hold = t >= p.change_end + min(1.0, p.hold_s / 2)
    q_true = a["q"][:, : ref.q_target.size]
    ee_ref = ref.foot + ref.ee_in_foot(ref.full_q(1.0))
    ee = a["ee"][hold]
    airborne = t >= p.arm_at + p.takeoff_s
    return {
        "t": t,
        "pos_err": pos_err,
        "att_err": att,
        "q": q_true,
        "q_ref": q_ref,
        "thrust": a["thrust"],
        "window": window,
        "pos_rmse": _rms(pos_err[window]),
        "att_rmse": _rms(att[window]),
        "pos_max": _absmax(pos_err[window]),
        "att_max": _absmax(att[window]),
        "joint_final_error": _absmax(q_true[-1:] - ref.q_target),
        "joint_tracking_max": _absmax(q_true[window] - q_ref[window]),
        "thrust_max": float(a["thrust"][t >= p.arm_at].max()) if (t >= p.arm_at).any() else 0.0,
        "thrust_min_airborne": float(a["thrust"][airborne].min()) if airborne.any() else math.nan,
        "ee_std": np.std(ee, axis=0) if len(ee) else np.full(3, np.nan),
        "ee_rmse": _rms(ee - ee_ref),
        "ee_ref": ee_ref,
        "min_height": float(a["cog"][airborne, 2].min()) if airborne.any() else math.nan,
    }


def metrics_of(res: dict[str, Any], stack: Stack, margins: dict[str, Any]) -> list[Metric]:
    ms: list[Metric] = []
    for k, ax in enumerate(AXES):
        ms.append(
            Metric(
                f"root position RMSE {ax} (change window)",
                float(res["pos_rmse"][k]),
                PAPER_POSITION_RMSE[k],
                "m",
                "max",
                limit=PAPER_POSITION_BAND,
            )
        )
    for k, ax in enumerate(ANGLES):
        ms.append(
            Metric(
                f"root attitude RMSE {ax} (change window)",
                float(res["att_rmse"][k]),
                PAPER_ATTITUDE_RMSE[k],
                "rad",
                "max",
                limit=PAPER_ATTITUDE_BAND,
            )
        )
    ms += [
        Metric(
            "max |root position error| (change window)",
            float(res["pos_max"].max()),
            PAPER_POSITION_BAND,
            "m",
            "max",
        ),
        Metric(
            "max |root attitude error| (change window)",
            float(res["att_max"].max()),
            PAPER_ATTITUDE_BAND,
            "rad",
            "max",
        ),
        Metric(
            "max |q - q_target| at the end",
            float(res["joint_final_error"].max()),
            None,
            "rad",
            "max",
            limit=JOINT_TOLERANCE,
        ),
        Metric(
            "max rotor thrust (truth)",
            res["thrust_max"],
            None,
            "N",
            "max",
            limit=float(min(margins["thrust_max"])),
        ),
        Metric(
            "min static thrust margin on the path (model)",
            margins["min_margin"],
            None,
            "N",
            "info",
        ),
        Metric(
            "Spinal fail-safes",
            float(sum(stack.spinal.counters.failsafes.values())),
            None,
            "",
            "max",
            limit=0.0,
        ),
    ]
    for k, ax in enumerate(AXES):
        ms.append(
            Metric(
                f"end-effector position RMSE {ax} (hold)",
                float(res["ee_rmse"][k]),
                PAPER_EE_RMSE_FLIGHT[k],
                "m",
                "info",
            )
        )
    for k, ax in enumerate(AXES):
        ms.append(
            Metric(
                f"end-effector position std {ax} (hold)", float(res["ee_std"][k]), None, "m", "info"
            )
        )
    return ms


def plot(stack: Stack, res: dict[str, Any], ref: Reference) -> None:
    t = res["t"]
    p = ref.plan
    plot_panels(
        stack.folder.plot("flight_joints"),
        t,
        [
            (
                "(A) joint angles q (truth)",
                {f"q{j + 1}": res["q"][:, j] for j in range(res["q"].shape[1])},
                "rad",
            ),
            (
                "planned q (minimum-jerk, sent with set_trajectory)",
                {f"q{j + 1} ref": res["q_ref"][:, j] for j in range(res["q_ref"].shape[1])},
                "rad",
            ),
            ("rotor thrust (truth)", {f"rotor{i + 1}": res["thrust"][:, i] for i in range(4)}, "N"),
        ],
        title=f"flight: configuration change {p.change_start:g}-{p.change_end:g} s",
    )
    air = t >= p.arm_at + p.takeoff_s
    plot_tracking_errors(
        stack.folder.plot("flight_root_position_error"),
        t[air],
        res["pos_err"][air],
        ["x", "y", "z"],
        band=PAPER_POSITION_BAND,
        ylabel="m",
        title="(B) root position tracking errors (foot frame, truth)",
    )
    plot_tracking_errors(
        stack.folder.plot("flight_root_attitude_error"),
        t[air],
        res["att_err"][air],
        ["roll", "pitch", "yaw"],
        band=PAPER_ATTITUDE_BAND,
        ylabel="rad",
        title="(C) root attitude tracking errors (foot frame, truth)",
    )


def make_script(plan: FlightPlan, robot: Robot) -> Callable[[Stack, float], None]:
    """The scenario script: nothing before ``plan.arm_at``, then a :class:`FlightScript`
    whose take-off ramp starts where the robot rests (the plant's ground truth at arming).
    ``script.flight_script(stack)`` gives that script (made then if not yet)."""
    made: dict[str, FlightScript] = {}

    def flight_script(stack: Stack) -> FlightScript:
        if "s" not in made:
            cog0 = np.asarray(stack.plant.ground_truth().cog_position, dtype=float)
            made["s"] = FlightScript(Reference(plan, robot, cog0))
        return made["s"]

    def script(stack: Stack, now: float) -> None:
        if now >= plan.arm_at:
            flight_script(stack)(stack, now)

    script.flight_script = flight_script  # type: ignore[attr-defined]
    # The lockstep kernel's parts it reads or changes (rdm.nodes.lockstep_kernel): the
    # plant (the ground truth at arming); the rest is the onboard node.
    script.kernel_touches = ("plant",)  # type: ignore[attr-defined]
    return script


def run(
    base: str | Path,
    duration: float | None = None,
    seed: int = 0,
    uart: str = "inproc",
    speed: float | None = None,
    plan: FlightPlan | None = None,
    log: bool = True,
    plots: bool = True,
    desire_coordinate: bool = True,
) -> ScenarioResult:
    """Run the scenario. ``duration`` longer than the plan extends the hold; shorter cuts
    the run (then the windows are clipped at the end)."""
    plan = plan or DEFAULT_PLAN
    if duration is not None and duration > plan.duration:
        plan = replace(plan, hold_s=duration - plan.change_end)
    seconds = plan.duration if duration is None else duration
    onboard = OnboardConfig(
        send_desire_coordinate=desire_coordinate, servo_lead_s=scenario_servo_lead()
    )
    opts = sim_stack_options(seed, uart, speed=speed, log=log, onboard=onboard)
    robot = Robot.default()
    script = make_script(plan, robot)
    stack = build_stack("flight", base, opts, script)
    wall = run_stack(stack, seconds)
    ref = script.flight_script(stack).ref  # made here if the run stopped before arming
    margins = rotor_margins(robot, ref.q_target)
    res = analyse(stack, ref)
    metrics = metrics_of(res, stack, margins)
    if plots:
        plot(stack, res, ref)
    facts = {
        "plan": asdict(plan),
        "root_target": ref.foot.tolist(),
        "root_position_rmse": res["pos_rmse"].tolist(),
        "root_attitude_rmse": res["att_rmse"].tolist(),
        "root_position_max": res["pos_max"].tolist(),
        "root_attitude_max": res["att_max"].tolist(),
        "joint_final_error": res["joint_final_error"].tolist(),
        "joint_tracking_max": res["joint_tracking_max"].tolist(),
        "thrust_max": res["thrust_max"],
        "thrust_min_airborne": res["thrust_min_airborne"],
        "rotor_margins": margins,
        "ee_std": res["ee_std"].tolist(),
        "ee_rmse": res["ee_rmse"].tolist(),
        "onboard_counts": dict(stack.onboard.counts),
        "desire_coordinate": desire_coordinate,
    }
    result = ScenarioResult("flight", stack, metrics, facts)
    result.analysis = res  # type: ignore[attr-defined]
    return finish(result, seconds, wall)
