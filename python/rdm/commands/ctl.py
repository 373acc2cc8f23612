"""``rdm ctl``: the operator's end of the ground link (docs/flying.md, "The ground link").

Examples::

    rdm ctl keygen robot.key
    rdm ctl --to udp:192.168.1.20:7301 --key robot.key arm
    rdm ctl --to udp:192.168.1.20:7301 --key robot.key takeoff 1.0
    rdm ctl --to udp:192.168.1.20:7301 --key robot.key goto 0.5 0 1.0 0
    rdm ctl --to udp:192.168.1.20:7301 --key robot.key --heartbeat 5

One command: sends it signed, waits for its ack, prints the ack as JSON; exit 0 accepted,
1 rejected, 2 bad arguments or no ack. ``--heartbeat HZ`` sends heartbeats until Ctrl-C.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import threading
import time
from typing import Any

from rdm.commands.arg_types import positive_finite

#: The positional values of the commands that take some.
USAGE = {
    "takeoff": "HEIGHT",
    "goto": "X Y Z YAW",
    "joints": "Q1 ... Q6 (or every joint)",
    "perch": "[SPEED]",
    "gains": "PROFILE",
    "ee": "X Y Z",
    "mocap": "X Y Z (or --json with velocity, yaw)",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``ctl``'s options."""
    parser.add_argument(
        "cmd",
        nargs="?",
        help="takeoff, land, halt, force_landing, arm, disarm, goto, joints, perch, unperch, "
        "gains, mocap, ee, status, heartbeat; or keygen FILE",
    )
    parser.add_argument("params", nargs="*", help="the command's values (see docs/flying.md)")
    parser.add_argument("--to", help="the robot's control port, udp:HOST:PORT")
    parser.add_argument("--key", help="the shared key file (rdm ctl keygen FILE)")
    parser.add_argument(
        "--insecure", action="store_true", help="send unsigned (robot run with --insecure-control)"
    )
    parser.add_argument("--json", dest="args_json", help="the command's args as a JSON object")
    parser.add_argument("--src", help="sender name (default ctl-HOST-PID)")
    parser.add_argument(
        "--timeout", type=positive_finite, default=0.5, help="seconds per try (default 0.5)"
    )
    parser.add_argument("--retries", type=int, default=2, help="resends (default 2)")
    parser.add_argument(
        "--plan-timeout",
        type=positive_finite,
        default=30.0,
        help="seconds to wait for an ee plan (default 30)",
    )
    parser.add_argument(
        "--heartbeat", type=positive_finite, metavar="HZ", help="send heartbeats until Ctrl-C"
    )


class _BadArgs(Exception):
    pass


def _numbers(cmd: str, params: list[str], count: int | None) -> list[float]:
    """``params`` as finite floats: exactly ``count`` of them (None: at least one)."""
    if (len(params) != count) if count is not None else not params:
        want = count if count is not None else "at least 1"
        raise _BadArgs(f"{cmd}: expected {want} numbers ({USAGE[cmd]}), got {len(params)}")
    out = []
    for p in params:
        try:
            v = float(p)
        except ValueError:
            raise _BadArgs(f"{cmd}: {p!r} is not a number") from None
        if not math.isfinite(v):
            raise _BadArgs(f"{cmd}: {p!r} is not finite")
        out.append(v)
    return out


def command_args(cmd: str, params: list[str], args_json: str | None) -> dict[str, Any]:
    """The ``args`` object of ``cmd`` from its positional values or ``--json``."""
    from rdm.ground.commands import check_args
    from rdm.ground.message import Rejected

    if args_json is not None:
        if params:
            raise _BadArgs(f"{cmd}: give the values either as words or with --json, not both")
        try:
            args = json.loads(args_json)
        except (ValueError, RecursionError) as exc:
            raise _BadArgs(f"--json: not JSON ({exc})") from None
        if not isinstance(args, dict):
            raise _BadArgs("--json: must be a JSON object")
    elif cmd == "takeoff":
        args = {"height": _numbers(cmd, params, 1)[0]}
    elif cmd == "goto":
        v = _numbers(cmd, params, 4)
        args = {"position": v[:3], "yaw": v[3]}
    elif cmd == "joints":
        args = {"q": _numbers(cmd, params, None)}
    elif cmd == "perch" and params:
        args = {"speed": _numbers(cmd, params, 1)[0]}
    elif cmd in ("ee", "mocap"):
        args = {"position": _numbers(cmd, params, 3)}
    elif cmd == "gains":
        if len(params) != 1:
            raise _BadArgs(f"gains: expected one PROFILE name, got {len(params)} words")
        args = {"profile": params[0]}
    elif params:
        raise _BadArgs(f"{cmd}: takes no values, got {' '.join(params)!r}")
    else:
        args = {}
    try:
        check_args(cmd, args)
    except Rejected as exc:
        raise _BadArgs(f"{exc.reason.value}: {exc.detail}") from None
    return args


def _keygen(params: list[str]) -> int:
    from rdm.ground.auth import write_key

    if len(params) != 1:
        print("rdm ctl: keygen: expected one FILE", file=sys.stderr)
        return 2
    try:
        write_key(params[0])
    except FileExistsError:
        print(f"rdm ctl: keygen: {params[0]} exists; not overwritten", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"rdm ctl: keygen: {params[0]}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    print(f"rdm ctl: wrote key file {params[0]} (mode 0600)", file=sys.stderr)
    return 0


def _client(args: argparse.Namespace) -> Any:
    from rdm.ground.auth import load_key
    from rdm.ground.client import GroundClient

    if not args.to:
        raise _BadArgs("--to udp:HOST:PORT is required")
    if args.insecure and args.key:
        raise _BadArgs("--insecure and --key exclude each other")
    if not args.insecure and not args.key:
        raise _BadArgs("--key FILE is required (or --insecure for an insecure robot)")
    if args.retries < 0:
        raise _BadArgs("--retries must be >= 0")
    key = None if args.insecure else load_key(args.key)  # KeyFileError: a ValueError
    return GroundClient(
        args.to, key, src=args.src, timeout_s=args.timeout, retries=args.retries,
        plan_timeout_s=args.plan_timeout,
    )  # fmt: skip


def _heartbeat(client: Any, hz: float) -> int:
    """Send heartbeats at ``hz`` until SIGINT/SIGTERM; report ack loss on stderr."""
    stop = threading.Event()
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
    sent = acked = 0
    last_ack = time.monotonic()
    silent = False
    print(f"rdm ctl: heartbeat at {hz:g} Hz as {client.src}; Ctrl-C stops", file=sys.stderr)
    while not stop.is_set():
        _, data = client.datagram("heartbeat")
        try:
            client.send(data)
            sent += 1
        except OSError as exc:
            print(f"rdm ctl: heartbeat: {exc.strerror or exc}", file=sys.stderr)
        for ack in client.poll_acks():
            if ack["outcome"] == "accepted":
                acked += 1
                last_ack = time.monotonic()
            else:
                print(f"rdm ctl: heartbeat rejected: {ack.get('reason')}", file=sys.stderr)
        quiet = time.monotonic() - last_ack > max(1.0, 3.0 / hz)
        if quiet != silent:
            silent = quiet
            print(
                "rdm ctl: heartbeat: no ack from the robot"
                if quiet
                else "rdm ctl: heartbeat: the robot answers again",
                file=sys.stderr,
            )
        stop.wait(1.0 / hz)
    print(json.dumps({"heartbeats_sent": sent, "acked": acked}), flush=True)
    return 0


def run(args: argparse.Namespace) -> int:
    """Send one command (or keygen, or heartbeats); exit 0 accepted, 1 rejected, 2 else."""
    from rdm.ground.client import AckTimeout

    if args.cmd == "keygen":
        return _keygen(args.params)
    try:
        if args.heartbeat is None and args.cmd is None:
            raise _BadArgs("a command is required (or --heartbeat HZ, or keygen FILE)")
        if args.heartbeat is not None and args.cmd is not None:
            raise _BadArgs("--heartbeat sends heartbeats only; give no command")
        cmd_args = None if args.cmd is None else command_args(args.cmd, args.params, args.args_json)
        client = _client(args)
    except (_BadArgs, ValueError) as exc:
        print(f"rdm ctl: {exc}", file=sys.stderr)
        return 2
    try:
        if args.heartbeat is not None:
            return _heartbeat(client, args.heartbeat)
        try:
            ack = client.command(args.cmd, cmd_args)
        except AckTimeout as exc:
            print(f"rdm ctl: {exc} (is the robot running, --to right, the key the same?)",
                  file=sys.stderr)  # fmt: skip
            return 2
        except OSError as exc:
            print(f"rdm ctl: {args.to}: {exc.strerror or exc}", file=sys.stderr)
            return 2
        print(json.dumps(ack), flush=True)
        return 0 if ack["outcome"] == "accepted" else 1
    finally:
        client.close()
