"""The Spinal mirror's busy ms (docs/spinal.md): its Rust-built frames and one-call steps
against the Python codec and the rules written out, and its command handlers.

* ``rdm._rdm.spinal_imu_frame`` (stamp + ``spinal/Imu`` pack + frame in Rust) against
  ``ClientClock.now`` + the Python codec + ``encode_frame`` on random values, clocks, ticks
  and topic ids: the same bytes whenever it answers, and it answers whenever the values are
  finite float32s and the stamp fits; other argument types are declined.
* ``rdm._rdm.spinal_duty_list`` against the clamp rule (each duty in [idle, 1.0]) on the
  steps of an armed ``SpinalStep`` with random commands; None when the step has events.
* ``MessageCodec.decode_values`` against ``decode`` on random valid, cut and extended
  payloads of every Spinal type with a flat or variable layout: values exactly when
  ``decode`` succeeds.
* ``ClientSession.deliver_values`` against a session delivering messages on a random
  stream: the same events (values vs decoded messages), output bytes and counters;
  ``send_frame`` / ``send_payload`` against ``_send`` (too large, ring full, not configured).
* ``ServoBridge.states_frame`` (the master's table framed in one call) against encoding
  ``states()`` with the Python codec; declines for stamps, topic ids and codecs it does not
  take. ``servo/target_states`` against its rules written out (lengths, indices, 15-bit
  values, the last of a repeated index).
* The command handlers from field values against the message handlers (the ones a
  subscriber of another layout takes) on random good and bad commands (rejections, logs,
  counters, core state).
* A whole hover stack: the busy ms take the Rust frames, duty lists and value routes.
"""

from __future__ import annotations

import itertools
import math
import random
import struct
import tempfile
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
        frame = _rdm.spinal_imu_frame(
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
        if frame is None:
            declined += 1
            assert not must, (acc, mag, stamp)
        else:
            answered += 1
            assert must and frame == reference
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


# ----------------------------------------------------------------------------- decode_values
def _payload(codec: Any, rng: random.Random) -> bytes:
    """A valid payload of a flat or variable layout codec: random bytes in its shape."""
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
    log = REG.msg("rosserial_msgs/Log")  # a string: no flat or variable layout
    assert log.decode_values(log.encode(log.new(level=1, msg="x"))) is None


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
    messages, values = ClientSession.from_layout(), ClientSession.from_layout()
    marked = values.deliver_values([*FIVE, "uav_info", "imu_calib", "no such topic"])
    assert sorted(s.name for s in marked) == sorted([*FIVE, "uav_info"])  # no service half
    tuples = 0
    for t in range(400):
        data = b"".join(_stream_piece(rng, messages) for _ in range(rng.randrange(4)))
        cut = rng.randrange(len(data) + 1)
        for chunk in (data[:cut], data[cut:]):
            a, b = messages.spin(chunk, t), values.spin(chunk, t)
            tuples += sum(e.__class__ is tuple for e in b)
            assert [_event_form(e) for e in a] == [_event_form(e) for e in b]
            assert messages.take_output() == values.take_output()
    assert dict(messages.counts) == dict(values.counts)
    assert dict(messages.parser.counts) == dict(values.parser.counts)
    assert tuples > 150
    assert values.deliver_values(()) == [] and not any(s.values for s in values.subscribers)


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
def _stack(base: str, **options: Any):
    from rdm.scenarios.common import sim_stack_options
    from rdm.scenarios.hover import HOVER_Z, make_script
    from rdm.scenarios.stack import build_stack

    opts = sim_stack_options(0, "inproc", speed=None, **options)
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


def _mirror(values: bool) -> tuple[sm.SpinalMirror, Any]:
    """A mirror on an in-process UART (and the PC's end of it) and a bus of its own;
    without ``values`` every command goes through the message handlers."""
    from rdm.link.can import open_can
    from rdm.link.uart_pipe import open_inproc_uart

    dev, host = open_inproc_uart()
    bus = open_can(f"virtual:spinal_busy_{next(_BUSES)}")
    mirror = sm.SpinalMirror(dev, bus, boot_delay_ms=0)
    if not values:
        mirror._value_routes = {}  # armed by the first receive: no topic delivered as values
        mirror._command_kinds = bytes(len(mirror._command_kinds))
    return mirror, host


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
    (by_values, values_pc), (by_messages, messages_pc) = _mirror(True), _mirror(False)
    try:
        # configured (the PC's topic request on the wire) and set up alike
        for m, pc in ((by_values, values_pc), (by_messages, messages_pc)):
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
            slot = next(s for s in by_values.session.subscribers if s.name == topic)
            if k == 50:
                for m in (by_values, by_messages):
                    m.core.flight_config(ARM_ON, now)
            for m in (by_values, by_messages):
                m._now_s = now
            values = slot.codec.decode_values(payload)
            assert values is not None and topic in by_values._value_routes
            by_values._route_values(slot, values, payload)
            by_messages._route(topic, slot.codec.decode(payload))
            routed += 1
            for m in (by_values, by_messages):
                m.tick(now)
            assert values_pc.read_available() == messages_pc.read_available()
            assert by_values.diagnostics() == by_messages.diagnostics()
            assert by_values.core.target_angles.tolist() == by_messages.core.target_angles.tolist()
            assert by_values.core.base_thrust.tolist() == by_messages.core.base_thrust.tolist()
            assert repr(by_values.last_output.duty) == repr(by_messages.last_output.duty)
        rejected = by_values.counters.rejected
        assert routed and sum(rejected.values()) > 20 and len(rejected) >= 3, rejected
        assert sum(by_values.counters.received.values()) > 100
    finally:
        by_values.close()
        by_messages.close()


# ----------------------------------------------------------------------------- whole stack
TICKS = 4300  # past the 2 s CAN boot, servo reports, a UART cut and its restore


def test_stack_busy_ms_take_the_rust_frames_duties_and_value_routes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A hover stack with a UART cut: the ``imu`` and ``servo/states`` publications are the
    Rust-built frames, the control steps' duty lists the one-call ones, and the commands
    arrive as field values (no silent fallback to the message paths)."""
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
    with tempfile.TemporaryDirectory() as base:
        # The mirror's own tick every ms (the lockstep kernel's busy ms are checked in
        # tests/test_spinal_kernel_busy.py).
        stack = _stack(base, lockstep_kernel=False)
        spinal = stack.spinal
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
    assert taken["values"] >= received["servo/target_states"] + received["rpy/gain"] > 100
    assert taken["servo_states"] >= published["servo/states"] > 50
