"""The hover scenario with the nodes as separate processes on real ports.

::

    robot process:   MuJoCo plant + PlantBridge + 4 NeuronMirror (CAN) + LeptrinoSensorNode
                     (pty master) + MocapSender; physics steps 1 ms at a time to catch up with
                     the shared clock
    spinal process:  SpinalMirror (CAN + the Spinal UART pty master) + ImuReceiver
    onboard process: OnboardNode (Spinal UART + Leptrino UART, the pty slaves) + MocapReceiver
                     + the hover script (target and arm at ``arm_at``)
    this process:    starts them, logs the CAN bus (candump ``can.log``), collects the results

CAN is any :func:`rdm.sim.udp_can.open_bus` spec: ``socketcan:vcan0`` (real kernel bus) or
``udp_multicast:<group>,port=N`` (hosts without SocketCAN). IMU and mocap travel on the side
channels of :mod:`rdm.sim.side_channels`. All processes share a :class:`ScaledClock` (common
epoch, ``scale`` simulated s per wall s); each writes ``<out>/<role>.json`` (deadline stats,
diagnostics) and the robot ``<out>/truth.npz`` (ground truth every 10 ms).

Start-up handshake (line-based, on each child's stdin/stdout): the child builds its nodes and
prints ``RDM-READY <json>`` (the pty path it offers); the parent answers one JSON line
``{"epoch": ..., "scale": ..., "duration": ...}``; the child runs until ``duration`` and prints
``RDM-DONE``. Child entry point: ``python -m rdm.sim.processes ROLE CONFIG_JSON``.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import queue
import secrets
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from rdm.sim.scaled_clock import ScaledClock, SharedTimes, WakeSocket, run_scaled

ROLES = ("robot", "spinal", "onboard")
READY = "RDM-READY "
DONE = "RDM-DONE"
#: The hover scenario's target and arming time (rdm.scenarios.hover).
HOVER_TARGET = (0.483, 0.0, 0.4)
ARM_AT = 1.5


@dataclass
class ProcessRunOptions:
    """What :func:`run_hover_processes` takes."""

    can: str = "socketcan:vcan0"
    #: ``hover`` (:class:`HoverScript`) or ``perching`` (:class:`rdm.scenarios.perching.
    #: PerchingScript` in the onboard process, ``perching.onboard_config()``).
    scenario: str = "hover"
    #: perching only: :data:`rdm.scenarios.perching.QUICK_TIMING` (contact at ~9 s, not ~14.8)
    quick: bool = False
    duration: float = 5.0
    #: Simulated seconds per wall second (0.05 = 20 wall s per simulated s).
    scale: float = 0.05
    seed: int = 0
    arm_at: float = ARM_AT
    target: tuple[float, float, float] = HOVER_TARGET
    #: Never let a controller's clock pass the time the robot process has produced its
    #: outputs for (shared through a memory-mapped file): a slow plant slows the run instead
    #: of lagging behind the controllers, and Spinal's 200 Hz control always sees the IMU
    #: sample of its own tick (as its SPI read on the board). False: a pure scaled wall
    #: clock (real-time behaviour; the IMU sample may then be one IMU period old).
    gate: bool = True
    #: Wall seconds between "all ready" and simulated time 0.
    start_margin_s: float = 1.0
    #: Wall seconds a child may take to import and build its nodes.
    startup_timeout_s: float = 300.0
    #: With ``gate``, the run may take this many times ``duration / scale`` (plus 2 min)
    #: before it is declared hung.
    max_slowdown: float = 4.0
    python: str = sys.executable
    candump: bool = True


@dataclass
class ProcessRun:
    """Results of a process-level run."""

    folder: Path
    options: ProcessRunOptions
    truth: dict[str, np.ndarray]
    reports: dict[str, dict[str, Any]]
    wall_s: float
    startup_wall_s: float
    metrics: dict[str, float] = field(default_factory=dict)

    @property
    def candump(self) -> Path:
        return self.folder / "can.log"


class ProcessRunError(RuntimeError):
    """A child failed to start, crashed, or overran the time budget (message has its log)."""


# ----------------------------------------------------------------------------- the roles
def stack_config(seed: int) -> dict[str, Any]:
    """The lockstep stack's defaults (:class:`rdm.scenarios.stack.StackOptions`) as plain data
    for the children, so that only the robot process imports MuJoCo and none imports the
    scenarios."""
    from rdm.scenarios.stack import StackOptions, spinal_flash_calibration

    opt = StackOptions(seed=seed)
    keys = (
        "seed",
        "ceiling_height",
        "floor_height",
        "base_position",
        "boot_delay_ms",
        "spinal_rate_hz",
        "gyro_calib_duration_s",
        "spinal_time_matched",
        "leptrino_rate_hz",
        "mocap_period",
        "truth_period",
        "esc_tau",
        "battery_voltage",
        "master_backend",
        "plant_sleep",
        "plant_contact_gate",
        "plant_lazy_sensors",
    )
    cfg = {k: getattr(opt, k) for k in keys}
    cfg["servo"] = None if opt.servo is None else asdict(opt.servo)
    cfg["spinal_flash"] = spinal_flash_calibration(opt)
    return cfg


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
    from rdm.sim.uart import TappedLink

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
        raise SystemExit("rdm.sim.processes: parent closed stdin before the start line")
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
        # the lockstep's CAN master (Rust by default) on this process's python-can bus
        master_backend=opt.master_backend,
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
            "can_master": type(spinal.master).__name__,
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


_MAINS = {"robot": robot_main, "spinal": spinal_main, "onboard": onboard_main}


# ----------------------------------------------------------------------------- the parent
class _Child:
    def __init__(self, role: str, cfg: dict[str, Any], python: str, folder: Path) -> None:
        import rdm

        root = str(Path(rdm.__file__).resolve().parents[1])
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
        self.role = role
        self.log_path = folder / f"{role}.log"
        self._log = open(self.log_path, "w")  # noqa: SIM115
        self.proc = subprocess.Popen(
            [python, "-m", "rdm.sim.processes", role, json.dumps(cfg)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self._log,
            text=True,
            env=env,
        )
        self.lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line)
        self.lines.put("")  # EOF

    def wait_ready(self, timeout: float) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise ProcessRunError(f"{self.role}: not ready after {timeout:g} s{self.tail()}")
            try:
                line = self.lines.get(timeout=min(left, 1.0))
            except queue.Empty:
                continue
            if line.startswith(READY):
                return json.loads(line[len(READY) :])
            if line == "":
                self.proc.wait(5)
                raise ProcessRunError(
                    f"{self.role}: exited ({self.proc.returncode}) before ready{self.tail()}"
                )

    def start(self, line: dict[str, Any]) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(json.dumps(line) + "\n")
        self.proc.stdin.flush()

    def tail(self, n: int = 25) -> str:
        self._log.flush()
        try:
            text = self.log_path.read_text().splitlines()[-n:]
        except OSError:
            text = []
        return "\n--- " + self.role + " log ---\n" + "\n".join(text) if text else ""

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)

    def close(self) -> None:
        self.kill()
        self._log.close()


def _candump_channel(spec: str) -> str:
    return spec.split(":", 1)[1].split(",")[0] if spec.startswith("socketcan:") else "can0"


SCENARIOS = ("hover", "perching")


def run_hover_processes(folder: str | Path, options: ProcessRunOptions) -> ProcessRun:
    """:func:`run_processes` (the name from when hover was the only scenario)."""
    return run_processes(folder, options)


def run_processes(folder: str | Path, options: ProcessRunOptions) -> ProcessRun:
    """Run ``options.scenario`` as three processes (module doc); raise
    :class:`ProcessRunError` if a child fails. Returns the ground truth, every child's report
    and the scenario's outcome (:func:`hover_outcome` or :func:`perching_outcome`)."""
    import can

    from rdm.sim.udp_can import open_bus

    opt = options
    if opt.scenario not in SCENARIOS:
        raise ValueError(f"scenario={opt.scenario!r}: one of {', '.join(SCENARIOS)}")
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    token = secrets.token_hex(6)
    base = {
        "out": str(out),
        "can": opt.can,
        "token": token,
        "stack": stack_config(opt.seed),
        "target": list(opt.target),
        "arm_at": opt.arm_at,
        "scenario": opt.scenario,
        "quick": opt.quick,
    }
    t0 = time.monotonic()
    children: dict[str, _Child] = {}
    notifier = writer = bus = None
    time_file: str | None = None
    try:
        for role in ROLES:  # in parallel: start-up is mostly imports
            children[role] = _Child(role, base, opt.python, out)
        ready = {r: c.wait_ready(opt.startup_timeout_s) for r, c in children.items()}
        if opt.candump:
            bus = open_bus(opt.can)
            writer = can.CanutilsLogWriter(out / "can.log", channel=_candump_channel(opt.can))
            notifier = can.Notifier(bus, [writer], timeout=0.2)
        startup = time.monotonic() - t0
        if opt.gate:
            fd, time_file = tempfile.mkstemp(prefix=f"rdm-{token}-", suffix=".time")
            os.close(fd)
            SharedTimes(time_file, SLOTS, init=(-1e-3, -math.inf, -math.inf)).close()
        epoch = time.monotonic() + opt.start_margin_s
        line = {
            "epoch": epoch,
            "scale": opt.scale,
            "duration": opt.duration,
            "spinal_pty": ready["spinal"]["spinal_pty"],
            "leptrino_pty": ready["robot"]["leptrino_pty"],
            "time_file": time_file,
        }
        for c in children.values():
            c.start(line)
        budget = opt.start_margin_s + opt.duration / opt.scale * opt.max_slowdown + 120.0
        deadline = time.monotonic() + budget
        running = dict(children)
        while running:  # any child failing ends the run at once
            for role, c in list(running.items()):
                rc = c.proc.poll()
                if rc is None:
                    continue
                if rc != 0:
                    raise ProcessRunError(f"{role}: exit status {rc}{c.tail()}")
                del running[role]
            if time.monotonic() > deadline:
                raise ProcessRunError(f"{sorted(running)}: still running after {budget:.0f} s")
            time.sleep(0.2)
        wall = time.monotonic() - epoch
    finally:
        if notifier is not None:
            notifier.stop()
        if writer is not None:
            writer.stop()
        if bus is not None:
            bus.shutdown()
        for c in children.values():
            c.close()
        if time_file is not None:
            with contextlib.suppress(OSError):
                os.unlink(time_file)
    reports = {r: json.loads((out / f"{r}.json").read_text()) for r in ROLES}
    truth = load_truth(out / "truth.npz")
    run = ProcessRun(out, opt, truth, reports, wall, startup)
    if opt.scenario == "perching":
        run.metrics = perching_outcome(
            truth, reports["onboard"]["perching"]["t_perch"], stack_ceiling()
        )
    else:
        run.metrics = hover_outcome(truth, np.asarray(opt.target), opt.arm_at, opt.duration)
    (out / "summary.json").write_text(
        json.dumps(
            {
                "options": asdict(opt),
                "metrics": run.metrics,
                "perching": reports["onboard"].get("perching"),
                "perch_status_counts": reports["onboard"].get("perch_status_counts"),
                "wall_s": round(wall, 3),
                "startup_wall_s": round(startup, 3),
                "deadlines": {r: reports[r]["deadlines"] for r in ROLES},
            },
            indent=1,
            default=str,
        )
    )
    return run


def load_truth(path: str | Path) -> dict[str, np.ndarray]:
    """The robot process's ``truth.npz`` as the arrays of
    :func:`rdm.scenarios.common.truth_arrays` (``t cog quat thrust contact force torque zmp
    slip foot q``; ``q`` = q1..q6)."""
    with np.load(path) as z:
        rows, foot = z["truth"], z["foot"]
    return {
        "t": rows[:, 0],
        "cog": rows[:, 1:4],
        "quat": rows[:, 4:8],
        "thrust": rows[:, 8:],
        "contact": foot[:, 0] > 0.5,
        "force": foot[:, 1:4],
        "torque": foot[:, 4:7],
        "zmp": foot[:, 7:9],
        "slip": foot[:, 9:11],
        "foot": foot[:, 11:14],
        "q": foot[:, 14:20],
    }


def stack_ceiling() -> float:
    """The ceiling height of the lockstep stack's defaults (the robot process's plant)."""
    from rdm.scenarios.stack import StackOptions

    h = StackOptions().ceiling_height
    return math.nan if h is None else float(h)


#: Perching outcome: contact is judged from this long after the perch switch (the contact
#: transient), as ``rdm.scenarios.perching``'s metrics.
PERCH_SETTLE_S = 0.5
#: Foot plate half sizes (Table IV, 0.10 x 0.15 m).
PLATE_HALF = (0.05, 0.075)


def perching_outcome(
    truth: dict[str, np.ndarray], t_perch: float | None, ceiling: float
) -> dict[str, float]:
    """The physical outcome of a perching run from ground truth (same numbers for lockstep
    and processes), from ``t_perch + 0.5 s`` to the end: perched (1/0), seconds held, the
    fraction of samples in contact, slip of the plate [mm], |mean foot height - ceiling|
    [mm], min ZMP margin to the plate edge [mm], min normal force [N], max |roll|,|pitch|
    after the perch [deg]. NaN where there is nothing to judge."""
    from rdm.scenarios.common import roll_pitch

    t = truth["t"]
    nan = math.nan
    held = t >= t_perch + PERCH_SETTLE_S if t_perch is not None else np.zeros(len(t), bool)
    out = {
        "perched": float(t_perch is not None),
        "t_perch": nan if t_perch is None else float(t_perch),
        "held_s": float(t[held][-1] - t[held][0]) if held.sum() > 1 else 0.0,
    }
    if not held.any():
        return out | dict.fromkeys(
            (
                "contact_kept",
                "slip_mm",
                "foot_height_err_mm",
                "min_zmp_margin_mm",
                "min_fz_n",
                "max_roll_pitch_deg_perched",
            ),
            nan,
        )
    slip = truth["slip"][held]
    zmp = truth["zmp"][held]
    with np.errstate(invalid="ignore"):
        margin = np.minimum(PLATE_HALF[0] - np.abs(zmp[:, 0]), PLATE_HALF[1] - np.abs(zmp[:, 1]))
    rp = np.degrees(np.abs(roll_pitch(truth["quat"][held])))
    return out | {
        "contact_kept": float(np.mean(truth["contact"][held])),
        "slip_mm": float(np.max(np.linalg.norm(slip - slip[0], axis=1)) * 1e3),
        "foot_height_err_mm": float(abs(np.mean(truth["foot"][held, 2]) - ceiling) * 1e3),
        "min_zmp_margin_mm": float(np.nanmin(margin) * 1e3) if np.isfinite(margin).any() else nan,
        "min_fz_n": float(np.min(truth["force"][held, 2])),
        "max_roll_pitch_deg_perched": float(np.max(rp)),
    }


def hover_outcome(
    truth: dict[str, np.ndarray], target: np.ndarray, arm_at: float, duration: float
) -> dict[str, float]:
    """The physical outcome of a hover run (same numbers for lockstep and processes): the
    worst |x|, |y|, |z| error of the CoG over the last second, the max |roll|,|pitch| after
    arming, the height gained, the final height."""
    from rdm.scenarios.common import roll_pitch

    t, cog = truth["t"], truth["cog"]
    last = t >= duration - 1.0
    err = np.abs(cog[last] - target) if last.any() else np.full((1, 3), np.nan)
    after = t > arm_at
    rp = np.degrees(np.abs(roll_pitch(truth["quat"][after]))) if after.any() else np.nan
    return {
        "max_abs_err_x_last1s": float(np.max(err[:, 0])),
        "max_abs_err_y_last1s": float(np.max(err[:, 1])),
        "max_abs_err_z_last1s": float(np.max(err[:, 2])),
        "max_roll_pitch_deg_after_arm": float(np.max(rp)),
        "climb_m": float(np.max(cog[:, 2]) - cog[0, 2]),
        "final_z": float(cog[-1, 2]),
    }


def main(argv: Sequence[str] | None = None) -> int:
    """Child entry point: ``python -m rdm.sim.processes ROLE CONFIG_JSON``."""
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 2 or args[0] not in _MAINS:
        print(f"usage: python -m rdm.sim.processes {{{','.join(ROLES)}}} CONFIG_JSON")
        return 2
    cfg = json.loads(args[1])
    if os.environ.get("RDM_PROCESSES_PROFILE") == "1":  # cProfile of the role: <out>/<role>.prof
        import cProfile

        cProfile.runctx(
            "_MAINS[args[0]](cfg)", globals(), locals(), str(Path(cfg["out"]) / f"{args[0]}.prof")
        )
    else:
        _MAINS[args[0]](cfg)
    print(DONE, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
