"""``rdm ctl`` as a process against a ground port in the test process (real UDP on
127.0.0.1, ephemeral ports), and ``rdm onboard --control`` as a process fed garbage."""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import signal
import socket
import stat
import subprocess
import sys
import time

import pytest
from spinal_peer import read_line
from test_ground_link import FakeNode
from test_onboard_cli import free_udp_port

from rdm.ground.auth import load_key, write_key
from rdm.ground.client import GroundClient
from rdm.ground.port import GroundLinkConfig, GroundPort

pytestmark = pytest.mark.timeout(180)
RDM = [sys.executable, "-m", "rdm.cli"]
ENV = dict(os.environ, PYTHONUNBUFFERED="1")


@pytest.fixture
def key_file(tmp_path):
    path = tmp_path / "robot.key"
    write_key(path)
    return path


@pytest.fixture
def port(key_file):
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    p = GroundPort(FakeNode(), load_key(key_file), sock=sock, config=GroundLinkConfig())
    yield p
    p.close()


def to(port: GroundPort) -> str:
    host, number = port.sock.getsockname()
    return f"udp:{host}:{number}"


def run_ctl(port: GroundPort | None, *args: str, timeout: float = 60.0):
    """Run ``rdm ctl ARGS`` while ticking ``port`` (node time = seconds since the start)."""
    proc = subprocess.Popen(
        [*RDM, "ctl", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV
    )
    t0 = time.monotonic()
    while proc.poll() is None and time.monotonic() - t0 < timeout:
        if port is not None:
            port.tick(time.monotonic() - t0)
        time.sleep(0.002)
    if proc.poll() is None:
        proc.kill()
    out, err = proc.communicate()
    return proc.returncode, out, err


def test_ctl_command_is_applied_once_and_its_signed_ack_printed(port, key_file) -> None:
    """takeoff 1.5: exit 0, the node called once, stdout one JSON ack whose hmac the test
    recomputes with hmac.new and the key file's bytes."""
    code, out, err = run_ctl(port, "--to", to(port), "--key", str(key_file), "takeoff", "1.5")
    assert code == 0, err
    assert port.node.calls == [("takeoff", 1.5)]
    ack = json.loads(out)
    body = {k: v for k, v in ack.items() if k != "hmac"}
    raw = json.dumps(body, sort_keys=True, separators=(",", ":")).encode()
    key = bytes.fromhex(key_file.read_text().strip())
    assert ack["hmac"] == hmac.new(key, raw, hashlib.sha256).hexdigest()
    assert ack["outcome"] == "accepted" and ack["cmd"] == "takeoff"
    assert isinstance(ack["ack"], int) and ack["ack"] > 0


def test_ctl_negative_numbers_and_json_args(port, key_file) -> None:
    code, _, err = run_ctl(port, "--to", to(port), "--key", str(key_file),
                             "goto", "-0.5", "0", "1.2", "-1")  # fmt: skip
    assert code == 0, err
    code, _, err = run_ctl(port, "--to", to(port), "--key", str(key_file), "mocap",
                             "--json", '{"position": [1, 2, 3], "yaw": 0.5}')  # fmt: skip
    assert code == 0, err
    code, _, err = run_ctl(port, "--to", to(port), "--key", str(key_file), "perch", "0.05")
    assert code == 0, err
    code, _, err = run_ctl(port, "--to", to(port), "--key", str(key_file), "perch")
    assert code == 0, err
    assert port.node.calls == [("goto", [-0.5, 0.0, 1.2], -1.0),
                               ("set_mocap", [1.0, 2.0, 3.0], None, 0.5),
                               ("perch", 0.05), ("perch", None)]  # fmt: skip


def test_ctl_rejection_exits_1(key_file) -> None:
    """A node refusing the command: exit 1, the ack printed with its reason."""

    class Refusing(FakeNode):
        def arm(self):
            return False

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    port = GroundPort(Refusing(), load_key(key_file), sock=sock)
    try:
        code, out, err = run_ctl(port, "--to", to(port), "--key", str(key_file), "arm")
    finally:
        port.close()
    assert code == 1, err
    assert json.loads(out)["reason"] == "refused"


def test_ctl_with_another_key_is_refused_as_bad_signature(port, tmp_path) -> None:
    other = tmp_path / "other.key"
    write_key(other)
    code, out, err = run_ctl(port, "--to", to(port), "--key", str(other), "land")
    assert code == 1, err
    ack = json.loads(out)
    assert (ack["reason"], ack["verified"]) == ("bad_signature", False)
    assert port.node.calls == []
    assert port.reasons == {"bad_signature": 1}


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["goto", "1", "2"], "goto: expected 4 numbers"),
        (["takeoff", "high"], "'high' is not a number"),
        (["takeoff", "nan"], "'nan' is not finite"),
        (["fly"], "unknown_command"),
        (["land", "now"], "land: takes no values"),
        (["perch", "0.1", "0.2"], "perch: expected 1 numbers"),
        (["mocap", "--json", "[1]"], "--json: must be a JSON object"),
        (["takeoff", "--json", '{"heigth": 1}'], "takeoff.heigth: unknown argument"),
        ([], "a command is required"),
    ],
)
def test_ctl_bad_arguments_exit_2_without_sending(port, key_file, args, message) -> None:
    code, _, err = run_ctl(port, "--to", to(port), "--key", str(key_file), *args)
    assert code == 2
    assert message in err and "Traceback" not in err
    assert port.outcomes == {}


def test_ctl_key_and_address_errors(tmp_path, key_file) -> None:
    """Missing --key, a world-readable key file, no robot answering: exit 2 with a message
    naming the problem, no traceback."""
    code, _, err = run_ctl(None, "--to", "udp:127.0.0.1:9", "land")
    assert code == 2 and "--key FILE is required" in err
    key_file.chmod(0o644)
    code, _, err = run_ctl(None, "--to", "udp:127.0.0.1:9", "--key", str(key_file), "land")
    assert code == 2 and str(key_file) in err and "world-readable" in err
    key_file.chmod(0o600)
    port = free_udp_port()
    code, _, err = run_ctl(None, "--to", f"udp:127.0.0.1:{port}", "--key", str(key_file),
                           "--timeout", "0.2", "--retries", "1", "land")  # fmt: skip
    assert code == 2 and "no ack from" in err
    code, _, err = run_ctl(None, "--to", "127.0.0.1:7301", "--key", str(key_file), "land")
    assert code == 2 and "expected udp:HOST:PORT" in err and "Traceback" not in err


def test_ctl_keygen(tmp_path) -> None:
    path = tmp_path / "k"
    code, _, err = run_ctl(None, "keygen", str(path))
    assert code == 0, err
    assert stat.S_IMODE(path.stat().st_mode) == 0o600 and len(load_key(path)) == 32
    before = path.read_bytes()
    code, _, err = run_ctl(None, "keygen", str(path))
    assert code == 2 and "not overwritten" in err
    assert path.read_bytes() == before


def test_ctl_heartbeat_keeps_the_link_and_its_end_trips_the_loss(port, key_file) -> None:
    """rdm ctl --heartbeat 20 arms the port's heartbeat without a loss while it runs; after
    SIGINT it prints its counts and exits 0, and the port reports the loss once when more
    than the timeout has passed."""
    proc = subprocess.Popen(
        [*RDM, "ctl", "--to", to(port), "--key", str(key_file), "--heartbeat", "20"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV,
    )  # fmt: skip
    t0 = time.monotonic()
    try:
        while port.commands["heartbeat"] < 10 and time.monotonic() - t0 < 60:
            port.tick(time.monotonic() - t0)
            time.sleep(0.002)
        assert port.commands["heartbeat"] >= 10
        assert port.heartbeat.armed and port.heartbeat.trips == 0
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    counts = json.loads(out.strip().splitlines()[-1])
    assert counts["heartbeats_sent"] >= 10 and counts["acked"] >= 1
    last = port.heartbeat.last
    port.tick(last + 0.9)
    assert ("on_ground_lost",) not in port.node.calls
    port.tick(last + 1.1)
    port.tick(last + 5.0)
    assert port.node.calls.count(("on_ground_lost",)) == 1


def _onboard(port: int, *extra: str) -> subprocess.Popen:
    return subprocess.Popen(
        [*RDM, "onboard", "--no-record", "--uart", "pty", "--foot-sensor", "none",
         "--control", f"udp:127.0.0.1:{port}", *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV,
    )  # fmt: skip


def test_rdm_onboard_survives_garbage_datagrams(key_file) -> None:
    """1000-'[' datagrams (the datagram that ended the node with a RecursionError), a
    100 kB one and non-UTF-8 bytes: the node keeps running, answers a signed status with
    them counted, and exits 0 at its --duration with the counts in its final line."""
    number = free_udp_port()
    proc = _onboard(number, "--key", str(key_file), "--duration", "6")
    try:
        read_line(proc, "rdm onboard: ready")
        garbage = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for _ in range(50):
            garbage.sendto(b"[" * 1000, ("127.0.0.1", number))
        garbage.sendto(b"[" * 60_000, ("127.0.0.1", number))
        garbage.sendto(b"\xff\xfe{}", ("127.0.0.1", number))
        garbage.close()
        client = GroundClient(f"udp:127.0.0.1:{number}", load_key(key_file), timeout_s=2.0)
        try:
            ack = client.command("status")
        finally:
            client.close()
        assert ack["outcome"] == "accepted"
        ground = ack["result"]["ground"]
        assert ground["rejected"] == {"too_deep": 50, "too_large": 1, "malformed": 1}
        assert ack["result"]["node"]["flight_state"]
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    final = json.loads(out.strip().splitlines()[-1])
    assert final["ground_link"]["rejected"]["too_deep"] == 50
    assert final["ground_link"]["commands"] == {"status": 1}
    assert "RecursionError" not in err and "Traceback" not in err


def test_rdm_onboard_refuses_an_unauthenticated_port_unless_asked(tmp_path) -> None:
    """--control without --key: exit 2 naming --insecure-control; with it: a warning, and
    unsigned commands are applied."""
    number = free_udp_port()
    proc = _onboard(number, "--duration", "5")
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 2 and "--insecure-control" in err
    proc = _onboard(number, "--insecure-control", "--duration", "4")
    try:
        read_line(proc, "rdm onboard: ready")
        client = GroundClient(f"udp:127.0.0.1:{number}", None, timeout_s=2.0)
        try:
            assert client.command("heartbeat")["outcome"] == "accepted"
        finally:
            client.close()
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert "WARNING: --insecure-control" in err
    assert json.loads(out.strip().splitlines()[-1])["ground_link"]["authenticated"] is False
