"""``rdm hil mission``: the operator's mission with the onboard PC as its own process.

::

    this process:   MuJoCo plant + Neuron bank (CAN) + Spinal mirror + Leptrino sensor, paced
                    at real time (lockstep, ``speed`` 1); Spinal's UART and the foot sensor on
                    ptys whose slaves the onboard process opens; motion capture as signed
                    ``pose`` datagrams (the marker body's pose, noise and latency); the
                    operator: ``rdm ctl`` processes (take-off, go-to, land) and one
                    ``rdm ctl --heartbeat``
    rdm onboard:    ``--uart serial:PTY --foot-sensor serial:PTY --control udp:... --key K``

The phases follow the ground truth as an operator watching the robot would: take off at
1.5 s; once the robot has held its height 1.5 s, the fault (if any) and the go-to; 2 s at the
goal; then (not ``quick``, no flight fault) ``joints`` to the hanging posture, ``perch``, once
in contact 1.5 s ``joints`` to move the arm and back, ``unperch``, ``joints`` to unfold; land.
Each joint motion counts as done when the joints are within 0.05 rad of their goal for 1 s.
``fault`` is one of :data:`FAULTS` (``foot-sensor-loss`` once perched; the run then ends held
perched); the run's record has the fields of :func:`rdm.scenarios.mission.outcome` plus the
onboard process's final status. The onboard process runs the configuration of the
hanging-posture experiments (``perching.onboard_config``, as a TOML file).
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from rdm.control import lqi
from rdm.ground.auth import load_key, write_key
from rdm.ground.client import GroundClient
from rdm.json_values import nulled

from . import perching
from .common import sim_stack_options, truth_arrays
from .mission import (
    GOTO_OFFSET,
    HOLD_PERCHED_S,
    MAX_TILT_DEG,
    PERCHED_ARM,
    PERCHED_FAULTS,
    SETTLE_S,
    TAKEOFF_HEIGHT,
)
from .mocap_node import MocapSensor
from .stack import DroppableLink, Stack, build_stack

ARM_AT = 1.5
HOLD_BEFORE_GOTO_S = 1.5
HOLD_AT_GOAL_S = 2.0
#: Within this of the go-to's goal (ground truth) counts as there, m: the flat posture's x loop
#: with Table V's gains swings about 0.1 m after a go-to (docs/flying.md).
GOAL_TOL = 0.2
#: The faults of the process-level mission (the lockstep mission's, and the ground link's).
FAULTS = (
    "none",
    "heartbeat-loss",  # the operator's heartbeat process dies
    "mocap-loss",  # the pose datagrams stop
    "uart-cut",  # Spinal's UART is cut for 0.3 s
    "low-battery",  # the battery sags to 3.4 V per cell
    "replayed-command",  # the take-off datagram is sent again (must change nothing)
    "garbage-datagram",  # 1000 '[' and random bytes to the control port
    "foot-sensor-loss",  # the foot sensor's line cut once perched (the node holds)
)
#: A joint motion is done once the joints are this close to the goal for ``JOINT_WAIT_S``.
JOINT_TOL = 0.05
JOINT_WAIT_S = 1.0
#: After ``unperch``: the path down (0.15 m) and a short hover before the unfold, s.
UNPERCH_S = 1.6
#: Longest wait for the contact after ``perch``, s (then the operator lands).
APPROACH_LIMIT_S = 15.0
#: The onboard process's configuration file: the hanging-posture experiments' gains and
#: perching parameters (``perching.POSITION_GAINS``, ``perching.PERCH_PARAMS``) and the LQI
#: weights the lockstep mission flies. ASSUMPTION: ``lqi.ROLL_DAMPED_Q`` (Table V rings the
#: straight posture's roll loop at 12 Hz under motion capture noise; docs/flying.md "The
#: hover's roll loop"), as the shipped ``rdm.toml``.
ONBOARD_TOML = f"""lqi_q_weights = {lqi.ROLL_DAMPED_Q.tolist()}

[position_gains]
k_roll = 1.0
y_pid = [3.0, 0.5, 4.0]

[perch_params]
epsilon_z = 8.0
"""


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Operator:
    """The mission's phases, run by the stack's script node every 10 ms."""

    kernel_touches = None

    def __init__(self, fault: str, quick: bool = False) -> None:
        #: the ``rdm ctl`` command line and the ground client; the phases wait for them
        self.ctl: list[str] = []
        self.quick = quick and fault not in PERCHED_FAULTS
        self.q_goal: np.ndarray | None = None
        self._phase_at = 0.0
        self._until: float | None = None
        self.client: Any = None
        self.fault = fault
        self.phase = "wait"
        self.procs: list[tuple[float, str, subprocess.Popen]] = []
        self.events: list[tuple[float, str]] = []
        self.max_duty = 0.0
        self._since: float | None = None
        self._retry_at = 0.0
        #: a signed ``land`` made at take-off and kept back: the replay fault sends it
        self.old_land: bytes | None = None
        self.fault_at: float | None = None
        self.heartbeat: subprocess.Popen | None = None
        self.done_at: float | None = None
        self.was_armed = False

    def _ctl(self, now: float, *words: str) -> None:
        proc = subprocess.Popen(
            [*self.ctl, *words], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        self.procs.append((now, " ".join(words), proc))
        self.events.append((round(now, 3), "rdm ctl " + " ".join(words)))

    def _status(self, word: str) -> str:
        """The last ``rdm ctl WORD``: "none", "running", "accepted" or "refused"."""
        for _, what, proc in reversed(self.procs):
            if what.split()[0] == word:
                code = proc.poll()
                return "running" if code is None else "accepted" if code == 0 else "refused"
        return "none"

    def __call__(self, stack: Stack, now: float) -> None:
        if not self.ctl:
            return
        self.max_duty = max([self.max_duty, *(stack.spinal.duties or [])])
        cog = stack.plant.ground_truth().cog_position
        if self.phase == "wait" and now >= ARM_AT:
            self._ctl(now, "takeoff", f"{TAKEOFF_HEIGHT}")
            self.old_land = self.client.datagram("land")[1]
            self.start_z = float(cog[2])
            self.phase = "takeoff"
        elif self.phase == "takeoff":
            at_height = abs(float(cog[2]) - self.start_z - TAKEOFF_HEIGHT) < 0.1
            self._since = (self._since or now) if at_height else None
            if self._since is not None and now - self._since >= HOLD_BEFORE_GOTO_S:
                if self.fault not in PERCHED_FAULTS:
                    self._inject(stack, now)
                self.goal = np.asarray(cog) + GOTO_OFFSET
                self.phase = "goto"
        elif self.phase == "goto":
            # retried each second while refused (not in hover yet) or before a fault's landing
            if self._status("goto") in ("none", "refused") and now >= self._retry_at:
                self._ctl(now, "goto", *(f"{v:.4f}" for v in self.goal), "0")
                self._retry_at = now + 1.0
            near = np.linalg.norm(np.asarray(cog) - self.goal) < GOAL_TOL
            self._since = (self._since or now) if near else None
            if self._since is not None and now - self._since >= HOLD_AT_GOAL_S:
                self._since = None
                if self.quick or self.fault_at is not None:
                    self._ctl(now, "land")
                    self.phase = "land"
                else:
                    self._joints(stack, now, perching.PERCH_POSTURE, "fold")
            elif self.fault_at is not None and now - self.fault_at > 8.0:
                self.phase = "land"  # the fault's reaction lands the robot
        elif self.phase in ("fold", "arm", "arm back", "unfold"):
            self._joint_phase(stack, now)
        elif self.phase == "approach":
            contact = stack.plant.ground_truth().foot_in_contact
            self._since = (self._since or now) if contact else None
            if self._since is not None and now - self._since >= SETTLE_S:
                self._since = None
                if self.fault in PERCHED_FAULTS:
                    self._inject(stack, now)
                    self.phase, self._until = "hold", now + HOLD_PERCHED_S
                else:
                    self._joints(stack, now, PERCHED_ARM, "arm")
            elif now - self._phase_at > APPROACH_LIMIT_S:
                self._ctl(now, "land")  # refused while perched: then unperch first
                self.phase = "land"
        elif self.phase == "unperch" and now - self._phase_at >= UNPERCH_S:
            self._joints(stack, now, (0.0,) * 6, "unfold")
        elif self.phase == "hold" and self._until is not None and now >= self._until:
            stack.loop.stop()  # held perched after the fault: the run's end
        if self.fault == "uart-cut" and self.fault_at is not None and now - self.fault_at > 0.3:
            stack.drop_uart(False)
        armed = stack.spinal.core.armed
        self.was_armed = self.was_armed or armed
        if self.was_armed and not armed and self.done_at is None:
            self.done_at = now  # disarmed after the take-off: landed, halted or crashed
        if self.done_at is not None and now - self.done_at >= 1.0:
            stack.loop.stop()  # a second on the floor is enough to judge the end

    def _joints(self, stack: Stack, now: float, q6: tuple[float, ...], phase: str) -> None:
        """``rdm ctl joints`` with the whole joint vector (q1..q6, the vectoring levelled)."""
        n_q = len(stack.plant.ground_truth().joint_positions)
        self.q_goal = perching.leveled(np.asarray(q6, dtype=float), n_q)
        self._ctl(now, "joints", *(f"{v:.5f}" for v in self.q_goal))
        self.phase, self._phase_at, self._since = phase, now, None

    def _joint_phase(self, stack: Stack, now: float) -> None:
        """Wait for the joints to reach their goal, then the next command."""
        assert self.q_goal is not None
        if self._status("joints") == "refused":
            self._ctl(now, "land")
            self.phase = "land"
            return
        q = np.asarray(stack.plant.ground_truth().joint_positions, dtype=float)
        reached = float(np.max(np.abs(q[:6] - self.q_goal[:6]))) < JOINT_TOL
        self._since = (self._since or now) if reached else None
        if self._since is None or now - self._since < JOINT_WAIT_S:
            return
        self._since = None
        if self.phase == "fold":
            self._ctl(now, "perch")
            self.phase, self._phase_at = "approach", now
        elif self.phase == "arm":
            self._joints(stack, now, perching.PERCH_POSTURE, "arm back")
        elif self.phase == "arm back":
            self._ctl(now, "unperch")
            self.phase, self._phase_at = "unperch", now
        else:  # unfold
            self._ctl(now, "land")
            self.phase = "land"

    def _inject(self, stack: Stack, now: float) -> None:
        if self.fault == "none":
            return
        self.fault_at = now
        self.events.append((round(now, 3), f"fault {self.fault}"))
        if self.fault == "heartbeat-loss" and self.heartbeat is not None:
            self.heartbeat.kill()
        elif self.fault == "mocap-loss":
            stack.mocap.enabled = False
        elif self.fault == "uart-cut":
            stack.drop_uart(True)
        elif self.fault == "low-battery":
            stack.bridge.set_battery(3.4 * 6)
        elif self.fault == "replayed-command" and self.old_land is not None:
            self.client.send(self.old_land)  # a land captured at take-off: old, refused
        elif self.fault == "garbage-datagram":
            self.client.send(b"[" * 1000)
            self.client.send(bytes(np.random.default_rng(0).integers(0, 256, 700, np.uint8)))
        elif self.fault == "foot-sensor-loss":  # the sensor's line cut: nothing reaches the PC
            stack.sensor.uart = DroppableLink(stack.sensor.uart)
            stack.sensor.uart.dropped = True

    def close(self) -> None:
        for _, _, proc in self.procs:
            if proc.poll() is None:
                proc.kill()
            proc.communicate()
        if self.heartbeat is not None and self.heartbeat.poll() is None:
            self.heartbeat.kill()
            self.heartbeat.communicate()


def _read_until(proc: subprocess.Popen, prefix: str, timeout: float) -> str:
    deadline = time.monotonic() + timeout
    assert proc.stdout is not None
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if line.startswith(prefix):
            return line.strip()
        if not line and proc.poll() is not None:
            break
    raise RuntimeError(f"rdm onboard did not print {prefix!r}")


#: Simulated seconds of the whole mission and of ``quick`` (take-off, go-to, land).
DURATION = 60.0
QUICK_DURATION = 24.0


def run(
    base: str | Path,
    fault: str = "none",
    seed: int = 0,
    duration: float | None = None,
    quick: bool = False,
) -> dict:
    """One process-level mission; returns its record (see the module doc)."""
    if fault not in FAULTS:
        raise ValueError(f"fault={fault!r}: one of {', '.join(FAULTS)}")
    if duration is None:
        duration = QUICK_DURATION if quick and fault not in PERCHED_FAULTS else DURATION
    opts = sim_stack_options(
        seed, "external", speed=1.0, mocap=MocapSensor(), lockstep_kernel=False
    )
    python = [sys.executable, "-m", "rdm.cli"]
    operator = Operator(fault, quick)
    stack = build_stack(f"hil-mission-{fault}", base, opts, operator)
    key_path = stack.folder.root / "ground.key"
    write_key(key_path)
    config_path = stack.folder.root / "onboard.toml"
    config_path.write_text(ONBOARD_TOML)
    port = _free_udp_port()
    to = f"udp:127.0.0.1:{port}"
    ctl = [*python, "ctl", "--to", to, "--key", str(key_path)]
    ext = stack.onboard
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    node = subprocess.Popen(
        [
            *python,
            "onboard",
            "--config",
            str(config_path),
            "--uart",
            f"serial:{ext.uart_path}",
            "--foot-sensor",
            f"serial:{ext.foot_path}@460800",
            "--control",
            to,
            "--key",
            str(key_path),
            "--servo-lead",
            f"{stack.onboard.config.servo_lead_s}",
            "--record",  # the flight recorder: rdm replay RUN_FOLDER
            str(stack.folder.root / "onboard"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    client = GroundClient(to, load_key(key_path), src="mocap")
    try:
        _read_until(node, "rdm onboard: ready", 60.0)
        ext.attach(client)
        operator.ctl, operator.client = ctl, client
        operator.heartbeat = subprocess.Popen(
            [*ctl, "--heartbeat", "5"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        t0 = time.monotonic()
        stack.loop.run(duration)
        wall = time.monotonic() - t0
    finally:
        operator.close()
        node.terminate()
        try:
            out, err = node.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            node.kill()
            out, err = node.communicate()
        client.close()
        stack.close()
    final = _last_json(out)
    record = _record(stack, operator, final, wall, err)
    # the run folder's summary is the record; then the folder is complete
    summary = json.dumps(nulled(record), indent=1, allow_nan=False)
    stack.folder.summary_json.write_text(summary + "\n", encoding="utf-8")
    stack.folder.mark_complete()
    return record


def _last_json(out: str) -> dict[str, Any]:
    for line in reversed(out.splitlines()):
        if line.startswith("{"):
            try:
                return json.loads(line)
            except ValueError:
                break
    return {}


def _record(stack: Stack, op: Operator, final: dict, wall: float, err: str) -> dict[str, Any]:
    a = truth_arrays(stack)
    t = a["t"]
    from .common import roll_pitch

    rp = np.degrees(np.abs(roll_pitch(a["quat"]))).max(axis=1)
    floor_z = float(a["cog"][np.searchsorted(t, ARM_AT) - 1, 2])
    airborne = a["cog"][:, 2] > floor_z + 0.05
    max_tilt = float(rp[airborne].max()) if airborne.any() else 0.0
    disarmed = final.get("flight_state") == "idle" and not stack.spinal.core.armed
    on_floor = abs(float(a["cog"][-1, 2]) - floor_z) < 0.05
    took_off = bool(airborne.any())
    perched = (
        not disarmed
        and final.get("flight_mode") == "perched"
        and final.get("perching") is True
        and bool(a["contact"][-1])
    )
    if max_tilt > MAX_TILT_DEG:
        outcome = "crashed"
    elif disarmed and on_floor and took_off:
        outcome = "landed"
    elif disarmed:
        outcome = "halted"
    elif perched:
        outcome = "perched"
    else:
        outcome = "airborne"
    monitors = final.get("monitors", {}).get("counts", {})
    link = final.get("ground_link", {})
    detected = {
        "none": None,
        "heartbeat-loss": bool(monitors.get("ground_lost")),
        "mocap-loss": bool(final.get("counts", {}).get("command_withheld")),
        "uart-cut": bool(monitors.get("spinal_silent")),
        # either battery monitor: the step down to 3.4 V/cell trips battery_sag first
        "low-battery": bool(monitors.get("battery_low") or monitors.get("battery_sag")),
        "replayed-command": "replayed" in json.dumps(link) or "stale" in json.dumps(link),
        "garbage-datagram": "too_deep" in json.dumps(link) or "malformed" in json.dumps(link),
        "foot-sensor-loss": bool(monitors.get("foot_stale")),
    }[op.fault]
    return {
        "outcome": outcome,
        "safe": outcome in ("landed", "perched") and op.max_duty <= 0.9375 + 1e-9,
        "fault": op.fault,
        "fault_detected": detected,
        "final_state": final.get("flight_state"),
        "max_tilt_deg": max_tilt,
        "max_duty": op.max_duty,
        "touchdown_s": next(
            (
                e["t"]
                for e in final.get("monitors", {}).get("events", [])
                if e["monitor"] == "touchdown"
            ),
            None,
        ),
        "wall_s": round(wall, 3),
        "operator": op.events,
        "monitors": monitors,
        "ground_link": link,
        "run_folder": str(stack.folder.root),
        "onboard_stderr_tail": err.splitlines()[-5:],
    }
