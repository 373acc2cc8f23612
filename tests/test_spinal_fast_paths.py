"""The Spinal mirror's per-ms fast paths against its plain (reference) path (docs/spinal.md,
"In the simulated stack").

* A whole lockstep hover stack run twice, once with every fast path off (mirror, servo bridge,
  Rust master duty hand-over): the UART, CAN and MCAP bytes and every counter are equal.
* The servo bridge's one-call table (Rust ``servo_keys`` / ``servo_reports``) against the view
  path on a running master: same messages, same rejections (bad index, wrong length).
* The Rust master's duty hand-over (``try_set_motor_duties``) against the Python checks on
  random and bad input (NaN, inf, out of range, ints, numpy floats, wrong lengths).
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np
import pytest

TICKS = 2600  # past the 2 s CAN boot: the master runs, servos report, duties flow


def _stack(base: str):
    from rdm.scenarios.common import sim_stack_options
    from rdm.scenarios.hover import HOVER_Z, make_script
    from rdm.scenarios.stack import build_stack

    opts = sim_stack_options(0, "inproc", speed=None)
    return build_stack("fastpaths", base, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))


def _run(base: str, fast: bool) -> tuple[dict[str, bytes], dict]:
    stack = _stack(base)
    spinal = stack.spinal
    spinal._fast = fast
    spinal.servos._fast = fast
    spinal.master.fast = fast
    spinal.uart.fast = fast
    stack.loop.run_ticks(TICKS)
    diag = spinal.diagnostics()
    stack.close()
    paths = sorted(p for p in Path(base).rglob("*") if p.is_file())
    files = {str(p.relative_to(base)): p.read_bytes() for p in paths}
    return files, diag


def test_stack_logs_and_counters_equal_with_and_without_fast_paths() -> None:
    with tempfile.TemporaryDirectory() as a, tempfile.TemporaryDirectory() as b:
        fast_files, fast_diag = _run(a, True)
        plain_files, plain_diag = _run(b, False)
    assert fast_diag == plain_diag
    assert fast_diag["published"]["servo/states"] > 0  # the servo reports ran
    assert fast_diag["received"]["servo/target_states"] > 0
    assert sorted(fast_files) == sorted(plain_files)
    uart = [k for k in fast_files if k.endswith(".bin")]
    assert uart and all(fast_files[k] for k in uart)
    for name in fast_files:
        assert fast_files[name] == plain_files[name], name


@pytest.fixture(scope="module")
def running_stack():
    with tempfile.TemporaryDirectory() as base:
        stack = _stack(base)
        stack.loop.run_ticks(TICKS)
        yield stack
        stack.close()


def _reference_check(duties, n: int) -> str | None:
    """The Python master's rule, re-stated: the error text, or None when accepted."""
    if len(duties) != n:
        return f"set_motor_duties: {len(duties)} duties for {n}"
    for i, d in enumerate(duties):
        if not isinstance(d, (int, float)) or not math.isfinite(d) or not 0.5 <= d <= 1.0:
            return f"set_motor_duties: duties[{i}]={d!r} not in 0.5..1.0"
    return None


def test_duty_hand_over_fast_equals_checks(running_stack) -> None:
    master = running_stack.spinal.master
    n = master.motor_number
    assert n > 0
    rng = np.random.default_rng(7)
    cases: list = [[0.5] * n, [1.0] * n, [0.75] * (n + 1), [0.75] * (n - 1), []]
    for _ in range(300):
        d = rng.uniform(0.3, 1.2, n).tolist()
        k = int(rng.integers(n))
        kind = int(rng.integers(6))
        if kind == 1:
            d[k] = math.nan
        elif kind == 2:
            d[k] = math.inf
        elif kind == 3:
            d[k] = 1  # an int: accepted by the checks, not by the one-call path
        elif kind == 4:
            d[k] = np.float64(0.8)  # a float subclass
        cases.append(d)
    for duties in cases:
        expected = _reference_check(duties, n)
        outcomes = []
        for fast in (True, False):
            master.fast = fast
            try:
                master.set_motor_duties(list(duties))
                outcomes.append(None)
            except ValueError as exc:
                outcomes.append(str(exc))
        master.fast = True
        assert outcomes == [expected, expected], duties
        exact = len(duties) == n and all(type(d) is float for d in duties) and expected is None
        assert master._core.try_set_motor_duties(list(duties)) is exact


def _outcome(call, *args):
    """None, or the type name and text of what ``call(*args)`` raised."""
    try:
        call(*args)
    except Exception as exc:  # the type and text are what is compared
        return type(exc).__name__, str(exc)
    return None


def _gains_array(step, rows) -> None:
    step.set_gains_wire(np.array(rows, dtype=np.int64).reshape(-1, 7))


def _pinv_array(step, pinv, inertia) -> None:
    step.set_pinv_inertia_wire(np.array(pinv, dtype=np.int16), inertia)


def test_gain_and_pinv_rows_equal_array_setters() -> None:
    from rdm.control.attitude import SpinalStep
    from rdm.nodes.spinal_mirror_commands import _applied

    rng = np.random.default_rng(3)
    cases = [rng.integers(-33000, 33000, (4, 7)).tolist() for _ in range(40)]
    cases += [[[1] * 7] * 3, [], [[1.5] * 7] * 4, [[2**70] + [0] * 6] * 4]
    converted = 0
    for rows in cases:
        a, b = SpinalStep(200.0), SpinalStep(200.0)
        a.set_uav_info(4, 32)
        b.set_uav_info(4, 32)
        try:
            applied = _applied(a.set_gains_wire_rows, rows)
            fast = None
        except ValueError as exc:
            applied, fast = True, (type(exc).__name__, str(exc))
        if not applied:
            assert rows in cases[-2:]  # floats, > int64: the mirror takes the array path
            continue
        converted += 1
        assert fast == _outcome(_gains_array, b, rows), rows
        assert np.array_equal(a.thrust_gains, b.thrust_gains)
        assert a.counters == b.counters
    assert converted == len(cases) - 2
    for _ in range(40):
        pinv = rng.integers(-32768, 32768, (int(rng.integers(3, 6)), 3)).tolist()
        inertia = rng.integers(-32768, 32768, 6).tolist()
        a, b = SpinalStep(200.0), SpinalStep(200.0)
        a.set_uav_info(4, 32)
        b.set_uav_info(4, 32)
        fast = _outcome(a.set_pinv_inertia_wire_rows, pinv, inertia)
        assert fast == _outcome(_pinv_array, b, pinv, inertia)
        assert a.counters == b.counters


def test_servo_targets_checks_equal_position_lookup(running_stack) -> None:
    master = running_stack.spinal.master
    keys = master.servo_keys()
    assert keys == list(master.servo_states)
    for targets in (
        {keys[0]: 2048, keys[-1]: 100},
        {(keys[0][0], 99): 1},
        {(200, 0): 1},
        {keys[0]: 1 << 20},
        {keys[0]: 1.5},
    ):
        expected = None
        for (slave, index), value in targets.items():  # the documented rule, re-stated
            if not isinstance(value, int) or not -(2**14) <= value < 2**14:
                expected = (
                    "ValueError",
                    f"servo ({slave}, {index}) target {value!r} not a 15-bit int",
                )
                break
            try:
                master._position(slave, index)
            except KeyError as exc:
                expected = ("KeyError", str(exc))
                break
        assert _outcome(master.set_servo_targets, targets) == expected
        if expected is None:
            for (slave, index), value in targets.items():
                assert master.servo(slave, index).goal_position == value


def _pump_counters(pump) -> tuple[int, ...]:
    return (
        pump.bytes_out,
        pump.bytes_discarded,
        pump.write_errors,
        len(pump.pending),
    )


def test_uart_pump_fast_send_equals_queue_path() -> None:
    from rdm.link.uart_pipe import open_inproc_uart
    from rdm.nodes.spinal_uart import UartPump

    rng = np.random.default_rng(11)
    sends = [rng.bytes(int(rng.integers(0, 3000))) for _ in range(200)]
    results = []
    for fast in (True, False):
        dev, host = open_inproc_uart()
        pump = UartPump(dev, max_pending=4096, fast=fast)
        received, trace = bytearray(), []
        for k, data in enumerate(sends):
            if k == 60:
                host.link.closed = True  # nobody listening: writes take 0 bytes, queue grows
            if k == 120:
                host.link.closed = False
            if k == 150:
                dev.link.closed = True  # the port itself fails: counted write errors
            if k == 180:
                dev.link.closed = False
            pump.send(data)
            received += host.read_available()
            trace.append(_pump_counters(pump))
        results.append((bytes(received), trace))
    assert results[0] == results[1]
    assert results[0][1][-1][1] > 0 and results[0][1][-1][2] > 0  # discards and errors ran


def test_uart_pump_fast_send_on_a_pty_loses_and_reorders_nothing() -> None:
    """The fd path with partial writes (a peer that reads late): how much the kernel takes is
    timing-dependent, so both paths are checked against the bytes sent, not each other."""
    import os
    import tty

    from rdm.nodes.spinal_uart import UartPump

    class PtyEnd:
        """The device end of a pty as UartPump sees a serial link."""

        def __init__(self, fd: int) -> None:
            self.port = self
            self.fd = fd

        def fileno(self) -> int:
            return self.fd

        def read_available(self) -> bytes:
            return b""

    def drain(fd: int, into: bytearray) -> None:
        while True:
            try:
                chunk = os.read(fd, 65536)
            except (BlockingIOError, OSError):
                return
            if not chunk:
                return
            into += chunk

    rng = np.random.default_rng(5)
    sends = [rng.bytes(int(rng.integers(1, 2500))) for _ in range(60)]
    for fast in (True, False):
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(slave, False)
        os.set_blocking(master, False)
        pump = UartPump(PtyEnd(slave), max_pending=1 << 20, fast=fast)
        received, held = bytearray(), 0
        try:
            for k, data in enumerate(sends):
                pump.send(data)  # the peer reads only every 20 sends: partial writes
                held = max(held, len(pump.pending))
                if k % 20 == 19:
                    drain(master, received)
            for _ in range(1000):
                if not pump.pending:
                    break
                pump.pump()
                drain(master, received)
            drain(master, received)
        finally:
            os.close(master)
            os.close(slave)
        assert bytes(received) == b"".join(sends)
        assert pump.bytes_out == len(received) and pump.write_errors == 0
        assert held > 0  # the queue held a remainder at some point


def test_four_axis_command_list_equals_array_setter() -> None:
    from rdm.control.attitude import ARM_ON, SpinalStep

    rng = np.random.default_rng(9)
    accepted = 0
    for k in range(60):
        n = int(rng.integers(3, 6))
        base = rng.uniform(-1.0, 12.0, n).tolist()
        if k % 7 == 3:
            base[0] = math.nan
        angles = rng.uniform(-0.5, 0.5, 3).tolist()
        a, b = SpinalStep(200.0), SpinalStep(200.0)
        for s in (a, b):
            s.set_uav_info(4, 32)
            s.set_pwm_info_hydrus_example()
            s.flight_config(ARM_ON, 0.0)
        fast = _outcome(a.four_axis_command_list, angles, base, 0.01)
        plain = _outcome(b.four_axis_command, angles, np.asarray(base, dtype=np.float64), 0.01)
        assert fast == plain
        accepted += fast is None
        assert np.array_equal(a.base_thrust, b.base_thrust)
        assert np.array_equal(a.target_angles, b.target_angles)
        assert a.counters == b.counters
    assert 0 < accepted < 60  # both accepted and rejected commands were compared
