"""The ``rdm`` command line.

Each sub-command lives in its own module under :mod:`rdm.commands` and is imported only
when it runs, so ``rdm --help`` stays fast and a command's heavy dependencies (MuJoCo,
scipy) load only for the commands that need them. The base install carries what the onboard
node and the ground link import (``rdm onboard``, ``rdm ctl``, ``rdm config``); a command
that needs an optional extra (``sim``: ``rdm sim``, ``rdm hil``, ``rdm spinal``, ...) and
finds it missing prints one line with the install command and exits 2.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence

#: Modules of an optional extra (``pyproject.toml``) -> (extra, what it is). A command whose
#: import or run fails on one of them says which extra to install (:func:`missing_extra`).
OPTIONAL_MODULES: dict[str, tuple[str, str]] = {
    "mujoco": ("sim", "the simulator extra"),
    "matplotlib": ("sim", "the simulator extra"),
    "scipy": ("sim", "the simulator extra"),
    "mcap": ("sim", "the simulator extra"),
    "msgpack": ("sim", "the simulator extra"),
    "clarabel": ("bench", "the benchmark extra"),
    "osqp": ("bench", "the benchmark extra"),
}

#: Exit code of a command that needs an optional extra that is not installed.
MISSING_EXTRA_EXIT = 2

#: Exit code when stdout's reader closed the pipe early: what a shell reports for a process
#: killed by SIGPIPE (128 + 13), as `seq 1 1000000 | head -1` leaves in PIPESTATUS.
BROKEN_PIPE_EXIT = 141

# name -> (module under rdm.commands, one-line help). Keep sorted by name.
COMMANDS: dict[str, tuple[str, str]] = {
    "bench": (
        "bench",
        "measure the real-time core against its 200 Hz and 40 Hz budgets and against peers",
    ),
    "config": ("config", "check an onboard configuration file and print it resolved"),
    "ctl": ("ctl", "send a signed command to rdm onboard over the ground link and print its ack"),
    "decode": ("decode", "decode a UART capture, candump log or Leptrino capture"),
    "design": ("design", "reachability/feasibility sweep reproducing Tables II-III"),
    "hil": (
        "hil",
        "fly the hover or perching scenario with the nodes as separate processes on real ports",
    ),
    "model": ("model", "load a robot and print its mass properties, allocation and aerial ZMP"),
    "neuron": ("neuron", "run a Neuron board mirror on a CAN bus"),
    "onboard": (
        "onboard",
        "run the onboard-PC node: rosserial server, 40 Hz position/perching control, LQI",
    ),
    "plan": ("plan", "plan an end-effector motion (differential-kinematics planner, Sec. V)"),
    "plant": ("plant", "build the MuJoCo model of a robot; export it for MuJoCo's viewer"),
    "replay": (
        "replay",
        "feed a flight recording of rdm onboard through the node and compare its output bytes",
    ),
    "sim": (
        "sim",
        "run the paper's experiments on the simulated robot with every byte on its wire",
    ),
    "spinal": ("spinal", "run a Spinal flight-controller mirror on a UART and a CAN bus"),
}


def build_parser() -> argparse.ArgumentParser:
    """Build the top-level parser; sub-command modules add their own arguments."""
    from rdm import __version__

    parser = argparse.ArgumentParser(
        prog="rdm",
        description="Control, planning and HIL stack for rotor-distributed aerial manipulators.",
    )
    parser.add_argument("--version", action="version", version=f"rdm {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (_module, help_text) in COMMANDS.items():
        sub.add_parser(name, help=help_text, add_help=False)
    return parser


def missing_extra(command: str, exc: ModuleNotFoundError) -> str | None:
    """The one line for ``command`` failing on a module of an optional extra (None: the
    module is none of :data:`OPTIONAL_MODULES`, a real error)."""
    top = (exc.name or "").split(".")[0]
    if top not in OPTIONAL_MODULES:
        return None
    extra, what = OPTIONAL_MODULES[top]
    return (
        f"rdm {command}: needs {what} ({top} is not installed): "
        f'pip install "rdm[{extra}]" (from a source tree: pip install ".[{extra}]")'
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``rdm`` console script; returns the process exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    if not argv or argv[0] not in COMMANDS:
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help()
            return 2
    name = argv[0]
    try:
        module = importlib.import_module(f"rdm.commands.{COMMANDS[name][0]}")
        cmd_parser = argparse.ArgumentParser(prog=f"rdm {name}", description=COMMANDS[name][1])
        module.add_arguments(cmd_parser)
        return int(module.run(cmd_parser.parse_args(argv[1:])) or 0)
    except ModuleNotFoundError as exc:
        line = missing_extra(name, exc)
        if line is None:
            raise
        print(line, file=sys.stderr)
        return MISSING_EXTRA_EXIT
    except BrokenPipeError:
        # The reader of our output went away (`rdm decode x.log | head`): stop quietly, as
        # a Unix filter does, and keep Python from failing again on the exit-time flush.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return BROKEN_PIPE_EXIT


if __name__ == "__main__":
    raise SystemExit(main())
