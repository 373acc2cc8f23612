"""The plant's sensor noise, the plant bridge's joint ticks and sampling schedule, the ceiling
effect in the rotor actuators and the CAN master's PWM frames.

Each check compares bit for bit (signed zeros and NaN included) with an independent numpy
computation: numpy's own generator called once per sample, the array forms of the noise
models on MuJoCo's ideal sensor values, the array expression of the tick conversion, the tick
arithmetic of the schedule, each ceiling model's ratio at the rotor distances, Spinal's PWM
packing.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from rdm import _rdm
from rdm._rdm import NormalStreamCore
from rdm.plant import Plant
from rdm.plant.mjcf import rotor_site
from rdm.plant.sensors import (
    ACCEL_LSB,
    ACCEL_RANGE,
    GYRO_LSB,
    GYRO_RANGE,
    LEPTRINO_FULL_SCALE_COUNTS,
    MAG_LSB,
    NORMAL_CHUNK,
)


def _same(x, y) -> bool:
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    return np.array_equal(x, y, equal_nan=True) and np.array_equal(np.signbit(x), np.signbit(y))


def test_normal_stream_equals_one_generator_call_per_take():
    stream = NormalStreamCore(np.random.default_rng(5), NORMAL_CHUNK)
    ref = np.random.default_rng(5)
    sizes = np.random.default_rng(1).integers(1, 40, 2000)  # crosses many chunk boundaries
    assert sizes.sum() > 10 * NORMAL_CHUNK
    for k in sizes.tolist():
        assert _same(stream.take(k), ref.normal(0.0, 1.0, k)), k
    assert stream.taken == sizes.sum()


def _flying_plant() -> Plant:
    plant = Plant("rdm", seed=3, ceiling_height=1.2, floor_height=0.0)
    plant.reset(base_position=(0.0, 0.0, 0.6), thrusts=[4.0, 4.5, 5.0, 4.2])
    plant.set_rotor_thrusts([5.0, 3.0, 6.0, 4.0])  # tumbles: gyro, accel, wrench all move
    return plant


def test_plant_imu_and_wrench_equal_the_array_form_of_the_ideal_values():
    plant = _flying_plant()
    seeds = np.random.SeedSequence(3).spawn(1 + len(plant.wrench_models))
    # IMU reference: the model's biases are the generator's first 3 x 3 normals, then 9
    # normals per sample, one call each.
    imu_rng = np.random.default_rng(seeds[0])
    noise = plant.imu_model.noise
    gb = imu_rng.normal(0.0, noise.gyro_bias_std, 3)
    ab = imu_rng.normal(0.0, noise.accel_bias_std, 3)
    mb = imu_rng.normal(0.0, noise.mag_bias_std, 3)
    keys = list(plant.wrench_models)
    w_rngs = {k: np.random.default_rng(s) for k, s in zip(keys, seeds[1:], strict=True)}
    for step in range(600):
        plant.step(1)
        if step % 3 == 0:
            ideal = plant.imu_ideal()
            r = plant.imu()
            w = imu_rng.normal(0.0, 1.0, 9)
            g = np.clip(ideal.gyro + gb + noise.gyro_std * w[0:3], -GYRO_RANGE, GYRO_RANGE)
            a = np.clip(ideal.accel + ab + noise.accel_std * w[3:6], -ACCEL_RANGE, ACCEL_RANGE)
            m = ideal.mag + mb + noise.mag_std * w[6:9]
            assert _same(r.gyro, np.round(g / GYRO_LSB) * GYRO_LSB), step
            assert _same(r.accel, np.round(a / ACCEL_LSB) * ACCEL_LSB), step
            assert _same(r.mag, np.round(m / MAG_LSB) * MAG_LSB), step
        for key in keys:
            model = plant.wrench_models[key]
            force, torque = plant.wrench_ideal(key)
            reading = plant.wrench(key)
            ref = np.concatenate([force, torque]) + 0.003 * model.rated * w_rngs[key].normal(
                0, 1, 6
            )
            sat = np.abs(ref) >= model.rated
            ref = np.clip(ref, -model.rated, model.rated)
            lsb = model.rated / LEPTRINO_FULL_SCALE_COUNTS
            ref = np.round(ref / lsb) * lsb
            assert _same(reading.force, ref[:3]) and _same(reading.torque, ref[3:]), step
            assert np.array_equal(reading.saturated, sat)
    try:
        plant.wrench("no_such_sensor")
    except ValueError as e:
        assert "no_such_sensor" in str(e)
    else:  # pragma: no cover
        raise AssertionError("unknown wrench sensor accepted")


def test_bridge_present_positions_equal_the_array_expression():
    """The bank coupling's present positions (raw ticks) are ``center + q * ticks_per_rad``
    of the snapshot's joint angles, read at the joints' qpos addresses."""
    from rdm.link.inproc_can import InProcessBus
    from rdm.nodes.neuron_bank import NeuronBankNode, NeuronSpec
    from rdm.nodes.servo_model import ServoConfig

    n = 4
    servos = tuple(ServoConfig(dynamixel_id=i + 1) for i in range(n))
    bank = NeuronBankNode(InProcessBus("bridge_ticks"), [NeuronSpec(1, servos, plant_driven=True)])
    scale = np.random.default_rng(2).uniform(-900.0, 900.0, n)
    qadr = [3, 0, 5, 1]
    bank.attach_bridge(2048, qadr, scale.tolist(), [(0, i, i) for i in range(n)], [], [0])
    core = _rdm.PlantBridgeCore([0.0] * n, 0, 0.001, _rdm.SampleSchedule(0, 0, 0, 0), [bank._core])
    qpos = np.zeros(7)
    gen = np.random.default_rng(4)
    specials = [0.0, -0.0, 1e-300, -1e-300, 5e-324]
    try:
        for k in range(300):
            q = gen.normal(size=n) * 10.0 ** gen.uniform(-8, 2)
            q[k % n] = specials[k % len(specials)]
            qpos[qadr] = q
            core.couple(0.0, 0.0, qpos)
            bank._core.bridge_push_positions()
            want = (2048 + qpos[qadr] * scale).tolist()
            assert _same([s.position for s in bank.boards[0].servos], want), k
    finally:
        bank.close()


def test_bridge_samples_on_the_first_tick_then_every_nth():
    from rdm.link.inproc_can import InProcessBus
    from rdm.nodes.neuron_mirror import NeuronMirror
    from rdm.nodes.plant_bridge import PlantBridge, default_layout

    plant = Plant("rdm", seed=1, fixed_base=True, ceiling_height=None)
    layout = default_layout(plant.description)
    buses = [InProcessBus("bridge_sched") for _ in layout.neurons]
    calls: dict[str, list[int]] = {"imu": [], "wrench": [], "mocap": [], "truth": []}
    tick = [0]
    try:
        neurons = [
            NeuronMirror(b, nl.slave, layout.servo_configs(nl.slave), plant_driven=True)
            for b, nl in zip(buses, layout.neurons, strict=True)
        ]
        bridge = PlantBridge(
            plant,
            neurons,
            imu_sink=lambda g, a, m: calls["imu"].append(tick[0]),
            imu_period=0.005,
            wrench_sinks={"foot_wrench": lambda w: calls["wrench"].append(tick[0])},
            wrench_period=0.002,
            mocap_sink=lambda t, pos, quat: calls["mocap"].append(tick[0]),
            mocap_period=0.003,
            truth_sink=lambda gt: calls["truth"].append(tick[0]),
            truth_period=0.01,
        )
        for k in range(103):
            tick[0] = k
            bridge.tick(plant.time)
            plant.step(1)
    finally:
        for b in buses:
            b.shutdown()
    assert calls["imu"] == list(range(0, 103, 5))
    assert calls["wrench"] == list(range(0, 103, 2))
    assert calls["mocap"] == list(range(0, 103, 3))
    assert calls["truth"] == list(range(0, 103, 10))
    assert bridge.schedule.count == 103


def test_sample_schedule_equals_the_multiples_of_each_period():
    """``_rdm.SampleSchedule`` (the bridge's and the lockstep kernel's one schedule) against
    numpy's ``arange % every == 0``: each reading in its own place of the tuple, 0 = off,
    ``peek`` without taking the tick; a negative period is refused by name."""
    from rdm._rdm import SampleSchedule

    n = 211
    for every in [(5, 1, 10, 10), (0, 2, 3, 7), (1, 0, 0, 0), (13, 4, 1, 0)]:
        schedule = SampleSchedule(*every)
        assert schedule.every == every
        got = []
        for _ in range(n):
            ahead = schedule.peek()
            got.append(schedule.advance())
            assert ahead == got[-1]
        k = np.arange(n)
        want = np.stack([(k % e == 0) if e else np.zeros(n, bool) for e in every], axis=1)
        assert np.array_equal(np.array(got), want), every
        assert schedule.count == n
    with pytest.raises(ValueError, match="mocap_every -1 is below 0"):
        SampleSchedule(1, 1, -1, 1)


# --------------------------------------------------------------------------- ceiling effect
def _sanchez_cuevas(effect, distance: float) -> float:
    """T/T0 = 1 / (1 - (R / (z + k2))^2 / k1), k2 = k2_over_radius * R, capped at
    max_ratio; z = 0 in contact; 1 without a ceiling ahead or for NoCeilingEffect."""
    if not hasattr(effect, "radius") or math.isinf(distance):
        return 1.0
    z = max(distance, 0.0)
    s = (effect.radius / (z + effect.k2_over_radius * effect.radius)) ** 2 / effect.k1
    return effect.max_ratio if s >= 1.0 else min(effect.max_ratio, 1.0 / (1.0 - s))


def test_rotor_thrusts_equal_the_ceiling_formula_at_mujocos_rotor_distances():
    from rdm.plant import NoCeilingEffect
    from rdm.plant.ceiling import ParametricCeilingEffect

    h = 0.75
    plant = Plant("rdm", seed=0, ceiling_height=h, floor_height=0.0)
    ratios = []
    for z in (0.3, 0.55, 0.6, 0.62, 0.65, 0.7, 0.74):
        plant.reset(
            base_position=(0.0, 0.0, z),
            base_quaternion=(0.99, 0.05, 0.1, 0.0),
            thrusts=[5.0, 6.0, 7.0, 8.0],
        )
        for effects in (
            [ParametricCeilingEffect(radius=r.radius) for r in plant.description.rotors],
            [NoCeilingEffect(), *(ParametricCeilingEffect(radius=0.1, max_ratio=1.2),) * 3],
            [ParametricCeilingEffect(radius=0.2, k1=0.05)] * 4,  # capped near the ceiling
        ):
            plant.ceiling_effects = effects
            d = plant._fresh()
            plant._apply_rotor_thrusts()
            m = plant.model
            r, dist = [], []
            for e, name in zip(effects, plant.rotor_names, strict=True):
                sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, rotor_site(name))
                axis_z = d.site_xmat[sid].reshape(3, 3)[2, 2]  # the rotor axis' world z
                gap = max(h - d.site_xpos[sid][2], 0.0)
                dist.append(gap / axis_z if axis_z > 1e-6 else math.inf)
                r.append(_sanchez_cuevas(e, dist[-1]))
            np.testing.assert_allclose(plant.rotor_distances_to_ceiling(), dist, rtol=1e-12)
            want = [esc.thrust * k for esc, k in zip(plant.escs, r, strict=True)]
            np.testing.assert_allclose(d.ctrl[plant._rotor_act], want, rtol=1e-12, atol=0)
            ratios += r
    assert any(1.01 < k < 1.2 for k in ratios) and 1.5 in ratios and 1.0 in ratios


# --------------------------------------------------------------------------- CAN master
def _booted_master(channel: str):
    from rdm.link.inproc_can import InProcessBus
    from rdm.nodes.can_master import CanMaster, MasterState
    from rdm.nodes.neuron_mirror import NeuronMirror
    from rdm.nodes.servo_model import ServoConfig

    buses = [InProcessBus(channel) for _ in range(3)]
    master = CanMaster(buses[0], boot_delay_ms=0)
    neurons = [
        NeuronMirror(buses[1], 2, [ServoConfig(dynamixel_id=1 + i) for i in range(2)]),
        NeuronMirror(buses[2], 5, [ServoConfig(dynamixel_id=1 + i) for i in range(3)]),
    ]
    for t in range(2000):
        master.tick_ms(t)
        for n in neurons:
            n.tick(t / 1000)
        if master.state is MasterState.RUNNING:
            break
    assert master.state is MasterState.RUNNING
    for b in buses:
        b.shutdown()
    return master


def test_can_master_pwm_frames_follow_each_new_duty_list():
    from rdm.link.inproc_can import InProcessBus
    from rdm.protocol import neuron as nr

    master = _booted_master("bridge_pwm")
    listener = InProcessBus("bridge_pwm_tx")
    master.bus = InProcessBus("bridge_pwm_tx")
    gen = np.random.default_rng(3)
    try:
        t = 10_000
        master.tick_ms(t)  # the jump from the boot's last ms: a catch-up of up to 10 ms
        t += 1
        list(iter(lambda: listener.recv(timeout=0), None))
        for _ in range(50):
            duties = gen.uniform(0.5, 1.0, master.motor_number).tolist()
            master.set_motor_duties(duties)
            for _ in range(4):
                master.tick_ms(t)
                t += 1
            sent = [
                bytes(m.data)
                for m in iter(lambda: listener.recv(timeout=0), None)
                if m.arbitration_id == nr.PwmFrame(0, (0,) * 6).can_id
            ]
            # independent: Spinal's (uint16_t)(duty * 2000 - 1000), 10 bits per slot
            values = [int(d * 2000.0 - 1000.0) for d in duties] + [0] * (6 - len(duties))
            word = sum(v << (10 * (i % 3) + 32 * (i // 3)) for i, v in enumerate(values))
            assert sent == [word.to_bytes(8, "little")] * 2
    finally:
        master.bus.shutdown()
        listener.shutdown()
