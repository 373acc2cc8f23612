"""``rdm onboard``: run the onboard-PC node in real time (rosserial server to Spinal, 40 Hz
position/perching control, LQI gain synthesis).

Examples::

    rdm onboard --uart serial:/dev/flight_controller --foot-sensor serial:/dev/ttyACM0@460800
    rdm onboard --uart pty --foot-sensor none --control udp:127.0.0.1:7301

``--uart pty`` / ``--foot-sensor pty`` create pseudo-terminals and print the path the other
side (a Spinal mirror, a sensor mirror) must open. ``--control udp:HOST:PORT`` takes one JSON
object per datagram with any of the keys ``mocap`` ({"position", "velocity", "yaw"}),
``target`` ({"position", "yaw", "velocity"}), ``joint_targets`` (list), ``trajectory``
([[t, q], ...], node time), ``perch`` (bool), ``arm`` / ``disarm`` / ``force_landing`` (true).
Stops on Ctrl-C / SIGTERM or after ``--duration`` seconds; prints a JSON status line every
``--status-interval`` seconds and at exit.
"""

from __future__ import annotations

import argparse
import json
import signal
import socket
import sys
import threading
from typing import Any

from rdm.commands.arg_types import positive_finite
from rdm.link.serial import SerialLink, SerialSpecError, open_pty_pair, open_serial
from rdm.nodes.base import run_realtime


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--uart", required=True, help="Spinal UART: serial:/dev/...[@baud] | pty")
    parser.add_argument(
        "--foot-sensor",
        default="none",
        help="Leptrino foot sensor: serial:/dev/ttyACM0@460800 | pty | none (default)",
    )
    parser.add_argument("--robot", default="rdm", help="shipped robot: rdm (default) or rcm")
    parser.add_argument("--rate", type=float, default=40.0, help="control rate, Hz (paper: 40)")
    parser.add_argument(
        "--lqi-every", type=int, default=1, help="synthesize LQI gains every N ticks (default 1)"
    )
    parser.add_argument(
        "--servo-lead",
        type=float,
        default=0.0,
        help="send trajectory servo goals S s ahead (feed-forward for the servos' lag; "
        "0 = the paper's; identify it, docs/servolead.md)",
    )
    parser.add_argument("--control", default=None, help="udp:HOST:PORT for JSON commands")
    parser.add_argument("--arm", action="store_true", help="start the arming sequence at once")
    parser.add_argument(
        "--duration", type=positive_finite, default=None, help="stop after this many s"
    )
    parser.add_argument(
        "--status-interval", type=float, default=0.0, help="print status every S s (0: at exit)"
    )


def _open(spec: str, what: str) -> tuple[SerialLink, Any]:
    """(link the node uses, object to keep alive); a pty prints its openable path."""
    if spec == "pty":
        slave, master = open_pty_pair()
        print(f"rdm onboard: {what} pty {slave.port.port}", flush=True)
        return master, slave
    if what == "foot-sensor" and spec.startswith("serial:") and "@" not in spec:
        spec += "@460800"  # Leptrino USB CDC default (fact sheet sec. 5)
    return open_serial(spec), None


class ControlPort:
    """UDP JSON commands applied to the node between its ticks (a Node of its own)."""

    name = "onboard_control"

    def __init__(self, spec: str, node: Any) -> None:
        host, _, port = spec.removeprefix("udp:").rpartition(":")
        if not host or not port.isdigit():
            raise ValueError(f"--control {spec!r}: expected udp:HOST:PORT")
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, int(port)))
        self.sock.setblocking(False)
        self.node = node
        self.period = node.period
        self.errors = 0

    def tick(self, now: float) -> None:
        for _ in range(1000):
            try:
                data = self.sock.recv(65536)
            except BlockingIOError:
                return
            try:
                self.apply(json.loads(data))
            except (ValueError, TypeError, KeyError, AttributeError):
                self.errors += 1

    def apply(self, cmd: dict[str, Any]) -> None:
        n = self.node
        if "mocap" in cmd:
            m = cmd["mocap"]
            n.set_mocap(m["position"], m["velocity"], m.get("yaw"))
        if "target" in cmd:
            g = cmd["target"]
            n.set_target(g["position"], g.get("yaw", 0.0), g.get("velocity"))
        if "joint_targets" in cmd:
            n.set_joint_targets(cmd["joint_targets"])
        if "trajectory" in cmd:
            n.set_trajectory([(t, q) for t, q in cmd["trajectory"]])
        if "perch" in cmd:
            n.request_perch(bool(cmd["perch"]))
        for key in ("arm", "disarm", "force_landing"):
            if cmd.get(key):
                getattr(n, key)()

    def close(self) -> None:
        self.sock.close()


class _StatusPrinter:
    name = "onboard_status"

    def __init__(self, node: Any, period: float) -> None:
        self.node, self.period = node, period

    def tick(self, now: float) -> None:
        print(json.dumps(self.node.status()), flush=True)


def run(args: argparse.Namespace) -> int:
    from rdm.model import Robot
    from rdm.nodes.onboard import OnboardNode
    from rdm.nodes.onboard_config import OnboardConfig

    keep: list[Any] = []
    links: list[SerialLink] = []
    try:
        robot = Robot.shipped(args.robot)
        config = OnboardConfig(
            rate_hz=args.rate, lqi_every=args.lqi_every, servo_lead_s=args.servo_lead
        )
        uart, k = _open(args.uart, "uart")
        links.append(uart)
        keep.append(k)
        foot = None
        if args.foot_sensor != "none":
            foot, k = _open(args.foot_sensor, "foot-sensor")
            links.append(foot)
            keep.append(k)
        node = OnboardNode(uart, foot, robot, config=config)
        nodes: list[Any] = []
        control = None
        if args.control:
            control = ControlPort(args.control, node)
            nodes.append(control)
        nodes.append(node)
        if args.status_interval > 0:
            nodes.append(_StatusPrinter(node, args.status_interval))
    except (SerialSpecError, OSError, ValueError) as exc:
        for link in links:
            link.close()
        print(f"rdm onboard: {exc}", file=sys.stderr)
        return 2
    if args.arm:
        node.arm()
    stop = threading.Event()
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
    print(f"rdm onboard: ready robot={args.robot} rate={args.rate} Hz", flush=True)
    try:
        stats = run_realtime(nodes, duration=args.duration, stop=stop)
    finally:
        node.close()
        if control is not None:
            control.close()
        for link in links:
            link.close()
        for k in keep:
            if k is not None:
                k.close()
    status = node.status()
    status["ticks"] = stats.ticks.get(node.name, 0)
    status["overruns"] = stats.overruns.get(node.name, 0)
    print(json.dumps(status), flush=True)
    return 0
