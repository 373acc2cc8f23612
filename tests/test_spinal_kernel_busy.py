"""Spinal's busy milliseconds inside the lockstep kernel (docs/spinal.md).

Oracle: golden runs (``tests/data/spinal_kernel_busy.json``): the SHA-256 of every log file
the kernel run writes and of the state of every node (``test_lockstep_kernel._state``), the
Spinal mirror's busy-ms state included (``_spinal_state``: control clock and counter,
``last_output``, duty lists and their identity, ``_last_pub``, publisher and battery times,
the session's counters and TX ring, the UART pump's and the chain's counters, the bytes
waiting at the PC's end). The golden digests were recorded from runs whose files and state
equalled those of the stack without fast parts (``StackOptions.lockstep_kernel=False``); after a
deliberate change of the simulated bytes, ``RDM_WRITE_GOLDEN=1 python -m pytest
tests/test_spinal_kernel_busy.py`` records them again (say why in the commit). The
kernel's ``stats()["spinal_busy"]`` shows which of its paths ran: routine steps, battery
samples and frames, and the hand-overs to Python (``finish_step``: a step with an event;
``finish_publish``: a frame the builders, the TX ring or the output size decline).
"""

from __future__ import annotations

import math
from pathlib import Path

import golden_digests
import numpy as np
from test_lockstep_kernel import NODES, _fast_counts, _spinal_state
from test_lockstep_kernel import _golden as _golden_run

from rdm.protocol.rosserial.timesync import ClientClock
from rdm.scenarios.hover import HOVER_Z, make_script
from rdm.scenarios.stack import Stack

SPINAL = NODES.index("spinal")
GOLDEN = "spinal_kernel_busy.json"


def _golden(tmp_path: Path, name: str, steps, make_script_=None, **options) -> dict:
    """The lockstep tests' golden run against ``tests/data/spinal_kernel_busy.json``, with
    every state key digested (``spinal_busy`` included)."""
    return _golden_run(tmp_path, name, steps, make_script_, golden_file=GOLDEN, skip=(), **options)


def test_declined_frames_battery_and_step_events_go_to_python(tmp_path: Path) -> None:
    """Each hand-over: a TX ring too small for the imu frame and an output size too small
    for servo/states (``finish_publish``; the session counts ``tx_ring_full`` /
    ``tx_too_large`` and logs), a non-finite battery sample (the Python tick counts it), a
    UART cut longer than the command timeout (the fail-safe event of a step:
    ``finish_step``), then back to routine."""
    seen: list[tuple] = []

    def steps(stack: Stack) -> None:
        spinal = stack.spinal
        session = spinal.session
        stack.loop.run(2.2)
        session._tx_chunks = 1  # a 68-byte imu frame needs 2 chunks of 64
        stack.loop.run(0.05)
        session._tx_chunks = 128
        stack.loop.run(0.05)
        session.output_size = 70  # imu (68) and the log line (69) fit, servo/states not
        stack.loop.run(0.1)
        session.output_size = 1024
        stack.loop.run(0.05)
        spinal.adc_scale = math.nan  # every battery sample rejected in Python
        stack.loop.run(0.1)
        spinal.adc_scale = 1.0
        stack.loop.run(0.2)
        stack.drop_uart(True)  # 0.8 s > the 0.5 s command timeout: fail-safe
        stack.loop.run(0.8)
        stack.drop_uart(False)
        stack.loop.run(0.6)
        seen.append(
            (
                session.counts["tx_ring_full"],
                session.counts["tx_too_large"],
                spinal.counters.rejected["battery_non_finite"],
                spinal.counters.failsafes["failsafe_timeout"],
            )
        )

    stats = _golden(tmp_path, "declined_frames", steps, log=False)
    # the run drove each case
    ring_full, too_large, battery, failsafe = seen[0]
    assert ring_full >= 9 and too_large >= 4 and battery == 5 and failsafe >= 1
    busy = stats["spinal_busy"]
    # the declined frames' ms went on in Python (those with a command received were
    # Python ticks anyway)
    assert busy["finish_publish"] >= 10
    assert busy["finish_step"] >= 2  # the arming ack, the fail-safe
    assert busy["steps"] > 500 and busy["imu_frames"] > 400
    assert _fast_counts(NODES, stats)["spinal"] > 2000


def test_battery_and_imu_set_from_outside_are_read_when_used(tmp_path: Path) -> None:
    """The bridge sets Spinal's battery input (a voltage of time: the bridge's Python tick,
    which re-reads no Spinal plan) and IMU sample (every ms, in the kernel): the kernel's
    battery samples and steps use the values of that moment."""

    def steps(stack: Stack) -> None:
        stack.loop.run(1.8)
        stack.bridge.set_battery(lambda t: 25.2 - 0.7 * math.floor((t - 1.8) / 0.13))
        stack.loop.run(1.2)

    stats = _golden(tmp_path, "battery_and_imu", steps)
    busy = stats["spinal_busy"]
    assert busy["battery_samples"] > 50 and busy["steps"] > 200


def test_a_clock_of_another_class_leaves_the_publications_to_python(tmp_path: Path) -> None:
    """The kernel's stamps are ``ClientClock.now``'s: with a clock of another class (here a
    subclass, as the mirror's own imu frame path declines it too) every publication is the
    Python tick's, while the control steps stay in the kernel."""

    class OtherClock(ClientClock):
        pass

    counts: list[dict] = []

    def steps(stack: Stack) -> None:
        stack.loop.run(2.4)
        if stack.loop.kernel is not None:
            counts.append(dict(stack.loop.kernel.stats()["spinal_busy"]))
        stack.spinal.session.clock.__class__ = OtherClock
        stack.loop.run(0.6)

    stats = _golden(tmp_path, "other_clock", steps)
    before, after = counts[0], stats["spinal_busy"]
    assert before["imu_frames"] > 100 and before["servo_frames"] > 25
    assert after["imu_frames"] == before["imu_frames"]
    assert after["servo_frames"] == before["servo_frames"]
    assert after["steps"] > before["steps"] + 60


def test_python_code_sees_the_same_spinal_state_at_every_script_tick(tmp_path: Path) -> None:
    """A scenario script (100 Hz; it may read anything: the kernel writes every part back
    before it) records the Spinal mirror's busy-ms state each time: the same records in
    golden run, through the cut and restore of the UART."""
    records: list[list] = []

    def make() -> object:
        inner = make_script(np.array([0.483, 0.0, HOVER_Z]))
        mine: list = []
        records.append(mine)

        def script(stack: Stack, now: float) -> None:
            inner(stack, now)
            sp = stack.spinal
            mine.append((now, sp.now_ms, sp._now_s, sp._can_ms, _spinal_state(sp)))

        return script

    def steps(stack: Stack) -> None:
        stack.loop.run(2.5)
        stack.drop_uart(True)
        stack.loop.run(0.3)
        stack.drop_uart(False)
        stack.loop.run(0.5)

    stats = _golden(tmp_path, "script_ticks", steps, make)
    (kernel,) = records
    assert len(kernel) == 330
    golden_digests.check(
        GOLDEN, "script_ticks/records", {"all": golden_digests.sha(repr(kernel).encode())}
    )
    assert stats["spinal_busy"]["steps"] > 300


def test_boot_busy_ms_run_in_the_kernel_with_the_same_state(tmp_path: Path) -> None:
    """Before the CAN master first runs (booting, enumerating, configuring: 0-1.5 s) the
    busy ms are the kernel's too: the control step with no duty hand-over (the master's
    motor number is still 0: an empty duty list, as ``_step_tail``), the imu frames, and
    servo/states with no message (no servo reported yet). The golden bytes and state at the
    end of the boot, across the switch to RUNNING and after it; the Spinal mirror's Python
    ticks in the boot are only those with UART bytes."""
    seen: list[tuple] = []

    def steps(stack: Stack) -> None:
        stack.loop.run(1.45)
        spinal = stack.spinal
        kernel = stack.loop.kernel
        seen.append(
            (
                spinal.master.state.name,
                spinal.master.motor_number,
                list(spinal.duties),
                spinal._last_pub.get("servo/states") is not None,
                None if kernel is None else dict(kernel.stats()["spinal_busy"]),
                None if kernel is None else kernel.stats()["python"][SPINAL],
            )
        )
        stack.loop.run(0.35)

    stats = _golden(tmp_path, "boot", steps)
    ((k_state, k_motors, k_duties, k_servo, k_busy, k_python),) = seen
    assert (k_state, k_motors, k_duties, k_servo) == ("CONFIGURING", 0, [], True)
    assert k_busy is not None and k_python is not None
    # 1.45 s at 200 Hz: every step but the first ones (before the session's first frame)
    assert k_busy["steps"] > 280 and k_busy["imu_frames"] > 200
    assert k_busy["finish_step"] == 0 and k_busy["finish_publish"] == 0
    # the rosserial handshake and the onboard's 40 Hz commands: about 60 ticks, not 580
    assert k_python < 120
    assert stats["spinal_busy"]["steps"] > k_busy["steps"] + 60
