"""``mission``: the operator's flight through every wire, with one injected fault.

The node sees motion capture as a real system gives it: the marker body's pose with noise and
latency (:class:`rdm.scenarios.mocap_node.MocapSensor`), the CoG state estimated on board
(:mod:`rdm.nodes.onboard_mocap`). The onboard node's operator layer flies it
(:mod:`rdm.nodes.onboard_flight`): take off 1 m,
go to a point 0.5 m away and 0.3 m up, land (touchdown, then ARM_OFF). ``fault`` injects one
fault once the robot hovers (:data:`FAULTS`); the robot must end safe: disarmed on the floor,
never beyond 30 deg of tilt, never a duty above ``motor_info``'s maximum.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from rdm.sim import Metric

from .common import ScenarioResult, finish, roll_pitch, run_stack, sim_stack_options, truth_arrays
from .mocap_node import MocapSensor
from .stack import Stack, build_stack

ARM_AT = 1.5  # s: the CAN master runs from ~1.4 s (boot delay + enumeration)
TAKEOFF_HEIGHT = 1.0
GOTO_OFFSET = np.array([0.5, 0.0, 0.3])
HOLD_AT_GOAL_S = 2.0
DEFAULT_DURATION = 30.0
#: The faults ``--fault`` injects, once the robot hovers after take-off.
FAULTS = (
    "none",
    "heartbeat-loss",  # the ground station falls silent (the node lands)
    "mocap-loss",  # motion capture stops for good (silence, Spinal's own force landing)
    "uart-cut",  # the Spinal UART is cut for 0.3 s (Spinal's 500 ms timeout does not fire)
    "low-battery",  # the battery sags to 3.4 V per cell (the node lands)
    "bad-adc-scale",  # set_adc_scale 0.07 reaches Spinal (1.75 V: rejected by its guard)
)
#: The safety bounds of a run.
MAX_TILT_DEG = 30.0


class MissionScript:
    """Operator commands by phase, the fault, and what the run must stay within."""

    kernel_touches = None  # reads the Spinal mirror's duties and can change its inputs

    def __init__(self, fault: str) -> None:
        self.fault = fault
        self.phase = "wait"
        self.fault_at: float | None = None
        self.goal_at: float | None = None
        self.max_duty = 0.0
        self.events: list[tuple[float, str]] = []

    def __call__(self, stack: Stack, now: float) -> None:
        node = stack.onboard
        duties = getattr(stack.spinal, "duties", None) or []
        self.max_duty = max([self.max_duty, *duties])
        mode = node.flight.mode.value
        if self.phase == "wait" and now >= ARM_AT:
            self._say(now, f"takeoff -> {node.takeoff(TAKEOFF_HEIGHT)}")
            self.phase = "takeoff"
        elif self.phase == "takeoff" and mode == "hover":
            self._inject(stack, now)
            p = np.asarray(node.mocap[0]) if node.mocap is not None else np.zeros(3)
            self._say(now, f"goto -> {node.goto(p + GOTO_OFFSET, 0.0)}")
            self.phase = "goto"
        elif self.phase == "goto" and mode == "hover" and node.flight.path is None:
            self.goal_at = self.goal_at or now
            if now - self.goal_at >= HOLD_AT_GOAL_S:
                self._say(now, f"land -> {node.land()}")
                self.phase = "land"
        if self.fault == "uart-cut" and self.fault_at is not None and now - self.fault_at > 0.3:
            stack.drop_uart(False)

    def _say(self, now: float, text: str) -> None:
        self.events.append((round(now, 3), text))

    def _inject(self, stack: Stack, now: float) -> None:
        if self.fault == "none":
            return
        self.fault_at = now
        self._say(now, f"fault {self.fault}")
        if self.fault == "heartbeat-loss":
            stack.onboard.on_ground_lost()
        elif self.fault == "mocap-loss":
            stack.mocap.enabled = False
        elif self.fault == "uart-cut":
            stack.drop_uart(True)
        elif self.fault == "low-battery":
            stack.bridge.set_battery(3.4 * stack.onboard.monitors.cells)
        elif self.fault == "bad-adc-scale":  # a set_adc_scale frame on the wire to Spinal
            scale = stack.onboard.session.registry.msg("std_msgs/Float32").new(data=0.07)
            stack.onboard.session.publish("set_adc_scale", scale)


#: Which monitor or counter shows that the node noticed each fault.
_DETECTED_BY = {
    "heartbeat-loss": ("monitors", "ground_lost"),
    "mocap-loss": ("node", "command_withheld"),
    "uart-cut": ("monitors", "spinal_silent"),
    "low-battery": ("monitors", "battery_low"),
    "bad-adc-scale": ("spinal", "adc_scale_implausible"),
}


def outcome(stack: Stack, script: MissionScript, a: dict[str, np.ndarray]) -> dict[str, Any]:
    """The run's safety record (the fields of ``rdm hil mission --json``)."""
    node = stack.onboard
    t = a["t"]
    if not len(t):
        raise RuntimeError("mission: the run recorded no ground truth")
    rp = np.degrees(np.abs(roll_pitch(a["quat"]))).max(axis=1)
    # the floor: the CoG height resting before arming (the robot settles after its drop)
    floor_z = float(a["cog"][np.searchsorted(t, ARM_AT) - 1, 2])
    airborne = a["cog"][:, 2] > floor_z + 0.05
    max_tilt = float(rp[airborne].max()) if airborne.any() else 0.0
    disarmed = node.state.value == "idle" and not stack.spinal.core.armed
    on_floor = abs(float(a["cog"][-1, 2]) - floor_z) < 0.05
    max_duty_allowed = node.config.pwm_info.max_pwm
    if disarmed and on_floor:
        result = "landed"
    elif disarmed:
        result = "halted"
    else:
        result = "airborne"
    if max_tilt > MAX_TILT_DEG:
        result = "crashed"
    where, key = _DETECTED_BY.get(script.fault, ("", ""))
    counts = {
        "monitors": node.monitors.counts,
        "node": node.counts,
        "spinal": stack.spinal.counters.rejected,
    }.get(where, {})
    touchdowns = [e["t"] for e in node.monitors.events if e["monitor"] == "touchdown"]
    return {
        "outcome": result,
        "safe": result == "landed"
        and max_tilt <= MAX_TILT_DEG
        and script.max_duty <= max_duty_allowed + 1e-9,
        "fault": script.fault,
        "fault_detected": bool(counts[key]) if key else None,
        "final_state": node.state.value,
        "max_tilt_deg": max_tilt,
        "max_duty": script.max_duty,
        "touchdown_s": touchdowns[-1] if touchdowns else None,
        "operator": script.events,
        "monitors": dict(node.monitors.counts),
    }


def run(
    base: str | Path,
    duration: float = DEFAULT_DURATION,
    seed: int = 0,
    uart: str = "inproc",
    speed: float | None = None,
    fault: str = "none",
) -> ScenarioResult:
    if fault not in FAULTS:
        raise ValueError(f"fault={fault!r}: one of {', '.join(FAULTS)}")
    # motion capture as a real system gives it: the marker body's pose, noisy and late
    opts = sim_stack_options(seed, uart, speed=speed, mocap=MocapSensor())
    script = MissionScript(fault)
    stack = build_stack(f"mission-{fault}", base, opts, script)
    wall = run_stack(stack, duration)
    a = truth_arrays(stack)
    record = outcome(stack, script, a)
    metrics = [
        Metric("safe end (disarmed on the floor)", float(record["safe"]), 1.0, "", "min", limit=1),
        Metric(
            "max |roll|,|pitch| in flight",
            record["max_tilt_deg"],
            None,
            "deg",
            "max",
            limit=MAX_TILT_DEG,
        ),
        Metric(
            "max duty",
            record["max_duty"],
            None,
            "",
            "max",
            limit=stack.onboard.config.pwm_info.max_pwm,
        ),
    ]
    if record["fault_detected"] is not None:
        metrics.append(
            Metric("fault detected", float(record["fault_detected"]), 1.0, "", "min", limit=1)
        )
    return finish(
        ScenarioResult(
            f"mission-{fault}", stack, metrics, facts={"mission": record}, script=script
        ),
        duration,
        wall,
    )
