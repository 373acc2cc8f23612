"""The ground-station end of the ground link (``rdm ctl``): signs commands, sends them and
waits for the robot's acknowledgement.

**Sequence numbers** are ``time.time_ns()``, raised to one above the last number if the
clock has not moved on: strictly increasing within a process, and a restarted client
starts above every number it used before (its clock moved on while it restarted) without
a state file. ASSUMPTION: the ground station's clock does not step back by more than the
restart takes; if it did, the robot would refuse the numbers as ``replayed`` (never accept
an old command), and the client's default ``src`` differs per process anyway.

**Sender name** (``src``): ``ctl-<host>-<pid>`` unless given, so two ``rdm ctl`` processes
on one station (the heartbeat and a command) keep separate sequences.

**Retries** resend the same datagram (same ``seq`` and ``hmac``): the robot answers a
retry of a command it already applied as a duplicate with its first answer and does not
apply it again. An ``ee`` command is answered ``pending`` at once and finally when its plan
is done; the client then waits up to ``plan_timeout_s`` without resending.
"""

from __future__ import annotations

import os
import re
import socket
import time
from collections.abc import Callable
from typing import Any

from rdm.ground.address import parse_udp
from rdm.ground.auth import sign, signature_ok
from rdm.ground.message import VERSION, Rejected, decode, encode

#: Seconds to wait for an ack before resending, and resends after the first try.
ACK_TIMEOUT_S = 0.5
RETRIES = 2
#: Seconds to wait for an ``ee`` plan's final ack after its ``pending`` one.
PLAN_TIMEOUT_S = 30.0


class AckTimeout(Exception):
    """No valid acknowledgement came in time."""


class Sequencer:
    """Strictly increasing sequence numbers from ``clock_ns`` (module doc)."""

    def __init__(self, clock_ns: Callable[[], int] = time.time_ns) -> None:
        self.clock_ns = clock_ns
        self.last = -1

    def next(self) -> int:
        """The next number: the clock's, or one above the last."""
        self.last = max(self.clock_ns(), self.last + 1)
        return self.last


def default_src() -> str:
    """``ctl-<host>-<pid>``, printable ASCII, at most 64 characters."""
    host = re.sub(r"[^\x21-\x7e]", "_", socket.gethostname())[:40] or "host"
    return f"ctl-{host}-{os.getpid()}"


class GroundClient:
    """Sends signed commands to ``address`` (``udp:HOST:PORT``) with ``key`` (None: unsigned,
    for a robot run with ``--insecure-control``)."""

    def __init__(
        self,
        address: str,
        key: bytes | None,
        src: str | None = None,
        timeout_s: float = ACK_TIMEOUT_S,
        retries: int = RETRIES,
        plan_timeout_s: float = PLAN_TIMEOUT_S,
        wall: Callable[[], float] = time.time,
    ) -> None:
        self.address = parse_udp(address, "--to")
        self.key = key
        self.src = src or default_src()
        self.timeout_s = timeout_s
        self.retries = retries
        self.plan_timeout_s = plan_timeout_s
        self.wall = wall
        self.seq = Sequencer()
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("0.0.0.0", 0))
        #: acks dropped: unreadable, unsigned/mis-signed, or for another command
        self.ignored = 0

    def datagram(self, cmd: str, args: dict[str, Any] | None = None) -> tuple[int, bytes]:
        """``(seq, bytes)`` of a new signed command."""
        seq = self.seq.next()
        fields = {"v": VERSION, "src": self.src, "seq": seq, "t": self.wall(), "cmd": cmd,
                  "args": dict(args or {})}  # fmt: skip
        return seq, encode(sign(fields, self.key))

    def send(self, data: bytes) -> None:
        """Send one datagram to the robot."""
        self.sock.sendto(data, self.address)

    def command(self, cmd: str, args: dict[str, Any] | None = None) -> dict[str, Any]:
        """Send ``cmd`` and return its final ack (``outcome`` accepted or rejected);
        :class:`AckTimeout` after ``1 + retries`` tries (and ``plan_timeout_s`` once a
        ``pending`` ack came)."""
        seq, data = self.datagram(cmd, args)
        pending = False
        for _ in range(1 + self.retries):
            self.send(data)
            ack = self.wait_ack(seq, self.timeout_s)
            if ack is not None and ack["outcome"] == "pending":
                pending = True
                ack = self.wait_ack(seq, self.plan_timeout_s, final=True)
            if ack is not None:
                return ack
            if pending:
                break
        what = "final ack" if pending else "ack"
        raise AckTimeout(f"no {what} from udp:{self.address[0]}:{self.address[1]} for {cmd}")

    def wait_ack(self, seq: int, timeout_s: float, final: bool = False) -> dict | None:
        """The first valid ack of ``seq`` within ``timeout_s`` (skipping ``pending`` ones if
        ``final``), or None."""
        deadline = time.monotonic() + timeout_s
        while (left := deadline - time.monotonic()) > 0:
            self.sock.settimeout(left)
            try:
                data, _ = self.sock.recvfrom(65536)
            except (TimeoutError, BlockingIOError):
                return None
            ack = self.read_ack(data, seq)
            if ack is not None and not (final and ack["outcome"] == "pending"):
                return ack
        return None

    def poll_acks(self) -> list[dict[str, Any]]:
        """Every valid ack waiting now, for any of our sequence numbers (no wait)."""
        out = []
        self.sock.setblocking(False)
        while True:
            try:
                data, _ = self.sock.recvfrom(65536)
            except (BlockingIOError, InterruptedError):
                return out
            ack = self.read_ack(data, None)
            if ack is not None:
                out.append(ack)

    def read_ack(self, data: bytes, seq: int | None) -> dict[str, Any] | None:
        """The ack in ``data`` if it is readable, for us and (if ``seq`` is given) for
        ``seq``, and signed with our key (when we have one); None otherwise (counted in
        ``ignored``). A rejection whose signature does not verify is returned marked
        ``"verified": false``."""
        try:
            ack = decode(data, max_size=65536)
        except Rejected:
            ack = None
        ok = (
            isinstance(ack, dict)
            and ack.get("to") == self.src
            and (seq is None or ack.get("ack") == seq)
            and ack.get("outcome") in ("accepted", "rejected", "pending")
        )
        if not ok:
            self.ignored += 1
            return None
        if self.key is not None and not signature_ok(ack, self.key):
            if ack["outcome"] != "rejected":  # only a refusal may be taken unverified
                self.ignored += 1
                return None
            # A robot with another key signs its "bad_signature" answer with that key: shown
            # to the operator (it can only make a command look refused, never applied).
            ack = {**ack, "verified": False}
        return ack

    def close(self) -> None:
        """Close the socket."""
        self.sock.close()
