"""Benchmark case ``onboard-loop``: ``rdm onboard`` as a process, its command period seen from
the other end of its UART.

The command runs as its own process (``rdm onboard --uart pty --foot-sensor none``);
this process is Spinal on the pty it prints: the rosserial client (the firmware's layout)
acks every ``flight_config_cmd`` and, once configured, publishes ``imu`` and
``servo/states`` every 10 ms; it is also the operator's station on the ground link
(``--control udp:127.0.0.1:PORT --insecure-control``): a motion-capture sample and a
heartbeat every 10 ms, ``arm`` and a ``goto`` to the hover point once Spinal is configured,
so the node runs its whole control tick (LQI, allocation) and sends ``four_axes/command``.
It waits on the pty with ``select`` and stamps each read with ``time.monotonic()`` the
moment it wakes, so the stamps resolve the node's output to the wake-up latency of this
process, not to a polling period.

Measurement ``onboard_loop``: the sample is the jitter ``|period - 25 ms|`` between two
consecutive arrivals of the node's per-tick output (``four_axes/command`` once armed; the
first :data:`WARMUP_S` seconds, handshake and arming, are left out). Target: p99 at most 1
ms. ``onboard_loop_rt`` is the same with ``--rt-priority 50 --mlock --gc-freeze`` (and this
process at SCHED_FIFO 49 while it measures); left out, with a note, when the OS refuses
them. ``onboard_loop_spin`` is the default loop with ``--spin-us 1000`` alone. Each
measurement's notes carry the command period (p50/p99/max) and, from the node's
final status, its UART-in to command-out latency (each control tick from its UART read to
the hand-over of its output to the port: the ``loop.tick`` histogram), its late ticks and
its dropped writes.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from rdm.bench.cases import Case, Context, Measurement, Target, register
from rdm.bench.statistics import percentiles, summarize_ns

#: The node's control period [s] (40 Hz).
PERIOD_S = 0.025
#: Seconds of each run left out at its start (handshake, arming).
WARMUP_S = 2.0
#: Command periods measured by a full / quick run.
PERIODS_FULL = 1200
PERIODS_QUICK = 200
#: The goal: p99 of the command-period jitter at most this many microseconds.
TARGET_P99_US = 1000.0
#: Options of the ``onboard_loop_rt`` run.
RT_OPTIONS = ("--rt-priority", "50", "--mlock", "--gc-freeze")
#: Options of the ``onboard_loop_spin`` run: the default loop polling the clock for the last
#: 1 ms before each tick (``--spin-us``), without the other real-time options.
SPIN_OPTIONS = ("--spin-us", "1000")
#: The peer's publishing interval [s].
PUBLISH_S = 0.01
#: ``rdm onboard``'s options in every run (the ground link's are added).
NODE_ARGS = ("--uart", "pty", "--foot-sensor", "none")
#: The topic whose arrivals time the node's ticks.
COMMAND_TOPIC = "four_axes/command"


@dataclass
class LoopRun:
    """One run: command arrival stamps [s], the node's final status, or why it failed."""

    arrivals: np.ndarray
    status: dict[str, Any] | None
    refused: str | None = None


class JitterMeasurement(Measurement):
    """A measurement whose target may be ``p99_us`` (an upper limit on the p99)."""

    def evaluate_targets(self) -> None:
        rest = []
        for t in self.targets:
            if t.kind == "p99_us":
                t.value = self.summary.p99_us
                t.met = t.value <= t.limit
            else:
                rest.append(t)
        kept, self.targets = self.targets, rest
        try:
            super().evaluate_targets()
        finally:
            self.targets = kept


def _read_line(proc: subprocess.Popen, prefix: str, timeout: float = 60.0) -> str | None:
    """The first stdout line starting with ``prefix`` (None if the process ends first)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stdout.readline()  # type: ignore[union-attr]
        if line.startswith(prefix):
            return line.strip()
        if not line and proc.poll() is not None:
            return None
    return None


def be_spinal(path: str, seconds: float, control: str, count: int | None = None) -> np.ndarray:
    """Be Spinal on the pty ``path`` and the operator on the ground link ``control`` for
    ``seconds``, or until ``count`` arrivals came after the warm-up; the arrival stamps of
    :data:`COMMAND_TOPIC` (``time.monotonic()`` at the read that completed each)."""
    from rdm.ground.client import GroundClient
    from rdm.protocol.rosserial import spinal_registry
    from rdm.protocol.rosserial.client import ClientSession
    from rdm.protocol.rosserial.events import MessageReceived

    reg = spinal_registry()
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    spinal = ClientSession.from_layout()
    state = reg.msg("spinal/ServoState")
    servo_states = reg.msg("spinal/ServoStates").new(
        servos=[state.new(index=i, angle=2048) for i in range(10)]
    )
    imu = reg.msg("spinal/Imu").new(quaternion=[0, 0, 0, 1])
    ack = reg.msg("std_msgs/UInt8")
    ground = GroundClient(control, None)
    mocap = {"position": [0.0, 0.0, 1.0], "velocity": [0.0, 0.0, 0.0], "yaw": 0.0}
    armed = False
    arrivals: list[float] = []
    pending = b""
    t0 = time.monotonic()
    next_publish = t0
    try:
        while True:
            now = time.monotonic()
            if now - t0 >= seconds:
                break
            if count and len(arrivals) >= count and arrivals[-count] >= arrivals[0] + WARMUP_S:
                break
            readable, _, _ = select.select([fd], [], [], max(0.0, next_publish - now))
            stamp = time.monotonic()
            data = b""
            if readable:
                try:
                    data = os.read(fd, 65536)
                except BlockingIOError:
                    data = b""
                except OSError:  # EIO: the node closed its end
                    break
            for e in spinal.spin(data, round((stamp - t0) * 1000)):
                if isinstance(e, MessageReceived):
                    if e.topic == COMMAND_TOPIC:
                        arrivals.append(stamp)
                    elif e.topic == "flight_config_cmd":
                        spinal.publish("flight_config_ack", ack.new(data=e.message.cmd))
            if stamp >= next_publish:
                next_publish += PUBLISH_S
                if spinal.configured:
                    spinal.publish("imu", imu)
                    spinal.publish("servo/states", servo_states)
                    ground.send(ground.datagram("mocap", mocap)[1])
                    ground.send(ground.datagram("heartbeat")[1])
                    if not armed:
                        ground.send(ground.datagram("arm")[1])
                        goto = {"position": mocap["position"], "yaw": 0.0}
                        ground.send(ground.datagram("goto", goto)[1])
                        armed = True
            pending += spinal.take_output()
            if pending:
                try:
                    pending = pending[os.write(fd, pending) :]
                except BlockingIOError:
                    pass
                except OSError:
                    break
    finally:
        os.close(fd)
        ground.close()
    return np.asarray(arrivals, dtype=np.float64)


@contextlib.contextmanager
def _fifo_peer(on: bool):
    """This process at SCHED_FIFO 49 while measuring (``on`` and permitted); yields whether."""
    if not on:
        yield False
        return
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(49))
    except OSError:
        yield False
        return
    try:
        yield True
    finally:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def run_onboard(
    seconds: float, options: tuple[str, ...] = (), fifo_peer: bool = False, count: int | None = None
) -> LoopRun:
    """``rdm onboard`` for ``seconds`` with ``options`` against :func:`be_spinal` (which
    stops after ``count`` arrivals past the warm-up); the node stops by SIGTERM."""
    control = f"udp:127.0.0.1:{_free_udp_port()}"
    command = [sys.executable, "-m", "rdm.cli", "onboard", *NODE_ARGS, "--control", control]
    command += ["--insecure-control", "--duration", f"{seconds + 1.0:g}", *options]
    # The flight recorder runs as on the robot (on by default), into a folder of its own.
    with tempfile.TemporaryFile("w+") as err_file, tempfile.TemporaryDirectory() as rec:
        command += ["--record", os.path.join(rec, "onboard")]
        proc = subprocess.Popen(
            command,
            stdout=subprocess.PIPE,
            stderr=err_file,  # the ground link's log: a file, so a full pipe never blocks it
            text=True,
            env=dict(os.environ, PYTHONUNBUFFERED="1"),
        )
        try:
            line = _read_line(proc, "rdm onboard: uart pty")
            if line is None or _read_line(proc, "rdm onboard: ready") is None:
                proc.wait(timeout=30)
                err_file.seek(0)
                err = err_file.read().strip().splitlines()
                return LoopRun(np.zeros(0), None, refused=err[-1] if err else "no output")
            with _fifo_peer(fifo_peer):
                arrivals = be_spinal(line.split()[-1], seconds, control, count)
            proc.send_signal(signal.SIGTERM)
            out, _err = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    status = None
    for text in reversed(out.strip().splitlines()):
        if text.startswith("{"):
            status = json.loads(text)
            break
    return LoopRun(arrivals, status)


def _ms(x: float | None) -> str:
    return "-" if x is None else f"{x:.3f}"


def _notes(run: LoopRun, periods: np.ndarray, options: tuple[str, ...]) -> list[str]:
    p50, p99 = percentiles(periods * 1e3, (50.0, 99.0))
    notes = [
        f"command period from the peer (ms): p50 {p50:.3f}, p99 {p99:.3f}, "
        f"min {periods.min() * 1e3:.3f}, max {periods.max() * 1e3:.3f}, n {periods.size}",
        "rdm onboard "
        + " ".join([*NODE_ARGS, "--control udp:127.0.0.1:PORT --insecure-control", *options]),
    ]
    s = run.status
    if s is not None:
        loop, tick = s["loop"], s["loop"]["tick"]
        notes.append(
            "UART-in to command-out in the node (loop.tick, ms): "
            f"p50 {_ms(tick['p50_ms'])}, p99 {_ms(tick['p99_ms'])}, max {_ms(tick['max_ms'])}"
        )
        jit = loop["period_jitter"]
        notes.append(
            f"node: {loop['late']} late ticks (> {loop['late_tolerance_ms']} ms) of "
            f"{s.get('ticks')}, overruns {s.get('overruns')}, own period jitter p99 "
            f"{_ms(jit['p99_ms'])} ms max {_ms(jit['max_ms'])} ms; UART writes dropped "
            f"{s['uart_writes']['dropped_writes']}; realtime {s['realtime']}"
        )
    return notes


def _measure(name: str, title: str, run: LoopRun, options: tuple[str, ...], n: int) -> Measurement:
    arrivals = run.arrivals[run.arrivals >= run.arrivals[0] + WARMUP_S]
    periods = np.diff(arrivals)[:n]
    if periods.size == 0:
        raise RuntimeError(f"{name}: no {COMMAND_TOPIC} arrived after the warm-up")
    jitter_ns = np.abs(periods - PERIOD_S) * 1e9
    return JitterMeasurement(
        name,
        title,
        summarize_ns(jitter_ns),
        TARGET_P99_US,
        0,
        [Target("p99_us", TARGET_P99_US)],
        {},
        _notes(run, periods, options),
    )


def run_onboard_loop(ctx: Context) -> list[Measurement]:
    """The default loop and the loop with the real-time options (if the OS grants them)."""
    n = ctx.iterations or (PERIODS_QUICK if ctx.quick else PERIODS_FULL)
    seconds = WARMUP_S + 1.5 * n * PERIOD_S + 5.0  # the run ends after n periods
    ctx.progress(f"onboard-loop: rdm onboard against a Spinal peer on a pty, {seconds:.0f} s")
    plain = run_onboard(seconds, count=n + 1)
    if plain.refused is not None or plain.arrivals.size < 2:
        raise RuntimeError(f"onboard-loop: rdm onboard did not run: {plain.refused}")
    out = [_measure("onboard_loop", "rdm onboard command-period jitter |T - 25 ms|", plain, (), n)]
    ctx.progress(f"onboard-loop: the same with {' '.join(RT_OPTIONS)}")
    rt = run_onboard(seconds, RT_OPTIONS, fifo_peer=True, count=n + 1)
    if rt.refused is not None or rt.arrivals.size < 2:
        out[0].notes.append(f"{' '.join(RT_OPTIONS)} not measured: {rt.refused}")
    else:
        out.append(
            _measure(
                "onboard_loop_rt",
                "the same, SCHED_FIFO + mlockall + gc.freeze",
                rt,
                RT_OPTIONS,
                n,
            )
        )
    ctx.progress(f"onboard-loop: the same with {' '.join(SPIN_OPTIONS)}")
    spin = run_onboard(seconds, SPIN_OPTIONS, count=n + 1)
    if spin.refused is not None or spin.arrivals.size < 2:
        raise RuntimeError(f"onboard-loop: rdm onboard {' '.join(SPIN_OPTIONS)}: {spin.refused}")
    out.append(
        _measure(
            "onboard_loop_spin",
            "the default loop with the clock polled for its last 1 ms",
            spin,
            SPIN_OPTIONS,
            n,
        )
    )
    return out


register(
    Case(
        "onboard-loop",
        "rdm onboard as a process: command-period jitter and UART-in to command-out",
        run_onboard_loop,
        ("onboard_loop", "onboard_loop_rt", "onboard_loop_spin"),
        (),
    )
)
