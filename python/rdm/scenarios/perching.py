"""``perching-hanging``: approach the ceiling, flight-to-perching transition, joint motion
while perched (paper Sec. VII-B, Fig. 10) in the hanging posture: the foot unit 0.42 m under
the plate, ``PERCH_PARAMS``' eps_z = 8 N. The tracking, push, task, robustness and
process-level experiments perch in this posture and build on this module; ``rdm sim
perching`` (the default scenario) flies the paper's posture,
:mod:`rdm.scenarios.perching_foot_at_plate`.

Phases (simulated time):

1. boot (Neurons enumerate, Spinal calibrates its gyro), arm at ``ARM_AT``;
2. climb to ``APPROACH_Z`` under the perching spot (setpoint ramped at ``CLIMB_SPEED``);
3. approach and perch: the onboard node's perch sequence (``OnboardNode.perch``,
   :mod:`rdm.nodes.onboard_flight`): the CoG setpoint rises at ``APPROACH_SPEED`` until the
   PC's foot sensor reads a normal force above ``FlightLimits.contact_fz`` (what the onboard
   PC can see; no ground truth); then λ_perch of eqs. 37-49 is added (eq. 20) and the altitude
   setpoint is frozen at the contact height;
5. joint motion while perched: q follows ``PERCHED_MOTION`` (smooth joint-space segments);
6. hold.

Metrics (ground truth from MuJoCo, from the perch switch to the end): foot contact kept, slip
of the foot plate, ZMP margin to the plate edge, friction-cone and yaw-friction usage, the
perching QP status counts, and the root attitude. The paper reports these as plots (Fig. 10)
and the statement that contact stability held; the limits here are ours: contact kept,
slip < 1 mm, ZMP inside the plate.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rdm.nodes.onboard_config import OnboardConfig
from rdm.nodes.onboard_flight import FlightMode
from rdm.sim import Metric
from rdm.sim.plots import plot_panels

from .common import (
    ScenarioResult,
    SetpointRamp,
    finish,
    observed,
    roll_pitch,
    run_stack,
    scenario_servo_lead,
    sim_stack_options,
    truth_arrays,
)
from .stack import Stack, build_stack

ARM_AT = 1.5  # s
CLIMB_Z = 0.8  # m: CoG height of the first hover (arm horizontal)
CLIMB_SPEED = 0.3  # m/s
#: Perching posture (q1..q6): the root link hangs straight down from the foot plate, so the
#: foot rotors (the perch rotors of Table VII) are under the plate and λ_perch presses
#: without a moment about it; the middle link leans forward (q2 < 0) to keep the arm rotors
#: off the vertical through the CoG (pitch authority). ASSUMPTION (paper Fig. 10 shows the
#: robot hanging from the ceiling; the angles are ours).
PERCH_POSTURE = (1.5708, -0.5, 0.0, 0.0, 0.0, 0.0)
RECONFIGURE_S = 8.0  # s for q: 0 -> PERCH_POSTURE in flight
RECONFIGURE_Z = 0.95  # m: CoG height after the reconfiguration (the foot is 0.5 m above)
APPROACH_SPEED = 0.08  # m/s
#: Joint motion while perched (Fig. 10 moves the arm while the foot holds): (duration [s],
#: q1..q6 goal). ASSUMPTION: arm pitch and yaw sweeps of the size shown in Fig. 10.
PERCHED_MOTION: tuple[tuple[float, tuple[float, ...]], ...] = (
    (3.0, (1.5708, -0.9, 0.0, 0.5, 0.0, 0.0)),
    (3.0, (1.5708, -0.9, 0.4, 0.5, 0.3, 0.0)),
    (3.0, PERCH_POSTURE),
)
SETTLE_S = 1.5  # s perched before the joint motion starts
PLATE_HALF = (0.05, 0.075)  # m: Table IV foot plate 0.10 x 0.15
MU = (0.9, 0.9, 0.5)  # Table VII friction (x, y, yaw)
#: Scenario name (registry, run folder, summary).
NAME = "perching-hanging"
DEFAULT_DURATION = 30.0
#: Position gains for the hanging posture: y by roll (eq. 31, k_phi_d = 1) as well as by the
#: foot apparatus: with the root link vertical, eqs. (33)-(34) are singular (the apparatus
#: axis is the thrust axis) and the vectoring falls back to the leveling targets. ASSUMPTION
#: (Table V's k_phi_d = 0 is for the horizontal flight of Fig. 9).
POSITION_GAINS: dict = {"k_roll": 1.0, "y_pid": (3.0, 0.5, 4.0)}
#: Roll-based y control (a slow loop: the hanging robot's roll inertia is ~0.3 kg m^2)
#: oscillates with Table V's vectoring y gains (7.0, 0.005, 10.5); these are ours.
#: Minimum normal force ε_z of eq. (39): Table VII's 1.0 N lets the plate rock on an edge in
#: the simulation (the residual pitch moment of the hanging robot is ~0.3-0.5 N m and only
#: F_z is controlled, U_mask = diag[1,0,0,0]); 8 N keeps it flat. ASSUMPTION (docs/scenarios.md).
PERCH_PARAMS: dict = {"epsilon_z": 8.0}
#: Position gains for flying in the hanging posture (over ``POSITION_GAINS``): there the LQI
#: roll and pitch loops are slow (I_xx 0.26 kg m^2 against a 0.07 m rotor lever), and
#: ``POSITION_GAINS``' y PID (3.0, 0.5, 4.0) through roll and Table V's x PID (4.6, 1.5, 7.0)
#: through pitch are linearly unstable (pairs +0.41 +- 1.97j and +0.17 +- 3.68j rad/s,
#: ``flight_envelope.horizontal_loop_poles``). These are the best-damped gains of a scan
#: (damping 0.33 and 0.29; docs/scenarios.md). For tracking's hanging flight stage and, as an
#: option (``PerchTiming.fold_gains``), the hanging approach.
HANGING_FLIGHT_GAINS: dict = {**POSITION_GAINS, "x_pid": (1.0, 0.1, 2.0), "y_pid": (0.3, 0.05, 0.8)}
#: Where along the fold (fraction of its duration) ``PerchTiming.fold_gains`` take over. The
#: linearised loops (``horizontal_loop_poles``) along the cosine fold put the configured y pair
#: in the right half-plane from 0.53 of the fold on (x from 0.72), while the hanging gains
#: stay stable all along; but their slow x loop (P 1.0) cannot follow the CoG's shift during
#: the fold (switched at 0.4 or 0.55 the CoG drifted 0.7-0.9 m in x, seed 0), so they take over
#: once the posture is reached. docs/scenarios.md.
FOLD_GAINS_AT = 1.0
#: The hanging gains for the approach, with a stiffer x integral: (1.5, 1.0, 2.0) is the
#: best-damped x PID of a scan with I >= 1 (damping >= 0.26 from mid-fold on), and it holds
#: the x offset the fold leaves (seed 0: the foot perched 35 mm from the planned point, 119 mm
#: with the configured gains, 204 mm with (1.0, 0.1, 2.0)). docs/scenarios.md.
FOLD_GAINS: dict = {**HANGING_FLIGHT_GAINS, "x_pid": (1.5, 1.0, 2.0)}
#: Spinal's roll/pitch integration is stopped while the IMU link (the root link) turns
#: against the CoG frame faster than this [rad/s] (``OnboardConfig.rp_integration_hold_rate``):
#: Spinal's D term takes the root link's rate, so the fold (q1) otherwise winds the pitch
#: integral up and carries its moment into the perch (docs/scenarios.md, "Where the integral
#: comes from"). ASSUMPTION: 0.02 rad/s, above one Dynamixel tick (1.5 mrad) per 0.1 s
#: window (0.015 rad/s, the node's quantisation of a still joint) and 1/10 of the fold's
#: mean rate (0.2 rad/s), so only planned joint motion holds it.
RP_INTEGRATION_HOLD_RATE = 0.02
EDGE_MM = 1.0  # ZMP within this of the plate edge counts as "on the edge" (tipping)


def onboard_config(**overrides: Any) -> OnboardConfig:
    """The onboard configuration of the hanging-posture experiments (perching, push,
    tracking, tasks): :data:`POSITION_GAINS`, :data:`PERCH_PARAMS` and
    :data:`RP_INTEGRATION_HOLD_RATE` over the defaults; ``overrides`` replace whole fields."""
    kw: dict[str, Any] = {
        "position_gains": dict(POSITION_GAINS),
        "perch_params": dict(PERCH_PARAMS),
        "servo_lead_s": scenario_servo_lead(),
        "rp_integration_hold_rate": RP_INTEGRATION_HOLD_RATE,
    }
    kw.update(overrides)
    return OnboardConfig(**kw)


def leveled(q6: np.ndarray, n_q: int) -> np.ndarray:
    """Full joint vector with the vectoring apparatus levelled for planar arm poses
    (q3 = q5 = 0): alpha_i = 0, beta_1 = -q1, beta_2 = -(q1 + q2) (the pitch joints undo the
    parent link's pitch; joint_order q1..q6, alpha1, beta1, alpha2, beta2)."""
    q = np.zeros(n_q)
    q[:6] = q6
    q[7] = -q6[0]
    q[9] = -(q6[0] + q6[1])
    return q


def joint_path(
    t0: float, q_start: np.ndarray, segments, n_q: int
) -> tuple[list[tuple[float, np.ndarray]], float]:
    """Cosine (zero end-velocity) joint-space segments through the goals, 10 points each."""
    points = [(t0, leveled(q_start, n_q))]
    start, t = np.asarray(q_start, float), t0
    for duration, goal in segments:
        goal = np.asarray(goal, dtype=float)
        for k in range(1, 11):
            s = 0.5 - 0.5 * np.cos(np.pi * k / 10)
            points.append((t + duration * k / 10, leveled(start + s * (goal - start), n_q)))
        start, t = goal, t + duration
    return points, t


@dataclass(frozen=True)
class PerchTiming:
    """The phase machine's set points and durations (defaults: the module constants, i.e.
    the scenario). ``rdm hil perching --quick`` uses :data:`QUICK_TIMING`."""

    arm_at: float = ARM_AT
    climb_z: float = CLIMB_Z
    climb_speed: float = CLIMB_SPEED
    reconfigure_s: float = RECONFIGURE_S
    reconfigure_z: float = RECONFIGURE_Z
    #: seconds after the fold before the approach starts
    reconfigure_wait_s: float = 1.0
    approach_speed: float = APPROACH_SPEED
    #: position gains (``ControlPipeline.set_position_gains``) from ``fold_gains_at`` of the
    #: fold until the perch switch, when the configured gains are restored (default
    #: :data:`FOLD_GAINS`); None: the configured gains throughout (the behaviour before
    #: docs/scenarios.md, whose configured loops are unstable in the hanging posture)
    fold_gains: dict | None = field(default_factory=lambda: dict(FOLD_GAINS))
    #: fraction of the fold's duration at which ``fold_gains`` take over
    fold_gains_at: float = FOLD_GAINS_AT
    #: seconds perched before the arm motion starts (the ZMP-edge metric starts after
    #: :data:`SETTLE_S` whatever this is)
    settle_s: float = SETTLE_S


#: A shorter perching run for the process-level runs in the emulated VM (docs/processes.md):
#: the fold in 4 s instead of 8, ending 0.1 m higher (foot 5 cm under the ceiling instead of
#: 15 cm), approach after 0.5 s. Contact at 9.03 s instead of 14.83 s (seed 0). ASSUMPTION
#: (ours; a 3 s fold with a 0.5 m/s climb perched at 7.4 s but tilted 10.8 deg and rocked the
#: plate on its edge 91 % of the time).
#: The configured gains throughout (``fold_gains=None``): its approach lasts 0.9 s, too short
#: for the hanging instability, and the gain switch's transient (the position integral
#: restarts) just before the contact rocked the plate more (slip 0.060 vs 0.031 mm, min F_z
#: 2.5 vs 6.3 N; docs/scenarios.md).
QUICK_TIMING = PerchTiming(
    reconfigure_s=4.0, reconfigure_z=1.05, reconfigure_wait_s=0.5, fold_gains=None
)


def truth_cog(stack: Any) -> np.ndarray:
    """The CoG position the PC has from motion capture: the plant's ground truth in lockstep
    (the mocap node sends exactly that)."""
    return np.asarray(stack.plant.ground_truth().cog_position, dtype=float)


class PerchingScript:
    """The phase machine of the scenario, run by the stack's script node every 10 ms.

    ``stack`` only needs ``.onboard`` (the onboard node) and whatever ``cog(stack)`` reads:
    the process runner (:mod:`rdm.scenarios.processes`) passes the onboard node's latest mocap."""

    #: The lockstep kernel's parts it reads or changes (``rdm.nodes.lockstep_kernel``): the
    #: plant, through ``cog`` (the ground truth); the rest is the onboard node.
    kernel_touches = ("plant",)

    def __init__(
        self,
        motion=PERCHED_MOTION,
        timing: PerchTiming | None = None,
        cog: Callable[[Any], np.ndarray] = truth_cog,
    ) -> None:
        self.timing = timing or PerchTiming()
        self.cog = cog
        self.phase = "boot"
        self.ramp: SetpointRamp | None = None
        self.motion = motion
        self.t_perch: float | None = None
        self.t_contact: float | None = None
        self.t_motion_end: float | None = None
        self.t_phase_end = 0.0
        self.t_fold: float | None = None
        #: (on, off) simulated times of ``timing.fold_gains`` (off None until the perch)
        self.fold_gains_window: tuple[float, float | None] | None = None
        self.q_plan: list[tuple[float, np.ndarray]] = []
        self._last = 0.0

    def __call__(self, stack: Stack, now: float) -> None:
        dt = now - self._last
        self._last = now
        ob = stack.onboard
        n_q = ob.robot.n_q
        tm = self.timing
        if self.phase == "boot":
            if now >= tm.arm_at:
                self.ramp = SetpointRamp.arm_and_climb(
                    ob, self.cog(stack), tm.climb_speed, tm.climb_z
                )
                self.phase = "climb"
            return
        assert self.ramp is not None
        self.ramp.step(dt)
        if self.phase == "climb" and self.ramp.arrived:
            self.phase = "reconfigure"
            points, self.t_phase_end = joint_path(
                now, np.zeros(6), [(tm.reconfigure_s, PERCH_POSTURE)], n_q
            )
            ob.set_trajectory(points)
            self.q_plan = points
            self.t_fold = now
            goal = self.ramp.position.copy()
            goal[2] = tm.reconfigure_z
            self.ramp.set_goal(goal, (tm.reconfigure_z - tm.climb_z) / tm.reconfigure_s)
        elif self.phase == "reconfigure" and now > self.t_phase_end + tm.reconfigure_wait_s:
            # the node's perch sequence from the script's setpoint (approach, contact, perched)
            refusal = ob.perch(tm.approach_speed)
            self.phase = "approach" if refusal is None else f"perch refused: {refusal}"
        elif self.phase == "approach" and ob.flight.mode is FlightMode.PERCHED:
            self.t_contact = self.t_perch = ob.flight.perched_at
            hold = ob.flight.hold_position
            assert hold is not None
            self.ramp.position = hold
            self.ramp.set_goal(hold.copy())
            if self.fold_gains_window is not None:  # the node switched to its perched gains
                self.fold_gains_window = (self.fold_gains_window[0], self.t_perch)
            self.phase = "settle"
        elif (
            self.phase == "settle" and self.t_perch is not None and now - self.t_perch > tm.settle_s
        ):
            self.phase = "motion"
            points, self.t_motion_end = joint_path(now, np.array(PERCH_POSTURE), self.motion, n_q)
            ob.set_trajectory(points)
            self.q_plan = points
        elif self.phase == "motion" and self.t_motion_end is not None and now > self.t_motion_end:
            self.phase = "hold"
        self._schedule_fold_gains(stack, now)
        ob.set_target(self.ramp.position, 0.0, self.ramp.velocity)

    def _schedule_fold_gains(self, stack: Any, now: float) -> None:
        tm = self.timing
        if (
            tm.fold_gains is not None
            and self.fold_gains_window is None
            and self.t_fold is not None
            and self.t_perch is None
            and now >= self.t_fold + tm.fold_gains_at * tm.reconfigure_s
        ):
            stack.onboard.use_position_gains(tm.fold_gains, "fold")
            self.fold_gains_window = (now, None)

    def phase_gains(self, stack: Any) -> dict:
        """The position gains the phase machine has in effect now: ``timing.fold_gains``
        between their switch and the perch, else the configured ones (what a stage that set
        its own gains restores)."""
        w = self.fold_gains_window
        if w is not None and w[1] is None and self.timing.fold_gains is not None:
            return self.timing.fold_gains
        return stack.onboard.config.position_gains


def run(
    base: str | Path,
    duration: float = DEFAULT_DURATION,
    seed: int = 0,
    uart: str = "inproc",
    speed: float | None = None,
    motion=PERCHED_MOTION,
    log: bool = True,
    timing: PerchTiming | None = None,
    observer: Callable[[Stack, float], None] | None = None,
    **stack_overrides: Any,
) -> ScenarioResult:
    """Run the scenario; ``observer(stack, now)``, if given, is called after the script on
    each of its ticks (a test's probe of the controller's own quantities)."""
    if "onboard" not in stack_overrides:
        stack_overrides["onboard"] = onboard_config()
    opts = sim_stack_options(seed, uart, speed=speed, log=log, **stack_overrides)
    script = PerchingScript(motion, timing)
    stack = build_stack(NAME, base, opts, observed(script, observer))
    wall = run_stack(stack, duration)
    return finish(evaluate(stack, script), duration, wall)


def evaluate(stack: Stack, script: PerchingScript, name: str = NAME) -> ScenarioResult:
    """The perching metrics (module docstring) from MuJoCo's ground truth and the onboard
    status records, the figure ``<name>.png``; a :class:`ScenarioResult` named ``name``
    (perching variants, :mod:`rdm.scenarios.perching_foot_at_plate`, add rows to it)."""
    a = truth_arrays(stack)
    t = a["t"]
    perched = t >= (script.t_perch + 0.5) if script.t_perch is not None else np.zeros_like(t, bool)
    nan = float("nan")
    if perched.any():
        contact = a["contact"][perched]
        force = a["force"][perched]
        torque = a["torque"][perched]
        zmp = a["zmp"][perched]
        slip = a["slip"][perched]
        fz = force[:, 2]
        kept = float(np.mean(contact))
        slip_mm = float(np.max(np.linalg.norm(slip - slip[0], axis=1)) * 1e3)
        with np.errstate(invalid="ignore", divide="ignore"):
            margin = np.min(
                np.stack([PLATE_HALF[0] - np.abs(zmp[:, 0]), PLATE_HALF[1] - np.abs(zmp[:, 1])]),
                axis=0,
            )
            cone = np.maximum(
                np.abs(force[:, 0]) / (MU[0] * fz), np.abs(force[:, 1]) / (MU[1] * fz)
            )
            yaw_use = np.abs(torque[:, 2]) / (MU[2] * fz)
        zmp_margin_mm = float(np.nanmin(margin) * 1e3) if np.isfinite(margin).any() else nan
        # the ZMP criterion from the end of the settling time (the contact transient rocks the
        # plate for ~1 s, as in the paper's Fig. 10 at the transition)
        settled = t[perched] >= script.t_perch + SETTLE_S
        edge_fraction = float(np.mean(~(margin[settled] * 1e3 > EDGE_MM)))
        cone_max = float(np.nanmax(cone)) if np.isfinite(cone).any() else nan
        yaw_max = float(np.nanmax(yaw_use)) if np.isfinite(yaw_use).any() else nan
        fz_min = float(np.min(fz))
    else:
        kept = slip_mm = zmp_margin_mm = cone_max = yaw_max = fz_min = edge_fraction = nan
    rp = roll_pitch(a["quat"])
    statuses: dict[str, int] = {}
    for rec in stack.status:
        s = rec.get("perch_status")
        if s is not None:
            statuses[s] = statuses.get(s, 0) + 1
    solved = statuses.get("solved", 0) + statuses.get("almost_solved", 0)
    total = sum(statuses.values())
    q_err = nan
    if script.q_plan and script.phase == "hold":
        q_goal = script.q_plan[-1][1][:6]
        q_err = float(np.degrees(np.max(np.abs(a["q"][-1, :6] - q_goal))))
    metrics = [
        Metric(
            "perched (foot contact reached)", float(script.t_perch is not None), 1.0, "", "near"
        ),
        Metric("foot contact kept while perched", kept, 1.0, "fraction", "min", limit=1.0),
        Metric("foot slip while perched", slip_mm, None, "mm", "max", limit=1.0),
        Metric("min ZMP margin to the plate edge", zmp_margin_mm, None, "mm", "info"),
        Metric(
            f"time with the ZMP on the plate edge (< {EDGE_MM:g} mm)",
            edge_fraction,
            None,
            "fraction",
            "max",
            limit=0.05,
        ),
        Metric("max friction-cone usage |F_t|/(mu F_z)", cone_max, None, "", "max", limit=1.0),
        Metric("max yaw-friction usage |M_z|/(mu_z F_z)", yaw_max, None, "", "max", limit=1.0),
        Metric("min normal force while perched", fz_min, 1.0, "N", "min"),
        Metric(
            "perching QP solved ticks",
            solved / total if total else nan,
            1.0,
            "fraction",
            "min",
            limit=0.99,
        ),
        Metric("joint goal reached after the motion", q_err, None, "deg", "max", limit=5.0),
        Metric(
            "max |roll|,|pitch| after take-off",
            float(np.degrees(np.abs(rp[t > ARM_AT]).max())) if (t > ARM_AT).any() else nan,
            None,
            "deg",
            "max",
            limit=20.0,
        ),
    ]
    facts = {
        "t_contact": script.t_contact,
        "t_perch": script.t_perch,
        "final_phase": script.phase,
        "perch_status_counts": statuses,
        "fold_gains_window": script.fold_gains_window,
    }
    _plots(stack, a, rp, name)
    return ScenarioResult(name, stack, metrics, facts)


def _plots(stack: Stack, a: dict, rp: np.ndarray, name: str) -> None:
    t = a["t"]
    fz = a["force"][:, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        cone = np.abs(a["force"][:, 0:2]).max(axis=1) / (MU[0] * fz)
        yaw = np.abs(a["torque"][:, 2]) / (MU[2] * fz)
    plot_panels(
        stack.folder.plot(name),
        t,
        [
            ("CoG position", {"x": a["cog"][:, 0], "y": a["cog"][:, 1], "z": a["cog"][:, 2]}, "m"),
            ("rotor thrust", {f"rotor{i + 1}": a["thrust"][:, i] for i in range(4)}, "N"),
            ("foot force", {"Fx": a["force"][:, 0], "Fy": a["force"][:, 1], "Fz": fz}, "N"),
            (
                "foot moment",
                {"Mx": a["torque"][:, 0], "My": a["torque"][:, 1], "Mz": a["torque"][:, 2]},
                "N m",
            ),
            ("contact usage", {"friction cone": cone, "yaw friction": yaw}, "ratio"),
            ("ZMP", {"x": a["zmp"][:, 0], "y": a["zmp"][:, 1]}, "m"),
            ("joints q1-q6", {f"q{i + 1}": a["q"][:, i] for i in range(6)}, "rad"),
            ("attitude", {"roll": np.degrees(rp[:, 0]), "pitch": np.degrees(rp[:, 1])}, "deg"),
        ],
        title=f"{name}: approach, transition, joint motion (Fig. 10)",
    )
