"""``--live``, ``--live-host``, ``--live-port`` of ``rdm sim`` and ``rdm onboard``: a Foxglove
WebSocket server with the run's signal channels (:mod:`rdm.sim.live`; docs/sim.md "Live
telemetry")."""

from __future__ import annotations

import argparse
import importlib.util
import sys
from typing import Any, Literal

#: The defaults of rdm.sim.live (kept here so that the base install parses the options
#: without importing the sim package). ASSUMPTION: loopback and Foxglove's default port.
DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765


def _port(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if not 0 <= v <= 65535:
        raise argparse.ArgumentTypeError(f"{text!r} must be in 0..65535 (0: any free port)")
    return v


def add_live_arguments(parser: argparse.ArgumentParser, prog: str) -> None:
    """The live telemetry options of ``prog``."""
    parser.add_argument(
        "--live",
        action="store_true",
        help="serve the signal channels live to Foxglove Studio (Foxglove WebSocket; needs "
        "the sim extra); off by default",
    )
    parser.add_argument(
        "--live-host",
        default=DEFAULT_HOST,
        metavar="HOST",
        help=f"address the --live server binds (default {DEFAULT_HOST}: this computer only)",
    )
    parser.add_argument(
        "--live-port",
        type=_port,
        default=DEFAULT_PORT,
        metavar="PORT",
        help=f"port of the --live server (default {DEFAULT_PORT}; 0: any free port)",
    )


def live_missing(prog: str) -> str | None:
    """The one-line message of ``--live`` on an install without the ``sim`` extra, else
    None."""
    if all(importlib.util.find_spec(m) is not None for m in ("foxglove", "mcap")):
        return None
    return (
        f"{prog}: --live needs the simulator extra (foxglove-sdk and mcap are not both "
        'installed): pip install "rdm[sim]" (from a source tree: pip install ".[sim]")'
    )


def start_live(
    args: argparse.Namespace, prog: str, advertise: dict[str, Any] | None = None
) -> Any | None:
    """The :class:`rdm.sim.live.LivePublisher` of ``--live`` (None without it), its
    ``advertise`` channels made before it serves; ValueError with a one-line message when
    it cannot start (missing extra, port taken)."""
    if not getattr(args, "live", False):
        return None
    missing = live_missing(prog)
    if missing is not None:
        raise ValueError(missing.split(": ", 1)[1])
    from rdm.sim.live import LiveError, LivePublisher, layout_path

    try:
        live = LivePublisher(args.live_host, args.live_port, name=prog, advertise=advertise)
    except LiveError as exc:
        raise ValueError(str(exc)) from None
    print(
        f"{prog}: live telemetry on ws://{live.host}:{live.port} (Foxglove Studio: Open "
        f"connection, Foxglove WebSocket); layout: {layout_path()}",
        file=sys.stderr,
        flush=True,
    )
    return live


def open_live(args: argparse.Namespace, prog: str) -> Any | Literal[False] | None:
    """:func:`start_live`, or False after its message on stderr: the command then exits 2."""
    try:
        return start_live(args, prog)
    except ValueError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return False


#: Seconds between two live records of ``rdm onboard --live`` (20 Hz).
ONBOARD_LIVE_PERIOD_S = 0.05


class OnboardLive:
    """A node of ``rdm onboard --live``, run after the onboard node's tick (it reads the
    node and writes nothing to it, so it is off the actuator path): the node's status on
    ``/onboard/status`` (as the flight recorder's ``signals.mcap`` holds it) and its
    controller signals on ``/onboard/signals`` (as ``rdm sim``'s), each built only while a
    client is subscribed to it. A failure of the publisher prints one line and turns it off;
    the loop goes on."""

    name = "onboard_live"

    def __init__(self, node: Any, live: Any, period: float = ONBOARD_LIVE_PERIOD_S) -> None:
        from rdm.nodes.onboard_signals import onboard_signals

        self.node, self.live, self.period = node, live, period
        self._signals = onboard_signals
        self.errors = 0

    @staticmethod
    def advertise(node: Any) -> dict[str, Any]:
        """The example records of the channels (for :func:`start_live`'s ``advertise``)."""
        from rdm.nodes.onboard_signals import onboard_signals

        return {
            "/onboard/status": node.status(),
            "/onboard/signals": onboard_signals(node, 0.0),
        }

    def tick(self, now: float) -> None:
        live = self.live
        if live is None:
            return
        try:
            if live.wants("/onboard/status"):
                live.log_json("/onboard/status", now, self.node.status())
            if live.wants("/onboard/signals"):
                live.log_json("/onboard/signals", now, self._signals(self.node, now))
        except Exception as exc:
            self.errors += 1
            self.live = None
            print(f"rdm onboard: live telemetry off after an error: {exc!r}", file=sys.stderr)
