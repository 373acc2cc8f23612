"""The Spinal mirror's busy-ms fast paths (docs/spinal.md) against their plain paths.

* ``rdm._rdm.spinal_imu_frame`` (stamp + ``spinal/Imu`` pack + frame in Rust) against
  ``ClientClock.now`` + the Python codec + ``encode_frame`` on random values, clocks, ticks
  and topic ids: the same bytes whenever it answers, and it answers whenever the values are
  finite float32s and the stamp fits; other argument types are declined.
* ``rdm._rdm.spinal_duty_list`` against ``SpinalMirror._step_tail``'s list on the steps of
  an armed ``SpinalStep`` with random commands; None when the step has events.
* ``MessageCodec.decode_values`` against ``decode`` on random valid, cut and extended
  payloads of every Spinal type with a fast layout: values exactly when ``decode`` succeeds.
* ``ClientSession.deliver_values`` against a session without it on a random stream: the
  same events (values vs messages), output bytes and counters; ``send_frame`` /
  ``send_payload`` against ``_send`` (too large, ring full, not configured).
* ``ServoBridge.states_frame`` (the master's table framed in one call) against encoding
  ``states()`` with the Python codec; declines for stamps, topic ids and codecs it does not
  take. ``servo/target_states`` against its rules written out (lengths, indices, 15-bit
  values, the last of a repeated index).
* The command handlers from field values against the message handlers on random good and
  bad commands (rejections, logs, counters, core state).
* The whole hover stack with the fast paths on and off: same bytes in every log and the
  same counters, and each new fast path was taken.
"""

from __future__ import annotations

import itertools
import math
import random
import struct
import tempfile
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from rdm import _rdm
from rdm.control.attitude import ARM_ON, INTEGRATION_CONTROL_ON, UAV_HYDRUS, SpinalStep
from rdm.nodes import spinal_mirror as sm
from rdm.nodes import spinal_mirror_control as sm_control
from rdm.nodes import spinal_mirror_publishers as sm_publishers
from rdm.nodes.can_master import IDLE_DUTY
from rdm.nodes.spinal_servo_bridge import ServoBridge
from rdm.protocol.rosserial import constants as C
from rdm.protocol.rosserial.client import ClientSession
from rdm.protocol.rosserial.codec import DecodeError, EncodeError, RosTime
from rdm.protocol.rosserial.events import MessageReceived
from rdm.protocol.rosserial.framing import encode_frame
from rdm.protocol.rosserial.registry import spinal_registry
from rdm.protocol.rosserial.timesync import ClientClock

REG = spinal_registry()
IMU = REG.msg("spinal/Imu")
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
    """The value the fast path must take: finite and a float32 (struct packs it)."""
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


def test_imu_frame_equals_python_codec_and_declines_only_what_it_must() -> None:
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
        fast = _rdm.spinal_imu_frame(
            topic, now_ms, clock.synced, clock._sync_tick, clock._sync_ns, acc, out, mag
        )
        stamp = clock.now(now_ms)
        msg = IMU.new(
            stamp=stamp,
            acc=list(acc),
            gyro=out.angular_velocity.tolist(),
            mag=list(mag),
            quaternion=out.quaternion.tolist(),
        )
        try:
            reference = encode_frame(topic, IMU.encode(msg))
        except (EncodeError, OverflowError):  # what the codec raises for those values
            reference = None
        values = [*acc, *msg.gyro, *mag, *msg.quaternion]
        must = stamp.sec < 2**32 and all(_packs(x) for x in values)
        if fast is None:
            declined += 1
            assert not must, (acc, mag, stamp)
        else:
            answered += 1
            assert must and fast == reference
    assert answered > 1000 and declined > 500


@pytest.mark.parametrize(
    "change",
    [
        {"acc": [0, 0, 9]},  # ints: struct packs them, the fast path leaves them to it
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
def _tail_duties(out: Any, n: int) -> list[float]:
    return [min(1.0, max(IDLE_DUTY, d)) for d in out.duty.tolist()[:n]]


def test_duty_list_equals_the_python_tail() -> None:
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
                assert got == _tail_duties(out, n)
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


# ----------------------------------------------------------------------------- decode_values
def _payload(codec: Any, rng: random.Random) -> bytes:
    """A valid payload of a fast-layout codec: random bytes in the layout's shape."""
    if codec._flat is not None:
        return rng.randbytes(codec._flat.size)
    out = b""
    for seg in codec._var._segments:
        if seg[0] == "fixed":
            out += rng.randbytes(struct.calcsize("<" + seg[2]))
        else:
            n = rng.choice([0, 1, 4, rng.randrange(12)])
            out += struct.pack("<I", n) + rng.randbytes(n * seg[3])
    return out


def _as_values(value: Any) -> Any:
    if hasattr(value, "__dataclass_fields__"):
        return tuple(_as_values(getattr(value, f)) for f in value.__dataclass_fields__)
    if isinstance(value, list):
        return [_as_values(v) for v in value]
    return value


def test_decode_values_equals_decode() -> None:
    rng = random.Random(2)
    types = [n for n in REG.message_names if REG.msg(n)._flat or REG.msg(n)._var]
    assert "spinal/ServoControlCmd" in types and "spinal/RollPitchYawTerms" in types
    taken = 0
    for name in types:
        codec = REG.msg(name)
        for _ in range(60):
            data = _payload(codec, rng)
            kind = rng.random()
            if kind < 0.2 and data:
                data = data[: rng.randrange(len(data))]
            elif kind < 0.35:
                data += rng.randbytes(rng.randint(1, 5))
            elif kind < 0.45 and len(data) >= 4:
                data = struct.pack("<I", rng.randrange(2**32)) + data[4:]
            try:
                msg = codec.decode(data)
            except DecodeError:
                msg = None
            values = codec.decode_values(data)
            assert (values is None) == (msg is None), (name, data)
            if values is not None:
                # repr: NaN compares equal as text
                assert repr(values) == repr(_as_values(msg)), name
                taken += 1
            assert codec.decode_values(bytearray(data)) is None
    assert taken > 500
    plain = REG.msg("rosserial_msgs/Log")  # a string: no fast layout
    assert plain.decode_values(plain.encode(plain.new(level=1, msg="x"))) is None


# ----------------------------------------------------------------------------- sessions
FIVE = {
    "four_axes/command": "spinal/FourAxisCommand",
    "rpy/gain": "spinal/RollPitchYawTerms",
    "p_matrix_pseudo_inverse_inertia": "spinal/PMatrixPseudoInverseWithInertia",
    "desire_coordinate": "spinal/DesireCoord",
    "servo/target_states": "spinal/ServoControlCmd",
}


def _stream_piece(rng: random.Random, session: ClientSession) -> bytes:
    kind = rng.random()
    if kind < 0.05:
        return encode_frame(C.TopicId.PUBLISHER, b"")
    if kind < 0.1:
        t = REG.msg("std_msgs/Time")
        return encode_frame(C.TopicId.TIME, t.encode(t.new(data=RosTime(5, 6))))
    slots = {s.name: s for s in session.subscribers}
    if kind < 0.75:
        slot = slots[rng.choice([*FIVE, "uav_info", "flight_config_cmd"])]
        data = _payload(slot.codec, rng)
        if rng.random() < 0.2 and data:
            data = data[: rng.randrange(len(data))]  # a drop with its reason
        elif rng.random() < 0.1:
            data += b"\x00"
        return encode_frame(slot.topic_id, data)
    if kind < 0.85:
        slot = slots["imu_calib"]  # a service: the response goes out during spin
        return encode_frame(slot.topic_id, slot.codec.encode(slot.codec.new(command=0)))
    if kind < 0.9:
        return encode_frame(100 + rng.randrange(60), rng.randbytes(rng.randrange(8)))
    return rng.randbytes(rng.randrange(1, 12))


def _event_form(event: Any) -> Any:
    if event.__class__ is tuple:  # (slot, values, payload)
        slot, values, payload = event
        assert repr(values) == repr(slot.codec.decode_values(payload))
        return ("message", slot.name, repr(slot.codec.decode(payload)))
    if isinstance(event, MessageReceived):
        return ("message", event.topic, repr(event.message))
    return repr(event)


@pytest.mark.parametrize("seed", range(4))
def test_deliver_values_session_equals_message_session(seed: int) -> None:
    rng = random.Random(seed)
    plain, fast = ClientSession.from_layout(), ClientSession.from_layout()
    marked = fast.deliver_values([*FIVE, "uav_info", "imu_calib", "no such topic"])
    assert sorted(s.name for s in marked) == sorted([*FIVE, "uav_info"])  # no service half
    tuples = 0
    for t in range(400):
        data = b"".join(_stream_piece(rng, plain) for _ in range(rng.randrange(4)))
        cut = rng.randrange(len(data) + 1)
        for chunk in (data[:cut], data[cut:]):
            a, b = plain.spin(chunk, t), fast.spin(chunk, t)
            tuples += sum(e.__class__ is tuple for e in b)
            assert [_event_form(e) for e in a] == [_event_form(e) for e in b]
            assert plain.take_output() == fast.take_output()
    assert dict(plain.counts) == dict(fast.counts)
    assert dict(plain.parser.counts) == dict(fast.parser.counts)
    assert tuples > 150
    assert fast.deliver_values(()) == [] and not any(s.values for s in fast.subscribers)


def test_send_frame_and_send_payload_equal_send() -> None:
    rng = random.Random(4)
    sessions = [ClientSession.from_layout() for _ in range(3)]
    for step in range(600):
        if step % 150 == 0:
            configure = step != 300
            for s in sessions:
                s.configured = configure
        topic = rng.choice([7, 10, 100, 154, 170])
        n = rng.choice([0, 1, 60, 1000, 1016, 1017, 2000])
        payload = rng.randbytes(n)
        got = [
            sessions[0]._send(topic, payload),
            sessions[1].send_frame(topic, encode_frame(topic, payload)),
            sessions[2].send_payload(topic, payload),
        ]
        assert got[0] == got[1] == got[2]
        if rng.random() < 0.1:  # else the TX ring fills and drops
            outs = [s.take_output() for s in sessions]
            assert outs[0] == outs[1] == outs[2]
    assert dict(sessions[0].counts) == dict(sessions[1].counts) == dict(sessions[2].counts)
    assert {"tx_ring_full", "tx_too_large", "tx_not_configured"} <= set(sessions[0].counts)


# ----------------------------------------------------------------------------- servo states
def _stack(base: str):
    from rdm.scenarios.common import sim_stack_options
    from rdm.scenarios.hover import HOVER_Z, make_script
    from rdm.scenarios.stack import build_stack

    opts = sim_stack_options(0, "inproc", speed=None)
    return build_stack("busy", base, opts, make_script(np.array([0.483, 0.0, HOVER_Z])))


def test_servo_states_frame_equals_the_encoded_message() -> None:
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
                    assert frame == encode_frame(topic, codec.encode(message))
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


# ----------------------------------------------------------------------------- value handlers
_BUSES = itertools.count()


def _mirror(fast: bool) -> tuple[sm.SpinalMirror, Any]:
    """A mirror on an in-process UART (and the PC's end of it) and a bus of its own."""
    from rdm.link.can import open_can
    from rdm.link.uart_pipe import open_inproc_uart

    dev, host = open_inproc_uart()
    bus = open_can(f"virtual:spinal_busy_{next(_BUSES)}")
    return sm.SpinalMirror(dev, bus, fast_paths=fast, boot_delay_ms=0), host


def _command(topic: str, rng: random.Random) -> Any:
    codec = REG.msg(FIVE[topic])
    if topic == "four_axes/command":
        n = rng.choice([4, 4, 3, 0])
        angles = [rng.choice([0.0, 0.1, -0.3, math.nan, 2.0]) for _ in range(3)]
        base = [rng.choice([5.0, 9.0, 0.0, -1.0, math.inf]) for _ in range(n)]
        return codec.new(angles=angles, base_thrust=base)
    if topic == "rpy/gain":
        term = REG.msg("spinal/RollPitchYawTerm")
        motors = [
            term.new(**{f.name: rng.randint(-3000, 3000) for f in term.spec.fields})
            for _ in range(rng.choice([4, 4, 3, 5]))
        ]
        return codec.new(motors=motors)
    if topic == "p_matrix_pseudo_inverse_inertia":
        unit = REG.msg("spinal/PMatrixPseudoInverseUnit")
        rows = [
            unit.new(r=rng.randint(-900, 900), p=rng.randint(-900, 900), y=rng.randint(-900, 900))
            for _ in range(rng.choice([4, 4, 2]))
        ]
        return codec.new(pseudo_inverse=rows, inertia=[rng.randint(-50, 200) for _ in range(6)])
    if topic == "desire_coordinate":
        return codec.new(roll=rng.choice([0.0, 0.2, math.nan]), pitch=0.1, yaw=-0.4)
    n = rng.choice([1, 2, 0])
    return codec.new(
        index=[rng.randint(0, 3) for _ in range(n)], angles=[rng.randint(-5, 5) for _ in range(n)]
    )


def test_value_handlers_equal_message_handlers() -> None:
    rng = random.Random(9)
    (fast, fast_pc), (plain, plain_pc) = _mirror(True), _mirror(False)
    try:
        # configured (the PC's topic request on the wire) and set up alike
        for m, pc in ((fast, fast_pc), (plain, plain_pc)):
            pc.write(encode_frame(C.TopicId.PUBLISHER, b""))
            m.tick(0.0)
            assert m.session.configured
            m.core.set_uav_info(4, UAV_HYDRUS)
            m.core.set_pwm_info_hydrus_example()
        routed = 0
        for k in range(1, 400):
            now = k * 0.001
            topic = rng.choice(list(FIVE))
            msg = _command(topic, rng)
            payload = REG.msg(FIVE[topic]).encode(msg)
            slot = next(s for s in fast.session.subscribers if s.name == topic)
            if k == 50:
                for m in (fast, plain):
                    m.core.flight_config(ARM_ON, now)
            for m in (fast, plain):
                m._now_s = now
            values = slot.codec.decode_values(payload)
            assert values is not None and topic in fast._value_routes
            fast._route_values(slot, values, payload)
            plain._route(topic, slot.codec.decode(payload))
            routed += 1
            for m in (fast, plain):
                m.tick(now)
            assert fast_pc.read_available() == plain_pc.read_available()
            assert fast.diagnostics() == plain.diagnostics()
            assert fast.core.target_angles.tolist() == plain.core.target_angles.tolist()
            assert fast.core.base_thrust.tolist() == plain.core.base_thrust.tolist()
            assert repr(fast.last_output.duty) == repr(plain.last_output.duty)
        rejected = fast.counters.rejected
        assert routed and sum(rejected.values()) > 20 and len(rejected) >= 3, rejected
        assert sum(fast.counters.received.values()) > 100
    finally:
        fast.close()
        plain.close()


# ----------------------------------------------------------------------------- whole stack
TICKS = 4300  # past the 2 s CAN boot, servo reports, a UART cut and its restore


def _run(base: str, fast: bool, monkeypatch: pytest.MonkeyPatch) -> tuple[dict, dict, dict]:
    taken = {"imu": 0, "duties": 0, "values": 0, "servo_states": 0}

    def counting(name: str, inner: Any) -> Any:
        def call(*args: Any) -> Any:
            got = inner(*args)
            if got is not None and got is not False:
                taken[name] += 1
            return got

        return call

    monkeypatch.setattr(sm_publishers, "_imu_frame", counting("imu", sm_publishers._imu_frame))
    monkeypatch.setattr(sm_control, "_duty_list", counting("duties", sm_control._duty_list))
    stack = _stack(base)
    spinal = stack.spinal
    spinal._fast = fast
    spinal.servos._fast = fast
    spinal.master.fast = fast
    spinal.uart.fast = fast
    # The Python busy paths under test: the lockstep kernel runs only the idle ms (its own
    # busy ms are compared in tests/test_spinal_kernel_busy.py).
    spinal.kernel_busy = False
    route_values = spinal._route_values

    def counting_values(*args: Any) -> None:
        taken["values"] += 1
        route_values(*args)

    spinal._route_values = counting_values
    command_run = spinal._apply_command_run  # the same routes, a run of frames in one call

    def counting_run(items: list) -> int:
        done = command_run(items)
        taken["values"] += done
        return done

    spinal._apply_command_run = counting_run
    states = spinal.servos.states_frame
    spinal.servos.states_frame = counting("servo_states", states)
    stack.loop.run_ticks(3000)
    stack.spinal_link.dropped = True
    stack.loop.run_ticks(700)
    stack.spinal_link.dropped = False
    stack.loop.run_ticks(TICKS - 3700)
    diag = spinal.diagnostics()
    stack.close()
    paths = sorted(p for p in Path(base).rglob("*") if p.is_file())
    return {str(p.relative_to(base)): p.read_bytes() for p in paths}, diag, taken


def test_stack_bytes_and_counters_equal_with_busy_fast_paths_on_and_off(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    with tempfile.TemporaryDirectory() as a, tempfile.TemporaryDirectory() as b:
        fast_files, fast_diag, taken = _run(a, True, monkeypatch)
        plain_files, plain_diag, plain_taken = _run(b, False, monkeypatch)
    assert fast_diag == plain_diag
    published, received = fast_diag["published"], fast_diag["received"]
    assert taken["imu"] >= published["imu"] - 5 > 500  # all but the first few (no output)
    assert taken["duties"] > 300
    assert taken["values"] >= received["servo/target_states"] + received["rpy/gain"] > 100
    assert taken["servo_states"] >= published["servo/states"] > 50
    assert plain_taken == {"imu": 0, "duties": 0, "values": 0, "servo_states": 0}
    assert sorted(fast_files) == sorted(plain_files)
    for name in fast_files:
        assert fast_files[name] == plain_files[name], name


# ----------------------------------------------------------------------------- UART chain
def _chain(base: Path, name: str, cut: bool, tapped: bool) -> tuple[Any, ...]:
    from rdm.link.tapped_link import TappedLink
    from rdm.link.uart_pipe import InProcessUartEnd
    from rdm.scenarios.stack import DroppableLink

    dev, host = InProcessUartEnd("device"), InProcessUartEnd("host")
    dev.peer, host.peer = host, dev
    link: Any = dev
    tap = None
    if tapped:
        link = tap = TappedLink(dev, base / f"{name}.tx", base / f"{name}.rx")
    drop = DroppableLink(link) if cut else None
    return (drop or link), drop, tap, dev, host


def _pump_state(rig: tuple[Any, ...]) -> tuple[Any, ...]:
    pump, drop, tap, dev, host = rig
    return (
        pump.bytes_in,
        pump.bytes_out,
        pump.bytes_discarded,
        pump.write_errors,
        pump.read_errors,
        bytes(pump.pending),
        None if drop is None else (drop.dropped, drop.bytes_lost),
        None if tap is None else (tap.tx_bytes, tap.rx_bytes),
        bytes(host.inbox),
        bytes(dev.inbox),
    )


@pytest.mark.parametrize(
    ("cut", "tapped"), [(True, True), (False, True), (True, False), (False, False)]
)
def test_uart_pump_chain_equals_calls_through_the_wrappers(cut: bool, tapped: bool) -> None:
    from rdm.nodes.spinal_uart import UartPump

    rng = random.Random(int(cut) * 2 + int(tapped))
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp)
        rigs = []
        for name, fast in (("fast", True), ("plain", False)):
            link, drop, tap, dev, host = _chain(base, name, cut, tapped)
            pump = UartPump(link, max_pending=300, fast=fast)
            assert pump._chain == (drop, tap, dev)  # the plain pump has it too, unused
            rigs.append((pump, drop, tap, dev, host))
        ops = ["send", "send", "pump", "pc_send", "pc_send", "pc_read", "drop", "peer", "end"]
        for step in range(3000):
            op = rng.choice(ops)
            data = rng.randbytes(rng.choice([0, 1, 7, 70, 400]))
            outs = []
            for pump, drop, tap, dev, host in rigs:
                if step == 2900 and tap is not None:
                    tap._tx.close()  # captures closed: ValueError on their writes, counted
                    tap._rx.close()
                if op == "send":
                    pump.send(data)
                elif op == "pump":
                    outs.append(pump.pump())
                elif op == "pc_send":
                    if not host.closed:
                        host.write(data)
                    outs.append(pump.read())
                elif op == "pc_read":
                    outs.append(host.read_available())
                elif op == "drop" and drop is not None:
                    drop.dropped = not drop.dropped
                elif op == "peer":  # the PC end goes away / comes back: writes are lost
                    host.closed = not host.closed
                elif op == "end" and step % 5 == 0:  # our end closed: OSError, counted
                    dev.closed = not dev.closed
            assert outs[:1] == outs[1:]
            assert _pump_state(rigs[0]) == _pump_state(rigs[1])
        assert rigs[0][0].write_errors > 0 and rigs[0][0].bytes_out > 1000
        for pump, *_ in rigs:
            pump.link.close()
        if tapped:
            for kind in ("tx", "rx"):
                fast_bytes = (base / f"fast.{kind}").read_bytes()
                assert fast_bytes == (base / f"plain.{kind}").read_bytes() and fast_bytes
