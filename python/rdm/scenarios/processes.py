"""A scenario with its nodes as separate processes on real ports (``rdm hil``).

Three children (:mod:`rdm.scenarios.process_roles`: robot, Spinal, onboard) are started at
once; this process logs the CAN bus (candump ``can.log``) and collects the results.

CAN is any :func:`rdm.sim.udp_can.open_bus` spec: ``socketcan:vcan0`` (real kernel bus) or
``udp_multicast:<group>,port=N`` (hosts without SocketCAN). IMU and mocap travel on the side
channels of :mod:`rdm.sim.side_channels`. All processes share a :class:`ScaledClock` (common
epoch, ``scale`` simulated s per wall s); each child writes ``<out>/<role>.json`` (deadline
stats, diagnostics) and the robot ``<out>/truth.npz`` (ground truth every 10 ms).
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
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rdm.scenarios.process_roles import READY, ROLES, SLOTS
from rdm.sim.scaled_clock import SharedTimes

#: The hover scenario's target and arming time (rdm.scenarios.hover).
HOVER_TARGET = (0.483, 0.0, 0.4)
ARM_AT = 1.5


@dataclass
class ProcessRunOptions:
    """What :func:`run_processes` takes."""

    can: str = "socketcan:vcan0"
    #: ``hover`` (:class:`rdm.scenarios.process_roles.HoverScript`) or ``perching``
    #: (:class:`rdm.scenarios.perching.PerchingScript` in the onboard process,
    #: ``perching.onboard_config()``).
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


def stack_config(seed: int) -> dict[str, Any]:
    """The lockstep stack's defaults (:class:`rdm.scenarios.stack.StackOptions`) as plain data
    for the children (JSON on their command line), so that only the robot process imports
    MuJoCo."""
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
        "plant_sleep",
        "plant_contact_gate",
        "plant_lazy_sensors",
    )
    cfg = {k: getattr(opt, k) for k in keys}
    cfg["servo"] = None if opt.servo is None else asdict(opt.servo)
    cfg["spinal_flash"] = spinal_flash_calibration(opt)
    return cfg


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
            [python, "-m", "rdm.scenarios.process_roles", role, json.dumps(cfg)],
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
