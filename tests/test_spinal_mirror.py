"""Spinal mirror in lockstep with the REAL protocol peers on the other side.

* UART: a pty pair; the PC side is a :class:`ServerSession` (the rosserial server role);
* CAN: python-can ``virtual:`` buses with :class:`NeuronMirror` boards and a listening bus
  whose frames are decoded by the tests (codec / cantools), never by the mirror's bookkeeping.

One simulated millisecond per :meth:`Rig.step`: server output -> pty -> mirror tick -> pty ->
server; then every Neuron ticks; then the listener is drained.
"""

from __future__ import annotations

import itertools
import math
import time
from pathlib import Path
from typing import Any

import can
import cantools
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rdm.control.attitude import SpinalStep
from rdm.estimate import AttitudeEstimator
from rdm.link.can import open_can
from rdm.link.serial import open_pty_pair
from rdm.nodes.base import drain
from rdm.nodes.neuron_mirror import NeuronMirror
from rdm.nodes.servo_model import ServoConfig
from rdm.nodes.spinal_mirror import LEVEL_ACC, LEVEL_GYRO, LEVEL_MAG, SpinalMirror
from rdm.protocol import neuron as nr
from rdm.protocol.rosserial import constants as C
from rdm.protocol.rosserial import spinal_registry
from rdm.protocol.rosserial.codec import RosTime
from rdm.protocol.rosserial.events import LogReceived, MessageReceived
from rdm.protocol.rosserial.server import ServerSession

REG = spinal_registry()
PWM_ID = 15  # MOTOR broadcast, message 0 (DBC: MotorPwmSlaves1To6)
DBC_DIR = Path(__file__).resolve().parents[1] / "firmware_protocol" / "neuron"
EPOCH_NS = 1_767_225_600 * 10**9
_channels = itertools.count()

#: Hydrus quad motor_info (fact sheet sec. 3.6): SQRT mode, one 25.2 V reference.
P0, P1, P2 = 12.3593793002, -6.627443098, 0.07983707
MIN_PWM, MAX_PWM, MIN_THRUST, FORCE_LANDING_THRUST = 0.59, 0.9375, 1.0, 6.5


def pc_time(now: float) -> RosTime:
    return RosTime.from_ns(EPOCH_NS + round(now * 1e9))


def msg(type_name: str, **fields: Any) -> Any:
    return REG.msg(type_name).new(**fields)


def pwm_info_msg() -> Any:
    motor = msg("spinal/MotorInfo", voltage=25.2, max_thrust=20.0, polynominal=[P0, P1, P2, 0, 0])
    return msg(
        "spinal/PwmInfo",
        min_pwm=MIN_PWM,
        max_pwm=MAX_PWM,
        min_thrust=MIN_THRUST,
        force_landing_thrust=FORCE_LANDING_THRUST,
        pwm_conversion_mode=0,
        motor_info=[motor],
    )


class Rig:
    def __init__(
        self,
        slaves: tuple[int, ...] = (1, 2, 3, 4),
        servos_per_neuron: int = 1,
        rate_hz: float = 200.0,
        **spinal_options: Any,
    ) -> None:
        self.channel = f"spinal_mirror_test_{next(_channels)}"
        self.dev, self.pc = open_pty_pair()
        self.mirror = SpinalMirror(
            self.dev,
            open_can(f"virtual:{self.channel}"),
            rate_hz,
            boot_delay_ms=0,
            **spinal_options,
        )
        self.neurons = {
            s: NeuronMirror(
                open_can(f"virtual:{self.channel}"),
                s,
                [ServoConfig(dynamixel_id=i + 1) for i in range(servos_per_neuron)],
            )
            for s in slaves
        }
        self.listener = open_can(f"virtual:{self.channel}")
        self.server = ServerSession(time_source=pc_time)
        self.server_events: list[tuple[int, Any]] = []
        self.can_log: list[tuple[int, can.Message]] = []
        self.t = 0
        self._seen_out = 0
        self.neurons_on = True  # False: the Neurons stop (power cut on the CAN side)
        self.before_tick = None  # callable(t) run before the mirror's tick (IMU feed ...)

    # -- lockstep ---------------------------------------------------------------------------
    def step(self) -> None:
        t = self.t
        down = self.server.take_output()
        if down:
            self.pc.write(down)
            port = self.dev.port
            deadline = time.monotonic() + 2.0
            while port.in_waiting < len(down) and time.monotonic() < deadline:
                time.sleep(0.0001)
            assert port.in_waiting >= len(down), "pty did not deliver the server's bytes"
        if self.before_tick is not None:
            self.before_tick(t)
        self.mirror.tick(t / 1000)
        n = self.mirror.uart.bytes_out - self._seen_out
        up = self._read_exact(n)
        self._seen_out += n
        self.server_events += [(t, e) for e in self.server.feed(up, t / 1000)]
        if self.neurons_on:
            for neuron in self.neurons.values():
                neuron.tick(t / 1000)
        self.can_log += [(t, m) for m in drain(self.listener)]
        self.t += 1

    def _read_exact(self, n: int) -> bytes:
        data = b""
        deadline = time.monotonic() + 2.0
        while len(data) < n and time.monotonic() < deadline:
            data += self.pc.read_available()
        assert len(data) == n, f"pty: expected {n} bytes from the mirror, got {len(data)}"
        return data

    def run_until(self, end_ms: int) -> None:
        while self.t < end_ms:
            self.step()

    def run_for(self, ms: int) -> None:
        self.run_until(self.t + ms)

    # -- helpers ----------------------------------------------------------------------------
    def handshake(self) -> None:
        self.server.start(self.t / 1000)
        self.run_for(5)
        assert self.mirror.session.configured
        assert "four_axes/command" in self.server.outbound

    def wait_can_running(self) -> None:
        from rdm.nodes.can_master import MasterState

        for _ in range(3000):
            if self.mirror.master.state is MasterState.RUNNING:
                return
            self.step()
        raise AssertionError("CAN master did not start")

    def publish(self, topic: str, message: Any) -> None:
        self.server.publish(topic, message)

    def received(self, topic: str, since: int = 0) -> list[tuple[int, Any]]:
        return [
            (t, e.message)
            for t, e in self.server_events
            if isinstance(e, MessageReceived) and e.topic == topic and t >= since
        ]

    def logs(self, level: int | None = None, since: int = 0) -> list[tuple[int, LogReceived]]:
        return [
            (t, e)
            for t, e in self.server_events
            if isinstance(e, LogReceived) and t >= since and (level is None or e.level == level)
        ]

    def pwm_frames(self, since: int = 0) -> list[tuple[int, tuple[int, ...]]]:
        """(ms, slot values) of every PWM frame 0 on the bus, decoded with the Neuron codec
        (id 15 is only ever sent Spinal -> Neuron)."""
        out = []
        for t, m in self.can_log:
            if t < since or m.arbitration_id != PWM_ID:
                continue
            frame = nr.decode_frame(m.arbitration_id, bytes(m.data), nr.Direction.SPINAL_TO_NEURON)
            if isinstance(frame, nr.PwmFrame) and frame.frame_index == 0:
                out.append((t, frame.values))
        return out

    def close(self) -> None:
        self.mirror.close()
        for n in self.neurons.values():
            n.close()
        self.listener.shutdown()


# ------------------------------------------------------------------------------- oracles
def f32(x: float) -> float:
    """What a float32 field carries."""
    return float(np.float32(x))


def can_value_to_thrust(value: int, voltage: float) -> float:
    """Independent inverse of the Hydrus SQRT curve (sec. 3.6): CAN value -> thrust (N).

    The CAN value is ``int(duty*2000 - 1000)``, i.e. the pulse minus 1000 us; the midpoint of
    the truncation interval is used. ``f = 0.1 p2 x^2 + 0.1 p1 x + p0`` with x in percent,
    then the SQRT voltage factor ``(Vref/V)^2`` is undone.
    """
    duty = (value + 0.5 + 1000.0) / 2000.0
    x = duty * 100.0
    f = 0.1 * f32(P2) * x * x + 0.1 * f32(P1) * x + f32(P0)
    return f / (25.2 / voltage) ** 2


def roll_pitch(quaternion_xyzw) -> tuple[float, float]:
    _yaw, pitch, roll = Rotation.from_quat(list(quaternion_xyzw)).as_euler("ZYX")
    return roll, pitch


def four_axis(angles, base) -> Any:
    return msg("spinal/FourAxisCommand", angles=list(angles), base_thrust=list(base))


def arm(rig: Rig) -> None:
    rig.publish("uav_info", msg("spinal/UavInfo", motor_num=4, uav_model=16, baselink=0))
    rig.publish("motor_info", pwm_info_msg())
    rig.run_for(2)
    rig.publish("flight_config_cmd", msg("spinal/FlightConfigCmd", cmd=0))
    rig.run_for(10)
    assert [m.data for _t, m in rig.received("flight_config_ack")] == [0]


@pytest.fixture
def rig():
    r = Rig()
    yield r
    r.close()


# ------------------------------------------------------------------------------- tests
def test_handshake_and_imu_at_200hz_with_the_estimators_attitude():
    """TopicInfo handshake; imu every 5 ms; its quaternion is the estimator's (independent
    AttitudeEstimator on the same samples) and the roll the integrated gyro implies."""
    r = Rig(slaves=(1,), gyro_calib_duration_s=0.1)
    try:
        est = AttitudeEstimator(rate_hz=200.0, gyro_calib_duration_s=0.1)
        expected: dict[int, np.ndarray] = {}

        def feed(t: int) -> None:
            gyro = (0.5, 0.0, 0.0) if t >= 500 else (0.0, 0.0, 0.0)
            r.mirror.set_imu_sample(gyro, (0.0, 0.0, 9.80665), (30.0, 0.0, -40.0))
            if t % 5 == 0:
                est.step(gyro, (0.0, 0.0, 9.80665), (30.0, 0.0, -40.0))
                expected[t] = est.quaternion.copy()

        r.before_tick = feed
        r.server.start(0.0)
        r.run_until(3000)
        registered = {e.topic for _t, e in r.server_events if type(e).__name__ == "TopicRegistered"}
        for topic in (
            "imu",
            "flight_config_ack",
            "motor_pwms",
            "servo/states",
            "four_axes/command",
            "rpy/gain",
            "servo/target_states",
        ):
            assert topic in registered
        imu = r.received("imu")
        in_window = [t for t, _m in imu if 1000 <= t < 3000]
        assert abs(len(in_window) - 400) <= 1  # 200 Hz over 2 simulated seconds
        assert all(b - a == 5 for a, b in itertools.pairwise([t for t, _ in imu]))
        for t, m in imu:
            np.testing.assert_allclose(m.quaternion, expected[t], atol=2e-7)
        # 0.5 rad/s about x for 2.5 s: the roll grows, bounded by the pure integral 1.25 rad
        # (the level accelerometer pulls the gravity estimate back)
        rolls = [roll_pitch(m.quaternion)[0] for t, m in imu if t >= 600 and t % 100 == 0]
        assert all(b > a for a, b in itertools.pairwise(rolls)), rolls
        roll, pitch = roll_pitch(imu[-1][1].quaternion)
        assert 0.3 < roll < 1.25 and abs(pitch) < 0.02
        np.testing.assert_allclose(imu[-1][1].gyro, [0.5, 0, 0], atol=1e-3)
    finally:
        r.close()


def test_arming_needs_uav_and_motor_info_and_arm_off_resets(rig: Rig):
    rig.handshake()
    rig.publish("flight_config_cmd", msg("spinal/FlightConfigCmd", cmd=0))
    rig.run_for(20)
    assert rig.received("flight_config_ack") == []  # nothing known: ignored, no ack
    rig.wait_can_running()  # the model and motor count are inferred from CAN
    rig.publish("uav_info", msg("spinal/UavInfo", motor_num=4, uav_model=16, baselink=0))
    rig.publish("flight_config_cmd", msg("spinal/FlightConfigCmd", cmd=0))
    rig.run_for(20)
    assert rig.received("flight_config_ack") == []  # still no motor_info
    assert rig.mirror.counters.rejected["not_activated"] == 2
    idle = rig.pwm_frames(since=rig.t - 10)
    assert idle and all(v[:4] == (0, 0, 0, 0) for _t, v in idle)
    rig.publish("motor_info", pwm_info_msg())
    rig.run_for(2)
    t_arm = rig.t
    rig.publish("flight_config_cmd", msg("spinal/FlightConfigCmd", cmd=0))
    rig.run_for(20)
    assert [m.data for _t, m in rig.received("flight_config_ack")] == [0]
    # armed with base thrust 0: the motors run at min_duty = duty of min_thrust 1 N (derived)
    armed = rig.pwm_frames(since=t_arm + 10)
    assert armed and all(v[:4] == armed[0][1][:4] for _t, v in armed)
    assert abs(can_value_to_thrust(armed[0][1][0], 25.2) - MIN_THRUST) < 0.03
    rig.publish("flight_config_cmd", msg("spinal/FlightConfigCmd", cmd=1))
    rig.run_for(20)
    assert [m.data for _t, m in rig.received("flight_config_ack")] == [0, 1]
    after = rig.pwm_frames(since=rig.t - 10)
    assert after and all(v[:4] == (0, 0, 0, 0) for _t, v in after)
    assert not rig.mirror.core.armed


def test_pwm_on_can_equals_an_independent_spinal_step(rig: Rig):
    """Gains, Pinv/inertia, commands at 40 Hz and a moving IMU: every PWM frame equals the
    duty of a separate SpinalStep fed the same inputs at the same times."""
    rig.mirror.set_battery_voltage(24.0)  # from t = 0: the low-passed value stays 24 V
    rig.handshake()
    rig.wait_can_running()
    ref = SpinalStep(200.0)
    ref.set_uav_info(4, 16)
    imu_of: dict[int, tuple] = {}

    def feed(t: int) -> None:
        s = t / 1000.0
        gyro = (0.2 * math.sin(7 * s), 0.15 * math.cos(5 * s), 0.05 * math.sin(3 * s))
        acc = (0.3 * math.sin(2 * s), -0.2, 9.7)
        mag = (30.0, 2.0 * math.sin(s), -40.0)
        rig.mirror.set_imu_sample(gyro, acc, mag)
        imu_of[t] = (gyro, acc, mag)

    rig.before_tick = feed
    gains = np.zeros((4, 7), dtype=np.int64)
    for i in range(4):
        gains[i] = [3000 + 100 * i, 500, 800, -2800 + 50 * i, 400, 700, 300 + 40 * i]
    pinv = np.array([[120, -80, 30], [-110, 90, -25], [100, 85, 20], [-95, -70, -35]], np.int16)
    inertia = [80, 90, 150, 2, -1, 3]
    inputs: list[tuple[int, str, tuple]] = []  # (ms applied, method, args)

    def send(topic: str, message: Any, method: str, args: tuple) -> None:
        rig.publish(topic, message)
        inputs.append((rig.t, method, args))

    send(
        "uav_info",
        msg("spinal/UavInfo", motor_num=4, uav_model=16, baselink=0),
        "set_uav_info",
        (4, 16),
    )
    info = pwm_info_msg()
    table = np.array([[f32(25.2), f32(20.0), f32(P0), f32(P1), f32(P2), 0.0, 0.0]])
    send(
        "motor_info",
        info,
        "set_pwm_info",
        (f32(MIN_PWM), f32(MAX_PWM), f32(MIN_THRUST), f32(FORCE_LANDING_THRUST), 0, table),
    )
    terms = [
        msg(
            "spinal/RollPitchYawTerm",
            **dict(
                zip(
                    ["roll_p", "roll_i", "roll_d", "pitch_p", "pitch_i", "pitch_d", "yaw_d"],
                    (int(v) for v in row),
                    strict=True,
                )
            ),
        )
        for row in gains
    ]
    send("rpy/gain", msg("spinal/RollPitchYawTerms", motors=terms), "set_gains_wire", (gains,))
    units = [
        msg("spinal/PMatrixPseudoInverseUnit", r=int(a), p=int(b), y=int(c)) for a, b, c in pinv
    ]
    send(
        "p_matrix_pseudo_inverse_inertia",
        msg("spinal/PMatrixPseudoInverseWithInertia", pseudo_inverse=units, inertia=inertia),
        "set_pinv_inertia_wire",
        (pinv, inertia),
    )
    rig.run_for(3)
    send("flight_config_cmd", msg("spinal/FlightConfigCmd", cmd=0), "flight_config", (0,))
    rig.run_for(3)
    send("flight_config_cmd", msg("spinal/FlightConfigCmd", cmd=160), "flight_config", (160,))
    start = rig.t
    for k in range(40):  # 1 s of commands at 40 Hz
        s = k * 0.025
        angles = [f32(0.05 * math.sin(3 * s)), f32(-0.04 * math.cos(2 * s)), f32(0.3 * s)]
        base = [f32(7.0 + 0.5 * math.sin(4 * s + i)) for i in range(4)]
        send(
            "four_axes/command",
            four_axis(angles, base),
            "four_axis_command",
            (angles, np.array(base)),
        )
        rig.run_for(25)
    end = rig.t
    # the independent reference, step by step on the mirror's schedule (every 5 ms)
    duty_at: dict[int, np.ndarray] = {}
    pending = sorted(inputs, key=lambda x: x[0])
    j = 0
    for t in range(0, end):
        while j < len(pending) and pending[j][0] == t:
            _t, method, args = pending[j]
            if method in ("flight_config", "four_axis_command"):
                getattr(ref, method)(*args, t / 1000)
            else:
                getattr(ref, method)(*args)
            j += 1
        if t % 5 == 0:
            gyro, acc, mag = imu_of.get(t, (LEVEL_GYRO, LEVEL_ACC, LEVEL_MAG))
            out = ref.step(t / 1000, gyro, acc, mag, 24.0)
            duty_at[t] = out.duty.copy()
    frames = rig.pwm_frames(since=start)
    assert abs(len(frames) - (end - start) / 2) <= 1  # 500 Hz broadcast
    varied = set()
    for t, values in frames:
        duty = duty_at[t - t % 5]
        expected = tuple(int(d * 2000.0 - 1000.0) for d in duty)
        assert values[:4] == expected, f"t={t}"
        assert values[4:] == (0, 0)
        varied.add(values[:4])
    assert len(varied) > 50  # the test exercised a moving control output
    # once: the same frame decoded by cantools from the DBC
    db = cantools.database.load_file(DBC_DIR / "neuron_spinal_to_neuron.dbc")
    t_last, m_last = next((t, m) for t, m in reversed(rig.can_log) if m.arbitration_id == 15)
    decoded = db.decode_message(15, bytes(m_last.data))
    assert [decoded[f"Pwm{i}"] for i in range(1, 5)] == [
        int(d * 2000.0 - 1000.0) for d in duty_at[t_last - t_last % 5]
    ]
    # and the Neurons' ESCs output exactly that (slave s reads slot s)
    for s, neuron in rig.neurons.items():
        assert neuron.esc.value == decoded[f"Pwm{s}"]
    # motor_pwms at ~10 Hz carries duty x 2000
    reports = rig.received("motor_pwms", since=start)
    assert 9 <= len(reports) <= 11
    t_rep, rep = reports[-1]
    assert list(rep.motor_value) == [int(d * 2000.0) for d in duty_at[t_rep - t_rep % 5]]


def test_stopped_command_stream_forces_landing_with_the_thrust_ramp(rig: Rig):
    rig.mirror.set_battery_voltage(24.0)
    rig.handshake()
    rig.wait_can_running()
    arm(rig)
    base = 9.0
    t_last = None
    for _ in range(20):  # 0.5 s at 40 Hz
        t_last = rig.t
        rig.publish("four_axes/command", four_axis([0, 0, 0], [base] * 4))
        rig.run_for(25)
    steady = rig.pwm_frames(since=rig.t - 20)
    thrust0 = can_value_to_thrust(steady[-1][1][0], 24.0)
    assert abs(thrust0 - base) < 0.03
    rig.run_until(t_last + 2000)
    acks = rig.received("flight_config_ack")
    assert [m.data for _t, m in acks] == [0, 2]
    t_ack = acks[-1][0]
    # the timeout is "more than 500 ms" since the last command, checked at the 200 Hz steps
    assert t_last + 500 < t_ack <= t_last + 505
    assert any(
        "cannot connect with ROS" in e.text and e.level == C.LogLevel.ERROR
        for _t, e in rig.logs(since=t_ack)
    )
    assert rig.mirror.counters.failsafes["failsafe_timeout"] == 1
    frames = rig.pwm_frames(since=t_last)
    before = [v for t, v in frames if t < t_ack]
    assert all(v[:4] == steady[-1][1][:4] for v in before)  # unchanged until the fail-safe
    ramp = [(t, can_value_to_thrust(v[0], 24.0)) for t, v in frames if t_ack + 20 <= t]
    ts = np.array([t for t, f in ramp if f > FORCE_LANDING_THRUST + 0.1]) / 1000.0
    fs = np.array([f for t, f in ramp if f > FORCE_LANDING_THRUST + 0.1])
    slope = np.polyfit(ts, fs, 1)[0]
    assert slope == pytest.approx(-2.5, rel=0.03)  # 2.5 N/s in the average (sec. 3.7)
    # reaches force_landing_thrust about (9 - 6.5)/2.5 = 1 s after the fail-safe, then holds
    tail = [f for t, f in ramp if t > t_ack + 1150]
    assert tail and all(abs(f - FORCE_LANDING_THRUST) < 0.05 for f in tail)


def test_wrong_length_command_is_rejected_logged_and_counted(rig: Rig):
    rig.handshake()
    rig.wait_can_running()
    arm(rig)
    for _ in range(4):
        rig.publish("four_axes/command", four_axis([0, 0, 0], [7.0] * 4))
        rig.run_for(25)
    before = rig.pwm_frames(since=rig.t - 20)[-1][1]
    t_bad = rig.t
    rig.publish("four_axes/command", four_axis([0, 0, 0], [12.0] * 3))
    rig.run_for(25)
    errors = rig.logs(level=C.LogLevel.ERROR, since=t_bad)
    assert any("base_thrust" in e.text for _t, e in errors), errors
    assert rig.mirror.counters.rejected["wrong_length"] == 1
    assert rig.mirror.diagnostics()["rejected"]["wrong_length"] == 1
    assert all(v == before for _t, v in rig.pwm_frames(since=t_bad))  # never applied
    # a gain message of the wrong length (3 motors) and a malformed servo command too
    terms = [msg("spinal/RollPitchYawTerm", roll_p=1000)] * 3
    rig.publish("rpy/gain", msg("spinal/RollPitchYawTerms", motors=terms))
    rig.publish("servo/target_states", msg("spinal/ServoControlCmd", index=[0, 1], angles=[5]))
    rig.publish("four_axes/command", four_axis([0, 0, 0], [7.0] * 4))
    rig.run_for(10)
    assert rig.mirror.counters.rejected["wrong_length"] == 3
    assert len(rig.logs(level=C.LogLevel.ERROR, since=t_bad)) == 3
    assert all(v == before for _t, v in rig.pwm_frames(since=t_bad))


def test_servo_goal_through_the_handshake_and_back_up_the_uart():
    r = Rig(slaves=(1, 2), servos_per_neuron=2)
    try:
        r.handshake()
        r.wait_can_running()
        r.run_for(50)
        table = list(r.mirror.master.servo_states)
        assert table == [(1, 0), (1, 1), (2, 0), (2, 1)]
        # servo index 3 = Neuron 2, servo 1
        r.publish("servo/torque_enable", msg("spinal/ServoTorqueCmd", index=[3], torque_enable=[1]))
        r.run_for(40)  # Neuron reports its goal (bit 2), Spinal acknowledges (bit 15)
        servo = r.neurons[2].servos[1]
        assert servo.torque_enable and not servo.send_goal_position
        t_goal = r.t
        r.publish("servo/target_states", msg("spinal/ServoControlCmd", index=[3], angles=[2900]))
        r.run_for(400)
        assert servo.goal == 2900
        assert abs(servo.position - 2900) <= 1
        assert r.neurons[2].servos[0].goal == r.neurons[2].servos[0].position  # untouched
        # the target frame on the bus, decoded by cantools: goal 2900 with the ack bit (a
        # Neuron's 8-byte servo state shares the id; the 2-servo target frame has DLC 4)
        db = cantools.database.load_file(DBC_DIR / "neuron_spinal_to_neuron.dbc")
        angle_id = db.get_message_by_name("ServoTargetAngle_S02").frame_id
        angle_frames = [
            db.decode_message(angle_id, bytes(m.data).ljust(8, b"\0"))
            for t, m in r.can_log
            if t > t_goal and m.arbitration_id == angle_id and len(m.data) == 4
        ]
        assert angle_frames[-1]["Servo1GoalPosition"] == 2900
        assert angle_frames[-1]["Servo1GoalAck"] == 1
        states = r.received("servo/states", since=t_goal)
        assert 19 <= len(states) <= 21  # 50 Hz
        last = {s.index: s for s in states[-1][1].servos}
        assert sorted(last) == [0, 1, 2, 3]
        assert abs(last[3].angle - 2900) <= 1
        torque = r.received("servo/torque_states")
        assert list(torque[-1][1].torque_enable) == [0, 0, 0, 1]
        bad = r.mirror.counters.rejected["servo_index"]
        r.publish("servo/target_states", msg("spinal/ServoControlCmd", index=[9], angles=[1]))
        r.run_for(5)
        assert r.mirror.counters.rejected["servo_index"] == bad + 1
    finally:
        r.close()


def test_tilt_beyond_one_radian_forces_landing():
    r = Rig(slaves=(1, 2, 3, 4), gyro_calib_duration_s=0.1)
    try:
        r.handshake()
        r.wait_can_running()
        arm(r)
        t_roll = r.t + 100

        def feed(t: int) -> None:
            gyro = (2.0, 0.0, 0.0) if t >= t_roll else (0.0, 0.0, 0.0)
            r.mirror.set_imu_sample(gyro, (0.0, 0.0, 9.80665), (30.0, 0.0, -40.0))

        r.before_tick = feed
        while r.t < t_roll + 1000:
            r.publish("four_axes/command", four_axis([0, 0, 0], [9.0] * 4))
            r.run_for(25)
        acks = r.received("flight_config_ack")
        assert [m.data for _t, m in acks] == [0, 2]
        rolls = [(t, roll_pitch(m.quaternion)[0]) for t, m in r.received("imu", since=t_roll)]
        first_over = next(t for t, roll in rolls if abs(roll) > 1.0)
        assert acks[-1][0] == first_over  # the step whose estimate exceeds 1 rad
        assert all(abs(roll) <= 1.0 for t, roll in rolls if t < first_over)
        assert r.mirror.counters.failsafes["failsafe_tilt"] == 1
        assert any("too large" in e.text for _t, e in r.logs(level=C.LogLevel.ERROR))
    finally:
        r.close()


def test_services_and_battery_voltage(rig: Rig):
    rig.handshake()
    rig.wait_can_running()
    t_set = rig.t
    rig.mirror.set_battery_voltage(23.0)
    rig.run_for(5)
    rig.server.call_service(
        "get_board_info", REG.srv("spinal/GetBoardInfo").request.new(), rig.t / 1000
    )
    rig.run_for(5)
    responses = [e for _t, e in rig.server_events if type(e).__name__ == "ServiceResponse"]
    boards = responses[-1].response.boards
    assert [b.slave_id for b in boards] == [1, 2, 3, 4]
    assert all(len(b.servos) == 1 and b.servos[0].p_gain == 800 for b in boards)
    rig.server.call_service(
        "set_attitude_control", REG.srv("std_srvs/SetBool").request.new(data=False), rig.t / 1000
    )
    rig.run_for(5)
    responses = [e for _t, e in rig.server_events if type(e).__name__ == "ServiceResponse"]
    assert responses[-1].response.success

    # battery: sampled every 20 ms from t = 0 (25.2 V default), low-passed 0.99/0.01
    def filtered(t: int) -> float:
        v = None
        for k in range(t // 20 + 1):
            sample = 23.0 if k * 20 >= t_set else 25.2
            v = sample if v is None else 0.99 * v + 0.01 * sample
        return v

    rig.run_for(1000)
    volts = rig.received("battery_voltage_status", since=t_set)
    assert 9 <= len(volts) <= 11
    assert all(b - a == 101 for (a, _), (b, _) in itertools.pairwise(volts))  # "> 100 ms"
    for t, m in volts:
        assert m.data == pytest.approx(f32(filtered(t)), abs=1e-5)
    assert volts[-1][1].data < 25.2 - 0.5


def test_pwm_test_mode_overrides_and_leaves(rig: Rig):
    """pwm_test (sec. 3.7): empty motor_index -> pwms[0] for all; per-index values, outside
    [0.5, 1] -> 0.5; empty pwms leaves test mode (back to the controller's idle 0.5)."""
    rig.handshake()
    rig.wait_can_running()
    rig.publish("pwm_test", msg("spinal/PwmTest", motor_index=[], pwms=[0.6]))
    rig.run_for(12)
    t1 = rig.t
    rig.publish("pwm_test", msg("spinal/PwmTest", motor_index=[1, 3], pwms=[0.7, 1.5]))
    rig.run_for(12)
    t2 = rig.t
    rig.publish("pwm_test", msg("spinal/PwmTest", motor_index=[], pwms=[]))
    rig.run_for(12)
    value = lambda d: int(f32(d) * 2000.0 - 1000.0)  # noqa: E731
    assert {v[:4] for t, v in rig.pwm_frames() if t1 - 4 <= t < t1} == {(value(0.6),) * 4}
    assert {v[:4] for t, v in rig.pwm_frames() if t2 - 4 <= t < t2} == {
        (value(0.6), value(0.7), value(0.6), 0)
    }
    assert {v[:4] for t, v in rig.pwm_frames() if rig.t - 4 <= t} == {(0, 0, 0, 0)}


def test_can_disconnect_is_logged_over_rosserial(rig: Rig):
    rig.handshake()
    rig.wait_can_running()
    rig.run_for(50)
    t_cut = rig.t
    rig.neurons_on = False
    rig.run_for(1250)
    errors = [(t, e.text) for t, e in rig.logs(level=C.LogLevel.ERROR, since=t_cut)]
    texts = [text for _t, text in errors]
    assert texts == ["CAN disconnected!!", "CAN disconnected!!"]  # at most once per second
    # the last frame came in at about t_cut; "no frame for more than 100 ms" (sec. 2.6)
    assert t_cut + 100 <= errors[0][0] <= t_cut + 103
    assert errors[1][0] - errors[0][0] == 1000


def test_control_steps_are_the_cores_count(rig: Rig):
    """``counters.control_steps`` equals the control outputs the mirror produced (a new
    ``last_output`` object per step, one step at most per 1 ms tick at 200 Hz), which is
    ``core.steps``, and one per 5 ms."""
    rig.wait_can_running()
    start = rig.mirror.counters.control_steps
    outputs = 0
    last = rig.mirror.last_output
    for _ in range(500):
        rig.step()
        if rig.mirror.last_output is not last:
            outputs += 1
            last = rig.mirror.last_output
    assert rig.mirror.counters.control_steps - start == outputs == 100
    assert rig.mirror.counters.control_steps == rig.mirror.core.steps
