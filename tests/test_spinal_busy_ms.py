"""The Spinal mirror's busy ms (docs/spinal.md): its Rust-built frames and one-call steps
against independent oracles: rosbags' ROS1 serializer (firmware_protocol/spinal/tools/
rosbags_oracle.py), the rosserial v2 frame written out with ``struct``, and the rules of the
clock, the duty clamp and ``servo/target_states`` written out here.

* ``rdm._rdm.spinal_imu_frame`` against the clock rule + rosbags' ``spinal/Imu`` bytes + the
  frame on random values, clocks, ticks and topic ids: it answers exactly when the values are
  finite float32s and the stamp fits, with those bytes; other argument types are declined.
* ``rdm._rdm.spinal_duty_list`` against the clamp rule (each duty in [idle, 1.0]).
* ``send_frame`` / ``send_payload`` queue exactly the protocol's frames of what they accept.
* ``ServoBridge.states_frame`` against the frame of rosbags' ``spinal/ServoStates`` bytes;
  ``servo/target_states`` against its rules written out.
* A whole hover stack: the busy ms take the Rust frames, duty lists and command runs.
"""

from __future__ import annotations

import math
import random
import struct
import sys
import tempfile
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from rdm import _rdm
from rdm.control.attitude import ARM_ON, INTEGRATION_CONTROL_ON, UAV_HYDRUS, SpinalStep
from rdm.nodes import spinal_mirror_control as sm_control
from rdm.nodes import spinal_mirror_publishers as sm_publishers
from rdm.nodes.can_master import IDLE_DUTY
from rdm.nodes.spinal_servo_bridge import ServoBridge
from rdm.protocol.rosserial import constants as C
from rdm.protocol.rosserial.client import ClientSession
from rdm.protocol.rosserial.codec import RosTime, message_to_dict
from rdm.protocol.rosserial.registry import spinal_registry
from rdm.protocol.rosserial.timesync import ClientClock

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "firmware_protocol/spinal/tools"))
import rosbags_oracle as oracle

REG = spinal_registry()
TS = oracle.make_typestore()
F32_MAX = struct.unpack("<f", b"\xff\xff\x7f\x7f")[0]


# ----------------------------------------------------------------------------- Imu frame
def _float(rng: random.Random) -> float:
    kind = rng.random()
    if kind < 0.4:
        return rng.uniform(-20.0, 20.0)
    if kind < 0.5:
        return rng.choice([0.0, -0.0, 1.0, -1.0, 1 + 2.0**-24, 1 + 3 * 2.0**-24])  # f32 ties
    if kind < 0.6:
        return rng.choice([1e-45, -3e-39, 1e-310, 2.0**-149, 2.0**-150])  # subnormals
    if kind < 0.7:
        return rng.choice([F32_MAX, -F32_MAX, 3.4028235e38, 3.4028236e38, 1e39, -1e300])
    if kind < 0.75:
        return rng.choice([math.inf, -math.inf, math.nan])
    return rng.uniform(-1.0, 1.0) * 10.0 ** rng.randint(-30, 30)


def _packs(x: float) -> bool:
    """The value the Rust frame must take: finite and a float32 (struct packs it)."""
    try:
        struct.pack("<f", x)
    except OverflowError:
        return False
    return math.isfinite(x)


def _clock(rng: random.Random) -> ClientClock:
    clock = ClientClock()
    if rng.random() < 0.7:
        clock.request_sent(rng.randrange(-(2**33), 2**33))
        sec = rng.choice([0, 1, rng.randrange(2**32), 2**32 - 1])
        clock.answer_received(
            RosTime(sec, rng.randrange(10**9)), rng.choice([0, rng.randrange(-(2**40), 2**40)])
        )
    return clock


def _outputs() -> list[Any]:
    """SpinalStepOutputs with moving estimates (random IMU samples, some wild)."""
    rng = np.random.default_rng(3)
    step = SpinalStep(200.0, gyro_calib_duration_s=0.05)
    outs = []
    for k in range(400):
        gyro = rng.normal(0.0, 2.0 if k % 50 else 1e3, 3)
        acc = rng.normal([0.0, 0.0, 9.8], 3.0)
        outs.append(step.step(k * 0.005, gyro.tolist(), acc.tolist(), [30.0, 1.0, -40.0], 25.0))
    return outs


def _frame(topic: int, payload: bytes) -> bytes:
    """A rosserial v2 frame written out from the protocol (``struct``): 0xFF 0xFE, the
    little-endian length, its checksum, the topic id, the payload, the message checksum."""
    n = len(payload)
    length_chk = 255 - ((n & 0xFF) + (n >> 8)) % 256
    message_chk = 255 - ((topic & 0xFF) + (topic >> 8) + sum(payload)) % 256
    return struct.pack("<BBHBH", 0xFF, 0xFE, n, length_chk, topic) + payload + bytes([message_chk])


def _stamp(synced: bool, sync_tick: int, sync_ns: int, now_ms: int) -> tuple[int, int]:
    """The client clock's rule (docs/rosserial.md): unsynchronised the uint32 tick in ms;
    synchronised the time at the sync plus the signed 32-bit tick difference, not below 0."""
    if not synced:
        ns = (now_ms % 2**32) * 10**6
    else:
        elapsed = (now_ms - sync_tick) % 2**32
        elapsed -= 2**32 if elapsed >= 2**31 else 0
        ns = max(0, sync_ns + elapsed * 10**6)
    return divmod(ns, 10**9)


def test_imu_frame_is_the_protocols_frame_of_rosbags_bytes() -> None:
    """Catches a stamp taken with an unsigned tick difference, a field written in another
    order than the .msg, or a non-finite value framed instead of declined."""
    rng = random.Random(11)
    outs = _outputs()
    answered = declined = 0
    for _ in range(4000):
        clock = _clock(rng)
        now_ms = rng.choice([0, 5, rng.randrange(2**31), rng.randrange(-(2**35), 2**35)])
        topic = rng.choice([150, 154, 0, 0xFFFF, rng.randrange(0x10000)])
        acc = tuple(_float(rng) for _ in range(3))
        mag = (
            [_float(rng) for _ in range(3)]
            if rng.random() < 0.5
            else tuple(_float(rng) for _ in range(3))
        )
        out = rng.choice(outs)
        sync = (clock.synced, clock._sync_tick, clock._sync_ns)
        frame = _rdm.spinal_imu_frame(topic, now_ms, *sync, acc, out, mag)
        sec, nsec = _stamp(*sync, now_ms)
        fields = {
            "acc": list(acc),
            "gyro": out.angular_velocity.tolist(),
            "mag": list(mag),
            "quaternion": out.quaternion.tolist(),
        }
        values = [v for k in ("acc", "gyro", "mag", "quaternion") for v in fields[k]]
        if not (sec < 2**32 and all(_packs(x) for x in values)):
            assert frame is None, (acc, mag, sec)
            declined += 1
            continue
        stamp = {"sec": sec - 2**32 if sec >= 2**31 else sec, "nsec": nsec}  # rosbags: int32
        payload = oracle.serialize(TS, "spinal/msg/Imu", {"stamp": stamp, **fields})
        assert frame == _frame(topic, payload)
        answered += 1
    assert answered > 1000 and declined > 500


@pytest.mark.parametrize(
    "change",
    [
        {"acc": [0, 0, 9]},  # ints: struct packs them, the Rust frame leaves them to it
        {"acc": np.array([0.0, 0.0, 9.8])},
        {"mag": (1.0, 2.0)},
        {"mag": (np.float64(1.0), 2.0, 3.0)},
        {"synced": 1},
        {"now_ms": 5.0},
        {"now_ms": 2**70},
        {"topic": True},
        {"topic": 70000},
        {"out": None},
        {"sync_ns": 2**64},
    ],
)
def test_imu_frame_declines_other_argument_types(change: dict[str, Any]) -> None:
    out = _outputs()[5]
    args = {
        "topic": 154,
        "now_ms": 1234,
        "synced": True,
        "sync_tick": 1000,
        "sync_ns": 5 * 10**9,
        "acc": (0.0, 0.0, 9.8),
        "out": out,
        "mag": (30.0, 0.0, -40.0),
    }
    assert _rdm.spinal_imu_frame(*args.values()) is not None
    args.update(change)
    assert _rdm.spinal_imu_frame(*args.values()) is None


# ----------------------------------------------------------------------------- duty list
def _clamped_duties(out: Any, n: int) -> list[float]:
    return [min(1.0, max(IDLE_DUTY, d)) for d in out.duty.tolist()[:n]]


def test_duty_list_is_the_clamped_duties() -> None:
    rng = np.random.default_rng(5)
    step = SpinalStep(200.0, gyro_calib_duration_s=0.05)
    step.set_uav_info(4, UAV_HYDRUS)
    step.set_pwm_info_hydrus_example()
    step.set_gains_wire_rows([(2000, 100, 300, 2000, 100, 300, 200)] * 4)
    compared = with_events = 0
    for k in range(1500):
        now = k * 0.005
        if k == 40:
            step.flight_config(ARM_ON, now)
            step.flight_config(INTEGRATION_CONTROL_ON, now)
        if k > 40 and k % 7 == 0:
            base = rng.uniform(0.0, 30.0, 4).tolist() if k % 91 else [1e4, 0.0, 5.0, 50.0]
            step.four_axis_command_list(rng.normal(0.0, 0.1, 3).tolist(), base, now)
        out = step.step(
            now, rng.normal(0.0, 0.3, 3).tolist(), [0.0, 0.0, 9.8], [30.0, 0.0, -40.0], 25.2
        )
        for n in (1, 2, 3, 4):
            got = _rdm.spinal_duty_list(out, n, IDLE_DUTY)
            if out.events:
                assert got is None
                with_events += 1
            else:
                assert got == _clamped_duties(out, n)
                assert all(type(d) is float for d in got)
                compared += 1
        for bad in (0, 5, -1, 4.0, True, None):
            assert _rdm.spinal_duty_list(out, bad, IDLE_DUTY) is None
    assert compared > 5000 and with_events >= 4
    assert _rdm.spinal_duty_list(object(), 4, IDLE_DUTY) is None
    # clamping both ways: an idle above the duties and a duty above 1.0 is not reachable
    # from the core, so check the comparison rule on the idle side
    for k in range(3):  # past the command time-out's events
        out = step.step(99.0 + k * 0.005, [0.0] * 3, [0.0, 0.0, 9.8], [30.0, 0.0, -40.0], 25.2)
    assert not out.events
    assert _rdm.spinal_duty_list(out, 4, 2.0) == [1.0] * 4
    assert _rdm.spinal_duty_list(out, 4, -1.0) == [min(1.0, d) for d in out.duty.tolist()]


# ----------------------------------------------------------------------------- sessions
def test_send_frame_and_send_payload_queue_the_protocols_frames() -> None:
    """Frames of 0 to 2000 bytes, configured or not, the TX ring filling: what is accepted
    (a positive return) leaves as the protocol's frame, a frame over the 1024-byte buffer
    leaves the firmware's error line instead, the rest leaves nothing and is counted.
    Catches a frame queued though it was counted as dropped."""
    rng = random.Random(4)
    session = ClientSession.from_layout()
    queued = bytearray()
    accepted = frames = 0
    log = {"level": int(C.LogLevel.ERROR), "msg": C.LOG_DROPPED_TOO_LARGE}
    too_large = _frame(C.TopicId.LOG, oracle.serialize(TS, "rosserial_msgs/msg/Log", log))
    for step in range(600):
        if step % 150 == 0:
            session.configured = step != 300
        topic = rng.choice([7, 10, 100, 154, 170])
        payload = rng.randbytes(rng.choice([0, 1, 60, 1000, 1016, 1017, 2000]))
        if step % 2:
            got = session.send_frame(topic, _frame(topic, payload))
        else:
            got = session.send_payload(topic, payload)
        if got > 0:
            queued += _frame(topic, payload)
            accepted += 1
        elif len(payload) + 8 > 1024 and session.counts["tx_frames"] > frames:
            queued += too_large  # the firmware's error line for a frame over its buffer
        frames = session.counts["tx_frames"]
        if rng.random() < 0.1:  # else the TX ring fills and drops
            assert session.take_output() == bytes(queued)
            queued.clear()
    assert session.take_output() == bytes(queued)
    assert accepted > 100
    assert {"tx_ring_full", "tx_too_large", "tx_not_configured"} <= set(session.counts)


# ----------------------------------------------------------------------------- servo states
def _stack(base: str, **options: Any):
    from rdm.scenarios.common import sim_stack_options
    from rdm.scenarios.hover import HOVER_Z, make_script
    from rdm.scenarios.stack import build_stack

    opts = sim_stack_options(0, "inproc", speed=None, **options)
    return build_stack("busy", base, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))


def test_servo_states_frame_is_the_protocols_frame_of_rosbags_bytes() -> None:
    """The master's servo table framed in one call against rosbags' bytes of the servos'
    states; stamps, topic ids and codecs it does not take are declined. Catches a servo's
    load and angle swapped or a stamp's nanoseconds dropped."""
    codec = REG.msg("spinal/ServoStates")
    msgs = SimpleNamespace(servo_state=REG.msg("spinal/ServoState"), servo_states=codec)
    stamp = RosTime(12, 345)
    with tempfile.TemporaryDirectory() as base:
        stack = _stack(base)
        try:
            stack.loop.run_ticks(2600)
            bridge = ServoBridge(stack.spinal.master)
            for _ in range(3):
                for topic, when in ((160, stamp), (0xFFFF, RosTime(2**32 - 1, 999_999_999))):
                    frame = bridge.states_frame(codec, when, topic)
                    message = ServoBridge(stack.spinal.master).states(msgs, when)
                    assert message is not None and len(message.servos) > 0
                    fields = message_to_dict(message)
                    fields["stamp"]["sec"] -= 2**32 if when.sec >= 2**31 else 0  # rosbags int32
                    payload = oracle.serialize(TS, "spinal/msg/ServoStates", fields)
                    assert frame == _frame(topic, payload)
                stack.loop.run_ticks(40)
            for topic, when in ((70000, stamp), (160, RosTime(2**32, 0)), (160, RosTime(-1, 0))):
                assert bridge.states_frame(codec, when, topic) is False
            assert bridge.states_frame(codec, (12, 345), 160) is False
            assert bridge.states_frame(REG.msg("spinal/Pwms"), stamp, 160) is False
        finally:
            stack.close()


def _goals(master: Any) -> list[int]:
    return [view.goal_position for view in master.servo_states.values()]


def _expected_targets(keys, start, index, angles):
    """``servo/target_states`` by its rules, written out: (reason or "ok", goals after)."""
    n = len(keys)
    if len(index) != len(angles):
        return "wrong_length", start
    if any(not 0 <= i < n for i in index):
        return "servo_index", start
    if any(not -(1 << 14) <= int(v) < (1 << 14) for v in angles):
        return "servo_value", start
    goals = dict(zip(keys, start, strict=True))
    for i, v in zip(index, angles, strict=True):
        goals[keys[i]] = int(v)  # a repeated index: the last value
    return "ok", [goals[k] for k in keys]


def test_servo_targets_follow_the_topic_rules() -> None:
    from rdm.nodes.spinal_servo_bridge import MirrorRejection

    rng = random.Random(12)
    with tempfile.TemporaryDirectory() as base:
        stack = _stack(base)
        try:
            stack.loop.run_ticks(2600)
            master = stack.spinal.master
            bridge = ServoBridge(master)
            keys = master.servo_keys()
            n = len(keys)
            seen = set()
            for case in range(600):
                k = rng.choice([0, 1, 3, n, n + 2])
                index = [rng.choice([0, 1, n - 1, rng.randrange(n)]) for _ in range(k)]
                angles = [rng.randint(-3000, 3000) for _ in range(k)]
                if case % 7 == 0 and k:
                    index[rng.randrange(k)] = rng.choice([n, 255, -1])
                if case % 11 == 0 and k:
                    angles[rng.randrange(k)] = rng.choice([1 << 14, -(1 << 14) - 1, 32767])
                if case % 13 == 0:
                    angles = angles[:-1] if angles else [5]
                if case % 17 == 0 and angles:
                    angles[0] = True  # a bool is an int: goal 1
                start = [rng.randint(-2000, 2000) for _ in range(n)]
                master.core.set_servo_target_list(
                    [(s, i, g) for (s, i), g in zip(keys, start, strict=True)]
                )
                try:
                    bridge.target_states_values(index, angles)
                    outcome = "ok"
                except MirrorRejection as exc:
                    outcome = exc.reason
                want = _expected_targets(keys, start, index, angles)
                assert (outcome, _goals(master)) == want, (index, angles)
                seen.add(outcome)
            assert seen == {"ok", "wrong_length", "servo_index", "servo_value"}
        finally:
            stack.close()


# ----------------------------------------------------------------------------- whole stack
FIVE = (
    "four_axes/command",
    "rpy/gain",
    "p_matrix_pseudo_inverse_inertia",
    "desire_coordinate",
    "servo/target_states",
)
TICKS = 4300  # past the 2 s CAN boot, servo reports, a UART cut and its restore


def test_stack_busy_ms_take_the_rust_frames_duties_and_command_runs(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A hover stack with a UART cut: the ``imu`` and ``servo/states`` publications are the
    Rust-built frames, the control steps' duty lists the one-call ones, and the steady
    commands are applied by the one-call runs (no silent fallback to the message handlers
    for most of them)."""
    taken = {"imu": 0, "duties": 0, "runs": 0, "servo_states": 0}

    def counting(name: str, inner: Any) -> Any:
        def call(*args: Any) -> Any:
            got = inner(*args)
            if got is not None and got is not False:
                taken[name] += 1
            return got

        return call

    monkeypatch.setattr(sm_publishers, "_imu_frame", counting("imu", sm_publishers._imu_frame))
    monkeypatch.setattr(sm_control, "_duty_list", counting("duties", sm_control._duty_list))
    with tempfile.TemporaryDirectory() as base:
        # The mirror's own tick every ms (the lockstep kernel's busy ms are checked in
        # tests/test_spinal_kernel_busy.py).
        stack = _stack(base, lockstep_kernel=False)
        spinal = stack.spinal
        command_run = spinal._apply_command_run  # the handlers' calls, a run in one call

        def counting_run(items: list) -> int:
            done = command_run(items)
            taken["runs"] += done
            return done

        spinal.session.command_run = counting_run
        spinal._runs_armed = True
        spinal.servos.states_frame = counting("servo_states", spinal.servos.states_frame)
        stack.loop.run_ticks(3000)
        stack.spinal_link.dropped = True
        stack.loop.run_ticks(700)
        stack.spinal_link.dropped = False
        stack.loop.run_ticks(TICKS - 3700)
        diag = spinal.diagnostics()
        stack.close()
    published, received = diag["published"], diag["received"]
    assert taken["imu"] >= published["imu"] - 5 > 500  # all but the first few (no output)
    assert taken["duties"] > 300
    steady = sum(received[topic] for topic in FIVE)
    assert received["servo/target_states"] > 50 and received["rpy/gain"] > 100
    assert taken["runs"] >= 0.9 * steady, (taken, received)  # all but frames after an event
    assert taken["servo_states"] >= published["servo/states"] > 50
