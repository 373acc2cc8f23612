"""The lockstep fast paths give exactly what the plain forms give (docs/sim.md).

Each test runs a fast path beside an independent plain form: a forward pass after every
physics step, the element-wise numpy noise model, the unmemoised Neuron codec, byte-at-a-time
Leptrino de-framing, python-can's own candump writer, the closed-form ESC lag.
"""

from __future__ import annotations

import math
import random

import can
import numpy as np
import pytest

from rdm.plant import NoCeilingEffect, Plant
from rdm.plant.description import load_robot
from rdm.plant.sensors import (
    ACCEL_LSB,
    ACCEL_RANGE,
    GYRO_LSB,
    GYRO_RANGE,
    LEPTRINO_FULL_SCALE_COUNTS,
    MAG_LSB,
    ImuModel,
    ImuNoise,
    WrenchNoise,
    WrenchSensorModel,
)
from rdm.protocol import leptrino as lep
from rdm.protocol import neuron as nr


def _near_ceiling_plant() -> Plant:
    p = Plant("rdm", seed=3, ceiling_height=0.6, floor_height=0.0)
    p.reset(q0=np.zeros(10), base_position=(0.0, 0.0, 0.5))
    p.set_rotor_duties([0.8, 0.82, 0.78, 0.8])
    return p


def test_lazy_forward_gives_the_trajectory_of_a_forward_after_every_step():
    lazy, eager = _near_ceiling_plant(), _near_ceiling_plant()
    ratios_seen = set()
    for k in range(1500):
        for p in (lazy, eager):
            p.step(1)
            if k % 3 == 0:
                p.wrench("foot_wrench")
            if k % 7 == 0:
                p.imu()
            if k == 400:
                p.set_servo_targets(np.full(10, 0.15))
                p.apply_body_wrench("end_effector", force=(0.5, 0.0, 0.0))
            if k == 900:
                p.set_rotor_duties([0.7, 0.9, 0.75, 0.85])
        eager.sync()  # the former behaviour: mj_forward right after every step
        ratios_seen.update(np.round(lazy.rotor_thrusts() / _lagged(lazy), 3).tolist())
        assert np.array_equal(lazy.data.qpos, eager.data.qpos), k
        assert np.array_equal(lazy.data.qvel, eager.data.qvel), k
    a, b = lazy.ground_truth(), eager.ground_truth()
    for name in a.__dataclass_fields__:
        assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), name
    assert max(ratios_seen) > 1.05  # the ceiling effect was exercised (ratio != 1)


def _lagged(p: Plant) -> np.ndarray:
    return np.array([esc.thrust for esc in p.escs])


def test_rotor_thrust_follows_the_closed_form_first_order_lag():
    p = Plant("rdm", seed=0, ceiling_height=None, ceiling_effect=NoCeilingEffect())
    p.reset(q0=np.zeros(10), base_position=(0.0, 0.0, 5.0))
    p.set_rotor_thrusts([6.0] * 4)
    tau, dt = p.escs[0].params.tau, p.model.opt.timestep
    for k in range(1, 121):
        p.step(1)
        want = 6.0 * (1.0 - math.exp(-k * dt / tau))
        assert p.rotor_thrusts() == pytest.approx([want] * 4, rel=1e-12, abs=1e-12)
        # the actuator force MuJoCo applied in this step is that thrust
        assert p.data.ctrl[p._rotor_act] == pytest.approx([want] * 4, rel=1e-12)


def test_ground_truth_is_shared_within_one_state_only():
    p = _near_ceiling_plant()
    p.step(5)
    g1 = p.ground_truth()
    assert p.ground_truth() is g1
    p.step(1)
    g2 = p.ground_truth()
    assert g2 is not g1 and g2.time > g1.time
    p.data.qpos[2] += 0.01  # outside access: the next truth is computed afresh
    assert p.ground_truth() is not g2


# --------------------------------------------------------------------------- sensor models
def _imu_array_form(m: ImuModel, rng, gyro, acc, mag):
    n = m.noise
    w = rng.normal(0.0, 1.0, 9)
    g = gyro + m.gyro_bias + n.gyro_std * w[0:3]
    a = acc + m.accel_bias + n.accel_std * w[3:6]
    mg = mag + m.mag_bias + n.mag_std * w[6:9]
    sat = bool(np.any(np.abs(g) > GYRO_RANGE) or np.any(np.abs(a) > ACCEL_RANGE))
    g = np.clip(g, -GYRO_RANGE, GYRO_RANGE)
    a = np.clip(a, -ACCEL_RANGE, ACCEL_RANGE)
    return (
        np.round(g / GYRO_LSB) * GYRO_LSB,
        np.round(a / ACCEL_LSB) * ACCEL_LSB,
        np.round(mg / MAG_LSB) * MAG_LSB,
        sat,
    )


def _same(x: np.ndarray, y: np.ndarray) -> bool:
    return np.array_equal(x, y, equal_nan=True) and np.array_equal(np.signbit(x), np.signbit(y))


def test_scalar_noise_models_equal_the_array_form_bit_for_bit():
    spec = load_robot("rdm").wrench_sensors["foot_wrench"]
    imu = ImuModel(ImuNoise(), np.random.default_rng(11))
    ref_rng = np.random.default_rng(11)
    ref_imu = ImuModel(ImuNoise(), ref_rng)  # same biases, its own copy of the stream
    wrench = WrenchSensorModel(spec, WrenchNoise(), np.random.default_rng(12))
    ref_wrng = np.random.default_rng(12)
    gen = np.random.default_rng(0)
    for k in range(3000):
        scale = 10.0 ** gen.uniform(-7, 3)
        gyro, acc, mag = (gen.normal(size=3) * scale for _ in range(3))
        if k % 5 == 0:
            gyro[0], acc[1] = 0.0, -0.0  # rounds to a signed zero
        if k % 41 == 0:
            acc[2] = np.nan
        r = imu.sample(gyro, acc, mag)
        g, a, m, sat = _imu_array_form(ref_imu, ref_rng, gyro, acc, mag)
        assert _same(r.gyro, g) and _same(r.accel, a) and _same(r.mag, m), k
        assert r.saturated == sat
        force, torque = gen.normal(size=3) * scale * 30, gen.normal(size=3) * scale
        w = wrench.sample(force, torque)
        ref = np.concatenate([force, torque]) + 0.003 * wrench.rated * ref_wrng.normal(0, 1, 6)
        ref_sat = np.abs(ref) >= wrench.rated
        ref = np.clip(ref, -wrench.rated, wrench.rated)
        lsb = wrench.rated / LEPTRINO_FULL_SCALE_COUNTS
        ref = np.round(ref / lsb) * lsb
        assert _same(w.force, ref[:3]) and _same(w.torque, ref[3:]), k
        assert np.array_equal(w.saturated, ref_sat)


# --------------------------------------------------------------------------- Neuron codec
def _random_frames(gen: random.Random, n: int) -> list[tuple[int, bytes]]:
    out = []
    ids = [0x0F0, 0x0F1, 0x10F, 0x102, 0x103, 0x112, 0x131, 0x200, 0x211, 0x225, 0x232]
    for _ in range(n):
        can_id = gen.choice(ids) if gen.random() < 0.8 else gen.randrange(0x800)
        data = bytes(gen.randrange(256) for _ in range(gen.choice([0, 1, 2, 4, 6, 8])))
        out.append((can_id, data))
    return out


def test_memoised_decode_equals_the_codec_and_fails_alike():
    gen = random.Random(4)
    frames = _random_frames(gen, 2000)
    for _ in range(1000):  # real frames of every busy kind, as the mirrors send them
        slave = gen.randrange(1, 15)
        frames.append(
            nr.encode_servo_state_cached(
                slave,
                gen.randrange(4),
                gen.randrange(4096),
                40,
                False,
                False,
                gen.randrange(-99, 99),
                0,
            )
        )
        frames.append(
            nr.encode_servo_words_cached(
                gen.random() < 0.5, slave, (gen.randrange(4096), gen.randrange(4096)), (True, False)
            )
        )
        frames += nr.encode_pwm_cached(tuple(gen.randrange(1001) for _ in range(4)))
    frames += frames[:500]  # repeats: served from the cache
    ok = bad = 0
    for can_id, data in frames:
        for direction in (nr.Direction.SPINAL_TO_NEURON, nr.Direction.NEURON_TO_SPINAL):
            try:
                want = nr.decode_frame(can_id, data, direction)
            except nr.NeuronFrameError as exc:
                with pytest.raises(nr.NeuronFrameError) as got:
                    nr.decode_frame_cached(can_id, data, direction)
                assert got.value.reason == exc.reason
                bad += 1
                continue
            assert nr.decode_frame_cached(can_id, data, direction) == want
            ok += 1
    assert ok > 500 and bad > 500


def test_memoised_encoders_equal_the_frame_classes():
    gen = random.Random(5)
    for _ in range(2000):
        slave, index = gen.randrange(1, 15), gen.randrange(4)
        fields = (
            gen.randrange(-0x8000, 0x8000),
            gen.randrange(256),
            gen.random() < 0.5,
            gen.random() < 0.5,
            gen.randrange(-0x8000, 0x8000),
            gen.randrange(256),
        )
        angle, temp, moving, goal, current, err = fields
        frame = nr.ServoState(slave, index, angle, temp, False, moving, goal, current, err)
        assert nr.encode_servo_state_cached(slave, index, *fields) == (
            frame.can_id,
            frame.encode(),
        )
        n = gen.randrange(1, 5)
        values = tuple(gen.randrange(-(1 << 14), 1 << 14) for _ in range(n))
        flags = tuple(gen.random() < 0.5 for _ in range(n))
        for current_frame, cls in ((False, nr.ServoTargetAngles), (True, nr.ServoTargetCurrents)):
            f = cls(slave, values, flags)
            got = nr.encode_servo_words_cached(current_frame, slave, values, flags)
            assert got == (f.can_id, f.encode())
        pwm = tuple(gen.randrange(0, 1001) for _ in range(gen.randrange(1, 13)))
        assert nr.encode_pwm_cached(pwm) == [(f.can_id, f.encode()) for f in nr.pack_pwm(pwm)]
    with pytest.raises(nr.NeuronFrameError):  # range checks still apply on a miss
        nr.encode_servo_state_cached(1, 0, 0x8000, 0, False, False, 0, 0)


# --------------------------------------------------------------------------- Leptrino
def test_leptrino_deframer_chunks_equal_byte_at_a_time():
    gen = random.Random(6)
    stream = b""
    for _ in range(400):
        r = gen.random()
        if r < 0.5:
            stream += lep.frame(bytes(gen.randrange(256) for _ in range(gen.randrange(1, 256))))
        elif r < 0.7:  # an over-long payload (overflow) with valid stuffing
            p = bytes(gen.randrange(256) for _ in range(gen.randrange(256, 400)))
            stream += b"\x10\x02" + p.replace(b"\x10", b"\x10\x10") + b"\x10\x03\x00"
        else:
            stream += bytes(gen.choice([0x10, 0x02, 0x03, gen.randrange(256)]) for _ in range(9))
    fast, slow = lep.LeptrinoStreamParser(), lep.LeptrinoStreamParser()
    events_fast, at = [], 0
    while at < len(stream):
        n = gen.choice([1, 7, 100, 3000])
        events_fast += fast.feed(stream[at : at + n])
        at += n
    events_slow = [e for b in stream for e in slow.feed(bytes([b]))]
    assert repr(events_fast) == repr(events_slow)
    assert (fast.frames, dict(fast.errors), fast.discarded_bytes) == (
        slow.frames,
        dict(slow.errors),
        slow.discarded_bytes,
    )
    assert fast.frames > 150 and fast.errors["overflow"] > 50


# --------------------------------------------------------------------------- candump
def test_candump_capture_writes_what_python_cans_writer_writes(tmp_path):
    from rdm.sim import CandumpCapture

    gen = random.Random(7)
    msgs = []
    t = 1.0
    for k in range(3000):
        t += gen.choice([0.0, 0.0005, 0.001])
        kind = gen.random()
        msgs.append(
            can.Message(
                timestamp=t if k % 500 else t - 0.7,  # a few out of order
                arbitration_id=gen.randrange(0x800 if kind < 0.9 else 0x2000_0000),
                is_extended_id=kind >= 0.9,
                is_remote_frame=0.95 <= kind < 0.97,
                is_error_frame=kind >= 0.99,
                data=b"" if 0.95 <= kind < 0.97 else bytes(gen.randrange(256) for _ in range(8)),
                channel=gen.choice(["rdm-sim", "rdm-sim", "0", None]),
                is_rx=gen.random() < 0.8,
            )
        )
    ours = CandumpCapture(tmp_path / "ours.log")
    theirs = can.CanutilsLogWriter(tmp_path / "theirs.log", channel="can0")
    for m in msgs:
        ours.on_message_received(m)
        theirs.on_message_received(m)
    ours.close()
    theirs.stop()
    assert (tmp_path / "ours.log").read_bytes() == (tmp_path / "theirs.log").read_bytes()


# --------------------------------------------------------------------------- joint feed
def test_servos_see_the_plant_angle_of_the_bridge_tick():
    """A Neuron reads its servo positions lazily, when a frame that needs them is handled;
    they are the plant's angles at the bridge tick (before that tick's physics step),
    converted to ticks."""
    from test_lockstep import SpinalFrames

    from rdm.link.inproc_can import InProcessBus
    from rdm.nodes.lockstep import Lockstep
    from rdm.nodes.neuron_mirror import NeuronMirror
    from rdm.nodes.plant_bridge import PlantBridge, default_layout

    plant = Plant("rdm", seed=1, fixed_base=True, ceiling_height=None)
    layout = default_layout(plant.description)
    buses = [InProcessBus("speed_feed") for _ in layout.neurons]
    # Spinal's side: torque on for q1 (Neuron 2's first servo), then its goal with the ack bit
    spinal = SpinalFrames(InProcessBus("speed_feed"), round(layout.to_ticks("q1", 0.3)))
    neurons = [
        NeuronMirror(b, nl.slave, layout.servo_configs(nl.slave), plant_driven=True)
        for b, nl in zip(buses, layout.neurons, strict=True)
    ]
    bridge = PlantBridge(plant, neurons)
    servo = neurons[1].servos[0]  # q1
    j = plant.joint_names.index("q1")
    seen = []

    class Probe:
        name, period = "probe", 0.001

        def tick(self, now):
            q = float(plant.servo_positions()[j])
            seen.append((servo.position, 2048 + q * (4096 / (2 * math.pi))))

    try:
        Lockstep([bridge, *neurons, spinal, Probe()], physics=plant).run(0.2)
    finally:
        for b in [*buses, spinal.bus]:
            b.shutdown()
    # from the first ms a frame that reads the positions reaches the board (the torque frame
    # sent at 1 ms, handled at 2 ms; every ms after it a goal frame)
    assert all(got == want for got, want in seen[2:])
    assert seen[-1][0] > seen[0][0] + 100  # the joint moved toward the goal


# --------------------------------------------------------------------------- in-process bus
def test_send_standard_delivers_what_send_of_a_standard_message_delivers():
    from rdm.link.inproc_can import InProcessBus, add_tap, remove_tap

    def fields(m: can.Message) -> tuple:
        return (m.timestamp, m.arbitration_id, m.is_extended_id, m.is_remote_frame,
                m.is_error_frame, m.channel, m.dlc, bytes(m.data), type(m.data), m.is_fd,
                m.is_rx, m.bitrate_switch, m.error_state_indicator)  # fmt: skip

    gen = random.Random(8)
    frames = [(gen.randrange(0x800), bytes(gen.randrange(256) for _ in range(gen.randrange(9))))
              for _ in range(300)]  # fmt: skip
    seen = {}
    for name, fast in (("speed_a", False), ("speed_b", True)):
        tx = InProcessBus(name, receive_own_messages=True)
        rx = InProcessBus(name)
        filtered = InProcessBus(name, can_filters=[{"can_id": 0x100, "can_mask": 0x700}])
        tapped: list = []
        add_tap(name, tapped.append)
        for can_id, data in frames:
            if fast:
                tx.send_standard(can_id, data)
            else:
                tx.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        got = [[fields(m) for m in tapped]]
        for b in (tx, rx, filtered):
            got.append([fields(m) for m in iter(lambda b=b: b.recv(timeout=0), None)])
        remove_tap(name, tapped.append)
        for b in (tx, rx, filtered):
            b.shutdown()
        seen[fast] = [
            [(*f[:5], "ch", *f[6:]) for f in group] for group in got
        ]  # channel names differ
    assert seen[True] == seen[False]
    assert len(seen[True][3]) > 10  # the filter let some through
