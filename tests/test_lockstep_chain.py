"""End-to-end open-loop lockstep chain: plant + bridge + Neuron mirrors + CAN master on
``inproc:`` + a core ``SpinalStep`` driving the duties + a Leptrino sensor node on a pty read by
the host-side parser, with MCAP, candump and UART captures.

Checks: enumeration, PWM duties reaching the plant's rotors, servo goals moving plant joints and
the present positions returning to the master's table, foot wrench frames at the host equal to
the plant's values within the sensor's quantisation, byte-identical captures for the same seed,
and every capture decodable by an independent reader (rosbags, mcap, decode_candump, Leptrino).

Run ``python tests/test_lockstep_chain.py [seconds] [--profile]`` for the speed figure.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from rdm.control import attitude
from rdm.link.can import open_can
from rdm.link.uart_pipe import open_inproc_uart
from rdm.nodes.can_master import CanMaster, MasterState
from rdm.nodes.leptrino_sensor import LeptrinoSensorNode
from rdm.nodes.lockstep import Lockstep
from rdm.nodes.neuron_mirror import NeuronMirror
from rdm.nodes.plant_bridge import PlantBridge, default_layout
from rdm.plant import Plant
from rdm.plant.description import load_robot
from rdm.plant.sensors import WrenchNoise
from rdm.plant.servo import ServoParams
from rdm.protocol import leptrino as lp
from rdm.sim import (
    CandumpCapture,
    McapLogger,
    ProbeNode,
    RunFolder,
    open_tapped_pty,
)

CHANNEL = "hil_chain"
RUNNING_AT = 1.401  # boot_delay 0, 4 Neurons: running at 1400 ms (docs/canbus.md)
SERVO_ON_AT = 1.45
TARGET_AT = 1.60
RAMP = (1.50, 2.40)  # base thrust ramp per rotor, seconds
THRUST = (2.0, 8.0)  # newtons at the ramp's start and end
Q1_STEP = 0.3  # rad added to q1 (Neuron 2 servo 0 in the default layout)


class SpinalDriver:
    """Stand-in for the Spinal mirror: the core ``SpinalStep`` at 200 Hz, IMU from the bridge,
    duties straight into ``CanMaster.set_motor_duties`` (no rosserial yet)."""

    name = "spinal"
    period = 0.005

    def __init__(self, master: CanMaster, logger: McapLogger | None) -> None:
        self.master = master
        self.logger = logger
        self.step = attitude.SpinalStep(200.0, gyro_calib_duration_s=0.0)
        self.step.set_uav_info(4, attitude.UAV_HYDRUS)
        self.step.set_pwm_info_hydrus_example()
        self.sample = (np.zeros(3), np.array([0, 0, 9.81]), np.array([30.0, 0, -35.0]))
        self.voltage = 23.0
        self.duties: list[float] = []
        self.armed_at: float | None = None

    def set_imu_sample(self, gyro, acc, mag) -> None:
        self.sample = (gyro, acc, mag)

    def set_battery_voltage(self, volts: float) -> None:
        self.voltage = volts

    def base_thrust(self, now: float) -> float:
        a = min(max((now - RAMP[0]) / (RAMP[1] - RAMP[0]), 0.0), 1.0)
        return THRUST[0] + a * (THRUST[1] - THRUST[0])

    def tick(self, now: float) -> None:
        if self.armed_at is None and self.master.state is MasterState.RUNNING:
            self.step.flight_config(attitude.ARM_ON, now)
            self.armed_at = now
        if self.armed_at is not None:
            self.step.four_axis_command([0.0, 0.0, 0.0], np.full(4, self.base_thrust(now)), now)
        gyro, acc, mag = self.sample
        out = self.step.step(now, gyro, acc, mag, self.voltage)
        if self.master.state is MasterState.RUNNING and self.master.motor_number == 4:
            self.duties = [float(d) for d in out.duty]
            self.master.set_motor_duties(self.duties)
        if self.logger is not None:
            q = out.quaternion
            self.logger.log_ros1(
                "/spinal/imu",
                "spinal/Imu",
                now,
                self.logger.registry.msg("spinal/Imu").new(
                    acc=[float(v) for v in acc],
                    gyro=[float(v) for v in gyro],
                    mag=[float(v) for v in mag],
                    quaternion=[float(v) for v in q],
                ),
            )


class ServoCommander:
    """Turns the servos on, then moves q1 once the goal handshake is done."""

    name = "servo_commander"
    period = 0.001

    def __init__(self, master: CanMaster, layout) -> None:
        self.master = master
        self.layout = layout
        self.torque_sent = False
        self.target_sent = False
        self.target_ticks: int | None = None

    def tick(self, now: float) -> None:
        m = self.master
        if m.state is not MasterState.RUNNING:
            return
        if not self.torque_sent and now >= SERVO_ON_AT:
            for slave, index in m.servo_states:
                m.set_servo_torque(slave, index, True)
            self.torque_sent = True
        entry = m.servo(2, 0)
        if self.torque_sent and not self.target_sent and now >= TARGET_AT and entry.goal_valid:
            self.target_ticks = round(self.layout.to_ticks("q1", Q1_STEP))
            m.set_servo_targets({(2, 0): self.target_ticks})
            self.target_sent = True


class LeptrinoHost:
    """The PC side of the foot sensor: asks for info and limits, starts the stream, parses."""

    name = "leptrino_host"
    period = 0.001

    def __init__(self, link) -> None:
        self.link = link
        self.parser = lp.LeptrinoStreamParser()
        self.responses: list[lp.Response] = []
        self.sent = False

    def tick(self, now: float) -> None:
        if not self.sent:
            self.link.write(lp.get_product_info() + lp.get_rated_values())
            self.link.write(lp.start_continuous_output())
            self.sent = True
        for ev in self.parser.feed(self.link.read_available()):
            if ev.payload is not None:
                self.responses.append(lp.parse_response(ev.payload))

    @property
    def samples(self) -> list[lp.ForceData]:
        return [r for r in self.responses if isinstance(r, lp.ForceData)]


class WrenchProbe:
    """Records the plant's ideal foot wrench whenever the sensor has just streamed a sample."""

    name = "wrench_probe"

    def __init__(self, plant: Plant, sensor: LeptrinoSensorNode) -> None:
        self.plant = plant
        self.sensor = sensor
        self.period = sensor.period
        self.truth: list[np.ndarray] = []
        self._sent = 0

    def tick(self, now: float) -> None:
        if self.sensor.frames_sent > self._sent and self.sensor.streaming:
            self._sent = self.sensor.frames_sent
            f, t = self.plant.wrench_ideal("foot_wrench")
            self.truth.append(np.concatenate([f, t]))


class PlateLoad:
    """A slowly varying load on the foot plate (the base is welded: it is what the F/T sees)."""

    name = "plate_load"
    period = 0.01

    def __init__(self, plant: Plant) -> None:
        self.plant = plant

    def tick(self, now: float) -> None:
        s = math.sin(2 * math.pi * 0.7 * now)
        self.plant.apply_body_wrench(
            "foot_plate", force=(3.0 * s, -2.0, 20.0 + 10.0 * s), torque=(0.3 * s, 0.1, -0.2)
        )


@dataclass
class Chain:
    plant: Plant
    master: CanMaster
    neurons: list[NeuronMirror]
    bridge: PlantBridge
    spinal: SpinalDriver
    commander: ServoCommander
    sensor: LeptrinoSensorNode
    host: LeptrinoHost
    probe: WrenchProbe
    loop: Lockstep
    folder: RunFolder
    logger: McapLogger
    candump: CandumpCapture
    closers: list = field(default_factory=list)
    thrust_log: list[tuple[float, np.ndarray]] = field(default_factory=list)
    q_log: list[tuple[float, np.ndarray]] = field(default_factory=list)

    def close(self) -> None:
        for c in self.closers:
            c()


def build_chain(
    base: Path, seed: int = 7, profile: bool = False, log: bool = True, pty: bool = True
) -> Chain:
    folder = RunFolder.create("openloop", base=base, seed=seed)
    # Stiff, strong servos (as the plant's own tests do) so joint angles show the commanded
    # goals rather than the sag under rotor thrust; the welded base makes the foot F/T read
    # the plate load.
    desc = load_robot("rdm")
    desc = dataclasses.replace(
        desc, joints=tuple(dataclasses.replace(j, stall_torque=50.0) for j in desc.joints)
    )
    plant = Plant(
        desc,
        seed=seed,
        fixed_base=True,
        servo=ServoParams(kp=1000.0, kv=50.0),
        ceiling_height=None,
        wrench_noise=WrenchNoise(noise_fraction_of_rated=0.0),
    )
    layout = default_layout(plant.description)
    master = CanMaster(open_can(f"inproc:{CHANNEL}"), boot_delay_ms=0)
    neurons = [
        NeuronMirror(
            open_can(f"inproc:{CHANNEL}"),
            nl.slave,
            layout.servo_configs(nl.slave),
            plant_driven=True,
        )
        for nl in layout.neurons
    ]
    logger = McapLogger(folder.mcap)
    candump = CandumpCapture(folder.candump, channel=CHANNEL)
    if pty:
        dev, host_link, barrier = open_tapped_pty(folder.uart_dir, "leptrino_foot", ".lep")
        barriers = [barrier]
    else:
        dev, host_link = open_inproc_uart(folder.uart_dir, "leptrino_foot", ".lep")
        barriers = []
    sensor = LeptrinoSensorNode(dev, "CFS034CA301U", rate_hz=500.0)
    host = LeptrinoHost(host_link)
    spinal = SpinalDriver(master, logger if log else None)
    chain_truth: list = []

    def truth_sink(gt) -> None:
        chain_truth.append(gt)
        if log:
            logger.log_truth(gt)

    bridge = PlantBridge(
        plant,
        neurons,
        layout,
        imu_sink=spinal.set_imu_sample,
        battery_sinks=[spinal.set_battery_voltage],
        wrench_sinks={"foot_wrench": sensor.set_wrench_values},
        wrench_period=0.002,
        truth_sink=truth_sink,
        truth_period=0.01,
    )
    commander = ServoCommander(master, layout)
    probe = WrenchProbe(plant, sensor)
    nodes = [
        bridge,
        PlateLoad(plant),
        *neurons,
        master,
        commander,
        spinal,
        sensor,
        probe,
        host,
    ]
    if log:
        nodes.append(
            ProbeNode(
                logger,
                {
                    "/diag/can_master": lambda: {
                        "rx": master.rx_count,
                        "tx": master.tx_count,
                        "rx_errors": sum(master.rx_errors.values()),
                        "state": master.state.value,
                    },
                    "/diag/leptrino": lambda: {
                        "frames_sent": sensor.frames_sent,
                        "errors": sum(sensor.errors.values()),
                    },
                },
                period=0.05,
            )
        )
    loop = Lockstep(
        nodes, physics=plant, can_channels=[CHANNEL], barriers=barriers, profile=profile
    )
    chain = Chain(
        plant,
        master,
        neurons,
        bridge,
        spinal,
        commander,
        sensor,
        host,
        probe,
        loop,
        folder,
        logger,
        candump,
    )
    chain.truth = chain_truth  # type: ignore[attr-defined]
    chain.closers = [
        logger.finish,
        candump.close,
        dev.close,
        host_link.close,
        master.close,
        *[n.close for n in neurons],
    ]
    return chain


def run_chain(base: Path, seconds: float = 2.5, seed: int = 7, pty: bool = True) -> Chain:
    chain = build_chain(base, seed, pty=pty)
    try:
        chain.loop.run(seconds)
    finally:
        chain.close()
    return chain


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("chain")
    a = run_chain(base / "a")
    b = run_chain(base / "b")
    return a, b


def test_neurons_enumerated_and_running(runs):
    chain, _ = runs
    m = chain.master
    assert m.state is MasterState.RUNNING
    assert m.slaves == [1, 2, 3, 4]
    assert m.motor_number == 4
    assert m.uav_model == 16  # every servo reports: HYDRUS
    # default layout: 2 + 3 + 2 + 3 servos
    assert [len(n.servos) for n in m.neurons] == [2, 3, 2, 3]
    assert sum(m.rx_errors.values()) == 0
    assert all(sum(n.rx_errors.values()) == 0 for n in chain.neurons)


def test_duties_reach_rotors_and_thrust_rises(runs):
    chain, _ = runs
    truth = chain.truth  # type: ignore[attr-defined]
    t = np.array([g.time for g in truth])
    thrust = np.array([g.rotor_thrusts for g in truth])
    before = thrust[t < RUNNING_AT - 0.01]
    assert np.all(before == 0.0)  # ESCs idle until Spinal's CAN master runs
    # Independent oracle: the Hydrus SQRT curve (docs/plant.md) at the plant's voltage,
    # duty -> steady thrust, compared with the thrust at the end after the 50 ms lag settles.
    # The duty each ESC outputs is what crossed the CAN bus: (value + 1000) / 2000.
    duty = np.array([n.esc.duty for n in chain.neurons])
    np.testing.assert_allclose(duty, chain.spinal.duties, atol=0.5 / 1000 + 1e-12)
    end = thrust[-1]
    p2, p1, p0, vref = 0.07983707, -6.627443098, 12.3593793002, 25.2
    x = duty * 100.0
    f = (0.1 * p2 * x * x + 0.1 * p1 * x + p0) / (vref / 23.0) ** 2
    # the ramp ended 0.1 s (2 tau) before: thrust within 14 % of its steady value, and the
    # commanded base thrust (8 N) is what the steady thrust represents
    np.testing.assert_allclose(end, f, rtol=0.14)
    np.testing.assert_allclose(f, THRUST[1], rtol=0.02)
    # rising during the ramp, every rotor
    mid = thrust[(t > RAMP[0] + 0.2) & (t < RAMP[1])]
    assert np.all(np.diff(mid, axis=0) >= -1e-9)
    assert np.all(mid[-1] > mid[0] + 2.0)


def test_servo_goal_moves_joint_and_position_returns(runs):
    chain, _ = runs
    assert chain.commander.target_sent
    q = chain.plant.servo_positions()
    q1 = chain.plant.joint_names.index("q1")
    # plant joint moved to the goal (stiff servo: within 0.02 rad of 0.3)
    assert abs(q[q1] - Q1_STEP) < 0.02, q[q1]
    entry = chain.master.servo(2, 0)
    expect_ticks = 2048 + q[q1] * 4096 / (2 * math.pi)
    # the table lags by at most one state report (every 4 ms): the joint has settled
    assert abs(entry.angle - expect_ticks) <= 2
    # other joints held at their handshake goals (0 rad within a tick plus the load sag)
    others = [k for k, n in enumerate(chain.plant.joint_names) if n != "q1"]
    assert np.all(np.abs(q[others]) < 0.02)


def test_leptrino_frames_match_plant_within_quantisation(runs):
    chain, _ = runs
    host = chain.host
    infos = [r for r in host.responses if isinstance(r, lp.ProductInfo)]
    limits = [r for r in host.responses if isinstance(r, lp.RatedValues)]
    assert infos and infos[0].product_name == "CFS034CA301U"
    np.testing.assert_allclose(limits[0].limits, (150, 150, 300, 4, 4, 4), rtol=1e-6)
    samples = host.samples
    truth = chain.probe.truth
    assert len(samples) > 1000  # 500 Hz for 2.5 s, minus the start
    assert 0 <= len(truth) - len(samples) <= 1  # the last tick's frame may still be unread
    rated = np.array(limits[0].limits)
    got = np.array([np.array(s.raw) * rated / 10000 for s in samples])
    want = np.array(truth[: len(samples)])
    assert np.ptp(want[:, 2]) > 15  # the load varies
    err = np.abs(got - want)
    assert np.all(err <= rated / 10000 / 2 + 1e-9), err.max(axis=0)
    assert chain.sensor.bytes_dropped == 0 and not chain.sensor.errors


def test_same_seed_same_bytes(runs):
    a, b = runs
    for name in (
        "can.log",
        "uart/leptrino_foot.device_tx.lep",
        "uart/leptrino_foot.host_tx.lep",
        "signals.mcap",
    ):
        pa, pb = a.folder.root / name, b.folder.root / name
        assert pa.stat().st_size > 0, name
        assert pa.read_bytes() == pb.read_bytes(), name


def test_pty_with_barrier_equals_in_process_pipe(runs, tmp_path):
    """The pty barrier makes the kernel's delivery invisible: the byte timeline (hence every
    capture and the whole signal log) equals the one over the in-process byte pipe."""
    a, _ = runs
    c = run_chain(tmp_path, pty=False)
    for name in (
        "can.log",
        "uart/leptrino_foot.device_tx.lep",
        "uart/leptrino_foot.host_tx.lep",
        "signals.mcap",
    ):
        assert (a.folder.root / name).read_bytes() == (c.folder.root / name).read_bytes(), name


def test_candump_decodes_every_frame(runs):
    from rdm.protocol.neuron import decode_candump

    chain, _ = runs
    records = list(decode_candump(chain.folder.candump))
    assert len(records) == chain.candump.frames > 3000
    assert all(r["ok"] for r in records), [r for r in records if not r["ok"]][:3]
    kinds = Counter(r["kind"] for r in records)
    # boot: one ENUM_REQUEST, four answers, one config request and CONFIG_0 per Neuron, one
    # CONFIG_1/2/3 per servo (10); then PWM every even ms and one servo pair every odd ms
    assert kinds["enum_request"] == 1 and kinds["enum_response"] == 4
    assert kinds["initial_config_request"] == kinds["initial_config_0"] == 4
    assert kinds["initial_config_1"] == kinds["initial_config_2"] == kinds["initial_config_3"] == 10
    running_ms = 2500 - 1400
    assert abs(kinds["pwm"] - running_ms / 2) <= 1
    assert kinds["servo_target_angle"] == kinds["servo_target_current"]
    assert abs(kinds["servo_target_angle"] - running_ms / 2) <= 1
    assert kinds["servo_state"] > 1000
    stamps = [r["timestamp"] for r in records]
    assert stamps == sorted(stamps) and stamps[-1] < 2.5


def test_uart_capture_decodes_with_leptrino_decoder(runs):
    chain, _ = runs
    data = (chain.folder.uart_dir / "leptrino_foot.device_tx.lep").read_bytes()
    recs = list(lp.decode_leptrino(data))
    assert all(r["ok"] for r in recs)
    assert sum(r["kind"] == "force_data" for r in recs) == chain.sensor.frames_sent - 2
    cmds = list(
        lp.decode_leptrino(
            (chain.folder.uart_dir / "leptrino_foot.host_tx.lep").read_bytes(), from_sensor=False
        )
    )
    assert [r["command"] for r in cmds] == ["GET_INF", "GET_LIMIT", "DATA_START"]


def test_mcap_readback_schemas_and_ros1_payloads(runs):
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    chain, _ = runs
    with open(chain.folder.mcap, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        for ch in summary.channels.values():
            assert ch.schema_id != 0 and ch.schema_id in summary.schemas, ch.topic
        topics = {ch.topic: ch for ch in summary.channels.values()}
        assert {"/spinal/imu", "/plant/ground_truth", "/diag/can_master"} <= set(topics)
        imu_schema = summary.schemas[topics["/spinal/imu"].schema_id]
        assert imu_schema.encoding == "ros1msg" and imu_schema.name == "spinal/Imu"
        ts = get_typestore(Stores.ROS1_NOETIC)
        ts.register(get_types_from_msg(imu_schema.data.decode(), "spinal/msg/Imu"))
        n_imu = n_truth = 0
        for _schema, channel, message in reader.iter_messages():
            if channel.topic == "/spinal/imu":
                msg = ts.deserialize_ros1(message.data, "spinal/msg/Imu")
                assert msg.acc.shape == (3,) and np.all(np.isfinite(msg.quaternion))
                n_imu += 1
            elif channel.topic == "/plant/ground_truth":
                doc = json.loads(message.data)
                assert abs(doc["time"] * 1e9 - message.log_time) < 1
                n_truth += 1
        assert n_imu == chain.loop.stats.ticks["spinal"]
        assert n_truth == 250


def main(argv: list[str]) -> None:
    import cProfile
    import pstats
    import tempfile

    seconds = float(argv[0]) if argv and not argv[0].startswith("-") else 3.0
    with tempfile.TemporaryDirectory() as tmp:
        chain = build_chain(
            Path(tmp),
            profile="--nodes" in argv,
            log="--no-log" not in argv,
            pty="--pipe" not in argv,
        )
        try:
            t0 = time.perf_counter()
            c0 = time.process_time()
            if "--profile" in argv:
                prof = cProfile.Profile()
                prof.enable()
                chain.loop.run(seconds)
                prof.disable()
            else:
                chain.loop.run(seconds)
            wall = time.perf_counter() - t0
            cpu = time.process_time() - c0
        finally:
            chain.close()
        waits = sum(b.waits for b in chain.loop.barriers)
        print(
            f"open-loop chain: {seconds:.1f} simulated s in {wall:.2f} wall s = "
            f"{seconds / wall:.2f}x real time ({seconds / cpu:.2f} simulated s per CPU s); "
            f"pty settles that waited: {waits}"
        )
        if "--nodes" in argv:
            print(chain.loop.profile_table())
        if "--profile" in argv:
            pstats.Stats(prof).sort_stats("tottime").print_stats(25)


if __name__ == "__main__":
    main(sys.argv[1:])
