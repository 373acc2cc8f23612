"""``rdm spinal``: run a Spinal flight-controller mirror in real time on a UART and a CAN bus.

Examples::

    rdm spinal --uart pty --can socketcan:vcan0          # prints the pty path for the PC side
    rdm spinal --uart serial:/dev/ttyUSB0@921600 --can socketcan:can0 --rate 1000

The mirror is the rosserial *client* on the UART (the PC runs the server), the Neuron CAN
master on the bus, and the on-board estimator / attitude controller at ``--rate`` Hz. With no
plant attached the IMU reads level and still. Stops on Ctrl-C / SIGTERM or after
``--duration`` seconds and prints one JSON line of diagnostics.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading

from rdm.commands.arg_types import positive_finite
from rdm.link.can import CanSpecError, CanUnavailableError, open_can
from rdm.link.serial import SerialSpecError, open_pty_pair, open_serial
from rdm.nodes.base import run_realtime
from rdm.nodes.can_master import BOOT_DELAY_MS
from rdm.nodes.spinal_mirror import DEFAULT_BATTERY_V, MAX_RATE_HZ, SpinalMirror


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--uart",
        required=True,
        help="UART spec: pty (prints the path for the PC side), serial:/dev/ttyUSB0@921600, "
        "loop://, socket://host:port",
    )
    parser.add_argument("--can", required=True, help="bus spec: socketcan:vcan0, virtual:name")
    parser.add_argument(
        "--rate", type=float, default=200.0, help=f"control rate, Hz (<= {MAX_RATE_HZ:g})"
    )
    parser.add_argument(
        "--boot-delay-ms",
        type=int,
        default=BOOT_DELAY_MS,
        help="wait before CAN enumeration (firmware HAL_Delay(5000))",
    )
    parser.add_argument(
        "--battery", type=float, default=DEFAULT_BATTERY_V, help="battery voltage read, V"
    )
    parser.add_argument(
        "--time-matched",
        action="store_true",
        help="rescale the estimator filters to the firmware's 1 kHz time constants",
    )
    parser.add_argument(
        "--period",
        type=float,
        default=0.001,
        help="tick period, s (1 ms = the firmware's core task; longer on slow hosts: the CAN "
        "schedule still covers every ms, in bursts)",
    )
    parser.add_argument(
        "--duration", type=positive_finite, default=None, help="stop after this many s"
    )


def _open_uart(spec: str):
    """The mirror's link and the path a peer opens (pty), or the spec itself."""
    if spec.strip() == "pty":
        slave, master = open_pty_pair()
        path = slave.port.port
        slave.port.close()  # the peer opens the slave by path; we keep only the master
        slave.peer = None
        return master, path
    return open_serial(spec), spec


def run(args: argparse.Namespace) -> int:
    if not 0 < args.rate <= MAX_RATE_HZ:
        print(f"rdm spinal: --rate must be in (0, {MAX_RATE_HZ:g}]", file=sys.stderr)
        return 2
    if not 0 < args.period <= 0.1:
        print("rdm spinal: --period must be in (0, 0.1] s", file=sys.stderr)
        return 2
    if args.boot_delay_ms < 0:
        print("rdm spinal: --boot-delay-ms must be >= 0", file=sys.stderr)
        return 2
    try:
        uart, uart_name = _open_uart(args.uart)
    except (SerialSpecError, OSError) as exc:
        print(f"rdm spinal: {exc}", file=sys.stderr)
        return 2
    try:
        bus = open_can(args.can)
    except (CanSpecError, CanUnavailableError, ValueError) as exc:
        uart.close()
        print(f"rdm spinal: {exc}", file=sys.stderr)
        return 2
    try:
        mirror = SpinalMirror(
            uart,
            bus,
            args.rate,
            period=args.period,
            boot_delay_ms=args.boot_delay_ms,
            time_matched=args.time_matched,
        )
    except ValueError as exc:  # refused: no bus or port left open behind it
        bus.shutdown()
        uart.close()
        print(f"rdm spinal: {exc}", file=sys.stderr)
        return 2
    mirror.set_battery_voltage(args.battery)
    stop = threading.Event()
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
    print(
        f"rdm spinal: ready uart={uart_name} can={args.can} rate={args.rate:g} pid={os.getpid()}",
        flush=True,
    )
    try:
        stats = run_realtime([mirror], duration=args.duration, stop=stop)
    finally:
        mirror.close()
    summary = mirror.diagnostics()
    summary["realtime"] = {
        "ticks": stats.ticks[mirror.name],
        "overruns": stats.overruns[mirror.name],
    }
    print(f"rdm spinal: stopped {json.dumps(summary, default=str)}", flush=True)
    return 0
