"""Spinal's CAN master + Neuron boards (the Rust firmware cores) in lockstep on python-can
``virtual:`` buses, driven by explicit simulated milliseconds (fact sheet sec. 2.5-2.7).

Every frame on the bus is captured by a separate listening bus, tagged with the simulated ms,
and checked with cantools (DBC files) or the codec's ``NeuronDecoder`` — never with the
master's or the mirrors' own bookkeeping.
"""

from __future__ import annotations

import itertools
import math
import random
from collections import Counter
from pathlib import Path

import can
import cantools
import pytest

from rdm.link.can import candump_logger, open_can
from rdm.nodes.base import drain
from rdm.nodes.can_master import CanMaster, MasterState, UavModel
from rdm.nodes.neuron_mirror import NeuronMirror
from rdm.nodes.servo_model import ServoConfig
from rdm.protocol import neuron as nr

DBC_DIR = Path(__file__).resolve().parents[1] / "firmware_protocol" / "neuron"
S2N = cantools.database.load_file(DBC_DIR / "neuron_spinal_to_neuron.dbc")
_channels = itertools.count()


class Lockstep:
    """Master first, then every Neuron, then the listener, once per simulated millisecond."""

    def __init__(self, neurons: dict[int, dict], boot_delay_ms: int = 0) -> None:
        self.channel = f"can_master_test_{next(_channels)}"
        self.buses: list[can.BusABC] = []
        self.master = CanMaster(self._bus(), boot_delay_ms=boot_delay_ms)
        self.neurons = {s: NeuronMirror(self._bus(), s, **kw) for s, kw in neurons.items()}
        self.listener = self._bus()
        self.log: list[tuple[int, can.Message]] = []
        self.t = 0
        self.master_on = True
        self.neurons_on = True
        self.logger: can.Listener | None = None

    def _bus(self) -> can.BusABC:
        bus = open_can(f"virtual:{self.channel}")
        self.buses.append(bus)
        return bus

    def run_until(self, end_ms: int) -> None:
        while self.t < end_ms:
            if self.master_on:
                self.master.tick_ms(self.t)
            if self.neurons_on:
                for n in self.neurons.values():
                    n.tick(self.t / 1000)
            for msg in drain(self.listener):
                self.log.append((self.t, msg))
                if self.logger is not None:
                    self.logger.on_message_received(msg)
            self.t += 1

    def boot(self) -> None:
        """Run until the master is RUNNING (bounded)."""
        limit = self.t + self.master.boot_delay_ms + 200 + 300 * len(self.neurons) + 10
        while self.master.state is not MasterState.RUNNING and self.t < limit:
            self.run_until(self.t + 1)
        assert self.master.state is MasterState.RUNNING

    def close(self) -> None:
        for b in self.buses:
            b.shutdown()


@pytest.fixture
def sim_factory():
    made: list[Lockstep] = []

    def make(neurons: dict[int, dict], **kw) -> Lockstep:
        sim = Lockstep(neurons, **kw)
        made.append(sim)
        return sim

    yield make
    for sim in made:
        sim.close()


def servos(n: int, gimbals: int = 0, **kw) -> list[ServoConfig]:
    return [ServoConfig(dynamixel_id=10 + i, send_data_flag=i >= gimbals, **kw) for i in range(n)]


def decoded(sim: Lockstep, since: int = 0) -> list[tuple[int, nr.NeuronFrame]]:
    """Decode the capture with a fresh codec decoder (learns servo counts from CONFIG_0)."""
    dec = nr.NeuronDecoder()
    out = []
    for t, msg in sim.log:
        res = dec.feed(msg.arbitration_id, bytes(msg.data))
        assert res.ok, (t, hex(msg.arbitration_id), msg.data.hex(), res.error)
        if t >= since:
            out.append((t, res.frame))
    return out


# ---------------------------------------------------------------- start-up


def test_boot_sequence_timing_enumeration_and_config_collection(sim_factory):
    layout = {
        2: {"servos": servos(3, profile_velocity=77)},
        1: {"servos": servos(1), "imu": True},
        3: {"servos": servos(4, current_limit=500)},
        4: {"servos": []},
    }
    sim = sim_factory(layout, boot_delay_ms=5000)
    sim.boot()
    frames = decoded(sim)
    requests = [(t, f) for t, f in frames if f.DIRECTION is nr.Direction.SPINAL_TO_NEURON]
    # HAL_Delay(5000), ENUM_REQUEST, 200 ms collection, then one config request per Neuron in
    # slave-id order, 200 ms apart, then 100 ms IMU init per Neuron.
    assert [(t, f.KIND, getattr(f, "slave", None)) for t, f in requests[:5]] == [
        (5000, "enum_request", None),
        (5200, "initial_config_request", 1),
        (5400, "initial_config_request", 2),
        (5600, "initial_config_request", 3),
        (5800, "initial_config_request", 4),
    ]
    # 4 x 100 ms IMU init after the last 200 ms wait: init ends at 6400 ms; the 1 kHz
    # schedule starts with the next tick (6401 odd: servo frames; 6402 even: PWM).
    assert sim.t == 6401
    sim.run_until(6403)
    frames = decoded(sim)
    first_servo = next(t for t, f in frames if f.KIND == "servo_target_angle")
    first_pwm = next(t for t, f in frames if f.KIND == "pwm")
    assert (first_servo, first_pwm) == (6401, 6402)
    assert sorted(f.slave for _, f in frames if f.KIND == "enum_response") == [1, 2, 3, 4]
    master = sim.master
    assert master.slaves == [1, 2, 3, 4] and master.motor_number == 4
    # The master's table equals what each mirror was configured with.
    for slave, kw in layout.items():
        for i, cfg in enumerate(kw["servos"]):
            entry = master.servo(slave, i)
            assert (entry.dynamixel_id, entry.profile_velocity, entry.current_limit) == (
                cfg.dynamixel_id,
                cfg.profile_velocity,
                cfg.current_limit,
            )
            assert entry.send_data_flag == cfg.send_data_flag
            assert entry.angle == cfg.initial_position
    assert [len(n.servos) for n in master.neurons] == [1, 3, 4, 0]
    assert master.neurons[0].imu_send_flag and not master.neurons[1].imu_send_flag


@pytest.mark.parametrize(
    ("gimbals_per_neuron", "model"),
    [(0, UavModel.HYDRUS), (1, UavModel.HYDRUS_XI), (2, UavModel.DRAGON)],
)
def test_robot_model_inferred_from_gimbal_servos(sim_factory, gimbals_per_neuron, model):
    sim = sim_factory({s: {"servos": servos(3, gimbals_per_neuron)} for s in (1, 2, 3)})
    sim.boot()
    assert sim.master.uav_model == model == {0: 16, 1: 17, 2: 32}[gimbals_per_neuron]
    assert sim.master.motor_number == 3


def test_no_neuron_disables_the_master(sim_factory):
    sim = sim_factory({})
    sim.run_until(400)
    assert sim.master.state is MasterState.DISABLED
    assert sim.master.motor_number == 0
    assert [f.KIND for _, f in decoded(sim)] == ["enum_request"]  # nothing after that


# ---------------------------------------------------------------- run-time schedule


@pytest.mark.parametrize("n_neurons", [2, 3, 7])
def test_pwm_broadcast_every_2ms_with_slot_values(sim_factory, n_neurons):
    sim = sim_factory({s: {"servos": servos(1)} for s in range(1, n_neurons + 1)})
    sim.boot()
    duties = [0.5 + 0.05 * i + 0.0004 for i in range(n_neurons)]
    sim.master.set_motor_duties(duties)
    start = sim.t + 10
    sim.run_until(start + 1000)
    pwm = [(t, m) for t, m in sim.log if t >= start and m.arbitration_id in (0x00F, 0x01F)]
    msg0 = [t for t, m in pwm if m.arbitration_id == 0x00F]
    msg1 = [t for t, m in pwm if m.arbitration_id == 0x01F]
    assert abs(len(msg0) - 500) <= 1  # 500 Hz over one simulated second
    assert all(t % 2 == 0 for t in msg0)  # even HAL ticks
    assert len(msg1) == (len(msg0) if n_neurons > 6 else 0)  # msg 1 only with > 6 motors
    # Slot values: (uint16)(duty * 2000 - 1000), motor i in slot i (cantools decoding).
    last = {m.arbitration_id: S2N.decode_message(m.arbitration_id, bytes(m.data)) for _, m in pwm}
    slots = [last[0x00F][f"Pwm{k}"] for k in range(1, 7)]
    if n_neurons > 6:
        slots += [last[0x01F][f"Pwm{k}"] for k in range(7, 13)]
    expected = [math.trunc(d * 2000 - 1000) for d in duties]
    assert slots[:n_neurons] == expected
    assert all(v == 0 for v in slots[n_neurons:])
    # Each mirror outputs its own slot.
    assert [sim.neurons[s].esc.value for s in sorted(sim.neurons)] == expected


def test_servo_round_robin_one_neuron_per_odd_tick(sim_factory):
    sim = sim_factory(
        {1: {"servos": servos(2)}, 2: {"servos": servos(1)}, 3: {"servos": servos(3)}}
    )
    sim.boot()
    start = sim.t + 1
    sim.run_until(start + 1002)
    frames = decoded(sim, since=start)
    targets = [(t, f) for t, f in frames if f.DIRECTION is nr.Direction.SPINAL_TO_NEURON]
    angle = [(t, f.slave) for t, f in targets if f.KIND == "servo_target_angle"]
    current = [(t, f.slave) for t, f in targets if f.KIND == "servo_target_current"]
    assert all(t % 2 == 1 for t, _ in angle)  # odd HAL ticks
    assert angle == current  # angle then current to the same Neuron in the same tick
    per_slave = Counter(s for _, s in angle)
    for slave in (1, 2, 3):
        assert abs(per_slave[slave] - 500 / 3) <= 1  # 500/N Hz each
    assert [s for _, s in angle[:6]] in ([1, 2, 3, 1, 2, 3], [2, 3, 1, 2, 3, 1], [3, 1, 2, 3, 1, 2])
    # DLC = 2 x servo_num of the addressed Neuron.
    sizes = {f.slave: len(f.values) for _, f in targets if f.KIND.startswith("servo_target")}
    assert sizes == {1: 2, 2: 1, 3: 3}
    # Each angle frame triggers exactly one state report per reporting servo.
    states = Counter(f.slave for t, f in frames if f.KIND == "servo_state" and t > start)
    assert states[3] == pytest.approx(3 * per_slave[3], abs=3)


def test_goal_handshake_and_servo_reaches_target(sim_factory):
    sim = sim_factory({1: {"servos": servos(1)}, 2: {"servos": servos(2, initial_position=1500)}})
    sim.boot()
    master = sim.master
    t_on = sim.t
    master.set_servo_torque(2, 1, True)
    sim.run_until(t_on + 20)
    frames = decoded(sim, since=t_on)
    reports = [
        t
        for t, f in frames
        if f.KIND == "servo_state" and f.slave == 2 and f.index == 1 and f.goal_reported
    ]
    assert reports, "the Neuron must report its goal (status bit 2) after torque-on"
    acked = [
        (t, f.values[1])
        for t, f in frames
        if f.KIND == "servo_target_angle" and f.slave == 2 and f.flags[1] and t > reports[0]
    ]
    assert acked and acked[0][1] == 1500  # Spinal echoes the reported goal with bit 15 set
    later = [f for t, f in frames if f.KIND == "servo_state" and f.slave == 2 and t > acked[0][0]]
    assert later and not any(f.goal_reported for f in later if f.index == 1)
    # Now a target goes through and the mirror's servo reaches it.
    master.set_servo_targets({(2, 1): 2500})
    sim.run_until(sim.t + 600)
    assert sim.neurons[2].servos[1].present_position == 2500
    assert master.servo(2, 1).angle == 2500
    assert master.servo(2, 0).angle == 1500  # torque off: not moved
    last = [
        f
        for _, f in decoded(sim, since=sim.t - 10)
        if f.KIND == "servo_target_current" and f.slave == 2
    ]
    assert last[-1].flags == (False, True)
    # Torque off clears the ack flag: the next enable goes through the handshake again.
    master.set_servo_torque(2, 1, False)
    sim.run_until(sim.t + 10)
    angle = [
        f
        for _, f in decoded(sim, since=sim.t - 6)
        if f.KIND == "servo_target_angle" and f.slave == 2
    ]
    assert angle[-1].flags == (False, False)


def test_servo_state_and_imu_table_scaling(sim_factory):
    sim = sim_factory({1: {"servos": servos(2), "imu": True}, 2: {"servos": servos(1)}})
    sim.boot()
    n1 = sim.neurons[1]
    n1.set_imu_raw(gyro=(100, -200, 300), acc=(-4096, 2048, 1), mag=(50, -60, 70))
    n1.servos[0].temperature = 61
    n1.servos[0].hardware_error = 0x80
    n1.servos[1].set_external_current(-321)
    sim.run_until(sim.t + 20)
    reading = sim.master.imu[1]
    kg, ka, km = 2000 / 32767 * math.pi / 180, 9.80665 / 4096, 4912 / 32760
    assert reading.gyro == pytest.approx((200 * kg, 100 * kg, 300 * kg), rel=1e-12)
    assert reading.acc == pytest.approx((-2048 * ka, -4096 * ka, 1 * ka), rel=1e-12)
    assert reading.mag == pytest.approx((-50 * km, -60 * km, -70 * km), rel=1e-12)
    assert 2 not in sim.master.imu  # IMU flag off on Neuron 2
    s0, s1 = sim.master.servo(1, 0), sim.master.servo(1, 1)
    assert (s0.temperature, s0.error) == (61, 0x80)
    assert s1.current == -321
    assert s0.stamp_ms is not None and sim.t - s0.stamp_ms <= 8


def test_motor_duties_are_validated(sim_factory):
    sim = sim_factory({1: {"servos": servos(1)}})
    sim.boot()
    with pytest.raises(ValueError, match="duties"):
        sim.master.set_motor_duties([0.5, 0.5])
    with pytest.raises(ValueError, match=r"duties\[0\]"):
        sim.master.set_motor_duties([1.2])
    with pytest.raises(ValueError, match=r"duties\[0\]"):
        sim.master.set_motor_duties([math.nan])
    with pytest.raises(ValueError, match="15-bit"):
        sim.master.set_servo_targets({(1, 0): 20000})
    with pytest.raises(KeyError):
        sim.master.set_servo_targets({(9, 0): 1})


# ---------------------------------------------------------------- watchdogs


def test_neuron_watchdog_stops_motor_100ms_after_bus_goes_quiet(sim_factory):
    sim = sim_factory({1: {"servos": servos(1)}, 2: {"servos": servos(1)}})
    sim.boot()
    sim.master.set_motor_duties([0.8, 0.7])
    sim.run_until(sim.t + 50)
    sim.master_on = False  # Spinal falls silent; the Neurons keep ticking
    quiet_from = sim.t
    # Per Neuron, the last master frame its filter accepts (slave field 15 or its own id).
    spinal_frames = [
        (t, f) for t, f in decoded(sim) if f.DIRECTION is nr.Direction.SPINAL_TO_NEURON
    ]
    last_rx = {s: max(t for t, f in spinal_frames if getattr(f, "slave", s) == s) for s in (1, 2)}
    assert max(last_rx.values()) == quiet_from - 1
    values: dict[int, dict[int, int]] = {1: {}, 2: {}}
    while sim.t <= max(last_rx.values()) + 102:
        sim.run_until(sim.t + 1)
        for s, n in sim.neurons.items():
            values[s][sim.t - 1] = n.esc.value
    for s, running in ((1, 600), (2, 400)):
        assert values[s][last_rx[s] + 100] == running  # not before
        assert values[s][last_rx[s] + 101] == 0  # stopped (1000 us pulse)


def test_master_logs_disconnect_at_most_once_per_second(sim_factory):
    sim = sim_factory({1: {"servos": servos(1)}})
    sim.boot()
    sim.master.pop_events()
    sim.run_until(sim.t + 100)
    assert sim.master.connected and sim.master.pop_events() == []
    sim.neurons_on = False  # the Neuron stops answering
    last_rx = max(t for t, m in sim.log if m.arbitration_id == 0x201 and m.dlc == 8)
    sim.run_until(last_rx + 1 + 3500)
    events = [e for e in sim.master.events if e.text == "CAN disconnected!!"]
    # The master hears the reply one tick after the Neuron sent it.
    first = last_rx + 1 + 101
    assert [e.stamp_ms for e in events] == [first, first + 1000, first + 2000, first + 3000]
    assert not sim.master.connected


# ---------------------------------------------------------------- bad frames, board config


def test_garbage_frames_are_counted_and_ignored_by_both_sides(sim_factory):
    sim = sim_factory({1: {"servos": servos(2)}, 2: {"servos": servos(1)}})
    sim.boot()
    noise = sim._bus()
    before = dict(sim.master.servo_states)
    junk = [
        (0x201, b"\x01\x02\x03"),  # odd DLC on a servo id
        (0x241, b"\x00" * 8),  # servo message 4: unknown
        (0x709, b""),  # enum response of a Neuron that was never enumerated
        (0x211, b"\x00\x00\x00\xf8\x00\x00\x00\x00"),  # state with reserved status bits
        (0x101, b"\x00" * 5),  # IMU with DLC 5
        (0x50F, b"junk"),  # device 5
        (0x00F, b"\xff" * 8),  # PWM with reserved bits
    ]
    for cid, data in junk * 3:
        noise.send(can.Message(arbitration_id=cid, data=data, is_extended_id=False))
    noise.send(can.Message(arbitration_id=0x12345, data=b"", is_extended_id=True))
    sim.run_until(sim.t + 30)
    master_errors = sim.master.rx_errors
    assert master_errors.total() >= 3 * 5 + 1
    assert master_errors["not_standard_id"] == 1
    assert sum(n.rx_errors.total() for n in sim.neurons.values()) >= 3  # PWM junk, both
    assert sim.master.slaves == [1, 2]  # the stray enum response changed nothing
    assert set(sim.master.servo_states) == set(before)
    sim.master.set_motor_duties([0.75, 0.75])
    sim.run_until(sim.t + 10)
    assert [n.esc.value for n in sim.neurons.values()] == [500, 500]
    # Random standard frames of any id and DLC: both sides count or handle each, never raise.
    rng = random.Random(11)
    master_rx, neuron_rx = sim.master.rx_count, [n.rx_count for n in sim.neurons.values()]
    for _ in range(3000):
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(9)))
        noise.send(
            can.Message(arbitration_id=rng.randrange(0x800), data=data, is_extended_id=False)
        )
    sim.run_until(sim.t + 5)
    assert sim.master.rx_count - master_rx >= 3000
    assert sim.master.state is MasterState.RUNNING and sim.master.slaves == [1, 2]
    assert all(n.rx_count > r for n, r in zip(sim.neurons.values(), neuron_rx, strict=True))


def test_board_config_pauses_tx_for_2s_and_updates_table(sim_factory):
    sim = sim_factory({1: {"servos": servos(2)}, 2: {"servos": servos(1)}})
    sim.boot()
    t0 = sim.t
    sim.master.configure_board(nr.SetSendDataFlag(1, 1, False))
    sim.run_until(t0 + 2600)
    requests = [
        (t, f)
        for t, f in decoded(sim, since=t0)
        if f.DIRECTION is nr.Direction.SPINAL_TO_NEURON
        and f.KIND != "board_config_set_send_data_flag"
    ]
    sent = next(t for t, f in decoded(sim, since=t0) if f.KIND == "board_config_set_send_data_flag")
    assert sent <= t0 + 1
    assert all(t >= sent + 2000 for t, _ in requests)  # CAN_TX_PAUSE_TIME
    assert any(t <= sent + 2003 for t, _ in requests)  # and then the schedule resumes
    assert sim.master.servo(1, 1).send_data_flag is False
    assert sim.master.servo(1, 0).send_data_flag is True


def test_reboot_request_rerequests_config_after_5s(sim_factory):
    sim = sim_factory({1: {"servos": servos(1)}})
    sim.boot()
    t0 = sim.t
    sim.master.configure_board(nr.Reboot(1))
    sim.run_until(t0 + 5200)
    frames = decoded(sim, since=t0)
    sent = next(t for t, f in frames if f.KIND == "board_config_reboot")
    again = [t for t, f in frames if f.KIND == "initial_config_request"]
    assert again == [sent + 5000]
    assert sim.neurons[1].reboots == 1
    assert any(t >= again[0] for t, f in frames if f.KIND == "initial_config_0")


# ---------------------------------------------------------------- capture


def test_candump_capture_of_boot_and_run_decodes_cleanly(sim_factory, tmp_path):
    sim = sim_factory(
        {
            1: {"servos": servos(2, 1), "imu": True},
            2: {"servos": servos(2, 1)},
            3: {"servos": servos(3, 1)},
        },
        boot_delay_ms=50,
    )
    path = tmp_path / "boot_run.log"
    sim.logger = candump_logger(path, channel="vcan0")
    sim.boot()
    sim.master.set_servo_torque(2, 1, True)
    sim.master.set_motor_duties([0.6, 0.7, 0.8])
    sim.run_until(sim.t + 300)
    sim.logger.stop()
    rows = list(nr.decode_candump(path))
    assert len(rows) == len(sim.log) > 500
    bad = [r for r in rows if not r["ok"]]
    assert bad == []
    kinds = Counter(r["kind"] for r in rows)
    for kind in (
        "enum_request",
        "enum_response",
        "initial_config_request",
        "initial_config_0",
        "initial_config_1",
        "initial_config_2",
        "initial_config_3",
        "pwm",
        "servo_target_angle",
        "servo_target_current",
        "servo_state",
        "imu",
    ):
        assert kinds[kind] > 0, kind
    assert sim.master.uav_model == UavModel.HYDRUS_XI


# ---------------------------------------------------------------- real-time runner


class FakeClock:
    """A clock that only moves when ``sleep`` is called (or a tick burns time)."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now

    def sleep(self, dt: float) -> None:
        assert dt > 0
        self.now += dt


def test_run_realtime_ticks_nodes_at_their_periods_and_rephases_late_ones(sim_factory):
    from rdm.nodes.base import Node, run_realtime

    sim = sim_factory({1: {"servos": servos(1)}, 2: {"servos": servos(1)}})
    clock = FakeClock()
    nodes = [sim.master, *sim.neurons.values()]
    assert all(isinstance(n, Node) for n in nodes)
    stats = run_realtime(nodes, duration=1.0, clock=clock, sleep=clock.sleep)
    assert stats.ticks == {"can_master": 1000, "neuron1": 1000, "neuron2": 1000}
    assert sum(stats.overruns.values()) == 0
    assert sim.master.state is MasterState.RUNNING and sim.master.slaves == [1, 2]
    # Resuming continues node time; a slow node (5 ms per tick) is re-phased, not bursted.
    seen: list[float] = []

    class Slow:
        name, period = "slow", 0.001

        def tick(self, now: float) -> None:
            seen.append(now)
            clock.now += 0.005

    again = run_realtime(
        [Slow()], duration=0.1, clock=clock, sleep=clock.sleep, start_time=stats.end_time
    )
    assert seen[0] == pytest.approx(stats.end_time)
    assert again.ticks["slow"] == pytest.approx(0.1 / 0.005, abs=1)
    assert again.overruns["slow"] >= again.ticks["slow"] - 2
    assert all(b - a == pytest.approx(0.005) for a, b in itertools.pairwise(seen))
    with pytest.raises(ValueError, match="period"):
        Slow.period = 0.0
        run_realtime([Slow()], duration=0.1)


def test_core_errors_are_typed():
    from rdm import _rdm
    from rdm.link.inproc_can import InProcessBus

    core = _rdm.CanMaster(0, 0)
    with pytest.raises(_rdm.CanMasterError, match=r"duties: 1 values"):
        core.set_motor_duties([0.5])
    with pytest.raises(_rdm.CanMasterError, match="no servo 0 on Neuron 1"):
        core.set_servo_target(1, 0, 5)
    with pytest.raises(_rdm.CanMasterError, match="payload > 8"):
        core.configure_board(0x712, bytes(9))
    with pytest.raises(_rdm.CanMasterError, match="out of range"):
        core.servo(0, 0)
    master = CanMaster(InProcessBus("canwire_errors"))
    with pytest.raises(KeyError, match="no servo 1 on Neuron 3"):
        master.servo(3, 1)
    master.close()
