"""``rdm spinal`` and ``rdm neuron`` as separate processes on a REAL kernel SocketCAN bus
(``vcan0``), with this test as the rosserial server (the real ``ServerSession``) on the
Spinal's pty. Checks: handshake, enumeration of the Neurons, the 500 Hz PWM broadcast (counted
on a listening socket, kernel timestamps), a servo goal through the handshake, and the
command-timeout fail-safe (ack 2). The VM is software-emulated (guest Python ~16x slower than
the host), so the tolerances are generous and the phases short, and only two Neurons run: each
Neuron's socket takes all ~1500 frames/s of the bus in Python, which the guest cannot afford
for four.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import can

import rdm
from rdm.link.serial import open_serial
from rdm.protocol import neuron as nr
from rdm.protocol.rosserial import spinal_registry
from rdm.protocol.rosserial.events import MessageReceived, ServiceResponse
from rdm.protocol.rosserial.server import ServerSession

REPO = Path(__file__).resolve().parents[2]
# Child processes import the same `rdm` as this test (installed wheel or editable tree).
RDM_IMPORT_ROOT = str(Path(rdm.__file__).resolve().parents[1])
SPEC = "socketcan:vcan0"
REG = spinal_registry()
PWM_ID = 15  # MOTOR device, message 0, broadcast slave field (DBC: MotorPwmSlaves1To6)


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (RDM_IMPORT_ROOT, env.get("PYTHONPATH")) if p)
    return env


def _start(args: list[str]) -> tuple[subprocess.Popen, list[tuple[float, str]]]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "rdm.cli", *args],
        env=_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    lines: list[tuple[float, str]] = []

    def read() -> None:
        for line in proc.stdout:
            lines.append((time.monotonic(), line))

    threading.Thread(target=read, daemon=True).start()
    return proc, lines


def _wait_line(lines: list[tuple[float, str]], prefix: str, timeout: float) -> tuple[float, str]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for t, line in lines:
            if line.startswith(prefix):
                return t, line
        time.sleep(0.05)
    raise AssertionError(f"no {prefix!r} line within {timeout} s: {lines}")


def msg(type_name: str, **fields: Any) -> Any:
    return REG.msg(type_name).new(**fields)


class Pc:
    """The rosserial server on the wall clock. Keeps per-topic lists, not one event list: the
    emulated guest must not rescan thousands of imu messages every loop."""

    def __init__(self, spec: str) -> None:
        self.link = open_serial(spec)
        self.server = ServerSession()
        self.t0 = time.monotonic()
        self.topics: dict[str, list[tuple[float, Any]]] = defaultdict(list)
        self.responses: list[Any] = []
        self.server.start(0.0)

    def now(self) -> float:
        return time.monotonic() - self.t0

    def run(self, seconds: float, until=None, every=None) -> bool:
        end = self.now() + seconds
        while self.now() < end:
            if every is not None:
                every(self.now())
            self.link.write(self.server.take_output())
            data = self.link.read_available()
            t = self.now()
            for e in self.server.feed(data, t):
                if isinstance(e, MessageReceived):
                    self.topics[e.topic].append((t, e.message))
                elif isinstance(e, ServiceResponse):
                    self.responses.append(e.response)
            if until is not None and until():
                return True
            time.sleep(0.005)
        return until is None

    def received(self, topic: str) -> list[tuple[float, Any]]:
        return self.topics[topic]


def test_spinal_process_with_neuron_process_on_vcan0(vcan_bus):
    # One emulated vCPU for three Python processes: the nodes tick every 5 ms (the CAN master
    # still runs its schedule for every elapsed ms, the Neurons drain everything per tick).
    t0 = time.monotonic()
    neuron, neuron_out = _start(
        [
            "neuron",
            "--can",
            SPEC,
            "--slave-id",
            "1",
            "2",
            "--servos",
            "1",
            "--period",
            "0.005",
        ]
    )
    # firmware default boot delay: the Neurons start in parallel, as on the robot
    spinal, spinal_out = _start(
        ["spinal", "--uart", "pty", "--can", SPEC, "--boot-delay-ms", "5000", "--period", "0.005"]
    )
    phases: list[tuple[str, float]] = []

    def phase(name: str) -> None:
        phases.append((name, time.monotonic() - t0))
        print(f"vcan spinal test: {name} at {phases[-1][1]:.1f} s", flush=True)

    pc = None
    frames: list[can.Message] = []

    def capture(seconds: float, every=None) -> list[can.Message]:
        """PWM frames on a fresh listening socket while the PC keeps serving the UART (the
        listener runs only then: every Python recv costs the starved guest)."""
        listen = vcan_bus(can_filters=[{"can_id": PWM_ID, "can_mask": 0x7FF}])
        got: list[can.Message] = []
        stop = threading.Event()

        def loop() -> None:
            while not stop.is_set():
                m = listen.recv(timeout=0.1)
                # the kernel filter is set after bind: frames of that instant can slip through
                if m is not None and m.arbitration_id == PWM_ID:
                    got.append(m)

        thread = threading.Thread(target=loop, daemon=True)
        thread.start()
        try:
            pc.run(seconds, every=every)
        finally:
            stop.set()
            thread.join(timeout=5)
            listen.shutdown()
        frames.extend(got)
        return got

    try:
        t_spinal, ready = _wait_line(spinal_out, "rdm spinal: ready", 90)
        t_neuron, _ = _wait_line(neuron_out, "rdm neuron: ready", 90)
        assert t_neuron < t_spinal + 4.0, "Neurons not up before the Spinal enumerates"
        phase("both processes ready")
        # Stay off the single vCPU while the Spinal enumerates (boot delay 5 s after its ready
        # line, then a 200 ms ENUM window): a starved Neuron process would miss the window.
        time.sleep(max(0.0, t_spinal + 5.0 + 1.5 - time.monotonic()))
        pc = Pc(f"serial:{ready.split('uart=')[1].split()[0]}")
        assert pc.run(20, until=lambda: "four_axes/command" in pc.server.outbound)
        phase("handshake")

        # enumeration: servo/states for the 4 Neurons' servos, and get_board_info
        def four_servos() -> bool:
            states = pc.received("servo/states")
            return bool(states) and len(states[-1][1].servos) == 2

        assert pc.run(30, until=four_servos), pc.received("servo/torque_states")[-1:]
        pc.server.call_service(
            "get_board_info", REG.srv("spinal/GetBoardInfo").request.new(), pc.now()
        )
        assert pc.run(10, until=lambda: bool(pc.responses))
        response = pc.responses[0]
        assert [b.slave_id for b in response.boards] == [1, 2]
        phase("enumerated")

        # PWM broadcast, counted on a listening socket (kernel timestamps)
        idle = capture(1.3)
        assert idle, "no PWM frame on vcan0"
        n_1s = sum(1 for m in idle if m.timestamp - idle[0].timestamp < 1.0)
        # 500 Hz nominal. One emulated vCPU (~16x slower than the host) shared by three Python
        # processes starves the mirror's loop; the CAN schedule replays at most 10 ms per tick,
        # so the count measures the guest's CPU more than the mirror: only a broad check here
        # (the exact 500 Hz schedule is tested in lockstep, tests/test_spinal_mirror.py).
        assert 25 <= n_1s <= 560, n_1s
        decoded = {
            (
                m.arbitration_id,
                nr.decode_frame(m.arbitration_id, bytes(m.data), nr.Direction.SPINAL_TO_NEURON),
            )
            for m in idle
        }
        # not armed: every motor at duty 0.5, i.e. CAN value 0 in all six slots
        assert decoded == {(PWM_ID, nr.PwmFrame(0, (0,) * 6))}, decoded
        phase(f"PWM frames in 1 s on vcan0: {n_1s}")

        # a servo goal through the handshake: torque on, then target 2900 for servo index 0.
        # Like a real PC node the test re-sends until servo/torque_states (1 Hz) confirms the
        # torque and repeats the target every 100 ms as servo_bridge does: on the starved guest
        # a frame can miss rosserial's 20 ms frame timeout, and a target that arrives while
        # the Neuron's goal report is pending is overwritten by that report (sec. 2.4).
        sent = {"torque": -1.0, "target": -1.0}

        def torque_on() -> bool:
            states = pc.received("servo/torque_states")
            return bool(states) and states[-1][1].torque_enable[0] == 1

        def servo_commands(now: float) -> None:
            if not torque_on() and now - sent["torque"] >= 0.5:
                cmd = msg("spinal/ServoTorqueCmd", index=[0], torque_enable=[1])
                pc.server.publish("servo/torque_enable", cmd)
                sent["torque"] = now
            if now - sent["target"] >= 0.1:
                cmd = msg("spinal/ServoControlCmd", index=[0], angles=[2900])
                pc.server.publish("servo/target_states", cmd)
                sent["target"] = now

        def reached() -> bool:
            states = pc.received("servo/states")
            return bool(states) and abs(states[-1][1].servos[0].angle - 2900) <= 2

        assert pc.run(40, until=reached, every=servo_commands), pc.received("servo/states")[-1:]
        phase("servo goal reached")

        # arm, fly a command stream at 40 Hz, stop it: the Spinal forces landing (ack 2)
        pwm_info = msg(
            "spinal/PwmInfo",
            min_pwm=0.59,
            max_pwm=0.9375,
            min_thrust=1.0,
            force_landing_thrust=6.5,
            pwm_conversion_mode=0,
            motor_info=[
                msg(
                    "spinal/MotorInfo",
                    voltage=25.2,
                    max_thrust=20.0,
                    polynominal=[12.3593793002, -6.627443098, 0.07983707, 0, 0],
                )
            ],
        )
        pc.server.publish("uav_info", msg("spinal/UavInfo", motor_num=2, uav_model=16))
        pc.server.publish("motor_info", pwm_info)
        pc.run(0.3)
        pc.server.publish("flight_config_cmd", msg("spinal/FlightConfigCmd", cmd=0))

        def acks() -> list[int]:
            return [m.data for _, m in pc.received("flight_config_ack")]

        assert pc.run(10, until=lambda: acks() == [0]), acks()
        last_cmd = [0.0]

        def command(now: float) -> None:
            if now - last_cmd[0] >= 0.025:
                cmd = msg("spinal/FourAxisCommand", angles=[0, 0, 0], base_thrust=[7.0] * 2)
                pc.server.publish("four_axes/command", cmd)
                last_cmd[0] = now

        flying = [
            nr.decode_frame(m.arbitration_id, bytes(m.data), nr.Direction.SPINAL_TO_NEURON)
            for m in capture(1.0, every=command)
        ]
        assert flying and max(f.values[0] for f in flying) > 0  # motors above idle
        assert acks() == [0]
        t_stop = last_cmd[0]
        assert pc.run(10, until=lambda: acks() == [0, 2]), acks()
        t_ack = pc.received("flight_config_ack")[-1][0]
        assert t_ack - t_stop > 0.45  # not before the 500 ms timeout (± loop jitter)
        phase(f"force landing ack {t_ack - t_stop:.3f} s after the last command")
    finally:
        for proc in (spinal, neuron):
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=10)
        if pc is not None:
            pc.link.close()
        time.sleep(0.2)  # the reader threads take the last lines
        for _, line in spinal_out[-1:]:
            print(f"vcan spinal test: spinal said {line.strip()}")
    assert spinal.returncode == 0, spinal.stderr.read()
    assert neuron.returncode == 0, neuron.stderr.read()
    summary = [line for _, line in spinal_out if line.startswith("rdm spinal: stopped")]
    assert summary and '"slaves": [1, 2]' in summary[0], spinal_out
    assert '"failsafe_timeout": 1' in summary[0]
