"""``rdm spinal`` as a separate real-time process on a pty, with this test as the rosserial
server (the real ``ServerSession``) on the pty's slave path. CAN is a ``virtual:`` bus with no
Neuron (the CAN master disables itself after enumeration, as the firmware's Spine does)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import rdm
from rdm.link.serial import open_serial
from rdm.protocol.rosserial import spinal_registry
from rdm.protocol.rosserial.events import LogReceived, MessageReceived, ServiceResponse
from rdm.protocol.rosserial.server import ServerSession

REPO = Path(__file__).resolve().parents[1]
# Child processes import the same `rdm` as this test (installed wheel or editable tree).
RDM_IMPORT_ROOT = str(Path(rdm.__file__).resolve().parents[1])
REG = spinal_registry()


def start_spinal(*extra: str) -> tuple[subprocess.Popen, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (RDM_IMPORT_ROOT, env.get("PYTHONPATH")) if p)
    cmd = [sys.executable, "-m", "rdm.cli", "spinal", "--uart", "pty", *extra]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    assert line.startswith("rdm spinal: ready uart="), (line, proc.stderr.read())
    path = line.split("uart=")[1].split()[0]
    return proc, path


class RealtimeServer:
    """The PC side on a real port, on the wall clock (seconds since start)."""

    def __init__(self, spec: str) -> None:
        self.link = open_serial(spec)
        self.server = ServerSession()
        self.t0 = time.monotonic()
        self.events: list[tuple[float, Any]] = []
        self.server.start(0.0)

    def now(self) -> float:
        return time.monotonic() - self.t0

    def run(self, seconds: float, until=None) -> None:
        end = self.now() + seconds
        while self.now() < end:
            self.link.write(self.server.take_output())
            data = self.link.read_available()
            t = self.now()
            self.events += [(t, e) for e in self.server.feed(data, t)]
            if until is not None and until():
                return
            time.sleep(0.001)

    def received(self, topic: str, since: float = 0.0) -> list[tuple[float, Any]]:
        return [
            (t, e.message)
            for t, e in self.events
            if isinstance(e, MessageReceived) and e.topic == topic and t >= since
        ]

    def close(self) -> None:
        self.link.close()


def test_rdm_spinal_process_handshake_imu_service_and_sigterm():
    proc, path = start_spinal("--can", "virtual:cli_test", "--boot-delay-ms", "100")
    pc = None
    try:
        pc = RealtimeServer(f"serial:{path}")
        pc.run(5.0, until=lambda: "four_axes/command" in pc.server.outbound)
        assert "four_axes/command" in pc.server.outbound, pc.events[-5:]
        t0 = pc.now()
        pc.run(1.0)
        imu = pc.received("imu", since=t0)
        # 200 Hz nominal; a loaded 2-core machine is allowed to lag, never to exceed
        assert 100 <= len(imu) <= 205, len(imu)
        q = imu[-1][1].quaternion
        assert abs(q[3] - 1.0) < 1e-3  # level and still by default
        pc.server.call_service(
            "set_attitude_control", REG.srv("std_srvs/SetBool").request.new(data=True), pc.now()
        )
        pc.run(2.0, until=lambda: any(isinstance(e, ServiceResponse) for _t, e in pc.events))
        assert any(isinstance(e, ServiceResponse) and e.response.success for _t, e in pc.events)
        # no Neuron answered: the CAN master logs it and disables itself
        assert any(isinstance(e, LogReceived) and "no Neuron" in e.text for _t, e in pc.events)
    finally:
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=10)
        if pc is not None:
            pc.close()
    assert proc.returncode == 0, err
    assert "rdm spinal: stopped" in out and '"configured": true' in out


def test_rdm_spinal_rejects_bad_arguments():
    env = dict(os.environ, PYTHONPATH=RDM_IMPORT_ROOT)
    for extra in (["--rate", "5000"], ["--uart", "nonsense"], ["--can", "bogus:x"]):
        args = ["--uart", "pty", "--can", "virtual:y", *extra]
        res = subprocess.run(
            [sys.executable, "-m", "rdm.cli", "spinal", *args],
            env=env,
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert res.returncode == 2, (extra, res.stderr)
        assert "rdm spinal:" in res.stderr
