"""``mission``: the operator's flight through every wire, with one injected fault.

The node sees motion capture as a real system gives it: the marker body's pose with noise and
latency (:class:`rdm.scenarios.mocap_node.MocapSensor`), the CoG state estimated on board
(:mod:`rdm.nodes.onboard_mocap`). The onboard node's operator layer flies it
(:mod:`rdm.nodes.onboard_flight`), every step an operator command (the ``rdm ctl`` ones):

1. take off 1 m; go to a point 0.5 m away and 5 cm down (``quick`` ends here: land);
2. fold into the hanging posture (``joints``, a jerk-limited path);
3. ``perch``: approach until the foot sensor reads contact, perched with perching control;
4. move the arm and back (``joints``) while perched;
5. ``unperch``, unfold (``joints``), ``land`` (touchdown, ARM_OFF).

``fault`` injects one fault (:data:`FAULTS`): the flight faults once the robot hovers after
take-off, the perched ones (:data:`PERCHED_FAULTS`) once perched and settled. The robot must
end safe: disarmed on the floor or held perched, never beyond 30 deg of tilt in flight, never
a duty above ``motor_info``'s maximum (but for the faults of :data:`BEYOND_AIRFRAME`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from rdm.control import lqi
from rdm.nodes.onboard_flight import FlightMode
from rdm.sim import Metric
from rdm.sim.byte_faults import CorruptingLink

from . import perching
from .common import ScenarioResult, finish, roll_pitch, run_stack, sim_stack_options, truth_arrays
from .mission_faults import DeadRotor, SpikingImu, infeasible_perch_qp
from .mocap_node import MocapSensor
from .stack import DroppableLink, Stack, build_stack

ARM_AT = 1.5  # s: the CAN master runs from ~1.4 s (boot delay + enumeration)
TAKEOFF_HEIGHT = 1.0
#: The go-to from the take-off point: 0.5 m in x and 5 cm down, where the mission folds. The
#: CoG then hovers 0.55 m under the 1.6 m ceiling (0.25 m under it, the rotors' ceiling
#: effect rocks the flat robot by about 10 deg), and after the fold the foot ends about 0.1 m
#: under the ceiling (0.5 m above the CoG), so the approach in the hanging posture is short,
#: as in ``perching.QUICK_TIMING`` (the configured gains throughout).
GOTO_OFFSET = np.array([0.5, 0.0, -0.05])
HOLD_AT_GOAL_S = 2.0
#: Hover after the unperch path before the unfold, s: short, as the configured gains are
#: unstable in the hanging posture (``perching.HANGING_FLIGHT_GAINS``; docs/scenarios.md).
UNPERCH_WAIT_S = 0.2
#: The arm motion while perched (q1..q6 goal and back), as the perching scenario's first.
PERCHED_ARM = perching.PERCHED_MOTION[0][1]
#: Waits after a joint motion ends, and perched before the arm moves, s.
JOINT_WAIT_S = 1.0
SETTLE_S = perching.SETTLE_S
#: How long a held perch (``foot-sensor-loss``) is watched before the run ends, s.
HOLD_PERCHED_S = 3.0
DEFAULT_DURATION = 75.0
QUICK_DURATION = 22.0
#: The faults ``--fault`` injects, once the robot hovers after take-off.
FAULTS = (
    "none",
    "heartbeat-loss",  # the ground station falls silent (the node lands)
    "mocap-loss",  # motion capture stops for good (silence, Spinal's own force landing)
    "uart-cut",  # the Spinal UART is cut for 0.3 s (Spinal's 500 ms timeout does not fire)
    "low-battery",  # the battery sags to 3.4 V per cell (the node lands)
    "bad-adc-scale",  # set_adc_scale 0.07 reaches Spinal (1.75 V: rejected by its guard)
    "uart-noise-1e-4",  # each byte on the Spinal UART flipped / lost / repeated at p = 1e-4
    "uart-noise-1e-3",  # ... at p = 1e-3 (about one damaged frame in 30)
    "battery-sag",  # the battery sags 1 V/s from where it is (the node lands by itself)
    "battery-sag-0.5",  # ... 0.5 V/s (battery_sag's rate rule)
    "battery-sag-0.3",  # ... 0.3 V/s
    "foot-sensor-loss",  # the foot sensor's cable is cut once perched (the node holds)
    "imu-spikes",  # IMU samples beyond the sensor's range, about 3 a second (both drop them)
    "dead-esc",  # rotor DEAD_ROTOR gives no thrust from the fault on (the node cuts, it falls)
    "stuck-servo",  # perched, q4's servo stops following its goal as the arm moves (held)
    "infeasible-qp",  # perched, the QP's friction limit set below what the contact needs
    "can-loss-1e-2",  # each frame on the Neuron CAN bus lost with p = 1e-2
    "can-loss-1e-1",  # ... with p = 1e-1
    "can-bus-off",  # the CAN bus disturbed for 20 ms: bus-off, then the recovery bits
    "neuron-reset",  # Neuron slave 1 (rotor 0's ESC) resets unasked: 100 ms deaf, power-on
)
#: Byte-fault probability of the ``uart-noise-*`` faults (sim.byte_faults.CorruptingLink).
UART_NOISE = {"uart-noise-1e-4": 1e-4, "uart-noise-1e-3": 1e-3}
#: Frame-loss probability of the ``can-loss-*`` faults (``rdm._rdm.CanWire.set_loss``).
CAN_LOSS = {"can-loss-1e-2": 1e-2, "can-loss-1e-1": 1e-1}
#: How long ``can-bus-off`` disturbs the bus, s; the controllers rejoin 128 x 11 recessive
#: bits (1.408 ms) after it. ASSUMPTION: a connector glitch of 20 ms. The ESCs hold their
#: last pulse meanwhile; from the mission's quiet hover (``lqi.ROLL_DAMPED_Q``) a 50 ms gap
#: is ridden out too (docs/flying.md); beyond the Neurons' 100 ms watchdog every motor stops.
BUS_OFF_S = 0.02
#: The rotor ``dead-esc`` stops (0: rotor 0, the heaviest-loaded; the tests set 1-3 too).
DEAD_ROTOR = 0
#: The board ``neuron-reset`` resets (bank index 0: slave 1, rotor 0's ESC and its servos).
RESET_BOARD = 0
#: The sag of ``battery-sag``, V/s (ASSUMPTION: a failing cell under hover load), down to
#: 3.0 V per cell. The operator then holds at the goal: the node must land by itself.
SAG_V_PER_S = 1.0
#: The sag of each battery-sag fault, V/s: the slow ones are left by ``battery_sag``'s rate
#: rule to ``battery_reserve`` (the pack below what the hover needs with a margin).
SAG_RATES = {
    "battery-sag": SAG_V_PER_S,
    "battery-sag-0.5": 0.5,
    "battery-sag-0.3": 0.3,
}
#: Faults injected once perched (the others: once hovering after take-off).
PERCHED_FAULTS = ("foot-sensor-loss", "stuck-servo", "infeasible-qp")
#: Perched faults injected as the arm motion starts (the others: once settled).
ARM_FAULTS = ("stuck-servo",)
#: The joint whose servo sticks (``stuck-servo``): q4, the joint the perched arm motion
#: moves furthest (0.5 rad).
STUCK_JOINT = "q4"
#: The friction coefficient ``infeasible-qp`` gives the perching QP (both axes): below what
#: the perched contact's tangential force needs, so eq. (49)'s friction rows cannot hold.
#: ASSUMPTION: a corrupted parameter (the configured values are 0.9).
INFEASIBLE_MU = 1e-4
#: Faults the tests do not require to end safe (docs/flying.md): none. Every fault must end
#: safe, a dead ESC and a Neuron reset included (its ESC stopped for the 100 ms the board
#: reboots: the node's lost-rotor reaction, "A lost rotor", holds the attitude without the
#: rotor and cuts).
BEYOND_AIRFRAME: tuple[str, ...] = ()
#: The safety bounds of a run.
MAX_TILT_DEG = 30.0


class MissionScript:
    """Operator commands by phase, the fault, and what the run must stay within."""

    kernel_touches = None  # reads the Spinal mirror's duties and can change its inputs

    def __init__(self, fault: str, quick: bool = False) -> None:
        self.fault = fault
        self.quick = quick and fault not in PERCHED_FAULTS
        self.phase = "wait"
        self.fault_at: float | None = None
        self.goal_at: float | None = None
        self._until: float | None = None
        self.max_duty = 0.0
        self.events: list[tuple[float, str]] = []

    def __call__(self, stack: Stack, now: float) -> None:
        node = stack.onboard
        duties = getattr(stack.spinal, "duties", None) or []
        self.max_duty = max([self.max_duty, *duties])
        mode = node.flight.mode
        if self.phase == "wait" and now >= ARM_AT:
            self._say(now, "takeoff", node.takeoff(TAKEOFF_HEIGHT))
            self.phase = "takeoff"
        elif self.phase == "takeoff" and mode is FlightMode.HOVER:
            if self.fault not in PERCHED_FAULTS:
                self._inject(stack, now)
            self.start = np.asarray(node.flight.hold_position)
            self._say(now, "goto", node.goto(self.start + GOTO_OFFSET, 0.0))
            self.phase = "goto"
        elif self.phase == "goto" and self.fault in SAG_RATES:
            pass  # hold at the goal: the node's battery monitor must land the robot
        elif self.phase == "goto" and self._arrived(node, now, HOLD_AT_GOAL_S):
            if self.quick or self.fault_at is not None:
                self._say(now, "land", node.land())
                self.phase = "land"
            else:
                self._joints(node, now, perching.PERCH_POSTURE, "fold")
        elif self.phase == "fold" and self._joints_done(node, now):
            self._say(now, "perch", node.perch())
            self.phase = "approach"
        elif self.phase == "approach" and mode is FlightMode.PERCHED:
            self.phase, self._until = "perched", now + SETTLE_S
        elif self.phase == "perched" and self._until is not None and now >= self._until:
            if self.fault in PERCHED_FAULTS:  # once settled on the perch
                if self.fault in ARM_FAULTS:  # the arm starts to move, then the fault
                    self._joints(node, now, PERCHED_ARM, "arm")
                self._inject(stack, now)
                self.phase, self._until = "hold", now + HOLD_PERCHED_S
            else:
                self._joints(node, now, PERCHED_ARM, "arm")
        elif self.phase == "arm" and self._joints_done(node, now):
            self._joints(node, now, perching.PERCH_POSTURE, "arm back")
        elif self.phase == "arm back" and self._joints_done(node, now):
            self._say(now, "unperch", node.unperch())
            self.phase = "unperch"
        elif self.phase == "unperch" and self._arrived(node, now, UNPERCH_WAIT_S):
            self._joints(node, now, (0.0,) * 6, "unfold")
        elif self.phase == "unfold" and self._joints_done(node, now):
            self._say(now, "land", node.land())
            self.phase = "land"
        elif self.phase == "hold" and self._until is not None and now >= self._until:
            stack.loop.stop()  # held perched after the fault: the run's end
            self.phase = "held"
        if self.fault == "uart-cut" and self.fault_at is not None and now - self.fault_at > 0.3:
            stack.drop_uart(False)

    def _arrived(self, node: Any, now: float, wait: float) -> bool:
        """In hover with no path left for ``wait`` s."""
        if node.flight.mode is not FlightMode.HOVER or node.flight.path is not None:
            self.goal_at = None
            return False
        self.goal_at = self.goal_at or now
        if now - self.goal_at >= wait:
            self.goal_at = None
            return True
        return False

    def _joints(self, node: Any, now: float, q: tuple[float, ...], phase: str) -> None:
        """``joints`` with the whole joint vector: q1..q6 and the vectoring apparatus
        levelled (:func:`rdm.scenarios.perching.leveled`)."""
        goal = perching.leveled(np.asarray(q, dtype=float), node.robot.n_q)
        self._say(now, f"joints {phase}", node.move_joints(goal.tolist()))
        trajectory = node._trajectory
        self._until = None if trajectory is None else float(trajectory[0][-1]) + JOINT_WAIT_S
        self.phase = phase

    def _joints_done(self, node: Any, now: float) -> bool:
        return self._until is not None and now >= self._until

    def _say(self, now: float, command: str, refusal: str | None = None) -> None:
        self.events.append((round(now, 3), f"{command} -> {refusal}"))

    def _inject(self, stack: Stack, now: float) -> None:
        if self.fault == "none":
            return
        self.fault_at = now
        self.events.append((round(now, 3), f"fault {self.fault}"))
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
        elif self.fault in UART_NOISE:  # both directions, each its own seeded stream
            seed = int(stack.plant.seed)
            for k, end in enumerate((stack.spinal_link, stack.onboard_link)):
                end.link = CorruptingLink(end.link, UART_NOISE[self.fault], 1000 * seed + k)
        elif self.fault in SAG_RATES:
            v0, floor = stack.spinal.battery_input, 3.0 * stack.onboard.monitors.cells
            rate = SAG_RATES[self.fault]
            stack.bridge.set_battery(lambda t: max(floor, v0 - rate * (t - now)))
        elif self.fault == "foot-sensor-loss":  # the sensor's cable cut at the PC
            foot = stack.onboard.foot
            foot.link = DroppableLink(foot.link)
            foot.link.dropped = True
        elif self.fault == "imu-spikes":  # the plant's IMU read by the bridge for Spinal
            stack.plant.imu = SpikingImu(stack.plant.imu, int(stack.plant.seed))
        elif self.fault == "dead-esc":
            effects = list(stack.plant.ceiling_effects)
            effects[DEAD_ROTOR] = DeadRotor(effects[DEAD_ROTOR])
            stack.plant.ceiling_effects = effects
        elif self.fault in CAN_LOSS:  # on the wire between Spinal and the Neurons
            link = _can_wire(stack)
            link.wire.set_loss(CAN_LOSS[self.fault], 1000 * int(stack.plant.seed) + 2)
        elif self.fault == "can-bus-off":
            link = _can_wire(stack)
            link.wire.bus_off(link.clock(), BUS_OFF_S)
        elif self.fault == "neuron-reset":  # the board's MCU, in the Rust Neuron bank
            stack.neurons[RESET_BOARD].power_cycle()
        elif self.fault == "stuck-servo":  # the shaft, behind its Neuron (the Rust bank)
            stack.bridge.stick_servo(STUCK_JOINT)
        elif self.fault == "infeasible-qp":
            infeasible_perch_qp(stack.onboard.control, INFEASIBLE_MU)


def _can_wire(stack: Stack) -> Any:
    """The Neuron bus of the stack (:class:`rdm.link.can_wire.CanWireLink`)."""
    link = stack.spinal.master.wire
    if link is None:
        raise ValueError("the CAN faults need the Rust CAN wire (StackOptions.can_wire)")
    return link


#: The node's battery monitors: a level held (``battery_low``) and a sag (``battery_sag``);
#: either detects a battery fault (a step down to 3.4 V/cell trips the sag rule first).
_BATTERY_MONITORS = ("battery_low", "battery_sag", "battery_reserve")
#: Which monitor or counter (or which of several monitors) shows that the node noticed each
#: fault.
_DETECTED_BY: dict[str, tuple[str, str | tuple[str, ...]]] = {
    "heartbeat-loss": ("monitors", "ground_lost"),
    "mocap-loss": ("node", "command_withheld"),
    "uart-cut": ("monitors", "spinal_silent"),
    "low-battery": ("monitors", _BATTERY_MONITORS),
    "bad-adc-scale": ("spinal", "adc_scale_implausible"),
    "uart-noise-1e-4": ("parser", "bad_frames"),
    "uart-noise-1e-3": ("parser", "bad_frames"),
    "battery-sag": ("monitors", _BATTERY_MONITORS),
    "battery-sag-0.5": ("monitors", _BATTERY_MONITORS),
    "battery-sag-0.3": ("monitors", _BATTERY_MONITORS),
    "foot-sensor-loss": ("monitors", "foot_stale"),
    # each outlier dropped by Spinal's estimator (``out_of_range``); its accelerometer value
    # reaches the node on ``imu``, which refuses it
    "imu-spikes": ("monitors", "imu_implausible"),
    "dead-esc": ("monitors", "rotor_lost"),
    "stuck-servo": ("monitors", "joint_tracking"),
    "infeasible-qp": ("monitors", "perch_qp_failed"),
    # Spinal's CAN peripheral: the error frames of damaged frames, the bus-off episode
    "can-loss-1e-2": ("can", "error_frames"),
    "can-loss-1e-1": ("can", "error_frames"),
    "can-bus-off": ("can", "bus_off"),
    # Spinal's CAN master: a servo goal report after the goal-sync handshake, torque on
    "neuron-reset": ("spinal_can", "goal_resyncs"),
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
    perched = (
        not disarmed
        and node.flight.mode is FlightMode.PERCHED
        and bool(a["contact"][-1])
        and node.status()["perching"]
    )
    if disarmed and on_floor:
        result = "landed"
    elif disarmed:
        result = "halted"
    elif perched:
        result = "perched"
    else:
        result = "airborne"
    if max_tilt > MAX_TILT_DEG:
        result = "crashed"
    where, key = _DETECTED_BY.get(script.fault, ("", ""))
    keys = (key,) if isinstance(key, str) else key
    counts = {
        "monitors": node.monitors.counts,
        "node": node.counts,
        "spinal": stack.spinal.counters.rejected,
        "parser": {"bad_frames": node.session.parser.bad_frames},
        "estimator": stack.spinal.core.estimator_counters,
        "failsafes": stack.spinal.counters.failsafes,
        "can": _can_wire(stack).wire.fault_counters() if where == "can" else {},
        "spinal_can": {"goal_resyncs": stack.spinal.master.goal_resyncs},
    }.get(where, {})
    touchdowns = [e["t"] for e in node.monitors.events if e["monitor"] == "touchdown"]
    record = {
        "outcome": result,
        "safe": result in ("landed", "perched")
        and max_tilt <= MAX_TILT_DEG
        and script.max_duty <= max_duty_allowed + 1e-9,
        "fault": script.fault,
        "fault_detected": any(counts[k] for k in keys) if key else None,
        "fault_at_s": script.fault_at,
        "final_state": node.state.value,
        "max_tilt_deg": max_tilt,
        "max_duty": script.max_duty,
        "touchdown_s": touchdowns[-1] if touchdowns else None,
        "operator": script.events,
        "monitors": dict(node.monitors.counts),
    }
    if script.fault != "none":  # when the node's monitor first tripped (None: another counter)
        after = script.fault_at or 0
        names = keys if where == "monitors" else ()
        trips = [e["t"] for e in node.monitors.events if e["monitor"] in names and e["t"] >= after]
        for k in names:  # the event list keeps only the latest
            first = node.monitors.first_trip.get(k)
            if first is not None and first >= after:
                trips.append(first)
        record["detected_at_s"] = min(trips) if trips else None
    return record


def hover_thrust_std(script: MissionScript, a: dict[str, np.ndarray]) -> float:
    """The largest standard deviation of the true rotor thrusts over the 0.5 s of hover
    before the go-to (NaN without a go-to): the hover the flight faults interrupt."""
    goto = [at for at, what in script.events if what.startswith("goto")]
    if not goto:
        return float("nan")
    t = a["t"]
    window = a["thrust"][(t > goto[0] - 0.5) & (t < goto[0])]
    return float(window.std(axis=0).max()) if len(window) > 1 else float("nan")


def run(
    base: str | Path,
    duration: float = DEFAULT_DURATION,
    seed: int = 0,
    uart: str = "inproc",
    speed: float | None = None,
    fault: str = "none",
    quick: bool = False,
) -> ScenarioResult:
    """The mission (``quick``: take-off, go-to and land only; a perched fault perches)."""
    if fault not in FAULTS:
        raise ValueError(f"fault={fault!r}: one of {', '.join(FAULTS)}")
    # motion capture as a real system gives it: the marker body's pose, noisy and late;
    # the configuration of the hanging-posture experiments (perching) with the LQI roll
    # weights that keep the straight posture's roll loop damped under that noise
    config = perching.onboard_config(lqi_q_weights=tuple(lqi.ROLL_DAMPED_Q.tolist()))
    opts = sim_stack_options(seed, uart, speed=speed, mocap=MocapSensor(), onboard=config)
    script = MissionScript(fault, quick)
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
    metrics.append(
        Metric(
            "hover rotor thrust std, 0.5 s before the go-to (largest rotor)",
            hover_thrust_std(script, a),
            None,
            "N",
            "info",
        )
    )
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
