"""``rdm onboard`` as a real-time process: pty paths printed, a rosserial Spinal peer and a
Leptrino sensor peer on the other ends, signed commands over the ground link (rdm.ground),
SIGTERM exits cleanly."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time

import pytest
import serial
from spinal_peer import read_line

from rdm.ground.auth import load_key, write_key
from rdm.ground.client import GroundClient
from rdm.protocol import leptrino as lp
from rdm.protocol.rosserial import spinal_registry
from rdm.protocol.rosserial.client import ClientSession
from rdm.protocol.rosserial.events import MessageReceived

pytestmark = pytest.mark.timeout(120)
REG = spinal_registry()


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_rdm_onboard_process_arms_and_commands(tmp_path) -> None:
    port = free_udp_port()
    key_file = tmp_path / "robot.key"
    write_key(key_file)
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "rdm.cli",
            "onboard",
            "--no-record",
            "--uart",
            "pty",
            "--foot-sensor",
            "pty",
            "--control",
            f"udp:127.0.0.1:{port}",
            "--key",
            str(key_file),
            "--lqi-every",
            "4",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        uart_path = read_line(proc, "rdm onboard: uart pty").split()[-1]
        foot_path = read_line(proc, "rdm onboard: foot-sensor pty").split()[-1]
        read_line(proc, "rdm onboard: ready")
        uart = serial.Serial(uart_path, 921600, timeout=0)
        foot = serial.Serial(foot_path, 460800, timeout=0)
        spinal = ClientSession.from_layout()
        ctl = GroundClient(f"udp:127.0.0.1:{port}", load_key(key_file))
        topics: dict[str, int] = {}
        foot_parser = lp.LeptrinoStreamParser()
        foot_cmds = []
        state = REG.msg("spinal/ServoState")
        servo_states = REG.msg("spinal/ServoStates").new(
            servos=[state.new(index=i, angle=2048) for i in range(10)]
        )
        t0 = time.monotonic()
        armed_sent = False
        while time.monotonic() - t0 < 4.0:
            now_ms = round((time.monotonic() - t0) * 1000)
            for e in spinal.spin(uart.read(uart.in_waiting or 1), now_ms):
                if isinstance(e, MessageReceived):
                    topics[e.topic] = topics.get(e.topic, 0) + 1
                    if e.topic == "flight_config_cmd":
                        spinal.publish(
                            "flight_config_ack", REG.msg("std_msgs/UInt8").new(data=e.message.cmd)
                        )
            if spinal.configured:
                spinal.publish("imu", REG.msg("spinal/Imu").new(quaternion=[0, 0, 0, 1]))
                spinal.publish("servo/states", servo_states)  # the joints at their zeros
            out = spinal.take_output()
            if out:
                uart.write(out)
            for ev in foot_parser.feed(foot.read(foot.in_waiting or 1)):
                if ev.payload:
                    foot_cmds.append(lp.parse_command(ev.payload).command)
            mocap = {"position": [0, 0, 1], "velocity": [0, 0, 0], "yaw": 0.0}
            ctl.send(ctl.datagram("mocap", mocap)[1])
            ctl.send(ctl.datagram("heartbeat")[1])  # the operator's station is alive
            if spinal.configured and not armed_sent:
                ctl.send(ctl.datagram("arm")[1])
                ctl.send(ctl.datagram("goto", {"position": [0, 0, 1], "yaw": 0.0})[1])
                armed_sent = True
            time.sleep(0.01)
        assert lp.Command.DATA_START in foot_cmds
        assert topics.get("flight_config_cmd", 0) >= 1
        assert topics.get("four_axes/command", 0) > 20  # commands flow after the ack
        assert topics.get("rpy/gain", 0) > 5
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        final = json.loads(out.strip().splitlines()[-1])
        assert final["flight_state"] == "armed"
        assert final["monitors"]["counts"].get("servo_stale", 0) == 0
        assert final["ticks"] > 100
        assert final["ground_link"]["commands"]["arm"] == 1
        assert final["ground_link"]["commands"]["mocap"] > 100
        ctl.close()
        uart.close()
        foot.close()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()


def test_rdm_onboard_refuses_a_negative_servo_lead() -> None:
    """``--servo-lead`` reaches the node's configuration: an invalid lead is a clear error
    (exit 2) before any port is opened."""
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "rdm.cli",
            "onboard",
            "--no-record",
            "--uart",
            "pty",
            "--servo-lead",
            "-0.1",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2
    assert "servo_lead_s" in out.stderr
