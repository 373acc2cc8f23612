"""The three child processes of a process-level run (:mod:`rdm.scenarios.processes`).

::

    robot:   MuJoCo plant + PlantBridge + 4 NeuronMirror (CAN) + LeptrinoSensorNode (pty
             master) + MocapSender; the physics steps 1 ms at a time to catch up with the
             shared clock
    spinal:  SpinalMirror (CAN + the Spinal UART pty master) + ImuReceiver
    onboard: OnboardNode (Spinal UART + Leptrino UART, the pty slaves) + MocapReceiver + the
             scenario's script (hover: target and arm at ``arm_at``; perching: the perching
             scenario's phase machine)

Entry point: ``python -m rdm.scenarios.process_roles ROLE CONFIG_JSON``. Start-up handshake
(line-based, on the child's stdin/stdout): the child builds its nodes and prints
``RDM-READY <json>`` (the pty path it offers); the parent answers one JSON line
``{"epoch": ..., "scale": ..., "duration": ..., ...}``; the child runs until ``duration``,
writes ``<out>/<role>.json`` and prints ``RDM-DONE``.

Each role imports what it needs inside its function, so that only the robot process imports
MuJoCo (imports dominate a child's start-up, most of all in the emulated VM).
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from rdm.sim.scaled_clock import ScaledClock, SharedTimes, WakeSocket, run_scaled

ROLES = ("robot", "spinal", "onboard")
READY = "RDM-READY "
DONE = "RDM-DONE"


def neuron_filters(slave: int) -> list[dict[str, Any]]:
    """Kernel acceptance filters of a Neuron: standard ids whose slave field is its own id or
    the broadcast id, which is the rule the mirror applies in software (then it counts the
    rest in ``rx_filtered``; with the kernel filter they never reach Python)."""
    from rdm.protocol.neuron.ids import BROADCAST_ID

    return [
        {"can_id": slave, "can_mask": 0xF, "extended": False},
        {"can_id": BROADCAST_ID, "can_mask": 0xF, "extended": False},
    ]


def _tapped_pty(folder: Path, stem: str, ext: str, clock: Callable[[], float]):
    """(device end with time-indexed captures, slave link kept open, slave path)."""
    from rdm.link.serial import open_pty_pair
    from rdm.link.tapped_link import TappedLink

    slave, master = open_pty_pair()
    slave.peer = None  # each end is closed on its own
    d = folder / "uart"
    d.mkdir(parents=True, exist_ok=True)
    dev = TappedLink(master, d / f"{stem}.device_tx{ext}", d / f"{stem}.host_tx{ext}", clock=clock)
    return dev, slave, slave.port.port


def _handshake(info: dict[str, Any]) -> dict[str, Any]:
    print(READY + json.dumps(info), flush=True)
    line = sys.stdin.readline()
    if not line:
        raise SystemExit("rdm.scenarios.process_roles: parent closed stdin before the start line")
    return json.loads(line)


#: Columns of ``truth.npz["foot"]`` (one row per truth sample): contact flag, contact force
#: (3, foot frame), torque (3), ZMP (2, foot frame), slip (2, world), foot position (3, world),
#: q1..q6.
FOOT_COLUMNS = 1 + 3 + 3 + 2 + 2 + 3 + 6


#: Slots of the shared time file: robot outputs produced up to; Spinal, onboard done up to.
SLOTS = 3
_SLOT = {"spinal": 1, "onboard": 2}
#: Wall seconds the robot waits for a controller before declaring it dead.
CONTROLLER_TIMEOUT_S = 120.0


def _clock(start: dict[str, Any], role: str, token: str):
    """The controllers' clock (scaled wall time, gated by the physics time if asked) and the
    ``progress`` callback of :func:`run_scaled` that tells the robot how far we are. While
    gated, the process blocks on its wake socket until the robot has produced a new tick."""
    if not start.get("time_file"):
        return ScaledClock(start["epoch"], start["scale"]), None
    shared = SharedTimes(start["time_file"], SLOTS)
    wake = WakeSocket(token, role)
    slot = _SLOT[role]
    clock = ScaledClock(
        start["epoch"],
        start["scale"],
        gate=lambda: shared.get(0),
        gate_slack=0.0,
        waiter=lambda s: wake.wait(min(s, 0.5)),
    )

    def progress(t: float) -> None:
        shared.set(slot, t)
        wake.notify("robot")

    return clock, progress


def _wait_for_controllers(shared: SharedTimes, wake: WakeSocket, produced: float) -> None:
    """Wake the controllers that have ticks due at or before ``produced`` and block until
    every controller has run them."""
    for role, slot in _SLOT.items():
        if shared.get(slot) < produced:
            wake.notify(role)
    deadline = None
    while min(shared.get(s) for s in _SLOT.values()) < produced:
        if deadline is None:
            deadline = time.monotonic() + CONTROLLER_TIMEOUT_S
        elif time.monotonic() > deadline:
            raise RuntimeError(f"controllers stuck before t={produced:.3f} s")
        wake.wait(0.05)


def _write_report(folder: Path, role: str, report: dict[str, Any]) -> None:
    (folder / f"{role}.json").write_text(json.dumps(report, indent=1, default=str))


def robot_main(cfg: dict[str, Any]) -> None:
    """Plant + bridge + Neurons + Leptrino + mocap; physics catches up with the clock."""
    from rdm.nodes.leptrino_sensor import LeptrinoSensorNode
    from rdm.nodes.lockstep import Lockstep
    from rdm.plant import ServoParams
    from rdm.scenarios.stack import StackOptions, make_bridge, make_neurons, make_plant
    from rdm.sim.side_channels import ImuSender, MocapSender
    from rdm.sim.udp_can import open_bus

    folder = Path(cfg["out"])
    stack_cfg = dict(cfg["stack"])
    servo = stack_cfg.pop("servo")
    stack_cfg.pop("spinal_flash")  # the Spinal process's (its estimator's calibration)
    opt = StackOptions(**stack_cfg, servo=None if servo is None else ServoParams(**servo))
    plant, q0 = make_plant(opt)

    def open_neuron_bus(slave: int) -> Any:
        bus = open_bus(cfg["can"])
        if cfg["can"].startswith("socketcan:"):
            bus.set_filters(neuron_filters(slave))
        return bus

    layout, neurons = make_neurons(plant, q0, open_neuron_bus)
    loop: Lockstep | None = None
    lep_dev, lep_slave, lep_path = _tapped_pty(
        folder, "leptrino_foot", ".lep", lambda: loop.time if loop is not None else 0.0
    )
    sensor = LeptrinoSensorNode(lep_dev, "CFS034CA301U", rate_hz=opt.leptrino_rate_hz)
    truth: list[tuple] = []
    foot: list[tuple] = []

    def record(gt: Any) -> None:
        truth.append((gt.time, *gt.cog_position, *gt.base_quaternion, *gt.rotor_thrusts))
        foot.append(
            (
                float(gt.foot_in_contact),
                *gt.foot_contact_force,
                *gt.foot_contact_torque,
                *gt.foot_zmp,
                *gt.foot_slip,
                *gt.base_position,
                *gt.joint_positions[:6],
            )
        )

    imu = ImuSender(cfg["token"], lambda: loop.time if loop is not None else 0.0)
    bridge = make_bridge(
        plant,
        neurons,
        layout,
        opt,
        imu_sink=imu.send_imu,
        battery_sink=imu.set_battery_voltage,
        foot_sensor=sensor,
        truth_sink=record,
    )
    mocap = MocapSender(cfg["token"], plant, opt.mocap_period)
    loop = Lockstep([bridge, *neurons, mocap, sensor], physics=plant)
    start = _handshake({"leptrino_pty": lep_path})
    clock = ScaledClock(start["epoch"], start["scale"])
    shared = SharedTimes(start["time_file"], SLOTS) if start.get("time_file") else None
    wake = WakeSocket(cfg["token"], "robot")
    end = float(start["duration"])
    dt = loop.dt
    late_steps, max_lag, sum_lag = 0, 0.0, 0.0
    clock.wait_for_epoch()
    wall0 = time.monotonic()
    try:
        while loop.time < end - 1e-9:
            lag = clock.now() - loop.time
            if lag < 0:
                clock.sleep(-lag)
                continue
            if shared is not None:
                _wait_for_controllers(shared, wake, loop.time - dt)
            if lag > dt:
                late_steps += 1
            sum_lag += lag
            max_lag = max(max_lag, lag)
            loop.step()
            if shared is not None:
                # The bridge, Neurons, mocap and Leptrino have produced everything for this
                # tick's time (loop.time - dt): the controllers may run up to it.
                shared.set(0, loop.time - dt)
    finally:
        if shared is not None:
            shared.set(0, math.inf)  # the physics is done: the others finish on the wall clock
        wall = time.monotonic() - wall0
        steps = loop.stats.base_ticks
        np.savez(
            folder / "truth.npz",
            truth=np.array(truth, dtype=float),
            foot=np.array(foot, dtype=float).reshape(len(foot), FOOT_COLUMNS),
        )
        _write_report(
            folder,
            "robot",
            {
                "deadlines": {
                    "physics_step": {
                        "ticks": steps,
                        "overruns": late_steps,
                        "max_late_ms": round(1e3 * max_lag, 3),
                        "mean_late_ms": round(1e3 * sum_lag / max(steps, 1), 3),
                    }
                },
                "wall_s": round(wall, 3),
                "ticks": dict(loop.stats.ticks),
                "neurons": {
                    n.name: {
                        "rx": n.rx_count,
                        "tx": n.tx_count,
                        "rx_errors": dict(n.rx_errors),
                        "tx_errors": n.tx_errors,
                        "pwm": n.esc.value,
                        "torque_on": [bool(s.torque_enable) for s in n.servos],
                    }
                    for n in neurons
                },
                "imu_sent": imu.out.sent,
                "imu_send_errors": imu.out.errors,
                "mocap_sent": mocap.out.sent,
                "mocap_send_errors": mocap.out.errors,
                "bridge_time_mismatches": bridge.time_mismatches,
            },
        )
        for n in neurons:
            n.close()
        imu.close()
        mocap.close()
        lep_dev.close()
        lep_slave.close()
        if shared is not None:
            shared.close()
        wake.close()


def spinal_main(cfg: dict[str, Any]) -> None:
    """The Spinal mirror on CAN + its UART pty, IMU from the side channel."""
    from rdm.nodes.spinal_mirror import SpinalMirror
    from rdm.sim.side_channels import ImuReceiver
    from rdm.sim.udp_can import open_bus

    folder = Path(cfg["out"])
    opt = SimpleNamespace(**cfg["stack"])
    # the captures' times: the shared scaled clock once the start line has set it
    started: list[ScaledClock] = []
    dev, slave, path = _tapped_pty(
        folder, "spinal", ".bin", lambda: started[0].now() if started else 0.0
    )
    spinal = SpinalMirror(
        dev,
        open_bus(cfg["can"]),
        rate_hz=opt.spinal_rate_hz,
        boot_delay_ms=opt.boot_delay_ms,
        gyro_calib_duration_s=opt.gyro_calib_duration_s,
        time_matched=opt.spinal_time_matched,
        # Spinal's CAN master on this process's python-can bus
        **opt.spinal_flash,  # the estimator's flash calibration, as in lockstep
    )
    imu_in = ImuReceiver(cfg["token"], spinal)
    start = _handshake({"spinal_pty": path})
    clock, progress = _clock(start, "spinal", cfg["token"])
    started.append(clock)
    stats = None
    try:
        stats = run_scaled([imu_in, spinal], clock, float(start["duration"]), progress)
    finally:
        report = {
            "deadlines": stats.as_dict() if stats else {},
            "wall_s": round(stats.wall_s, 3) if stats else None,
            "imu_samples": imu_in.samples,
            "imu_malformed": imu_in.malformed,
            "diagnostics": spinal.diagnostics(),
        }
        _write_report(folder, "spinal", report)
        imu_in.close()
        spinal.close()
        slave.close()


class LateLink:
    """A byte link whose port is attached after the node was built (nothing is read or
    written before :meth:`attach`)."""

    def __init__(self) -> None:
        self.link: Any = None

    def attach(self, link: Any) -> Any:
        self.link = link
        return link

    def read_available(self) -> bytes:
        return b"" if self.link is None else self.link.read_available()

    def write(self, data: bytes) -> int:
        return 0 if self.link is None else self.link.write(data)


class HoverScript:
    """The hover scenario's script in the onboard process: at ``arm_at`` set the target and
    arm (as ``rdm.scenarios.hover.make_script``)."""

    name = "script"
    period = 0.01

    def __init__(self, onboard: Any, target: Sequence[float], arm_at: float) -> None:
        self.onboard = onboard
        self.target = np.asarray(target, dtype=float)
        self.arm_at = arm_at
        self.armed_at: float | None = None

    def tick(self, now: float) -> None:
        if self.armed_at is None and now >= self.arm_at:
            self.armed_at = now
            self.onboard.set_target(self.target, 0.0)
            self.onboard.arm()


class PerchingScriptNode:
    """The perching scenario's phase machine (:class:`rdm.scenarios.perching.PerchingScript`)
    in the onboard process. The script reads the CoG twice (the climb's start, the contact
    height); in lockstep it takes the plant's ground truth, which is what the mocap node sends
    at that instant; here it takes the onboard node's latest mocap datagram (the same number
    when gated: mocap and script are both due every 10 ms and mocap ticks first). Nothing
    runs before the first mocap position arrived."""

    name = "script"
    period = 0.01

    def __init__(self, onboard: Any, mocap_in: Any, quick: bool) -> None:
        from rdm.scenarios.perching import QUICK_TIMING, PerchingScript

        self.view = SimpleNamespace(onboard=onboard)
        self.mocap_in = mocap_in
        self.script = PerchingScript(
            timing=QUICK_TIMING if quick else None, cog=lambda _view: self.mocap_in.position
        )
        self.waiting_for_mocap = 0

    def tick(self, now: float) -> None:
        if self.mocap_in.position is None:
            self.waiting_for_mocap += 1
            return
        self.script(self.view, now)

    def report(self) -> dict[str, Any]:
        sc = self.script
        return {
            "phase": sc.phase,
            "t_contact": sc.t_contact,
            "t_perch": sc.t_perch,
            "waiting_for_mocap": self.waiting_for_mocap,
        }


class PerchStatusLog:
    """Counts of the perching QP's status every 25 ms (as the lockstep ``StatusNode``)."""

    name = "perch_status"
    period = 0.025

    def __init__(self, onboard: Any) -> None:
        self.onboard = onboard
        self.counts: dict[str, int] = {}

    def tick(self, now: float) -> None:
        c = self.onboard.last_command
        perch = getattr(c, "perch", None) if c is not None else None
        st = getattr(perch, "status", None) if perch is not None else None
        if st is not None:
            key = str(getattr(st, "name", st))
            self.counts[key] = self.counts.get(key, 0) + 1


class StateLog:
    """Onboard flight-state changes (time, state) for the report."""

    name = "state_log"
    period = 0.025

    def __init__(self, onboard: Any) -> None:
        self.onboard = onboard
        self.changes: list[tuple[float, str]] = []

    def tick(self, now: float) -> None:
        s = self.onboard.state.value
        if not self.changes or self.changes[-1][1] != s:
            self.changes.append((round(now, 4), s))


def onboard_main(cfg: dict[str, Any]) -> None:
    """The onboard node on the two pty slaves, mocap from the side channel, the script."""
    from rdm.link.serial import open_serial
    from rdm.model import Robot
    from rdm.nodes.onboard import OnboardNode
    from rdm.nodes.onboard_config import OnboardConfig
    from rdm.sim.side_channels import MocapReceiver

    folder = Path(cfg["out"])
    opt = SimpleNamespace(**cfg["stack"])
    robot = Robot.default()
    # The scenario's onboard configuration (hover: the defaults, Table V gains; perching:
    # perching.onboard_config()), with the initial joint angles of the plant (all zero).
    q0 = tuple([0.0] * robot.n_q)
    if cfg.get("scenario") == "perching":
        from rdm.scenarios.perching import onboard_config

        config = onboard_config(initial_q=q0)
    else:
        config = OnboardConfig(initial_q=q0)
    # Built before the handshake (its lazy imports cost seconds in the emulated VM); the ptys
    # are offered by the other children and arrive with the start line.
    uart_end, foot_end = LateLink(), LateLink()
    node = OnboardNode(uart_end, foot_end, robot, config=config)
    mocap_in = MocapReceiver(cfg["token"], node, opt.mocap_period)
    perching = cfg.get("scenario") == "perching"
    script: Any = (
        PerchingScriptNode(node, mocap_in, bool(cfg.get("quick")))
        if perching
        else HoverScript(node, cfg["target"], cfg["arm_at"])
    )
    log = StateLog(node)
    extra = [PerchStatusLog(node)] if perching else []
    start = _handshake({})
    uart = uart_end.attach(open_serial(f"serial:{start['spinal_pty']}"))
    foot = foot_end.attach(open_serial(f"serial:{start['leptrino_pty']}@460800"))
    clock, progress = _clock(start, "onboard", cfg["token"])
    stats = None
    try:
        stats = run_scaled(
            [mocap_in, node, script, log, *extra], clock, float(start["duration"]), progress
        )
    finally:
        node.close()
        status = node.status()
        status["command"] = None  # numpy-heavy; the truth has the outcome
        report = {
            "deadlines": stats.as_dict() if stats else {},
            "wall_s": round(stats.wall_s, 3) if stats else None,
            "mocap_applied": mocap_in.applied,
            "mocap_errors": mocap_in.errors,
            "armed_at": getattr(script, "armed_at", None),
            "states": log.changes,
            "perching": script.report() if perching else None,
            "perch_status_counts": extra[0].counts if perching else None,
            "status": status,
        }
        _write_report(folder, "onboard", report)
        mocap_in.close()
        uart.close()
        foot.close()


MAINS = {"robot": robot_main, "spinal": spinal_main, "onboard": onboard_main}


def main(argv: Sequence[str] | None = None) -> int:
    """Child entry point: ``python -m rdm.scenarios.process_roles ROLE CONFIG_JSON``."""
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 2 or args[0] not in MAINS:
        print(f"usage: python -m rdm.scenarios.process_roles {{{','.join(ROLES)}}} CONFIG_JSON")
        return 2
    cfg = json.loads(args[1])
    if os.environ.get("RDM_PROCESSES_PROFILE") == "1":  # cProfile of the role: <out>/<role>.prof
        import cProfile

        cProfile.runctx(
            "MAINS[args[0]](cfg)", globals(), locals(), str(Path(cfg["out"]) / f"{args[0]}.prof")
        )
    else:
        MAINS[args[0]](cfg)
    print(DONE, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
