"""The ground link's wire protocol and onboard port (rdm.ground), driven datagram by datagram
with the times passed in, against a recording fake node. Signatures are checked against
``hmac.new`` over hand-written canonical bytes and a golden datagram."""

from __future__ import annotations

import hashlib
import hmac
import json
import math
import os
import socket
import stat

import numpy as np
import pytest

from rdm.ground import auth, message
from rdm.ground.client import GroundClient, Sequencer
from rdm.ground.message import MAX_DEPTH, Reason, Rejected, decode, json_depth
from rdm.ground.port import GroundLinkConfig, GroundPort

KEY = bytes(range(32))
WALL = 1000.0
#: The datagram of takeoff 1.5 m from "golden", seq 42, t 1000.0, signed with KEY. The hmac
#: is hmac.new(bytes(range(32)), <the same bytes without the hmac field>, sha256) (checked in
#: test_golden_datagram_bytes); fixed here so any change of the wire form fails.
GOLDEN = (
    b'{"args":{"height":1.5},"cmd":"takeoff",'
    b'"hmac":"c7131dc99c3210210616288ccb04a34944d2771d9a7e3b2be8d768882f5f53cd",'
    b'"seq":42,"src":"golden","t":1000.0,"v":1}'
)


class FakeNode:
    """Records every call the port makes; ``status`` returns ``status_value``."""

    period = 0.025

    def __init__(self) -> None:
        self.calls: list[tuple] = []
        self.status_value: dict = {"flight_state": "hover", "perching": False}
        self.present_q = [0.0] * 10

    def _rec(self, name: str, *a):
        self.calls.append((name, *a))

    def takeoff(self, height):
        self._rec("takeoff", height)

    def land(self):
        self._rec("land")

    def halt(self):
        self._rec("halt")

    def force_landing(self):
        self._rec("force_landing")

    def arm(self):
        self._rec("arm")

    def disarm(self):
        self._rec("disarm")

    def goto(self, position, yaw):
        self._rec("goto", position, yaw)

    def move_joints(self, q):
        self._rec("move_joints", q)

    def perch(self, speed=None):
        self._rec("perch", speed)

    def unperch(self):
        self._rec("unperch")

    def set_gain_profile(self, name):
        self._rec("set_gain_profile", name)

    def set_mocap(self, p, v, yaw):
        self._rec("set_mocap", p, v, yaw)

    def set_trajectory(self, points):
        self._rec("set_trajectory", points)

    def status(self):
        return self.status_value

    def on_ground_lost(self):
        self._rec("on_ground_lost")

    def on_ground_restored(self):
        self._rec("on_ground_restored")


def make_port(node=None, key=KEY, **config) -> GroundPort:
    return GroundPort(node or FakeNode(), key, config=GroundLinkConfig(**config), wall=lambda: WALL)


def datagram(cmd="takeoff", args=None, seq=1, t=WALL, src="op", key=KEY, **extra) -> bytes:
    fields = {"v": 1, "src": src, "seq": seq, "t": t, "cmd": cmd, "args": args or {}}
    fields.update(extra)
    return message.encode(auth.sign(fields, key))


# ---------------------------------------------------------------- signatures (oracle: hmac)
def test_signature_is_hmac_sha256_of_the_hand_written_canonical_bytes() -> None:
    """Catches: keys not sorted, spaces in the canonical form, the hmac field signed too, a
    hash other than SHA-256."""
    fields = {"v": 1, "t": 5.25, "src": "a", "seq": 7, "cmd": "goto",
              "args": {"yaw": 0.5, "position": [1, -2.5, 3]}, "hmac": "ignored"}  # fmt: skip
    canonical = (
        b'{"args":{"position":[1,-2.5,3],"yaw":0.5},"cmd":"goto","seq":7,"src":"a","t":5.25,"v":1}'
    )
    assert message.canonical(fields) == canonical
    assert auth.signature(fields, KEY) == hmac.new(KEY, canonical, hashlib.sha256).hexdigest()


def test_golden_datagram_bytes() -> None:
    """The client's bytes for a fixed command are the golden ones, whose hmac the test
    recomputes with hmac.new; the port accepts them and applies them once."""
    body = GOLDEN.replace(
        b'"hmac":"c7131dc99c3210210616288ccb04a34944d2771d9a7e3b2be8d768882f5f53cd",', b""
    )
    assert json.loads(GOLDEN)["hmac"] == hmac.new(KEY, body, hashlib.sha256).hexdigest()
    client = GroundClient("udp:127.0.0.1:9", KEY, src="golden", wall=lambda: 1000.0)
    client.seq = Sequencer(lambda: 42)
    try:
        assert client.datagram("takeoff", {"height": 1.5}) == (42, GOLDEN)
    finally:
        client.close()
    port = make_port()
    ack = port.handle(GOLDEN, None, 0.0)
    assert ack["outcome"] == "accepted" and ack["ack"] == 42 and ack["to"] == "golden"
    assert port.node.calls == [("takeoff", 1.5)]


def test_acks_on_the_socket_are_signed_over_their_canonical_bytes() -> None:
    """Through real UDP sockets on 127.0.0.1: the ack comes back to the sender's address
    with the command's seq and an hmac the test recomputes with hmac.new (catches unsigned
    acks, acks signed over other bytes, acks sent elsewhere)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    port = GroundPort(FakeNode(), KEY, sock=sock, wall=lambda: WALL)
    ground = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    ground.bind(("127.0.0.1", 0))
    ground.settimeout(10.0)
    try:
        ground.sendto(datagram("land", seq=12), sock.getsockname())
        while not port.node.calls:
            port.tick(0.0)
        sent = json.loads(ground.recv(65536))
    finally:
        port.close()
        ground.close()
    body = {k: v for k, v in sent.items() if k != "hmac"}
    raw = json.dumps(body, sort_keys=True, separators=(",", ":")).encode()
    assert sent["hmac"] == hmac.new(KEY, raw, hashlib.sha256).hexdigest()
    assert (sent["ack"], sent["outcome"], sent["to"]) == (12, "accepted", "op")
    assert port.node.calls == [("land",)]


# ---------------------------------------------------------------- refused datagrams
def _flip(data: bytes) -> bytes:
    d = json.loads(data)
    d["hmac"] = ("0" if d["hmac"][0] != "0" else "1") + d["hmac"][1:]
    return message.encode(d)


BAD = {
    "unsigned": (message.encode({"v": 1, "src": "op", "seq": 1, "t": WALL, "cmd": "arm"}),
                 "unsigned"),
    "mis_signed": (_flip(datagram("arm")), "bad_signature"),
    "other_key": (datagram("arm", key=bytes(32)), "bad_signature"),
    "args_changed": (datagram("takeoff", {"height": 1.0}).replace(b"1.0", b"9.0"),
                     "bad_signature"),
    "stale": (datagram("arm", t=WALL - 2.001), "stale"),
    "future": (datagram("arm", t=WALL + 2.001), "stale"),
    "too_large": (b" " * 8193, "too_large"),
    "too_deep": (b"[" * 1000, "too_deep"),
    "deep_valid_json": (b"[" * 9 + b"]" * 9, "too_deep"),
    "non_utf8": (b'{"v":1,"src":"\xff"}', "malformed"),
    "array": (b"[1,2]", "malformed"),
    "string": (b'"arm"', "malformed"),
    "not_json": (b"{v:1}", "malformed"),
    "nan": (b'{"v":1,"t":NaN}', "malformed"),
    "overflow": (b'{"v":1,"t":1e999}', "malformed"),
    "duplicate_key": (b'{"v":1,"v":1}', "malformed"),
    "unknown_field": (datagram("arm", extra=1), "malformed"),
    "bool_seq": (datagram("arm", seq=True), "malformed"),
    "negative_seq": (datagram("arm", seq=-1), "malformed"),
    "version": (datagram("arm", v=2), "malformed"),
    "unknown_command": (datagram("fly"), "unknown_command"),
    "empty": (b"", "malformed"),
}  # fmt: skip


@pytest.mark.parametrize("name", sorted(BAD))
def test_a_bad_datagram_is_counted_and_changes_nothing(name: str) -> None:
    """Each datagram is refused under its reason, counted once, acked as rejected, and
    the node sees no call; the heartbeat is not armed by it (unknown_command is
    authenticated, so it arms the heartbeat but calls nothing)."""
    data, reason = BAD[name]
    port = make_port()
    ack = port.handle(data, None, 0.0)
    port.tick(0.5)
    assert port.node.calls == []
    assert port.reasons == {reason: 1}
    assert port.outcomes == {"rejected": 1}
    assert ack["outcome"] == "rejected" and ack["reason"] == reason
    assert port.heartbeat.armed == (reason == "unknown_command")


def test_replayed_and_reused_sequence_numbers_are_refused() -> None:
    """A lower seq, or the same seq with other content, is 'replayed'; the node sees the
    first command only."""
    port = make_port()
    assert port.handle(datagram("takeoff", {"height": 1.0}, seq=5), None, 0.0)["outcome"] == (
        "accepted"
    )
    for data in (datagram("arm", seq=4), datagram("land", seq=5)):
        ack = port.handle(data, None, 0.1)
        assert (ack["outcome"], ack["reason"]) == ("rejected", "replayed")
    assert port.node.calls == [("takeoff", 1.0)]
    assert port.reasons == {"replayed": 2}


def test_time_window_boundary() -> None:
    """t exactly 2.0 s off is inside the window; 2.001 s is not (both sides)."""
    port = make_port()
    assert port.handle(datagram("arm", t=WALL - 2.0, seq=1), None, 0.0)["outcome"] == "accepted"
    assert port.handle(datagram("arm", t=WALL + 2.0, seq=2), None, 0.0)["outcome"] == "accepted"
    assert port.handle(datagram("arm", t=WALL + 2.001, seq=3), None, 0.0)["reason"] == "stale"


def test_a_retry_is_answered_as_a_duplicate_and_applied_once() -> None:
    """The same datagram twice: applied once, both acks accepted with its seq, the second
    marked duplicate (what lets rdm ctl resend safely)."""
    port = make_port()
    data = datagram("goto", {"position": [1, 2, 3], "yaw": 0.5}, seq=77)
    first = port.handle(data, None, 0.0)
    second = port.handle(data, None, 0.1)
    assert port.node.calls == [("goto", [1.0, 2.0, 3.0], 0.5)]
    assert first["ack"] == second["ack"] == 77
    assert first["outcome"] == second["outcome"] == "accepted"
    assert second.get("duplicate") is True and "duplicate" not in first
    assert port.outcomes == {"accepted": 1, "duplicate": 1}


def test_senders_have_their_own_sequences_and_the_table_is_bounded() -> None:
    """Two senders may use the same seq; a third sender is refused while the table (size
    2) holds live senders, and admitted once the oldest was silent for twice the window."""
    now = [WALL]
    port = GroundPort(FakeNode(), KEY, wall=lambda: now[0])
    port.verifier.max_senders = 2
    assert port.handle(datagram("arm", src="a", seq=1, t=now[0]), None, 0)["outcome"] == "accepted"
    assert port.handle(datagram("arm", src="b", seq=1, t=now[0]), None, 0)["outcome"] == "accepted"
    ack = port.handle(datagram("arm", src="c", seq=1, t=now[0]), None, 0)
    assert ack["reason"] == "too_many_senders"
    now[0] = WALL + 4.0  # exactly twice the window: not yet
    assert port.handle(datagram("arm", src="c", seq=2, t=now[0]), None, 0)["reason"] == (
        "too_many_senders"
    )
    now[0] = WALL + 4.001
    assert port.handle(datagram("arm", src="c", seq=3, t=now[0]), None, 0)["outcome"] == (
        "accepted"
    )
    assert set(port.verifier.senders) == {"b", "c"}


# ---------------------------------------------------------------- bounded parsing
def _depth(v) -> int:
    """Nesting depth of a parsed JSON value (independent of the byte scan)."""
    if isinstance(v, dict):
        return 1 + max((_depth(x) for x in v.values()), default=0)
    if isinstance(v, list):
        return 1 + max((_depth(x) for x in v), default=0)
    return 0


def test_hundred_thousand_deep_nesting_is_refused_without_recursion() -> None:
    """100k nested arrays (and objects) are too_deep, not a RecursionError, even with the
    size limit lifted."""
    for data in (b"[" * 100_000 + b"]" * 100_000, b'{"a":' * 100_000):
        with pytest.raises(Rejected) as exc:
            decode(data, max_size=10**7)
        assert exc.value.reason is Reason.TOO_DEEP


@pytest.mark.parametrize(
    "text",
    [
        '{"a":"[[[[[[[[[[[[[[[[[["}',
        '{"a":"\\"[[[[[[[[[[[[[[[[","b":[1]}',
        '{"a\\\\":[[[]]],"b":"]]]]]]]]]]]"}',
        "[" * MAX_DEPTH + "]" * MAX_DEPTH,
        '{"a":{"b":{"c":[[[[{"d":1}]]]]}}}',
        '[{"x":"{"},[["}"]]]',
    ],
)
def test_depth_scan_agrees_with_the_parsed_depth(text: str) -> None:
    """Brackets inside strings (escaped quotes included) do not count: the scan equals the
    depth of json.loads' result, so no valid command is refused as too deep."""
    assert json_depth(text.encode()) == _depth(json.loads(text))
    assert decode(text.encode()) == json.loads(text)


def test_json_safe_replaces_non_finite_numbers_with_null() -> None:
    """A status with NaN, inf and numpy values becomes strict JSON (allow_nan=False)."""
    value = {"a": math.nan, "b": np.array([1.0, np.inf]), "c": np.int64(3), "d": (1, -math.inf)}
    safe = message.json_safe(value)
    assert json.loads(json.dumps(safe, allow_nan=False)) == {
        "a": None, "b": [1.0, None], "c": 3, "d": [1, None],
    }  # fmt: skip


# ---------------------------------------------------------------- the command table
CALLS = [
    ("takeoff", {"height": 1.5}, ("takeoff", 1.5)),
    ("land", {}, ("land",)),
    ("halt", {}, ("halt",)),
    ("force_landing", {}, ("force_landing",)),
    ("arm", {}, ("arm",)),
    ("disarm", {}, ("disarm",)),
    ("goto", {"position": [0.5, -1, 1.2], "yaw": -0.3}, ("goto", [0.5, -1.0, 1.2], -0.3)),
    ("joints", {"q": [0.1, 0.2, 0, 0, 0, -0.5]}, ("move_joints", [0.1, 0.2, 0, 0, 0, -0.5])),
    ("perch", {}, ("perch", None)),
    ("perch", {"speed": 0.05}, ("perch", 0.05)),
    ("unperch", {}, ("unperch",)),
    ("gains", {"profile": "perch-soft_1"}, ("set_gain_profile", "perch-soft_1")),
    ("mocap", {"position": [1, 2, 3], "velocity": [0, 0, 0.5], "yaw": 0.25},
     ("set_mocap", [1.0, 2.0, 3.0], [0.0, 0.0, 0.5], 0.25)),
    ("mocap", {"position": [1, 2, 3]}, ("set_mocap", [1.0, 2.0, 3.0], None, None)),
]  # fmt: skip


@pytest.mark.parametrize(("cmd", "args", "call"), CALLS)
def test_each_command_calls_its_node_method_once(cmd, args, call) -> None:
    port = make_port()
    ack = port.handle(datagram(cmd, args, seq=9), None, 0.0)
    assert (ack["outcome"], ack["ack"], ack["cmd"]) == ("accepted", 9, cmd)
    assert port.node.calls == [call]
    assert port.commands == {cmd: 1}


BAD_ARGS = [
    ("takeoff", {"height": "1"}, "takeoff.height"),
    ("takeoff", {"height": -1}, "takeoff.height"),
    ("takeoff", {"height": 0}, "takeoff.height"),
    ("takeoff", {"height": True}, "takeoff.height"),
    ("takeoff", {}, "takeoff.height: missing"),
    ("takeoff", {"heigth": 1}, "takeoff.heigth: unknown"),
    ("goto", {"position": [1, 2], "yaw": 0}, "goto.position"),
    ("goto", {"position": [1, 2, "3"], "yaw": 0}, "goto.position"),
    ("goto", {"position": [1, 2, 3]}, "goto.yaw: missing"),
    ("joints", {"q": []}, "joints.q"),
    ("joints", {"q": [0.0] * 33}, "joints.q"),
    ("joints", {"q": 0.5}, "joints.q"),
    ("perch", {"speed": -0.1}, "perch.speed"),
    ("perch", {"speed": "fast"}, "perch.speed"),
    ("gains", {"profile": "two words"}, "gains.profile"),
    ("gains", {"profile": 3}, "gains.profile"),
    ("mocap", {"position": [1, 2, 3], "velocity": [1, 2]}, "mocap.velocity"),
    ("land", {"now": True}, "land.now: unknown"),
    ("ee", {"position": [1, 2]}, "ee.position"),
]


@pytest.mark.parametrize(("cmd", "args", "field"), BAD_ARGS)
def test_bad_arguments_are_refused_naming_the_field(cmd, args, field) -> None:
    port = make_port()
    ack = port.handle(datagram(cmd, args), None, 0.0)
    assert (ack["outcome"], ack["reason"]) == ("rejected", "bad_args")
    assert ack["detail"].startswith(field)
    assert port.node.calls == []


class Refusing(FakeNode):
    def takeoff(self, height):
        return False

    def goto(self, position, yaw):
        return "outside the geofence"

    def land(self):
        raise RuntimeError("boom")


def test_missing_refusing_and_raising_node_methods() -> None:
    """No method: unsupported; False or a reason string: refused (with the reason); an
    exception: node_error. The port lives on and applies the next command."""
    port = make_port(Refusing())
    bare = make_port(type("Bare", (), {"period": 0.025})())
    assert bare.handle(datagram("halt"), None, 0.0)["reason"] == "unsupported"
    assert port.handle(datagram("takeoff", {"height": 1}, seq=1), None, 0.0)["reason"] == "refused"
    ack = port.handle(datagram("goto", {"position": [9, 9, 9], "yaw": 0}, seq=2), None, 0.0)
    assert (ack["reason"], ack["detail"]) == ("refused", "goto(): outside the geofence")
    ack = port.handle(datagram("land", seq=4), None, 0.0)
    assert ack["reason"] == "node_error" and "RuntimeError: boom" in ack["detail"]
    assert port.handle(datagram("arm", seq=5), None, 0.0)["outcome"] == "accepted"
    assert port.node.calls == [("arm",)]


def test_status_ack_is_strict_json_with_the_ground_counts() -> None:
    node = FakeNode()
    node.status_value = {"battery": math.nan, "q": np.array([0.5, np.inf])}
    port = make_port(node)
    port.handle(b"[" * 20, None, 0.0)
    ack = port.handle(datagram("status"), None, 0.0)
    text = json.dumps(ack, allow_nan=False)
    result = json.loads(text)["result"]
    assert result["node"] == {"battery": None, "q": [0.5, None]}
    assert result["ground"]["rejected"] == {"too_deep": 1}


def test_refused_datagrams_are_answered_at_a_bounded_rate() -> None:
    """30 refused datagrams at one instant (garbage and mis-signed): 20 answers
    (rejection_acks_per_s), 10 counted as rate-limited; one second later answers resume.
    All are counted as rejected. Commands that pass the verifier are always answered."""
    port = make_port()
    bad = [b"x"] * 15 + [_flip(datagram("arm", seq=n)) for n in range(1, 16)]
    acks = [port.handle(d, ("127.0.0.1", 9), 5.0) for d in bad]
    assert sum(a is not None for a in acks) == 20
    assert port.counts["acks_rate_limited"] == 10
    assert port.handle(b"x", ("127.0.0.1", 9), 6.0) is not None
    assert port.reasons == {"malformed": 16, "bad_signature": 15}
    answered = [port.handle(datagram("land", seq=n), None, 6.0) for n in range(1, 30)]
    assert all(a is not None and a["outcome"] == "accepted" for a in answered)


# ---------------------------------------------------------------- heartbeat
def test_heartbeat_trips_once_just_above_the_timeout_and_restores_once() -> None:
    """Armed by the first datagram (at t = 10 s, timeout 1.0 s): no trip at 10.999 s nor at
    exactly 11.0 s; one on_ground_lost at 11.001 s and none after; the next datagram calls
    on_ground_restored once."""
    port = make_port(ground_timeout_s=1.0)
    port.tick(5.0)
    port.tick(50.0)  # not armed: silence before the first datagram is no loss
    assert port.node.calls == []
    port.handle(datagram("heartbeat", seq=1), None, 10.0)
    for t in (10.5, 10.999, 11.0):
        port.tick(t)
    assert port.node.calls == []
    port.tick(11.001)
    assert port.node.calls == [("on_ground_lost",)]
    for t in (11.5, 12.0, 30.0):
        port.tick(t)
    assert port.node.calls == [("on_ground_lost",)]
    port.handle(datagram("heartbeat", seq=2), None, 31.0)
    port.tick(31.5)
    assert port.node.calls == [("on_ground_lost",), ("on_ground_restored",)]
    assert (port.heartbeat.trips, port.heartbeat.restores) == (1, 1)
    port.tick(32.01)
    assert port.node.calls[-1] == ("on_ground_lost",) and port.heartbeat.trips == 2


def test_refused_datagrams_and_mocap_do_not_keep_the_heartbeat_alive() -> None:
    """After arming, only mis-signed datagrams and mocap come: the loss still trips."""
    port = make_port(ground_timeout_s=1.0)
    port.handle(datagram("heartbeat", seq=1), None, 0.0)
    port.handle(_flip(datagram("heartbeat", seq=2)), None, 0.9)
    port.handle(datagram("mocap", {"position": [0, 0, 1]}, seq=3), None, 0.95)
    port.tick(1.01)
    assert port.node.calls[-1] == ("on_ground_lost",)


def test_mocap_refreshes_the_heartbeat_when_configured() -> None:
    port = make_port(ground_timeout_s=1.0, mocap_refreshes_heartbeat=True)
    port.handle(datagram("mocap", {"position": [0, 0, 1]}, seq=1), None, 0.95)
    port.tick(1.5)
    assert ("on_ground_lost",) not in port.node.calls and port.heartbeat.armed


def test_a_node_without_on_ground_lost_gets_force_landing() -> None:
    class Old(FakeNode):
        on_ground_lost = None  # type: ignore[assignment]

    port = make_port(Old(), ground_timeout_s=1.0)
    port.handle(datagram("heartbeat", seq=1), None, 0.0)
    port.tick(1.5)
    assert port.node.calls == [("force_landing",)]
    assert port.counts["on_ground_lost_unsupported"] == 1


# ---------------------------------------------------------------- key files
def test_key_files(tmp_path) -> None:
    """keygen writes 64 hex digits, mode 0600, refuses to overwrite; raw keys of 32 bytes
    load; short, odd or world-readable files are refused naming the file and the rule."""
    path = tmp_path / "k"
    auth.write_key(path)
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert auth.load_key(path) == bytes.fromhex(path.read_text().strip())
    assert len(auth.load_key(path)) == 32
    with pytest.raises(FileExistsError):
        auth.write_key(path)
    raw = tmp_path / "raw"
    raw.write_bytes(os.urandom(32))
    raw.chmod(0o600)
    assert auth.load_key(raw) == raw.read_bytes()
    for name, content, rule in [
        ("short", b"\x01" * 31, "at least 32"),
        ("shorthex", b"ab" * 31 + b"\n", "at least 64"),
        ("oddhex", b"a" * 65, "even number"),
    ]:
        p = tmp_path / name
        p.write_bytes(content)
        p.chmod(0o600)
        with pytest.raises(auth.KeyFileError, match=rule) as exc:
            auth.load_key(p)
        assert str(p) in str(exc.value)
    path.chmod(0o644)
    with pytest.raises(auth.KeyFileError, match="world-readable") as exc:
        auth.load_key(path)
    assert str(path) in str(exc.value) and "chmod 600" in str(exc.value)
    with pytest.raises(auth.KeyFileError, match="No such file"):
        auth.load_key(tmp_path / "missing")


def test_sequence_numbers_increase_even_when_the_clock_stands_still() -> None:
    seq = Sequencer(lambda: 100)
    assert [seq.next() for _ in range(3)] == [100, 101, 102]


def test_the_simulated_mocap_channel_reads_with_the_same_bounds() -> None:
    """rdm.sim.side_channels.MocapReceiver: a mocap datagram reaches set_mocap; 1000 '[' and
    non-UTF-8 bytes are counted as errors, not raised."""
    from rdm.sim.side_channels import MocapReceiver, abstract_address

    node = FakeNode()
    token = f"ground-test-{os.getpid()}"
    rx = MocapReceiver(token, node, 0.01)
    tx = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    try:
        mocap = {"mocap": {"position": [1, 2, 3], "velocity": [0, 0, 0], "yaw": 0.5}}
        for data in (b"[" * 1000, b"\xff", json.dumps(mocap).encode()):
            tx.sendto(data, abstract_address(token, "mocap"))
        rx.tick(0.0)
    finally:
        tx.close()
        rx.close()
    assert node.calls == [("set_mocap", [1, 2, 3], [0, 0, 0], 0.5)]
    assert (rx.applied, rx.errors) == (1, 2)
    assert rx.position.tolist() == [1.0, 2.0, 3.0]


def test_a_pose_datagram_reaches_set_mocap_pose_and_refreshes_no_heartbeat() -> None:
    """``pose``: the marker body's pose as a motion-capture system gives it, checked (3 + 4
    finite numbers) and handed to the node; like ``mocap`` it is no sign of the operator."""
    from rdm.ground.commands import TABLE, Rejected

    calls = []

    class Node:
        def set_mocap_pose(self, p, q, stamp):
            calls.append((p, q, stamp))
            return True

    allowed, required, handler = TABLE["pose"]
    assert set(allowed) == set(required) == {"position", "quaternion"}
    handler(Node(), {"position": [1, 2, 3], "quaternion": [0, 0, 0, 1]})
    assert calls == [([1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 1.0], None)]
    with pytest.raises(Rejected):
        handler(Node(), {"position": [1, 2, 3], "quaternion": [0, 0, 1]})
    assert len(calls) == 1


def test_the_port_stamps_a_pose_with_its_signing_time() -> None:
    """A ``pose`` is taken when it was signed: the port stamps it ``now - (wall - t)`` in node
    time (its age by the Unix clock), at most POSE_AGE_MAX_S old."""
    from rdm.ground.port import POSE_AGE_MAX_S

    got = []

    class Node:
        def set_mocap_pose(self, p, q, stamp):
            got.append(stamp)

    wall = [1000.0]
    port = GroundPort(Node(), KEY, wall=lambda: wall[0])
    signed = [999.97]
    client = GroundClient("udp:127.0.0.1:9", KEY, src="mocap", wall=lambda: signed[0])
    pose = {"position": [0.0, 0.0, 1.0], "quaternion": [0.0, 0.0, 0.0, 1.0]}
    # signed 30 ms, 0 s and 1.5 s before the port reads it (the last one: at the age limit)
    for signed_at, now, expect in [
        (999.97, 5.0, 4.97),
        (1000.0, 5.0, 5.0),
        (998.5, 6.0, 6.0 - min(1.5, POSE_AGE_MAX_S)),
    ]:
        signed[0] = signed_at
        port.handle(client.datagram("pose", pose)[1], ("127.0.0.1", 9), now)
        assert got[-1] == pytest.approx(expect, abs=1e-9)
    assert port.outcomes["accepted"] == 3


@pytest.mark.parametrize("value", [10**400, -(10**400), float("inf"), True, "1"])
def test_numbers_a_float_cannot_hold_are_bad_arguments(value) -> None:
    """JSON gives Python ints of any size: one beyond a float's range is refused as a bad
    argument (not an OverflowError out of the handler)."""
    from rdm.ground.commands import Rejected, number, vector

    with pytest.raises(Rejected):
        number("takeoff", {"height": value}, "height")
    with pytest.raises(Rejected):
        vector("goto", {"position": [0.0, value, 1.0]}, "position", 3)
