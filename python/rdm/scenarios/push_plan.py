"""The ``push`` scenario's plan: what is pushed, how hard, when (paper Sec. VII-C-1, Tables
VIII-IX).

Table VIII's and IX's values, the fractions of them the simulated robot is pushed with, the
perched push posture and filter, the flight stage's gains, the push-then-pull profile and
:class:`PushPlan` (timing, forces, options) with the stage windows and the per-tick stage
record (:class:`StageLog`) the analysis reads. The run itself (scripts, analysis, metrics,
plots) is :mod:`rdm.scenarios.push`.

The force is applied to MuJoCo's end-effector body (``Plant.apply_body_wrench``) at the
end-effector frame origin, i.e. at the end-effector wrench sensor, along the end-effector
frame's axes (Table VIII gives forces "in the end-effector coordinate"), re-aimed every 10 ms
as the end effector turns. Nothing in the stack measures or compensates it ("without the
external wrench observation control"): the onboard node sees only the foot sensor, the IMU
and the mocap. Profile per axis (one push and one pull): ``F(s) = A sin(2 pi s) sin^2(pi s)``,
s in [0, 1] over ``push_s``, smooth (zero value and slope at both ends); ``A`` makes the
window's mean |F| equal to Table VIII's average times ``scale``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

AXES = ("x", "y", "z")
#: Table VIII: average and peak |F_ee| [N] (end-effector coordinate), flight and perched.
PAPER_FLIGHT_FORCE_AVG = (3.75, 1.76, 3.42)
PAPER_FLIGHT_FORCE_PEAK = (7.48, 2.62, 6.07)
PAPER_PERCHED_FORCE_AVG = (25.1, 8.4, 16.8)
PAPER_PERCHED_FORCE_PEAK = (41.8, 15.9, 32.1)
#: Table IX: standard deviation of the foot position [m], flight and perched.
PAPER_FOOT_STD_FLIGHT = (0.0416, 0.0281, 0.0220)
PAPER_FOOT_STD_PERCHED = (0.0009, 0.0011, 0.0004)
#: Fractions of Table VIII's averages the simulated robot holds (seed 0, measured, see
#: docs/scenarios.md). Flight, per axis x, y, z, arm straight (q = 0), FLIGHT_GAINS: x holds
#: the paper's force; a y push at the end effector (0.57 m ahead of the CoG) is a yaw moment
#: the rotors' drag cannot hold (1.0 saturates the foot/arm rotors, roll flips); a z push is a
#: pitch moment of 0.57 m x F_z against ~2.7 N m of pitch authority (arm rotors hover at
#: 3.8 N, 1 N minimum): 1.0 peels the arm rotors to their minimum and the robot flips.
#: Perched, per axis, in the push posture PERCHED_POSTURE with the 5 Hz foot-wrench filter
#: (PERCHED_CUTOFF_HZ): pushes whose peak stays within 80 % of the perching QP's static
#: ceiling there (perch rotors only, push_ceiling.ceiling: 1.6 / 6.1 / 3.5 N peak, i.e.
#: 3.1 / 36 / 10 % of Table VIII's averages), y kept at 0.2 (0.3 and 0.4 lost contact on
#: seed 1): the contact conditions the paper's controller enforces (eqs. 39-44) can hold
#: them, and the plate does not rock (foot z std 0.02 mm). Beyond the ceiling,
#: PERCHED_SCALE_BEYOND_CEILING is held too (slip 0.14 mm, contact
#: kept) but the x push rocks the plate on its edge by up to 80 mrad (foot z std 0.8 mm,
#: twice Table IX's); docs/scenarios.md. (Hanging posture, 1 Hz: 0.05 held, 0.1 slipped
#: 1.5 mm, 0.2 peeled, 1.0 fell.)
FLIGHT_SCALE = (1.0, 0.3, 0.4)
PERCHED_SCALE = (0.025, 0.2, 0.08)
PERCHED_SCALE_BEYOND_CEILING = (0.1, 0.2, 0.15)
#: Perched push posture (q1..q6), reached by a 4 s joint motion after the perch settled:
#: the middle link horizontal (q2 = -pi/2) and the tool turned up (q4 = -pi/2), so the end
#: effector is 0.2 m below the plate (0.4 m out) instead of 1.02 m (hanging posture): the
#: moment of a force there about the plate, which only F_z x H resists (eqs. 42-44), is
#: 5x smaller for y. ASSUMPTION (the paper does not give Fig. 12's posture).
PERCHED_POSTURE = (1.5708, -1.5708, 0.0, -1.5708, 0.0, 0.0)
#: Cutoff of the perching QP's foot-wrench filter in the push runs [Hz]. The paper's 1 Hz
#: (Sec. VII-B, the perching scenario's) lags the 0.4 Hz push-pull: the QP raises F_z only
#: after the plate is already on its edge; 5 Hz lets it follow (10 Hz slipped in y).
PERCHED_CUTOFF_HZ = 5.0
#: Position gains of the flight stage (q = 0): Table V (the flight scenario's) except the x
#: PID. With Table V's weights the LQI pitch loop has a slow pole at 2.8 rad/s (its limit
#: for a stiff actuator: sqrt(600/80)); Table V's x PID (4.6, 1.5, 7.0) through it leaves the
#: x/pitch mode at 4 rad/s with damping 0.085 (0.02 with 30 ms of loop delay; at most 0.24
#: for any inertia, docs/scenarios.md), and under the paper's x push
#: it asks for a 1 rad pitch target: Spinal's commanded-tilt fail-safe. (1.0, 0.1, 2.0) is
#: damped (0.36). ASSUMPTION (docs/scenarios.md); ``PushPlan(flight_gains={})`` is Table V.
FLIGHT_GAINS: dict = {"x_pid": (1.0, 0.1, 2.0)}
EE_BODY = "end_effector"
EE_SENSOR = "end_effector_wrench"


def profile(s: np.ndarray | float) -> np.ndarray:
    """Unit push-then-pull shape sin(2 pi s) sin^2(pi s) on s in [0, 1], zero outside."""
    s = np.asarray(s, dtype=float)
    inside = (s >= 0.0) & (s <= 1.0)
    return np.where(inside, np.sin(2 * np.pi * s) * np.sin(np.pi * s) ** 2, 0.0)


_GRID = np.linspace(0.0, 1.0, 20001)
#: mean |profile| and max |profile| over one window (for the amplitude and the peak)
PROFILE_MEAN_ABS = float(np.mean(np.abs(profile(_GRID))))
PROFILE_PEAK = float(np.max(np.abs(profile(_GRID))))


@dataclass(frozen=True)
class PushPlan:
    """Timing and size of the pushes (scenario-level choices, see docs/scenarios.md)."""

    quiet_s: float = 2.5  # no-push baseline window before the first push of a stage
    push_s: float = 2.5  # one push + pull along one axis (the paper looks at 2-2.5 s)
    gap_s: float = 1.5  # rest between axes
    #: mean |F_ee| per axis in flight / perched [N]: Table VIII's averages scaled to what the
    #: simulated robot holds (FLIGHT_SCALE, PERCHED_SCALE; docs/scenarios.md)
    flight_force: tuple[float, float, float] = tuple(
        k * f for k, f in zip(FLIGHT_SCALE, PAPER_FLIGHT_FORCE_AVG, strict=True)
    )  # type: ignore[assignment]
    perched_force: tuple[float, float, float] = tuple(
        k * f for k, f in zip(PERCHED_SCALE, PAPER_PERCHED_FORCE_AVG, strict=True)
    )  # type: ignore[assignment]
    axes: tuple[int, ...] = (0, 1, 2)
    flight: bool = True  # run the flight stage
    #: the flight stage hovers this much lower than the approach height [m] (a pull along
    #: the end-effector z lifts the robot: keep the foot clear of the 1.6 m ceiling)
    flight_drop: float = 0.0
    move_s: float = 3.0  # s to settle (go down) before the quiet window, and after the pushes
    #: where the flight stage is: "climb" (arm straight, q = 0, as the flight scenario) or
    #: "reconfigure" (in the hanging posture, after the fold)
    flight_after: str = "climb"
    #: onboard position gains during the flight stage (over Table V, the core defaults); the
    #: perching configuration's gains (perching.POSITION_GAINS) are restored after it
    flight_gains: dict = field(default_factory=lambda: dict(FLIGHT_GAINS))
    #: perched push posture q1..q6, reached by a joint motion of ``posture_s`` after the perch
    #: settled (None: stay in the hanging posture ``PERCH_POSTURE``)
    perched_posture: tuple[float, ...] | None = PERCHED_POSTURE
    posture_s: float = 4.0
    #: overrides of the perching QP's parameters for the whole run (over
    #: ``perching.PERCH_PARAMS``, e.g. ``{"epsilon_z": 12.0}``) and the foot-wrench filter's
    #: cutoff [Hz] (``OnboardConfig.perch_cutoff_hz``, whole run; the paper's Sec. VII-B and
    #: the perching scenario: 1 Hz)
    perch_params: dict = field(default_factory=dict)
    perch_cutoff_hz: float = PERCHED_CUTOFF_HZ
    #: ``OnboardConfig.rp_integration_hold_rate`` of the run [rad/s] ("default": the
    #: perching configuration's, ``perching.RP_INTEGRATION_HOLD_RATE``; None: never held)
    rp_integration_hold_rate: float | str | None = "default"

    def stage_s(self) -> float:
        return self.quiet_s + len(self.axes) * (self.push_s + self.gap_s)

    def flight_stage_s(self) -> float:
        return self.move_s + self.stage_s() + self.move_s

    def window(self, k: int) -> tuple[float, float]:
        """(start, end) of the push along axis index ``k`` of ``axes``, from stage start."""
        t0 = self.quiet_s + k * (self.push_s + self.gap_s)
        return t0, t0 + self.push_s

    def force(self, s: float, means: tuple[float, float, float]) -> np.ndarray:
        """End-effector-frame force [N] at ``s`` seconds into a stage."""
        f = np.zeros(3)
        for k, ax in enumerate(self.axes):
            t0, _ = self.window(k)
            amp = means[ax] / PROFILE_MEAN_ABS
            f[ax] += amp * float(profile((s - t0) / self.push_s))
        return f

    def stage_force(self, s: float, stage: str) -> np.ndarray:
        """End-effector-frame force [N] at ``s`` seconds into ``stage`` ("flight" or
        "perched"): :meth:`force` with the stage's means."""
        return self.force(s, self.flight_force if stage == "flight" else self.perched_force)


DEFAULT_PLAN = PushPlan()


@dataclass
class StageLog:
    """What the script records at each tick of a stage (10 ms)."""

    t: list[float] = field(default_factory=list)
    applied: list[np.ndarray] = field(default_factory=list)  # end-effector frame [N]
    sensor_force: list[np.ndarray] = field(default_factory=list)  # MuJoCo EE sensor [N]
    sensor_torque: list[np.ndarray] = field(default_factory=list)
    perch_thrust: list[np.ndarray] = field(default_factory=list)  # λ_perch commanded [N]
    #: the onboard node's cumulative perching-QP status counts (``perch_<status>``) per tick
    perch_counts: list[dict] = field(default_factory=list)

    def arrays(self) -> dict[str, np.ndarray]:
        """The record as arrays: t, applied, force, torque (N x 3), perch_thrust."""
        return {
            "t": np.array(self.t),
            "applied": np.array(self.applied).reshape(-1, 3),
            "force": np.array(self.sensor_force).reshape(-1, 3),
            "torque": np.array(self.sensor_torque).reshape(-1, 3),
            "perch_thrust": np.array(self.perch_thrust).reshape(len(self.t), -1)
            if self.t
            else np.zeros((0, 4)),
        }


def stage_windows(plan: PushPlan, t_stage: float | None) -> dict[str, Any] | None:
    """Absolute quiet window, push sequence window and per-axis windows of a stage."""
    if t_stage is None:
        return None
    first = plan.window(0)[0]
    last = plan.window(len(plan.axes) - 1)[1]
    return {
        "quiet": (t_stage + first - plan.push_s, t_stage + first),
        "pushes": (t_stage + first, t_stage + last),
        "axes": {
            plan.axes[k]: tuple(t_stage + w for w in plan.window(k)) for k in range(len(plan.axes))
        },
    }
