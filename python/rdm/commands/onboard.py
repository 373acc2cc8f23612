"""``rdm onboard``: run the onboard-PC node in real time (rosserial server to Spinal, 40 Hz
position/perching control, LQI gain synthesis).

Examples::

    rdm onboard --uart serial:/dev/flight_controller --foot-sensor serial:/dev/ttyACM0@460800
    rdm onboard --uart pty --foot-sensor none --control udp:127.0.0.1:7301 --key robot.key
    rdm onboard --config robot.toml

``--config FILE`` reads the node's whole configuration and its ports from a TOML file
(:mod:`rdm.nodes.onboard_config_file`; ``rdm config example`` prints the shipped one,
``rdm config check FILE`` the resolved result); the options given on the command line
override it.

``--uart pty`` / ``--foot-sensor pty`` create pseudo-terminals and print the path the other
side (a Spinal mirror, a sensor mirror) must open. ``--control udp:HOST:PORT --key FILE``
opens the ground link (:mod:`rdm.ground`, docs/flying.md): signed commands from
``rdm ctl``, acknowledged, with a heartbeat (``--ground-timeout``). Without ``--key`` the
port is refused unless ``--insecure-control`` says so explicitly (unsigned datagrams are then
accepted; a warning is printed). Stops on Ctrl-C / SIGTERM or after ``--duration`` seconds;
prints a JSON status line every ``--status-interval`` seconds and at exit (the ground link's
counts under ``ground_link``).

The loop (docs/onboard.md, "The real-time loop"): the status carries ``loop`` (late ticks
past ``late_tolerance_s``, p50/p99/max of tick duration, lateness, command period and its
jitter), ``uart_writes`` (the UART is written without blocking: backlog and dropped writes)
and ``realtime`` (``--rt-priority N``, ``--cpu K``, ``--mlock``, ``--gc-freeze``,
``--spin-us N``; an option the OS refuses ends the command with a one-line message).

The flight recorder (docs/onboard.md, "Flight recorder and replay";
:mod:`rdm.commands.onboard_record`) writes every UART and foot-sensor byte and every input
into ``--record DIR`` (default ``runs/onboard-<UTC time>``; ``--no-record``, ``--replace``,
``--record-max-mb``), with copies of the robot description and the ``--config`` file and the
loop's timing histograms; ``rdm replay DIR`` reproduces the node's output bytes from it.

``--robot`` takes a shipped name or the path of a description's TOML file (its URDF beside
it, same stem).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import signal
import sys
import threading
from dataclasses import replace
from typing import Any

from rdm.commands.arg_types import positive_finite
from rdm.commands.live import OnboardLive, add_live_arguments, start_live
from rdm.commands.onboard_record import (
    SignalLog,
    add_record_arguments,
    mcap_available,
    open_recorder,
    record_datagrams,
    write_loop_timing,
)
from rdm.ground.heartbeat import GROUND_TIMEOUT_S
from rdm.link.serial import SerialLink, SerialSpecError, open_pty_pair, open_serial
from rdm.nodes.base import run_realtime
from rdm.nodes.loop_timing import LoopTiming
from rdm.nodes.realtime_os import RealtimeOptionError, apply_realtime_options

#: Bytes of Spinal-bound output the UART backlog holds before a tick's output is dropped
#: (about 0.18 s of the 921600 baud line).
UART_BACKLOG_BYTES = 16384


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--config",
        default=None,
        help="TOML configuration file (rdm config example; every OnboardConfig field and "
        "[ports]); the options below override it",
    )
    parser.add_argument(
        "--uart", default=None, help="Spinal UART: serial:/dev/...[@baud] | pty (or ports.uart)"
    )
    parser.add_argument(
        "--foot-sensor",
        default=None,
        help="Leptrino foot sensor: serial:/dev/ttyACM0@460800 | pty | none "
        "(default: ports.foot_sensor, else none)",
    )
    parser.add_argument(
        "--robot",
        default="rdm",
        help="shipped robot (rdm, the default, or rcm) or the path of a robot TOML (its urdf "
        "key names the URDF beside it)",
    )
    parser.add_argument(
        "--rate", type=float, default=None, help="control rate, Hz (default: rate_hz, 40)"
    )
    parser.add_argument(
        "--lqi-every",
        type=int,
        default=None,
        help="synthesize LQI gains every N ticks (default: lqi_every, 1)",
    )
    parser.add_argument(
        "--servo-lead",
        type=float,
        default=None,
        help="send trajectory servo goals S s ahead (feed-forward for the servos' lag; "
        "default: servo_lead_s, 0 = the paper's; identify it: docs/scenarios.md, "
        "'Servo goals ahead of the plan')",
    )
    parser.add_argument(
        "--control", default=None, help="udp:HOST:PORT of the ground link (rdm ctl --to)"
    )
    parser.add_argument("--key", default=None, help="the ground link's key file (rdm ctl keygen)")
    parser.add_argument(
        "--insecure-control",
        action="store_true",
        help="accept unsigned control datagrams (no --key; anyone on the network can command)",
    )
    parser.add_argument(
        "--ground-timeout",
        type=positive_finite,
        default=GROUND_TIMEOUT_S,
        help=f"s without the ground station before on_ground_lost (default {GROUND_TIMEOUT_S})",
    )
    parser.add_argument("--arm", action="store_true", help="start the arming sequence at once")
    parser.add_argument(
        "--duration", type=positive_finite, default=None, help="stop after this many s"
    )
    parser.add_argument(
        "--status-interval", type=float, default=0.0, help="print status every S s (0: at exit)"
    )
    parser.add_argument(
        "--late-tolerance",
        type=float,
        default=None,
        help="s after its due time a tick counts late (default: late_tolerance_s, 0.002)",
    )
    parser.add_argument(
        "--rt-priority",
        type=int,
        default=None,
        help="run the loop under SCHED_FIFO at this priority (1..99)",
    )
    parser.add_argument("--cpu", type=int, default=None, help="pin the process to this CPU")
    parser.add_argument("--mlock", action="store_true", help="lock the process's memory (mlockall)")
    parser.add_argument(
        "--gc-freeze",
        action="store_true",
        help="gc.freeze() after setup: the collector skips what setup made",
    )
    parser.add_argument(
        "--spin-us",
        type=_spin_us,
        default=0,
        metavar="N",
        help=f"poll the clock for the last N us before each tick instead of sleeping through "
        f"them (0..{MAX_SPIN_US}; one CPU stays busy N us per tick; default 0: sleep)",
    )
    add_record_arguments(parser)
    add_live_arguments(parser, "rdm onboard")


#: The longest spin ``--spin-us`` takes: a fifth of the 25 ms control period.
MAX_SPIN_US = 5000


def _spin_us(text: str) -> int:
    """``--spin-us``: an integer 0..MAX_SPIN_US."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: not an integer") from None
    if not 0 <= v <= MAX_SPIN_US:
        raise argparse.ArgumentTypeError(f"{v} must be 0..{MAX_SPIN_US}")
    return v


def _configuration(args: argparse.Namespace) -> Any:
    """The node's :class:`OnboardConfig`: ``--config FILE`` (or the defaults), then the
    options given on the command line over it; the file's ports fill the port options left
    out (``args`` is updated; ``args.loaded`` keeps the loaded file). ValueError names the
    file and field, or the option."""
    from rdm.nodes.onboard_config import OnboardConfig
    from rdm.nodes.onboard_config_file import load_onboard_file

    config = OnboardConfig()
    if args.config is not None:
        args.loaded = load_onboard_file(args.config)
        config, ports = args.loaded.config, args.loaded.ports
        if args.uart is None:
            args.uart = ports.uart
        if args.foot_sensor is None:
            args.foot_sensor = ports.foot_sensor
        if args.control is None:
            args.control = ports.control
        if args.key is None and not args.insecure_control:
            args.key = ports.key
    if args.uart is None:
        raise ValueError("--uart is required (or ports.uart in the --config file)")
    if args.foot_sensor is None:
        args.foot_sensor = "none"
    overrides = {
        name: value
        for name, value in (
            ("rate_hz", args.rate),
            ("lqi_every", args.lqi_every),
            ("servo_lead_s", args.servo_lead),
            ("late_tolerance_s", args.late_tolerance),
        )
        if value is not None
    }
    return replace(config, **overrides) if overrides else config


def _open(spec: str, what: str) -> tuple[SerialLink, Any]:
    """(link the node uses, object to keep alive); a pty prints its openable path."""
    if spec == "pty":
        slave, master = open_pty_pair()
        print(f"rdm onboard: {what} pty {slave.port.port}", flush=True)
        return master, slave
    if what == "foot-sensor" and spec.startswith("serial:") and "@" not in spec:
        spec += "@460800"  # Leptrino USB CDC default (fact sheet sec. 5)
    return open_serial(spec), None


def _control_key(args: argparse.Namespace) -> bytes | None:
    """The ground link's key (None: no port, or ``--insecure-control``); ValueError (a key
    file refused, an insecure port not asked for) names the argument and the rule."""
    from rdm.ground.auth import load_key

    if args.control is None:
        if args.key or args.insecure_control:
            raise ValueError("--key/--insecure-control: only with --control udp:HOST:PORT")
        return None
    if args.key and args.insecure_control:
        raise ValueError("--key and --insecure-control exclude each other")
    if not args.key and not args.insecure_control:
        raise ValueError(
            "--control needs --key FILE (rdm ctl keygen FILE); an unauthenticated port "
            "needs --insecure-control"
        )
    return load_key(args.key) if args.key else None


def _control_port(args: argparse.Namespace, node: Any, key: bytes | None) -> Any:
    """The ground link's port for ``--control`` (None without it)."""
    from rdm.ground.ee import EePlanner
    from rdm.ground.port import GroundLinkConfig, GroundPort

    if args.control is None:
        return None
    if key is None:
        print(
            f"rdm onboard: WARNING: --insecure-control: {args.control} accepts unsigned "
            "commands from anyone who can reach it",
            file=sys.stderr,
            flush=True,
        )
    return GroundPort.bind(
        args.control,
        node,
        key,
        config=GroundLinkConfig(ground_timeout_s=args.ground_timeout),
        planner=EePlanner(args.robot),
        log=lambda line: print(f"rdm onboard: ground link: {line}", file=sys.stderr, flush=True),
    )


def _status(node: Any, timing: LoopTiming, uart: SerialLink, realtime: dict) -> dict:
    """The node's status with the loop's figures, the UART writes and the OS settings."""
    status = node.status()
    status["loop"] = timing.status()
    status["uart_writes"] = {
        "nonblocking": uart.backlog_limit is not None,
        "backlog_bytes": len(uart.backlog),
        "dropped_writes": uart.dropped_writes,
        "dropped_bytes": uart.dropped_bytes,
    }
    status["realtime"] = realtime
    return status


class _StatusPrinter:
    name = "onboard_status"

    def __init__(self, status: Any, period: float) -> None:
        self.status, self.period = status, period

    def tick(self, now: float) -> None:
        print(json.dumps(self.status()), flush=True)


def run(args: argparse.Namespace) -> int:
    from rdm.model import robot_source
    from rdm.nodes.onboard import OnboardNode
    from rdm.nodes.onboard_config_file import resolve_for_robot

    keep: list[Any] = []
    links: list[SerialLink] = []
    control = None
    recorder = None
    signals = None
    live = None
    try:
        config = _configuration(args)
        key = _control_key(args)
        source = robot_source(args.robot)
        robot = source.robot()
        if args.config is not None:
            config = resolve_for_robot(replace(args.loaded, config=config), robot)
        elif config.motor_num != robot.n_rotors:  # no file: uav_info follows the robot
            config = replace(config, motor_num=robot.n_rotors)
        uart, k = _open(args.uart, "uart")
        links.append(uart)
        keep.append(k)
        with contextlib.suppress(ValueError):  # a URL port (no descriptor) keeps blocking
            uart.nonblocking_writes(UART_BACKLOG_BYTES)
        foot = None
        if args.foot_sensor != "none":
            foot, k = _open(args.foot_sensor, "foot-sensor")
            links.append(foot)
            keep.append(k)
        node = OnboardNode(uart, foot, robot, config=config)
        if args.live:
            live = start_live(args, "rdm onboard", advertise=OnboardLive.advertise(node))
        recorder = open_recorder(args, node, source)
        timing = LoopTiming(node.period, config.late_tolerance_s)
        realtime: dict[str, Any] = {}
        nodes: list[Any] = []
        control = _control_port(args, node, key)
        if control is not None:
            nodes.append(control)
            if recorder is not None:
                record_datagrams(control, recorder)
        nodes.append(node)
        if recorder is not None:
            if mcap_available():
                signals = SignalLog(node, recorder, timing)
                nodes.append(signals)
            else:
                print(
                    "rdm onboard: the recording holds no signals.mcap: it needs the sim extra "
                    '(pip install "rdm[sim]"); the byte captures and the journal are complete',
                    file=sys.stderr,
                    flush=True,
                )
        if live is not None:
            nodes.append(OnboardLive(node, live))
        if args.status_interval > 0:
            nodes.append(
                _StatusPrinter(lambda: _status(node, timing, uart, realtime), args.status_interval)
            )
        realtime.update(
            apply_realtime_options(args.rt_priority, args.cpu, args.mlock, args.gc_freeze)
        )
        realtime["spin_us"] = args.spin_us
    except (SerialSpecError, OSError, ValueError, RealtimeOptionError) as exc:
        if control is not None:
            control.close()
        if recorder is not None:
            recorder.close(reason=f"rdm onboard did not start: {exc}")
        if live is not None:
            live.close()
        for link in [*links, *(k for k in keep if k is not None)]:
            link.close()
        print(f"rdm onboard: {exc}", file=sys.stderr)
        return 2
    if args.arm:
        node.arm()
    stop = threading.Event()
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
    print(f"rdm onboard: ready robot={args.robot} rate={config.rate_hz} Hz", flush=True)
    failure: str | None = "rdm onboard ended by an error"
    try:
        stats = run_realtime(
            nodes,
            duration=args.duration,
            stop=stop,
            timing={node.name: timing},
            spin=args.spin_us * 1e-6,
        )
        failure = None
    finally:
        node.close()
        if signals is not None:
            signals.close()
        if recorder is not None:
            write_loop_timing(recorder, timing)
            recorder.close(reason=failure)
        if control is not None:
            control.close()
        if live is not None:
            live.close()
        for link in links:
            link.close()
        for k in keep:
            if k is not None:
                k.close()
    status = _status(node, timing, uart, realtime)
    status["ticks"] = stats.ticks.get(node.name, 0)
    status["overruns"] = stats.overruns.get(node.name, 0)
    if control is not None:
        status["ground_link"] = control.status()
    print(json.dumps(status), flush=True)
    return 0
