"""A scripted Spinal on the other end of ``rdm onboard``'s UART pty, for process tests: the
rosserial client (H7_v2 layout) that acks every ``flight_config_cmd`` and, once configured,
publishes ``imu`` and ``servo/states`` (the joints at their zeros) as the firmware does."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from rdm.protocol.rosserial import spinal_registry
from rdm.protocol.rosserial.client import ClientSession
from rdm.protocol.rosserial.events import MessageReceived

REG = spinal_registry()


def read_line(proc: Any, prefix: str, timeout: float = 60.0) -> str:
    """The first line of ``proc``'s stdout starting with ``prefix`` (AssertionError if the
    process ends or ``timeout`` passes first)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if line.startswith(prefix):
            return line.strip()
        if not line and proc.poll() is not None:
            break
    raise AssertionError(f"no line starting with {prefix!r}")


@contextmanager
def spinal_mirror_pty(channel: str) -> Iterator[str]:
    """``rdm spinal`` (the Spinal mirror) on a pty with its CAN on ``virtual:<channel>``;
    yields the path the node opens, ends the mirror by SIGTERM."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    mirror = subprocess.Popen(
        [sys.executable, "-m", "rdm.cli", "spinal", "--uart", "pty", "--can", f"virtual:{channel}"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        yield read_line(mirror, "rdm spinal: ready uart=").split("uart=")[1].split()[0]
    finally:
        mirror.send_signal(signal.SIGTERM)
        try:
            mirror.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            mirror.kill()
            mirror.communicate()


def drive_spinal(
    uart_path: str,
    seconds: float,
    done: Callable[[dict[str, list[Any]]], bool] = lambda received: False,
) -> tuple[ClientSession, dict[str, list[Any]]]:
    """Be Spinal on ``uart_path`` for ``seconds`` or until ``done(received)``; the session
    and the messages the node sent (``received``: per topic).

    The pty is opened with ``os.open``, not pyserial: pyserial's open flushes the input, and
    with it the node's first topic request if the node wrote it before the peer opened the
    port (the node then asks again only after its 1 s attempt and 2 s re-open timers). The
    node's end already set the port raw."""
    fd = os.open(uart_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    spinal = ClientSession.from_layout()
    received: dict[str, list[Any]] = {}
    state = REG.msg("spinal/ServoState")
    servo_states = REG.msg("spinal/ServoStates").new(
        servos=[state.new(index=i, angle=2048) for i in range(10)]
    )
    pending = b""
    t0 = time.monotonic()
    try:
        while time.monotonic() - t0 < seconds and not done(received):
            now_ms = round((time.monotonic() - t0) * 1000)
            try:
                data = os.read(fd, 65536)
            except BlockingIOError:
                data = b""
            except OSError:  # EIO: the node closed its end of the pty
                break
            for e in spinal.spin(data, now_ms):
                if isinstance(e, MessageReceived):
                    received.setdefault(e.topic, []).append(e.message)
                    if e.topic == "flight_config_cmd":
                        ack = REG.msg("std_msgs/UInt8").new(data=e.message.cmd)
                        spinal.publish("flight_config_ack", ack)
            if spinal.configured:
                spinal.publish("imu", REG.msg("spinal/Imu").new(quaternion=[0, 0, 0, 1]))
                spinal.publish("servo/states", servo_states)
            pending += spinal.take_output()
            if pending:
                try:
                    pending = pending[os.write(fd, pending) :]
                except BlockingIOError:
                    pass
                except OSError:
                    break
            time.sleep(0.01)
    finally:
        os.close(fd)
    return spinal, received
