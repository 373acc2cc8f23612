"""The onboard end of the ground link: a node that reads command datagrams from a
non-blocking UDP socket, verifies each (``rdm.ground.auth``), applies the accepted ones to
the onboard node (``rdm.ground.commands``), acknowledges every datagram to its sender and
watches the ground station's heartbeat (``rdm.ground.heartbeat``).

Per tick: at most ``max_datagrams_per_tick`` datagrams (a flood cannot stall the robot;
the kernel drops the rest), then a finished ``ee`` plan is handed over, then the heartbeat
is checked. Every outcome is counted (:meth:`GroundPort.status`); no datagram, node fault
or socket error ends the port.

**Heartbeat.** Armed by the first authenticated datagram. More than ``ground_timeout_s``
without one calls ``node.on_ground_lost()`` once (the node decides: land in flight, hold
when perched); the next one calls ``node.on_ground_restored()`` once. A node without
``on_ground_lost`` gets ``force_landing()`` instead. ``mocap`` datagrams do not refresh
the heartbeat unless ``mocap_refreshes_heartbeat`` (ASSUMPTION: the heartbeat watches the
operator's station; a motion-capture stream alive without an operator must not keep the
robot flying).

**Acks.** Commands that pass the verifier are always answered (accepted, or rejected by
the command table or the node); answers to datagrams the verifier refuses (unreadable,
unsigned, mis-signed, stale, replayed) are limited to ``rejection_acks_per_s`` (a spoofed
flood must not turn the robot into a sender) and are never longer than a few hundred
bytes.
"""

from __future__ import annotations

import socket
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rdm.ground import commands
from rdm.ground.address import parse_udp
from rdm.ground.auth import WINDOW_S, Verifier, sign
from rdm.ground.ee import EePlanner
from rdm.ground.heartbeat import GROUND_TIMEOUT_S, Heartbeat
from rdm.ground.message import MAX_DATAGRAM, VERSION, Reason, Rejected, encode, json_safe

#: Largest ack sent [bytes] (a ``status`` result above it is replaced by a note).
MAX_ACK = 60_000


@dataclass(frozen=True)
class GroundLinkConfig:
    """The ground port's settings (module doc)."""

    window_s: float = WINDOW_S
    ground_timeout_s: float = GROUND_TIMEOUT_S
    mocap_refreshes_heartbeat: bool = False
    max_datagrams_per_tick: int = 64
    rejection_acks_per_s: float = 20.0
    #: ``src`` of the robot's acks.
    name: str = "rdm-onboard"


@dataclass
class _PendingPlan:
    future: Any
    q_start: list[float]
    src: str
    seq: int
    addr: Any


#: The oldest a ``pose`` sample is taken to be, s (older ones are stamped this old).
POSE_AGE_MAX_S = 0.5


class GroundPort:
    """The ground link's onboard node (module doc). ``sock`` is a bound UDP socket (made
    non-blocking here); ``key`` None accepts unsigned datagrams (insecure mode). ``wall``
    gives Unix time for the time window; ``log`` receives one line per notable event."""

    name = "ground_link"

    def __init__(
        self,
        node: Any,
        key: bytes | None,
        sock: socket.socket | None = None,
        config: GroundLinkConfig | None = None,
        period: float | None = None,
        wall: Callable[[], float] = time.time,
        planner: EePlanner | None = None,
        log: Callable[[str], None] | None = None,
    ) -> None:
        self.node = node
        self.config = config or GroundLinkConfig()
        self.key = key
        self.sock = sock
        if sock is not None:
            sock.setblocking(False)
        self.period = float(period if period is not None else getattr(node, "period", 0.025))
        self.wall = wall
        self.planner = planner
        self.log = log or (lambda line: None)
        self.verifier = Verifier(key, window_s=self.config.window_s)
        self.heartbeat = Heartbeat(self.config.ground_timeout_s)
        #: accepted / duplicate / rejected / pending datagrams
        self.outcomes: Counter[str] = Counter()
        #: rejections by reason
        self.reasons: Counter[str] = Counter()
        #: accepted commands by name
        self.commands: Counter[str] = Counter()
        #: socket_error, ack_send_error, acks_rate_limited, ground_lost_unhandled, ...
        self.counts: Counter[str] = Counter()
        self._plan: _PendingPlan | None = None
        self._tokens = self.config.rejection_acks_per_s
        self._token_time: float | None = None
        self._logged: dict[str, tuple[float, int]] = {}
        self._now = 0.0

    @classmethod
    def bind(cls, spec: str, node: Any, key: bytes | None, **kw: Any) -> GroundPort:
        """A port on a UDP socket bound to ``spec`` (``udp:HOST:PORT``)."""
        host, port = parse_udp(spec)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((host, port))
        except OSError:
            sock.close()
            raise
        return cls(node, key, sock=sock, **kw)

    # ------------------------------------------------------------------------ the tick
    def tick(self, now: float) -> None:
        """Read, verify, apply and acknowledge pending datagrams; hand over a finished
        plan; check the heartbeat."""
        self._now = now
        if self.sock is not None:
            for _ in range(self.config.max_datagrams_per_tick):
                try:
                    data, addr = self.sock.recvfrom(MAX_DATAGRAM + 1)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:  # e.g. an ICMP error queued on the socket
                    self.counts["socket_error"] += 1
                    break
                self.handle(data, addr, now)
        self._finish_plan(now)
        if self.heartbeat.check(now):
            self.log(f"ground station lost: no datagram for {self.heartbeat.age(now):.2f} s")
            self._notify("on_ground_lost", "force_landing")

    def handle(self, data: bytes, addr: Any, now: float) -> dict[str, Any] | None:
        """Process one datagram from ``addr`` at node time ``now``; the ack sent (None when
        rate-limited)."""
        verdict = self.verifier.verify(data, self.wall())
        if verdict.kind == "rejected":
            assert verdict.reason is not None and verdict.detail is not None
            self._count_rejection(verdict.reason, verdict.detail, addr, now)
            ack = self._ack(verdict.src, verdict.seq, None, "rejected", verdict.reason,
                            verdict.detail)  # fmt: skip
            if not self._take_token(now):
                self.counts["acks_rate_limited"] += 1
                return None
            return self._send(ack, addr)
        if verdict.kind == "duplicate":
            self.outcomes["duplicate"] += 1
            if verdict.ack is None:
                return None
            return self._send({**verdict.ack, "duplicate": True}, addr)
        msg = verdict.message
        assert msg is not None
        src, seq, cmd = msg["src"], msg["seq"], msg["cmd"]
        args = msg.get("args", {})
        refreshes = cmd not in ("mocap", "pose") or self.config.mocap_refreshes_heartbeat
        if refreshes and self.heartbeat.refresh(now):
            self.log("ground station back")
            self._notify("on_ground_restored", None)
        try:
            if cmd == "ee":
                ack = self._start_plan(msg, args, addr)
            elif cmd == "pose":
                # taken when it was signed: its age by the Unix clocks of both ends (one host,
                # or synchronised ones: ASSUMPTION), at most POSE_AGE_MAX_S
                age = min(max(self.wall() - float(msg["t"]), 0.0), POSE_AGE_MAX_S)
                commands.apply_pose(self.node, args, now - age)
                ack = self._ack(src, seq, cmd, "accepted")
                self.outcomes["accepted"] += 1
                self.commands[cmd] += 1
            else:
                result = commands.apply(self.node, cmd, args)
                if cmd == "status":
                    result = {**result, "ground": self.status()}
                ack = self._ack(src, seq, cmd, "accepted", result=result)
                self.outcomes["accepted"] += 1
                self.commands[cmd] += 1
        except Rejected as exc:
            self._count_rejection(exc.reason, exc.detail, addr, now)
            ack = self._ack(src, seq, cmd, "rejected", exc.reason, exc.detail)
        except Exception as exc:  # a fault of ours must not end the port either
            detail = f"internal: {type(exc).__name__}: {exc}"
            self._count_rejection(Reason.NODE_ERROR, detail, addr, now)
            ack = self._ack(src, seq, cmd, "rejected", Reason.NODE_ERROR, detail)
        self.verifier.remember_ack(src, seq, ack)
        return self._send(ack, addr)

    # ------------------------------------------------------------------------ ee plans
    def _start_plan(self, msg: dict[str, Any], args: dict[str, Any], addr: Any) -> dict:
        commands.check_args("ee", args)
        target = commands.vector("ee", args, "position", 3)
        if self.planner is None:
            raise Rejected(Reason.UNSUPPORTED, "no planner for ee (rdm onboard --robot)")
        if self._plan is not None:
            raise Rejected(Reason.BUSY, "an ee plan is being made")
        status = commands.call(self.node, "status")
        if not (isinstance(status, dict) and status.get("perching") is True):
            raise Rejected(Reason.NOT_PERCHED, "ee is planned only while perched")
        q = getattr(self.node, "present_q", None)
        if q is None:
            raise Rejected(Reason.UNSUPPORTED, "the node has no present_q")
        q_start = [float(v) for v in q]
        future = self.planner.submit(target, q_start)
        self._plan = _PendingPlan(future, q_start, msg["src"], msg["seq"], addr)
        self.outcomes["pending"] += 1
        return self._ack(msg["src"], msg["seq"], "ee", "pending")

    def _finish_plan(self, now: float) -> None:
        p = self._plan
        if p is None or not p.future.done():
            return
        self._plan = None
        assert self.planner is not None
        try:
            points = self.planner.points(p.future, p.q_start, now)
            commands.call(self.node, "set_trajectory", points)
            ack = self._ack(p.src, p.seq, "ee", "accepted", result={"points": len(points),
                            "duration_s": points[-1][0] - points[0][0]})  # fmt: skip
            self.outcomes["accepted"] += 1
            self.commands["ee"] += 1
        except Rejected as exc:
            self._count_rejection(exc.reason, exc.detail, p.addr, now)
            ack = self._ack(p.src, p.seq, "ee", "rejected", exc.reason, exc.detail)
        self.verifier.remember_ack(p.src, p.seq, ack)
        self._send(ack, p.addr)

    # ------------------------------------------------------------------------ helpers
    def _notify(self, method: str, fallback: str | None) -> None:
        for name in (method, fallback):
            if name is None:
                continue
            try:
                commands.call(self.node, name)
                return
            except Rejected as exc:
                self.counts[f"{method}_{exc.reason.value}"] += 1
                self.log(f"{method}: {exc.detail}")

    def _count_rejection(self, reason: Reason, detail: str, addr: Any, now: float) -> None:
        self.outcomes["rejected"] += 1
        self.reasons[reason.value] += 1
        last, count = self._logged.get(reason.value, (None, 0))
        if last is None or now - last >= 1.0:
            more = f" (+{count} more since the last line)" if count else ""
            self.log(f"rejected {reason.value} from {_where(addr)}: {detail}{more}")
            self._logged[reason.value] = (now, 0)
        else:
            self._logged[reason.value] = (last, count + 1)

    def _take_token(self, now: float) -> bool:
        rate = self.config.rejection_acks_per_s
        if self._token_time is not None:
            self._tokens = min(rate, self._tokens + rate * max(0.0, now - self._token_time))
        self._token_time = now
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            return True
        return False

    def _ack(
        self, to: str | None, seq: int | None, cmd: str | None, outcome: str,
        reason: Reason | None = None, detail: str | None = None, result: Any = None,
    ) -> dict[str, Any]:  # fmt: skip
        ack: dict[str, Any] = {
            "v": VERSION, "src": self.config.name, "to": to, "ack": seq, "t": self.wall(),
            "cmd": cmd, "outcome": outcome, "reason": None if reason is None else reason.value,
            "detail": detail,
        }  # fmt: skip
        if result is not None:
            ack["result"] = json_safe(result)
        return ack

    def _send(self, ack: dict[str, Any], addr: Any) -> dict[str, Any]:
        data = encode(sign(ack, self.key))
        if len(data) > MAX_ACK:
            ack = {**ack, "result": {"error": f"result of {len(data)} bytes not sent"}}
            data = encode(sign(ack, self.key))
        if self.sock is not None and addr is not None:
            try:
                self.sock.sendto(data, addr)
            except OSError:
                self.counts["ack_send_error"] += 1
        return ack

    # ------------------------------------------------------------------------ diagnostics
    def status(self) -> dict[str, Any]:
        """Counts and the heartbeat, JSON-ready."""
        hb = self.heartbeat
        return {
            "outcomes": dict(self.outcomes),
            "rejected": dict(self.reasons),
            "commands": dict(self.commands),
            "counts": dict(self.counts),
            "heartbeat": {
                "armed": hb.armed,
                "lost": hb.lost,
                "age_s": hb.age(self._now),
                "timeout_s": hb.timeout_s,
                "trips": hb.trips,
                "restores": hb.restores,
            },
            "authenticated": self.key is not None,
            "planning": self._plan is not None,
        }

    def close(self) -> None:
        """Close the socket and stop the planner's worker."""
        if self.sock is not None:
            self.sock.close()
        if self.planner is not None:
            self.planner.close()


def _where(addr: Any) -> str:
    if isinstance(addr, tuple) and len(addr) >= 2:
        return f"{addr[0]}:{addr[1]}"
    return str(addr)
