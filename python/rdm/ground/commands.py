"""The command table of the ground link: each command's arguments, their rules and the node
method it calls.

| command | args | node call |
|---|---|---|
| ``takeoff`` | ``height`` (m, > 0) | ``takeoff(height)`` |
| ``land`` / ``halt`` / ``force_landing`` / ``arm`` / ``disarm`` | none | same name |
| ``goto`` | ``position`` [x, y, z] m, ``yaw`` rad | ``goto(position, yaw)`` |
| ``joints`` | ``q`` (6 or all joints, rad) | ``move_joints(q)`` (jerk-limited path) |
| ``perch`` | optional ``speed`` (m/s, > 0) | ``perch(speed)`` (approach, contact, perched) |
| ``unperch`` | none | ``unperch()`` |
| ``gains`` | ``profile`` (name) | ``set_gain_profile(profile)`` |
| ``mocap`` | ``position`` [3], optional ``velocity`` [3], ``yaw`` | ``set_mocap(p, v, yaw)`` |
| ``pose`` | marker ``position`` [3] m, ``quaternion`` [x, y, z, w] | ``set_mocap_pose(p, q)`` |
| ``status`` | none | the ack's ``result`` is ``status()`` |
| ``heartbeat`` | none | nothing (refreshes the heartbeat) |
| ``ee`` | ``position`` [x, y, z] m, foot frame | planned (``rdm.ground.ee``) |

Every number must be finite and not a boolean; unknown argument names are refused (a
misspelt ``heigth`` must not become a default). A node without the method answers
``unsupported``; a method returning ``False`` or a reason string answers ``refused`` (with
that reason); a method raising answers ``node_error``. Limits beyond these rules
(geofence, altitude, joint ranges) are the node's: it refuses what its configuration does
not allow.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

from rdm.ground.message import Reason, Rejected, as_finite, json_safe

#: Most joint values in one ``joints`` command.
MAX_JOINTS = 32
_PROFILE = re.compile(r"[A-Za-z0-9_.\-]{1,64}")

Args = dict[str, Any]


def _bad(cmd: str, name: str, rule: str) -> Rejected:
    return Rejected(Reason.BAD_ARGS, f"{cmd}.{name}: {rule}")


def _only(cmd: str, args: Args, allowed: tuple[str, ...], required: tuple[str, ...]) -> None:
    for name in args:
        if name not in allowed:
            rule = f"unknown argument (allowed: {', '.join(allowed) or 'none'})"
            raise _bad(cmd, name[:32], rule)
    for name in required:
        if name not in args:
            raise _bad(cmd, name, "missing")


def number(cmd: str, args: Args, name: str, positive: bool = False) -> float:
    """``args[name]`` as a finite float (> 0 if ``positive``), else ``bad_args``."""
    x = as_finite(args[name])
    if x is None:
        raise _bad(cmd, name, "must be a finite number")
    if positive and not x > 0:
        raise _bad(cmd, name, "must be > 0")
    return x


def vector(cmd: str, args: Args, name: str, n: int | None, most: int = MAX_JOINTS) -> list[float]:
    """``args[name]`` as a list of ``n`` (or 1..``most``) finite floats, else ``bad_args``."""
    x = args[name]
    size = f"{n}" if n is not None else f"1-{most}"
    if not isinstance(x, list) or not (len(x) == n if n is not None else 1 <= len(x) <= most):
        raise _bad(cmd, name, f"must be a list of {size} finite numbers")
    out = []
    for v in x:
        f = as_finite(v)
        if f is None:
            raise _bad(cmd, name, f"must be a list of {size} finite numbers")
        out.append(f)
    return out


def call(node: Any, method: str, *a: Any) -> Any:
    """``node.method(*a)``: ``unsupported`` if missing, ``refused`` if it returns False or
    a reason (a string), ``node_error`` if it raises (the node's fault must not end the
    port); otherwise its result."""
    fn = getattr(node, method, None)
    if not callable(fn):
        raise Rejected(Reason.UNSUPPORTED, f"the node has no {method}()")
    try:
        result = fn(*a)
    except Exception as exc:  # any node fault is answered, counted and logged, never raised
        raise Rejected(Reason.NODE_ERROR, f"{method}(): {type(exc).__name__}: {exc}") from None
    if result is False:
        raise Rejected(Reason.REFUSED, f"the node refused {method}()")
    if isinstance(result, str):  # the node's refusal reason (its operator methods' form)
        raise Rejected(Reason.REFUSED, f"{method}(): {result}")
    return result


def _no_args(method: str, *a: Any) -> Callable[[Any, Args], None]:
    def handler(node: Any, args: Args) -> None:
        call(node, method, *a)

    return handler


def _takeoff(node: Any, args: Args) -> None:
    call(node, "takeoff", number("takeoff", args, "height", positive=True))


def _goto(node: Any, args: Args) -> None:
    call(node, "goto", vector("goto", args, "position", 3), number("goto", args, "yaw"))


def _joints(node: Any, args: Args) -> None:
    call(node, "move_joints", vector("joints", args, "q", None))


def _perch(node: Any, args: Args) -> None:
    if "speed" in args:
        call(node, "perch", number("perch", args, "speed", positive=True))
    else:
        call(node, "perch")


def _gains(node: Any, args: Args) -> None:
    profile = args["profile"]
    if not (isinstance(profile, str) and _PROFILE.fullmatch(profile)):
        raise _bad("gains", "profile", "must be 1-64 of A-Z a-z 0-9 _ . -")
    call(node, "set_gain_profile", profile)


def _mocap(node: Any, args: Args) -> None:
    p = vector("mocap", args, "position", 3)
    v = vector("mocap", args, "velocity", 3) if "velocity" in args else None
    yaw = number("mocap", args, "yaw") if "yaw" in args else None
    call(node, "set_mocap", p, v, yaw)


def _pose(node: Any, args: Args, stamp: float | None = None) -> None:
    """A motion-capture system's sample: the marker body's pose, taken at ``stamp`` (node
    time; None: now). The port stamps it from the datagram's own time (:func:`apply_pose`)."""
    p = vector("pose", args, "position", 3)
    call(node, "set_mocap_pose", p, vector("pose", args, "quaternion", 4), stamp)


def apply_pose(node: Any, args: Args, stamp: float) -> None:
    """``pose`` taken at ``stamp`` (node time): the port's form of :func:`apply` for it."""
    check_args("pose", args)
    _pose(node, args, stamp)


def _status(node: Any, args: Args) -> dict[str, Any]:
    return {"node": json_safe(call(node, "status"))}


def _nothing(node: Any, args: Args) -> None:
    return None


def _ee(node: Any, args: Args) -> None:
    raise Rejected(Reason.UNSUPPORTED, "ee is planned by the ground port (rdm.ground.port)")


# name -> (allowed args, required args, handler); ``ee`` is planned by the port.
TABLE: dict[str, tuple[tuple[str, ...], tuple[str, ...], Callable[[Any, Args], Any]]] = {
    "takeoff": (("height",), ("height",), _takeoff),
    "land": ((), (), _no_args("land")),
    "halt": ((), (), _no_args("halt")),
    "force_landing": ((), (), _no_args("force_landing")),
    "arm": ((), (), _no_args("arm")),
    "disarm": ((), (), _no_args("disarm")),
    "goto": (("position", "yaw"), ("position", "yaw"), _goto),
    "joints": (("q",), ("q",), _joints),
    "perch": (("speed",), (), _perch),
    "unperch": ((), (), _no_args("unperch")),
    "gains": (("profile",), ("profile",), _gains),
    "mocap": (("position", "velocity", "yaw"), ("position",), _mocap),
    "pose": (("position", "quaternion"), ("position", "quaternion"), _pose),
    "status": ((), (), _status),
    "heartbeat": ((), (), _nothing),
    "ee": (("position",), ("position",), _ee),
}


def check_args(cmd: str, args: Args) -> None:
    """Refuse an unknown ``cmd`` or arguments of the wrong names (the values are checked
    by the handler). Also what ``rdm ctl`` checks before it sends."""
    if cmd not in TABLE:
        raise Rejected(Reason.UNKNOWN_COMMAND, f"{cmd!r} (known: {', '.join(TABLE)})")
    allowed, required, _ = TABLE[cmd]
    _only(cmd, args, allowed, required)


def apply(node: Any, cmd: str, args: Args) -> Any:
    """Check ``args`` and run ``cmd`` on ``node``; the result for the ack (None for most),
    or :class:`Rejected`."""
    check_args(cmd, args)
    return TABLE[cmd][2](node, args)
