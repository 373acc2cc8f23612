"""Lockstep scheduler: exact per-node rates over a simulated second, a fixed order within a
tick, physics stepped once per tick after the nodes, pacing with an injected clock, progress,
stop, bad configuration; plus the plant bridge's default layout and its coupling in isolation,
and the Leptrino sensor node's command answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rdm.link.serial import open_pty_pair
from rdm.nodes.base import Node
from rdm.nodes.lockstep import Lockstep
from rdm.protocol import leptrino as lp


class Recorder:
    def __init__(self, name: str, period: float, log: list) -> None:
        self.name = name
        self.period = period
        self.log = log

    def tick(self, now: float) -> None:
        self.log.append((self.name, now))


class CountingPhysics:
    def __init__(self, log: list) -> None:
        self.log = log
        self.steps = 0

    def step(self, n: int = 1) -> None:
        self.steps += n
        self.log.append(("<physics>", self.steps))


RATES = {"onboard": 40, "spinal": 200, "can_master": 1000, "neuron1": 1000, "leptrino": 500}


def _nodes(log):
    return [Recorder(n, 1.0 / hz, log) for n, hz in RATES.items()]


def test_each_node_ticks_at_exactly_its_rate_over_one_simulated_second():
    log: list = []
    nodes = _nodes(log)
    assert all(isinstance(n, Node) for n in nodes)
    loop = Lockstep(nodes, physics=CountingPhysics(log))
    stats = loop.run(1.0)
    assert stats.ticks == RATES  # counts per node
    assert loop.physics.steps == 1000 and stats.base_ticks == 1000
    for name, hz in RATES.items():
        times = [t for n, t in log if n == name]
        # tick j of a node at rate hz happens at exactly j / hz (k * dt, no running sum)
        expect = [round(1000 / hz) * j * 0.001 for j in range(hz)]
        assert times == expect, name


def test_fixed_order_within_a_tick_and_physics_last():
    log: list = []
    loop = Lockstep(_nodes(log), physics=CountingPhysics(log))
    loop.run(0.05)
    names = list(RATES)
    # split the log into ticks at each physics step; every tick lists its due nodes in order
    tick: list = []
    k = 0
    for entry in log:
        if entry[0] == "<physics>":
            due = [n for n in names if k % round(1000 / RATES[n]) == 0]
            assert [n for n, _ in tick] == due, k
            assert all(t == k * 0.001 for _, t in tick)
            tick, k = [], k + 1
        else:
            tick.append(entry)
    assert k == 50


def test_offsets_stagger_same_rate_nodes():
    log: list = []
    a, b = Recorder("a", 0.005, log), Recorder("b", 0.005, log)
    Lockstep([a, b], offsets={"b": 2}).run(0.02)
    assert [t for n, t in log if n == "a"] == pytest.approx([0.0, 0.005, 0.010, 0.015])
    assert [t for n, t in log if n == "b"] == pytest.approx([0.002, 0.007, 0.012, 0.017])


def test_real_time_pacing_with_injected_clock_and_progress():
    wall = [0.0]
    slept: list[float] = []

    def clock() -> float:
        return wall[0]

    def sleep(s: float) -> None:
        slept.append(s)
        wall[0] += s

    reports = []
    loop = Lockstep(
        [Recorder("n", 0.001, [])],
        speed=2.0,
        wall_clock=clock,
        sleep=sleep,
        progress=reports.append,
        progress_every=0.1,
    )
    stats = loop.run(0.5)
    # nodes take no wall time here: the loop must sleep so that 0.5 sim s take 0.25 wall s
    assert wall[0] == pytest.approx(0.25)
    assert len(slept) == 500
    assert [r.sim_time for r in reports] == pytest.approx([0.1, 0.2, 0.3, 0.4, 0.5])
    assert all(r.real_time_factor == pytest.approx(2.0) for r in reports)
    assert stats.real_time_factor == pytest.approx(2.0)


def test_as_fast_as_possible_never_sleeps_and_stop_from_a_node():
    def no_sleep(s: float) -> None:
        raise AssertionError("slept")

    loop: Lockstep

    class Stopper:
        name, period = "stopper", 0.001

        stopped = False

        def tick(self, now: float) -> None:
            if now >= 0.0095 and not self.stopped:
                self.stopped = True
                loop.stop()

    loop = Lockstep([Stopper()], sleep=no_sleep)
    loop.run(1.0)
    assert loop.k == 11  # ticks 0..10, stopped after the tick at 10 ms
    loop.run_until(0.02)
    assert loop.k == 20 and math.isclose(loop.time, 0.02)


def test_barriers_settle_after_the_nodes_and_before_the_physics_of_every_tick():
    """Oracle: the log written out from the rates (nodes due in order, then each barrier,
    then the physics). Catches barriers settled before the nodes, after the physics, once
    per run or not at all in a single ``step``."""
    log: list = []

    class Barrier:
        def __init__(self, name: str) -> None:
            self.name = name

        def settle(self) -> None:
            log.append((self.name, None))

    loop = Lockstep(
        [Recorder("a", 0.001, log), Recorder("b", 0.002, log)],
        physics=CountingPhysics(log),
        barriers=[Barrier("x"), Barrier("y")],
    )
    loop.run_ticks(4)
    loop.step()
    want: list = []
    for k in range(5):
        want.append(("a", k * 0.001))
        if k % 2 == 0:
            want.append(("b", k * 0.001))
        want += [("x", None), ("y", None), ("<physics>", k + 1)]
    assert log == want
    assert loop.stats.base_ticks == 5 and loop.stats.ticks == {"a": 5, "b": 3}


def test_stop_from_the_progress_callback_and_step_is_not_paced():
    def no_sleep(s: float) -> None:
        raise AssertionError("slept")

    loop: Lockstep

    def progress(p) -> None:
        if p.sim_time >= 0.05 - 1e-12:
            loop.stop()

    loop = Lockstep(
        [Recorder("n", 0.001, [])],
        progress=progress,
        progress_every=0.01,
        wall_clock=lambda: 0.0,
        sleep=no_sleep,
    )
    loop.run(1.0)
    assert loop.k == 50  # the report after the tick at 49 ms asked for the stop
    slow = Lockstep([Recorder("n", 0.001, [])], speed=1e-3, sleep=no_sleep)
    for _ in range(3):
        slow.step()  # a single step never sleeps (the caller paces it)
    assert slow.k == 3


def test_a_node_reads_the_loop_time_during_its_tick():
    """``loop.k`` and ``loop.time`` inside a tick are the tick in progress (its ``now``), as
    a node that stamps with the loop's time reads them. Catches a counter published before
    the tick or read through the running loop (refused while it runs)."""
    seen: list = []
    loop: Lockstep

    class Reader:
        name, period = "reader", 0.002

        def tick(self, now: float) -> None:
            seen.append((loop.k, loop.time, now))

    loop = Lockstep([Reader()], offsets={"reader": 1})
    loop.run_ticks(7)
    loop.step()
    assert seen == [(k, k * 0.001, k * 0.001) for k in (1, 3, 5, 7)]
    assert loop.k == 8


@pytest.mark.parametrize(
    ("period", "kwargs"),
    [(0.0015, {}), (0.0, {}), (float("nan"), {}), (0.001, {"speed": -1.0}), (0.001, {"dt": 0})],
)
def test_bad_configuration_is_refused(period, kwargs):
    with pytest.raises(ValueError):
        Lockstep([Recorder("x", period, [])], **kwargs)


def test_duplicate_names_and_unknown_offsets_refused():
    with pytest.raises(ValueError, match="two nodes"):
        Lockstep([Recorder("x", 0.001, []), Recorder("x", 0.002, [])])
    with pytest.raises(ValueError, match="unknown"):
        Lockstep([Recorder("x", 0.001, [])], offsets={"y": 0})
    with pytest.raises(ValueError, match="offset"):
        Lockstep([Recorder("x", 0.002, [])], offsets={"x": 2})


def test_profile_table_lists_nodes():
    loop = Lockstep(_nodes([]), physics=CountingPhysics([]), profile=True)
    loop.run(0.1)
    table = loop.profile_table()
    for name in [*RATES, "<physics>", "<barriers>"]:
        assert name in table


# --------------------------------------------------------------------- default bus layout


def test_default_layout_of_the_rdm():
    from rdm.nodes.plant_bridge import default_layout
    from rdm.plant.description import load_robot

    desc = load_robot("rdm")
    layout = default_layout(desc)
    got = {n.slave: (n.rotor, n.joints) for n in layout.neurons}
    assert got == {
        1: ("rotor1", ("alpha1", "beta1")),
        2: ("rotor2", ("q1", "q2", "q3")),
        3: ("rotor3", ("alpha2", "beta2")),
        4: ("rotor4", ("q4", "q5", "q6")),
    }
    # every joint of the description exactly once
    assert sorted(j for n in layout.neurons for j in n.joints) == sorted(desc.joint_order)
    # Dynamixel mapping: 2048 at 0 rad, 4096 ticks per turn
    assert layout.to_ticks("q1", math.pi / 2) == pytest.approx(3072.0)
    assert layout.to_ticks("q1", -math.pi / 2) == pytest.approx(1024.0)


# --------------------------------------------------------------------- plant bridge alone


def test_bridge_couples_duties_goals_positions_and_sinks():
    import dataclasses

    from rdm.link.inproc_can import InProcessBus
    from rdm.nodes.neuron_bank import NeuronBankNode, NeuronSpec
    from rdm.nodes.plant_bridge import PlantBridge, default_layout
    from rdm.plant import Plant
    from rdm.plant.description import load_robot
    from rdm.plant.servo import ServoParams

    desc = load_robot("rdm")  # strong stiff servos: the joint shows the goal, not thrust sag
    desc = dataclasses.replace(
        desc, joints=tuple(dataclasses.replace(j, stall_torque=50.0) for j in desc.joints)
    )
    plant = Plant(
        desc, seed=1, fixed_base=True, ceiling_height=None, servo=ServoParams(1000.0, 50.0)
    )
    layout = default_layout(plant.description)
    specs = [
        NeuronSpec(nl.slave, tuple(layout.servo_configs(nl.slave)), plant_driven=True)
        for nl in layout.neurons
    ]
    bank = NeuronBankNode(InProcessBus("bridge_alone"), specs)
    neurons = bank.boards
    goal = round(layout.to_ticks("q1", 0.2))
    feeder = SpinalFrames(InProcessBus("bridge_alone"), goal)
    imu, wrench, mocap, volts = [], [], [], []
    bridge = PlantBridge(
        plant,
        neurons,
        battery_voltage=lambda t: 24.0 - t,
        battery_sinks=[volts.append],
        imu_sink=lambda g, a, m: imu.append(a.copy()),
        wrench_sinks={"foot_wrench": lambda w: wrench.append(w[:3])},
        mocap_sink=lambda t, p, q: mocap.append((t, p, q)),
        mocap_period=0.005,
    )
    try:
        # Spinal's frames on the bus (no CAN master): PWM 500 (duty 0.75) in every slot each
        # ms; torque on, then the goal with its ack bit, for q1 (Neuron 2's first servo)
        loop = Lockstep([bridge, bank, feeder], physics=plant)
        loop.run(0.5)
        assert [n.esc.value for n in neurons] == [500] * 4
        servo = neurons[1].servos[0]  # q1 on Neuron 2
        assert servo.torque_enable and servo.goal == goal
        # independent: the plant's own duty -> steady thrust map at the bridge's voltage
        want = plant.escs[0].params.steady_thrust(0.75, volts[-1])
        assert np.allclose(plant.rotor_thrusts(), plant.rotor_thrusts()[0])
        # the 50 ms ESC lag trails the 1 V/s battery sag by ~0.05 V: 0.4 % of thrust
        assert plant.rotor_thrusts()[0] == pytest.approx(want, rel=1e-2)
        assert want < plant.escs[0].params.steady_thrust(0.75, 24.0) * 0.97
        q = plant.servo_positions()
        assert abs(q[plant.joint_names.index("q1")] - 0.2) < 0.01
        # present positions fed back (raw ticks of the plant's angle)
        # (the bridge wrote the angle of the state before the last physics step: 1 ms old)
        assert servo.position == pytest.approx(2048 + q[0] * 4096 / (2 * math.pi), abs=1.0)
        assert len(imu) == 100 and len(wrench) == 500 and len(mocap) == 100
        assert imu[-1][2] == pytest.approx(9.81, abs=0.3)  # welded base, level: +g
        assert len(volts) == 500 and volts[0] == 24.0
        assert bridge.time_mismatches == 0
    finally:
        bank.close()
        feeder.bus.shutdown()


class SpinalFrames:
    """Spinal's side of the bus, written out: PWM 500 in every slot each ms; at 1 ms torque
    on for Neuron 2's first servo, from 2 ms its goal with the ack bit (fact sheet sec. 2.4)."""

    name = "spinal_frames"
    period = 0.001

    def __init__(self, bus, goal: int) -> None:
        self.bus = bus
        self.goal = goal
        self.ticks = 0

    def tick(self, now: float) -> None:
        import can

        from rdm.protocol.neuron.memo import encode_pwm_cached, encode_servo_words_cached

        frames = list(encode_pwm_cached([500] * 4))
        if self.ticks == 1:
            frames.append(encode_servo_words_cached(True, 2, (0, 0, 0), (True, False, False)))
        elif self.ticks > 1:
            frames.append(
                encode_servo_words_cached(False, 2, (self.goal, 0, 0), (True, False, False))
            )
        for can_id, payload in frames:
            self.bus.send(can.Message(arbitration_id=can_id, data=payload, is_extended_id=False))
        self.ticks += 1


def test_bridge_refuses_a_layout_that_does_not_match_the_mirrors():
    from rdm.link.inproc_can import InProcessBus
    from rdm.nodes.neuron_mirror import NeuronMirror
    from rdm.nodes.plant_bridge import PlantBridge
    from rdm.plant import Plant

    plant = Plant("rdm", fixed_base=True, ceiling_height=None)
    bus = InProcessBus("bridge_bad")
    try:
        with pytest.raises(ValueError, match="servos"):
            PlantBridge(plant, [NeuronMirror(bus, 1, [], plant_driven=True)])
    finally:
        bus.shutdown()


# --------------------------------------------------------------------- Leptrino sensor node


def test_leptrino_node_answers_commands_and_streams():
    from rdm.link.tapped_link import TappedLink
    from rdm.nodes.leptrino_sensor import LeptrinoSensorNode
    from rdm.sim.pty_pair import PtyPair

    dev, host = open_pty_pair()
    dev.peer = None
    d, h = TappedLink(dev), TappedLink(host)
    barrier = PtyPair(d, h)
    node = LeptrinoSensorNode(d, "CFS018CA201U", rate_hz=1000)
    parser = lp.LeptrinoStreamParser()
    got: list = []

    class Host:
        name, period = "host", 0.001

        def tick(self, now: float) -> None:
            k = round(now * 1000)
            script = {
                0: lp.get_product_info() + lp.get_rated_values() + lp.get_digital_filter(),
                1: lp.set_digital_filter(3) + lp.get_digital_filter(),
                2: lp.start_continuous_output(),
                6: lp.stop_continuous_output(),
                8: lp.frame(bytes([4, 0xFF, 0x77, 0])),  # unknown command
                9: lp.frame(bytes([4, 0x05, 0x2A, 0])),  # another sensor's number
            }
            if k in script:
                h.write(script[k])
            for ev in parser.feed(h.read_available()):
                try:
                    got.append((k, lp.parse_response(ev.payload)))
                except lp.LeptrinoError:  # the host codec refuses unknown command echoes
                    got.append((k, lp.Ack(ev.payload[2], ev.payload[3], ev.payload[1])))

    node.set_wrench((10.0, -20.0, 50.0), (0.1, -0.2, 0.3))
    try:
        Lockstep([node, Host()], barriers=[barrier]).run(0.012)
    finally:
        d.close()
        h.close()
    kinds = [type(r).__name__ for _, r in got]
    assert kinds[:4] == ["ProductInfo", "RatedValues", "DigitalFilter", "Ack"]
    assert got[0][1].product_name == "CFS018CA201U"
    assert got[1][1].limits == pytest.approx((100, 100, 200, 1, 1, 1))
    assert got[2][1].digital_filter == 0 and got[4][1].digital_filter == 3
    data = [(k, r) for k, r in got if isinstance(r, lp.ForceData)]
    # DATA_START read at tick 3 (sent in tick 2): samples at ticks 3,4,5,6; stop read at 7
    assert len(data) == 4
    # raw = round(value * 10000 / rated), computed here from the rated values
    assert data[0][1].raw == (1000, -2000, 2500, 1000, -2000, 3000)
    acks = [r for _, r in got if isinstance(r, lp.Ack)]
    assert [(a.command, a.result) for a in acks] == [
        (lp.Command.SET_DF, 0),
        (lp.Command.DATA_STOP, 0),
        (0x77, lp.Result.UNDEFINED_COMMAND),
    ]
    assert node.errors["not_addressed"] == 1 and node.errors["command_command"] == 1


def test_leptrino_node_clips_to_int16_and_refuses_nan():
    from rdm.nodes.leptrino_sensor import LeptrinoSensorNode

    class Sink:
        def __init__(self) -> None:
            self.data = b""

        def read_available(self) -> bytes:
            return b""

        def write(self, b: bytes) -> int:
            self.data += b
            return len(b)

    sink = Sink()
    node = LeptrinoSensorNode(sink, "CFS034CA301U")
    node.streaming = True
    node.set_wrench((1e6, 0, 0), (0, 0, 0))
    node.set_wrench((float("nan"), 0, 0), (0, 0, 0))  # refused: the previous value stays
    node.tick(0.0)
    (event,) = lp.LeptrinoStreamParser().feed(sink.data)
    assert lp.parse_response(event.payload).raw[0] == 32767
    assert node.saturated_samples == 1 and node.errors["bad_wrench"] == 1


def test_bridge_refuses_boards_outside_a_neuron_bank():
    from types import SimpleNamespace

    from rdm.nodes.plant_bridge import PlantBridge, default_layout
    from rdm.plant import Plant

    plant = Plant("rdm", fixed_base=True, ceiling_height=None)
    boards = [
        SimpleNamespace(slave_id=nl.slave, servos=[None] * len(nl.joints))
        for nl in default_layout(plant.description).neurons
    ]
    with pytest.raises(ValueError, match="Neuron 1 is not a board of a NeuronBankNode"):
        PlantBridge(plant, boards)
