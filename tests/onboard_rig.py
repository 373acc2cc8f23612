"""Lockstep rig for the onboard-node tests: OnboardNode on one end of a pty pair, a real rosserial
ClientSession with Spinal's H7_v2 slot layout on the other (scripted Spinal), optionally a
Leptrino sensor-side encoder on a second pty pair. Simulated time only."""

from __future__ import annotations

import time
from collections import defaultdict
from typing import Any

import numpy as np

from rdm.control.attitude import AttitudeController, CommandRejectedError
from rdm.link.serial import open_pty_pair
from rdm.protocol import leptrino as lp
from rdm.protocol.rosserial import spinal_registry
from rdm.protocol.rosserial.client import ClientSession
from rdm.protocol.rosserial.events import MessageReceived

REG = spinal_registry()
TICK = 4096 / (2 * np.pi)
G = 9.80665


def raw_ticks(q: np.ndarray) -> list[int]:
    """Independent Dynamixel conversion (centre 2048, 4096 per turn)."""
    return [round(2048 + v * TICK) for v in q]


def wait_in(port, n: int, timeout: float = 2.0) -> None:
    deadline = time.monotonic() + timeout
    while port.in_waiting < n and time.monotonic() < deadline:
        time.sleep(0.0002)


class Rig:
    def __init__(self, node_factory, foot: bool = False) -> None:
        self.node_link, self.peer_link = open_pty_pair()
        self.foot_node_link = self.foot_peer_link = None
        if foot:
            self.foot_node_link, self.foot_peer_link = open_pty_pair()
        self.node = node_factory(self.node_link, self.foot_node_link)
        self.spinal = ClientSession.from_layout()
        self.received: list[tuple[float, str, object]] = []
        self.by_topic: dict[str, list[tuple[float, object]]] = defaultdict(list)
        self._read = 0
        self.auto_ack = True
        self.imu_quaternion = [0.0, 0.0, 0.0, 1.0]
        self.imu_acc = [0.0, 0.0, 9.8]
        self.battery_v = 24.5
        #: Spinal publishes nothing while True (a silent or unplugged flight controller)
        self.silent = False
        self.servo_q: np.ndarray | None = None
        self.servo_extra: list[tuple[int, int]] = []
        self.foot_raw: tuple[int, ...] | None = None
        self.foot_garbage = b""
        self.foot_commands: list[lp.CommandFrame] = []
        self.foot_sent: list[tuple[float, tuple[int, ...]]] = []
        self._foot_parser = lp.LeptrinoStreamParser()
        self.t = 0.0
        #: optional hooks: on_message(t, topic, msg) per received message; after_spin(t)
        self.on_message = None
        self.after_spin = None

    def close(self) -> None:
        self.node_link.close()
        if self.foot_node_link is not None:
            self.foot_node_link.close()

    def publish(self, topic: str, msg) -> None:
        self.spinal.publish(topic, msg)

    def step(self, t: float) -> None:
        """One 25 ms lockstep: node tick, Spinal spins on what it got, answers."""
        self.t = t
        self.node.tick(t)
        data = b""
        deadline = time.monotonic() + 2
        while self._read + len(data) < self.node.bytes_written and time.monotonic() < deadline:
            data += self.peer_link.read_available()
        assert self._read + len(data) == self.node.bytes_written
        self._read += len(data)
        ms = round(t * 1000)
        for e in self.spinal.spin(data, ms):
            if isinstance(e, MessageReceived):
                self.received.append((t, e.topic, e.message))
                self.by_topic[e.topic].append((t, e.message))
                if self.on_message is not None:
                    self.on_message(t, e.topic, e.message)
                if e.topic == "flight_config_cmd" and self.auto_ack and e.message.cmd <= 2:
                    ack = REG.msg("std_msgs/UInt8").new(data=e.message.cmd)
                    self.publish("flight_config_ack", ack)
        if self.after_spin is not None:
            self.after_spin(t)
        if self.spinal.configured and not self.silent:
            imu = REG.msg("spinal/Imu").new(
                quaternion=list(self.imu_quaternion), acc=list(self.imu_acc)
            )
            self.publish("imu", imu)
            if self.servo_q is not None:
                st = REG.msg("spinal/ServoState")
                # Spinal's index of joint j: the node's CAN-table map (checked on its own in
                # test_onboard.py::test_default_servo_map_is_the_can_table_order)
                index = self.node.config.servo_map.servo_index
                servos = [
                    st.new(index=index[j], angle=a) for j, a in enumerate(raw_ticks(self.servo_q))
                ]
                servos += [st.new(index=i, angle=a) for i, a in self.servo_extra]
                self.publish("servo/states", REG.msg("spinal/ServoStates").new(servos=servos))
            battery = REG.msg("std_msgs/Float32").new(data=self.battery_v)
            self.publish("battery_voltage_status", battery)
        out = self.spinal.take_output()
        if out and not self.silent:
            self.peer_link.write(out)
            wait_in(self.node_link.port, len(out))
        if self.foot_peer_link is not None:
            self._foot_side(t)

    def _foot_side(self, t: float) -> None:
        """Sensor role: read host commands, stream one data frame per step after DATA_START."""
        for ev in self._foot_parser.feed(self.foot_peer_link.read_available()):
            if ev.payload is not None:
                self.foot_commands.append(lp.parse_command(ev.payload))
        started = any(c.command == lp.Command.DATA_START for c in self.foot_commands)
        out = self.foot_garbage
        self.foot_garbage = b""
        if started and self.foot_raw is not None:
            out += lp.encode_response(lp.ForceData(tuple(self.foot_raw), 25, 0))
            self.foot_sent.append((t, tuple(self.foot_raw)))
        if out:
            self.foot_peer_link.write(out)
            wait_in(self.foot_node_link.port, len(out))

    def run(self, t0: float, t1: float, dt: float = 0.025, each=None) -> float:
        n = round((t1 - t0) / dt)
        t = t0
        for k in range(n):
            t = t0 + k * dt
            if each is not None:
                each(t)
            self.step(t)
        return t0 + n * dt

    def count(self, topic: str, t0: float, t1: float) -> int:
        return sum(1 for t, _ in self.by_topic[topic] if t0 <= t < t1)


class VerticalPlant:
    """A point mass on a floor at z = 0 under the rotors' summed thrust (vertical only):
    enough physics to see a climb, a descent and a touchdown."""

    def __init__(self, mass: float, z: float = 0.0) -> None:
        self.mass, self.z, self.vz = mass, z, 0.0
        self.specific_force = G

    def step(self, dt: float, thrust: float) -> None:
        a = thrust / self.mass - G
        self.vz += a * dt
        self.z += self.vz * dt
        if self.z <= 0.0:
            self.z, self.vz = 0.0, max(self.vz, 0.0)
            self.specific_force = G  # the floor carries the rest
        else:
            self.specific_force = thrust / self.mass


class SpinalCore:
    """Applies the node's messages to an AttitudeController and steps it at 200 Hz; with a
    :class:`VerticalPlant`, the rotors' thrust moves it (level, no rotation) and the rig's
    IMU reports its specific force."""

    def __init__(self, rig: Rig, plant: VerticalPlant | None = None, voltage: float = 25.2):
        self.rig = rig
        self.core = AttitudeController(200.0)
        self.plant = plant
        self.voltage = voltage
        self.rejected = 0
        self.now = 0.0
        self.last_output = None
        rig.auto_ack = False
        rig.on_message, rig.after_spin = self.on_message, self.after_spin

    def on_message(self, t: float, topic: str, m) -> None:
        c = self.core
        try:
            if topic == "uav_info":
                c.set_uav_info(m.motor_num, m.uav_model)
            elif topic == "motor_info":
                rows = np.array([[u.voltage, u.max_thrust, *u.polynominal] for u in m.motor_info])
                c.set_pwm_info(
                    m.min_pwm,
                    m.max_pwm,
                    m.min_thrust,
                    m.force_landing_thrust,
                    m.pwm_conversion_mode,
                    rows,
                )
            elif topic == "flight_config_cmd":
                c.flight_config(m.cmd, t)
            elif topic == "rpy/gain":
                names = ("roll_p", "roll_i", "roll_d", "pitch_p", "pitch_i", "pitch_d", "yaw_d")
                terms = np.array([[getattr(u, n) for n in names] for u in m.motors], np.int64)
                c.set_gains_wire(terms)
            elif topic == "p_matrix_pseudo_inverse_inertia":
                pinv = np.array([[u.r, u.p, u.y] for u in m.pseudo_inverse], dtype=np.int16)
                c.set_pinv_inertia_wire(pinv, list(m.inertia))
            elif topic == "four_axes/command":
                c.four_axis_command(list(m.angles), np.array(m.base_thrust, dtype=float), t)
        except CommandRejectedError:
            self.rejected += 1

    def after_spin(self, t: float) -> None:
        for k in range(5):  # 200 Hz inside the 25 ms tick
            self.now = t + k * 0.005
            out = self.core.step(self.now, np.eye(3), [0.0, 0.0, 0.0], self.voltage)
            self.last_output = out
            if self.plant is not None:
                # a running rotor gives at least min_thrust (the min duty); stopped: none
                thrust = np.maximum(np.asarray(out.thrust), 1.0) if self.core.armed else [0.0]
                self.plant.step(0.005, float(np.sum(thrust)))
                self.rig.imu_acc = [0.0, 0.0, self.plant.specific_force]
            for name, value in out.events:
                if name == "ack":
                    ack = REG.msg("std_msgs/UInt8").new(data=int(value))
                    self.rig.publish("flight_config_ack", ack)


class FlightRig:
    """:class:`Rig` + :class:`SpinalCore` + a vertical ``plant`` in simulated time (25 ms
    ticks): the node gets the plant's z as mocap unless ``mocap`` is False; ``log`` keeps
    (t, z, setpoint z) per tick. Subclasses extend :meth:`feed`."""

    DT = 0.025

    def __init__(self, node_factory, plant: VerticalPlant, foot: bool = False) -> None:
        self.rig = Rig(node_factory, foot=foot)
        self.plant = plant
        self.spinal = SpinalCore(self.rig, plant)
        self.node = self.rig.node
        self.rig.servo_q = np.zeros(self.node.robot.n_q)
        self.mocap = True
        self.t = 0.0
        self.log: list[tuple[float, float, float]] = []

    def feed(self, t: float) -> None:
        if self.mocap:
            self.node.set_mocap([0.0, 0.0, self.plant.z], [0.0, 0.0, self.plant.vz], 0.0)
        sp = self.node._flight_setpoint or self.node.setpoint
        self.log.append((t, self.plant.z, float(sp.position[2])))

    def run(self, seconds: float) -> None:
        self.t = self.rig.run(self.t, self.t + seconds, each=self.feed)

    def run_until(self, condition, limit: float) -> float:
        """Ticks until ``condition()``; the time it took (fails past ``limit``)."""
        start = self.t
        while not condition():
            assert self.t - start < limit, f"not within {limit} s"
            self.run(self.DT)
        return self.t - start

    def close(self) -> None:
        self.rig.close()


def servo_readings(rng, n: int, count: int) -> list[list[tuple[int, int]]]:
    """``count`` random ``servo/states`` readings for ``n`` servos as (index, angle) lists:
    full, partial, with an unknown index (99) or with a joint twice."""
    readings = []
    for _ in range(count):
        idx = list(range(n))
        kind = rng.random()
        if kind < 0.2:
            idx = idx[: rng.randint(1, n - 1)]  # partial
        elif kind < 0.3:
            idx = [*idx, 99]  # unknown index
        elif kind < 0.4:
            idx = [*idx, idx[2]]  # a joint twice
        readings.append([(i, rng.randint(1800, 2300)) for i in idx])
    return readings


def assert_same_servo_state(fast, plain) -> None:
    """Two onboard nodes hold the same present q, seen flags, joint targets and counters
    (in the same order)."""
    assert fast.present_q.tobytes() == plain.present_q.tobytes()
    assert fast._seen.tobytes() == plain._seen.tobytes()
    assert (fast.joint_targets is None) == (plain.joint_targets is None)
    if plain.joint_targets is not None:
        assert fast.joint_targets.tobytes() == plain.joint_targets.tobytes()
    assert list(fast.counts.items()) == list(plain.counts.items())


def handshake(servers: list[Any]) -> ClientSession:
    """Server sessions through one handshake with a Spinal-layout client (the same bytes
    from each server; the client answers the last)."""
    client = ClientSession.from_layout()
    for s in servers:
        s.start(0.0)
    for ms in range(0, 400, 5):
        out = b""
        for s in servers:
            out = s.take_output()  # the same bytes from each
        data = b"".join(e for e in [out])
        client.spin(data, ms)
        wire = client.take_output()
        for s in servers:
            s.feed(wire, ms / 1000)
    assert client.configured
    return client
