"""Shared pieces of the scenarios: the default simulated-robot tuning, the run result, the
ground-truth arrays and the metrics/plots/summary writer."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from rdm.nodes.onboard_config import OnboardConfig, check_servo_lead
from rdm.output_files import write_atomic
from rdm.sim import Metric, format_metrics_table, write_summary

from .stack import SIM_SERVO_LEAD_S, Stack, StackOptions

_PROGRESS: ContextVar[Callable[[Any, float], None] | None] = ContextVar(
    "rdm_sim_progress", default=None
)


@contextmanager
def progress_to(stream: TextIO, duration: float) -> Iterator[None]:
    """Every stack built inside the block reports once per simulated second on ``stream``:
    simulated time, the onboard state, perching on/off and the speed so far."""
    start = time.perf_counter()

    def report(stack: Any, now: float) -> None:
        wall = max(time.perf_counter() - start, 1e-9)
        ob = stack.onboard
        perch = "perched" if ob.control.perching else "flight"
        stream.write(
            f"\r  {now:6.1f} / {duration:g} s simulated  {ob.state.value:<8} {perch:<7} "
            f"{now / wall:5.2f}x real time"
        )
        stream.flush()

    token = _PROGRESS.set(report)
    try:
        yield
    finally:
        _PROGRESS.reset(token)
        stream.write("\n")
        stream.flush()


_SERVO_LEAD: ContextVar[float | None] = ContextVar("rdm_sim_servo_lead", default=None)


def scenario_servo_lead(default: float = SIM_SERVO_LEAD_S) -> float:
    """The servo-goal lead [s] a scenario configures (``OnboardConfig.servo_lead_s``): the
    value of an enclosing :func:`servo_lead` block, else the scenario's ``default``
    (:data:`SIM_SERVO_LEAD_S`)."""
    value = _SERVO_LEAD.get()
    return default if value is None else value


@contextmanager
def servo_lead(seconds: float) -> Iterator[None]:
    """Every scenario run inside the block sends its servo goals ``seconds`` ahead of the
    planned joint path (0 = the paper's feed-forward; ``rdm sim --servo-lead``)."""
    token = _SERVO_LEAD.set(check_servo_lead(seconds))
    try:
        yield
    finally:
        _SERVO_LEAD.reset(token)


_RECORD_ONBOARD: ContextVar[bool] = ContextVar("rdm_sim_record_onboard", default=False)
#: Where :func:`record_onboard` puts the recording, inside the run folder.
ONBOARD_RECORDING = "onboard"


@contextmanager
def record_onboard() -> Iterator[None]:
    """Every stack built inside the block records its onboard node into the run folder's
    :data:`ONBOARD_RECORDING` (``rdm sim --record-onboard``; ``rdm replay RUN``)."""
    token = _RECORD_ONBOARD.set(True)
    try:
        yield
    finally:
        _RECORD_ONBOARD.reset(token)


def sim_stack_options(seed: int, uart: str, **overrides: Any) -> StackOptions:
    """Stack options of the scenarios (assumptions in docs/sim.md and :class:`StackOptions`).
    Inside :func:`progress_to` the stack reports its progress; inside :func:`record_onboard`
    it records its onboard node."""
    kw: dict[str, Any] = {"seed": seed, "uart": uart, "progress": _PROGRESS.get()}
    if _RECORD_ONBOARD.get():
        kw["record_onboard"] = ONBOARD_RECORDING
    kw.update(overrides)
    if "onboard" not in kw:
        # the paper's Table V gains (the core defaults); joint goals lead the plan by the
        # simulated servos' identified lag
        kw["onboard"] = OnboardConfig(servo_lead_s=scenario_servo_lead())
    return StackOptions(**kw)


@dataclass
class ScenarioResult:
    """What a scenario run returns."""

    name: str
    stack: Stack
    metrics: list[Metric]
    facts: dict[str, Any] = field(default_factory=dict)
    #: the scenario's script object when it keeps logs of its own (tasks: per-tick contacts)
    script: Any = None

    @property
    def folder(self) -> Path:
        return self.stack.folder.root

    @property
    def all_passed(self) -> bool:
        return all(m.passed is not False for m in self.metrics)


class _Observed:
    """A scenario script followed by an observer, declaring the script's kernel parts."""

    def __init__(
        self, script: Callable[[Stack, float], None], observer: Callable[[Stack, float], None]
    ) -> None:
        self.script, self.observer = script, observer
        self.kernel_touches = getattr(script, "kernel_touches", None)

    def __call__(self, stack: Stack, now: float) -> None:
        self.script(stack, now)
        self.observer(stack, now)


def observed(
    script: Callable[[Stack, float], None], observer: Callable[[Stack, float], None] | None
) -> Callable[[Stack, float], None]:
    """``script``, or ``script`` then ``observer(stack, now)`` on each of its ticks (the
    observer reads what the script may read: the onboard node and the plant)."""
    return script if observer is None else _Observed(script, observer)


def truth_arrays(stack: Stack) -> dict[str, np.ndarray]:
    """Ground truth of the run as arrays (rows = truth samples)."""
    tr = stack.truth
    return {
        "t": np.array([g.time for g in tr]),
        "cog": np.array([g.cog_position for g in tr]),
        "quat": np.array([g.base_quaternion for g in tr]),
        "q": np.array([g.joint_positions for g in tr]),
        "thrust": np.array([g.rotor_thrusts for g in tr]),
        "contact": np.array([g.foot_in_contact for g in tr]),
        "force": np.array([g.foot_contact_force for g in tr]),
        "torque": np.array([g.foot_contact_torque for g in tr]),
        "zmp": np.array([g.foot_zmp for g in tr]),
        "slip": np.array([g.foot_slip for g in tr]),
        "ee": np.array([g.end_effector_position for g in tr]),
        "foot": np.array([g.base_position for g in tr]),
    }


def roll_pitch(quat_wxyz: np.ndarray) -> np.ndarray:
    """(n, 2) ZYX roll and pitch [rad] of (n, 4) quaternions."""
    w, x, y, z = np.asarray(quat_wxyz, dtype=float).T
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1, 1))
    return np.stack([roll, pitch], axis=1)


def run_stack(stack: Stack, seconds: float) -> float:
    """Advance ``stack`` by ``seconds`` of simulated time and close it, whatever happens;
    returns the wall seconds it took."""
    t0 = time.perf_counter()
    try:
        stack.loop.run(seconds)
    finally:
        stack.close()
    return time.perf_counter() - t0


def finish(result: ScenarioResult, seconds: float, wall_s: float) -> ScenarioResult:
    """Write metrics.txt and summary.json (with the simulated time the plant reached, at most
    ``seconds``), both atomically, and take the run folder's INCOMPLETE marker away; returns
    the result."""
    st = result.stack
    table = format_metrics_table(result.metrics)
    write_atomic(st.folder.metrics_txt, table + "\n")
    facts = dict(result.facts)
    # what the plant really simulated (a scenario may stop before its ``seconds`` bound)
    simulated = float(st.plant.time) if math.isfinite(st.plant.time) else seconds
    facts.update(
        scenario=result.name,
        simulated_s=round(simulated, 6),
        wall_s=round(wall_s, 3),
        sim_s_per_wall_s=round(simulated / wall_s, 3) if wall_s > 0 else math.nan,
        spinal_failsafes=dict(st.spinal.counters.failsafes),
        spinal_rejected=dict(st.spinal.counters.rejected),
        onboard_state=st.onboard.state.value,
        servo_lead_s=st.onboard.config.servo_lead_s,
    )
    result.facts = facts
    write_summary(st.folder.summary_json, result.metrics, seed=st.plant.seed, **facts)
    st.folder.mark_complete()
    return result


class SetpointRamp:
    """A position setpoint that moves toward its goal at a bounded speed (what an operator's
    joystick or a planner would send), so that a step in the goal does not saturate rotors."""

    def __init__(self, start: np.ndarray, speed: float) -> None:
        self.position = np.asarray(start, dtype=float).copy()
        self.goal = self.position.copy()
        self.speed = float(speed)
        self.velocity = np.zeros(3)

    def set_goal(self, goal: np.ndarray, speed: float | None = None) -> None:
        self.goal = np.asarray(goal, dtype=float).copy()
        if speed is not None:
            self.speed = float(speed)

    def step(self, dt: float) -> None:
        delta = self.goal - self.position
        # np.linalg.norm of a 1-D float vector is sqrt(x.dot(x)): the same bits, without its
        # dispatch (the script calls this at 100 Hz)
        dist = math.sqrt(delta.dot(delta))
        reach = self.speed * dt
        if dist <= reach:
            self.position = self.goal.copy()
            self.velocity = np.zeros(3)
        else:
            self.velocity = delta / dist * self.speed
            self.position = self.position + delta / dist * reach

    @property
    def arrived(self) -> bool:
        # element-wise float ==, as np.all(position == goal)
        return self.position.tolist() == self.goal.tolist()

    @classmethod
    def arm_and_climb(
        cls, onboard: Any, start: np.ndarray, speed: float, climb_z: float
    ) -> SetpointRamp:
        """Arms ``onboard`` with its target at ``start`` and returns the ramp that climbs from
        there straight up to ``climb_z`` at ``speed`` (the take-off of the perching scenarios)."""
        ramp = cls(start, speed)
        ramp.set_goal(np.array([start[0], start[1], climb_z]))
        onboard.set_target(ramp.position, 0.0)
        onboard.arm()
        return ramp
