"""``rdm neuron``: run one or several Neuron board mirrors in real time on a CAN bus.

Example: ``rdm neuron --can socketcan:vcan0 --slave-id 1 2 3 4 --servos 2 --gimbals 1 --imu``
(four Neurons, two servos each, servo 0 without send_data_flag: a HYDRUS_XI-like robot).
Each Neuron opens its own bus object, as separate boards would. Stops on Ctrl-C / SIGTERM or
after ``--duration`` seconds, then prints one summary line per Neuron.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from rdm.commands.arg_types import positive_finite
from rdm.link.can import CanSpecError, CanUnavailableError, open_can
from rdm.nodes.base import run_realtime
from rdm.nodes.neuron_mirror import NeuronMirror
from rdm.nodes.servo_model import ServoConfig


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--can", required=True, help="bus spec: socketcan:vcan0, virtual:name")
    parser.add_argument(
        "--slave-id", type=int, nargs="+", required=True, metavar="N", help="slave ids 1..14"
    )
    parser.add_argument("--servos", type=int, default=1, help="servos per Neuron, 0..4")
    parser.add_argument(
        "--gimbals",
        type=int,
        default=0,
        help="how many of them (the first ones) have no send_data_flag (gimbal servos)",
    )
    parser.add_argument("--imu", action="store_true", help="set the IMU send flag")
    parser.add_argument("--no-esc", action="store_true", help="Neurons without an ESC")
    parser.add_argument("--period", type=float, default=0.001, help="tick period, s")
    parser.add_argument(
        "--duration", type=positive_finite, default=None, help="stop after this many s"
    )


def run(args: argparse.Namespace) -> int:
    if not 0 <= args.servos <= 4 or not 0 <= args.gimbals <= args.servos:
        print("rdm neuron: need 0 <= --gimbals <= --servos <= 4", file=sys.stderr)
        return 2
    if len(set(args.slave_id)) != len(args.slave_id):
        print(f"rdm neuron: duplicate slave ids {args.slave_id}", file=sys.stderr)
        return 2
    if not args.period > 0:
        print("rdm neuron: --period must be > 0", file=sys.stderr)
        return 2
    servos = [
        ServoConfig(dynamixel_id=i + 1, send_data_flag=i >= args.gimbals)
        for i in range(args.servos)
    ]
    nodes: list[NeuronMirror] = []
    try:
        for slave in args.slave_id:
            bus = open_can(args.can)
            try:
                node = NeuronMirror(
                    bus, slave, servos, imu=args.imu, esc=not args.no_esc, period=args.period
                )
            except BaseException:
                bus.shutdown()  # a refused board leaves no bus open behind it
                raise
            nodes.append(node)
    except (CanSpecError, CanUnavailableError, ValueError) as exc:
        for node in nodes:
            node.close()
        print(f"rdm neuron: {exc}", file=sys.stderr)
        return 2
    stop = threading.Event()
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
    print(f"rdm neuron: ready slaves={args.slave_id} on {args.can}", flush=True)
    try:
        stats = run_realtime(nodes, duration=args.duration, stop=stop)
    finally:
        for node in nodes:
            node.close()
    for node in nodes:
        print(
            f"{node.name}: ticks {stats.ticks[node.name]} overruns {stats.overruns[node.name]} "
            f"rx {node.rx_count} tx {node.tx_count} rx_errors {dict(node.rx_errors)} "
            f"tx_errors {node.tx_errors} pwm {node.esc.value}",
            flush=True,
        )
    return 0
