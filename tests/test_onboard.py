# ruff: noqa: RUF002, RUF003  (paper notation: Greek letters, minus and times signs)
"""OnboardNode against a real rosserial ClientSession (Spinal role, H7_v2 layout) over a pty
pair, in simulated time. Numbers are checked against independent computations: scipy's CARE,
numpy re-derivations of eqs. (30)-(36), the JSK sec. 4 mappings, and the model's own
kinematics for the vectoring geometry."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from lqi_reference import hover_state_model
from onboard_rig import REG, Rig, raw_ticks

from rdm.model import Robot
from rdm.nodes.onboard import OnboardNode
from rdm.nodes.onboard_config import OnboardConfig
from rdm.nodes.onboard_control import to_wire
from rdm.nodes.onboard_monitors import MonitorLimits

pytestmark = pytest.mark.timeout(300)

ROBOT = Robot.default()
G = 9.80665
DT = 0.025
MD5 = json.loads(
    (Path(__file__).resolve().parents[1] / "firmware_protocol/spinal/md5sums.json").read_text()
)
# Table V, W1 in the JSK state order (docs/lqi.md assumption 1), W2 = I.
W1 = np.diag([20.0, 30.0, 90.0, 12.8, 600.0, 80.0, 100.0, 50.0, 20.0, 0.15, 1.0, 0.5])
Q_BENT = np.array([0.3, -0.2, 0.25, 0.4, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0])
#: a bent configuration whose hover thrust is inside (0, 20) N for every rotor
Q_FLY = np.array([0.1, -0.1, 0.1, 0.2, 0.05, 0.0, 0.0, 0.0, 0.0, 0.0])


#: The rig's Spinal reports the servo angles a test sets, never the goals the node sends:
#: to the node's joint-tracking monitor that is a stuck servo. 7 rad is more than any joint
#: can be from its goal, so that monitor stays out of these tests (its own tests:
#: test_onboard_monitor_rules.py, the stuck-servo fault of test_fault_campaign.py).
RIG_MONITORS = MonitorLimits(joint_tracking_rad=7.0)


def make_rig(foot: bool = False, **cfg) -> Rig:
    cfg.setdefault("monitors", RIG_MONITORS)
    return Rig(lambda uart, f: OnboardNode(uart, f, ROBOT, config=OnboardConfig(**cfg)), foot=foot)


@pytest.fixture
def rig():
    r = make_rig()
    yield r
    r.close()


# ------------------------------------------------------------------ independent references
def quantized(q: np.ndarray) -> np.ndarray:
    return (np.array(raw_ticks(q)) - 2048) / (4096 / (2 * np.pi))


def model_at(q: np.ndarray) -> dict:
    return ROBOT.evaluate(q)


def scipy_gains(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """K from scipy's CARE on eqs. (21)-(26) built here (JSK order), and the sec. 4 per-rotor
    (roll, pitch, yaw, z) x (P, I, D) gains before clampGain."""
    o = model_at(q)
    m, inertia, qbar = o["mass"], o["inertia"], o["allocation_bar"]
    a, b = hover_state_model(m, inertia, qbar)
    p = scipy.linalg.solve_continuous_are(a, b, W1, np.eye(4))
    k = -b.T @ p
    gains = np.zeros((4, 4, 3))
    for axis, j in ((0, 1), (1, 2), (2, 3), (3, 0)):  # roll, pitch, yaw, z <- state pair j
        gains[:, axis] = np.column_stack([-k[:, 2 * j], k[:, 8 + j], -k[:, 2 * j + 1]])
    return k, gains


def wire_terms(gains: np.ndarray) -> np.ndarray:
    """clampGain (sec. 4) then x1000 truncation: roll p/i/d, pitch p/i/d, yaw d."""
    g = gains.copy()
    for axis, term in ((0, 0), (0, 2), (1, 0), (1, 2), (2, 2)):
        mx = np.abs(g[:, axis, term]).max()
        if mx > 32.767:
            g[:, axis, term] *= 32.767 / mx
    cols = [g[:, 0, 0], g[:, 0, 1], g[:, 0, 2], g[:, 1, 0], g[:, 1, 1], g[:, 1, 2], g[:, 2, 2]]
    return np.clip(np.trunc(np.column_stack(cols) * 1000), -32768, 32767)


def gains_of(msg) -> np.ndarray:
    names = ("roll_p", "roll_i", "roll_d", "pitch_p", "pitch_i", "pitch_d", "yaw_d")
    return np.array([[getattr(m, n) for n in names] for m in msg.motors], dtype=float)


def arm_and_fly(rig: Rig, t: float, q: np.ndarray, until: float) -> float:
    rig.servo_q = q
    rig.node.set_target([0.0, 0.0, 1.0], 0.0)
    rig.node.set_mocap([0.0, 0.0, 1.0], [0.0, 0.0, 0.0], 0.0)
    rig.node.arm()

    def each(t):
        rig.node.set_mocap([0.0, 0.0, 1.0], [0.0, 0.0, 0.0], 0.0)

    return rig.run(t, until, each=each)


# --------------------------------------------------------------------------------- tests
def test_handshake_rates_types_md5(rig: Rig) -> None:
    t = rig.run(0.0, 0.5)
    assert rig.spinal.configured
    node = rig.node
    spinal_subs = {ep.name: ep for ep in rig.spinal.subscribers}
    for topic, typ in (
        ("uav_info", "spinal/UavInfo"),
        ("motor_info", "spinal/PwmInfo"),
        ("flight_config_cmd", "spinal/FlightConfigCmd"),
        ("four_axes/command", "spinal/FourAxisCommand"),
        ("rpy/gain", "spinal/RollPitchYawTerms"),
        ("p_matrix_pseudo_inverse_inertia", "spinal/PMatrixPseudoInverseWithInertia"),
        ("servo/target_states", "spinal/ServoControlCmd"),
    ):
        remote = node.session.outbound[topic]  # accepted by the server only if md5s agree
        assert remote.type == typ == spinal_subs[topic].type
        assert spinal_subs[topic].md5 == MD5["messages"][typ]
    rig.node.set_joint_targets(np.zeros(6))
    t = arm_and_fly(rig, t, np.zeros(10), 3.0)
    assert node.state.value == "armed"
    for topic in (
        "four_axes/command",
        "rpy/gain",
        "p_matrix_pseudo_inverse_inertia",
        "servo/target_states",
    ):
        assert rig.count(topic, 2.0, 3.0) == 40, topic  # 40 Hz over one simulated second
    infos = [tt for tt, _ in rig.by_topic["uav_info"]]
    assert 1 <= len(infos) <= 10 and rig.by_topic["motor_info"]
    assert all(b - a >= 0.1 - 1e-9 for a, b in itertools.pairwise(infos))
    pwm = rig.by_topic["motor_info"][0][1]
    assert (pwm.min_pwm, pwm.max_pwm, pwm.pwm_conversion_mode) == (
        pytest.approx(0.59),
        pytest.approx(0.9375),
        0,
    )
    assert pwm.motor_info[0].polynominal[:3] == pytest.approx(
        [12.3593793002, -6.627443098, 0.07983707], rel=1e-6
    )
    uav = rig.by_topic["uav_info"][0][1]
    assert (uav.motor_num, uav.uav_model) == (4, 16)
    # the node takes in what Spinal publishes
    assert node.counts["rx:imu"] > 0 and node.counts["rx:servo/states"] > 0
    assert node.battery_voltage == pytest.approx(24.5)


def test_arming_waits_for_infos_and_ack(rig: Rig) -> None:
    t = rig.run(0.0, 0.3)
    # one announcement after the handshake (so Spinal accepts gains before arming)
    assert len(rig.by_topic["uav_info"]) == len(rig.by_topic["motor_info"]) == 1
    rig.auto_ack = False
    t_arm = t
    rig.node.arm()
    t = rig.run(t, 1.6)
    cmds = rig.by_topic["flight_config_cmd"]
    assert cmds and all(m.cmd == 0 for _, m in cmds)
    infos = [tt for topic in ("uav_info", "motor_info") for tt, _ in rig.by_topic[topic]]
    after_arm = [tt for tt in infos if tt >= t_arm]
    assert len(after_arm) >= 2 and cmds[0][0] > min(after_arm)  # ARM_ON after the infos
    assert len(cmds) >= 2  # re-sent without an ack
    assert rig.node.state.value == "starting" and not rig.by_topic["four_axes/command"]
    rig.node.set_mocap([0, 0, 0], [0, 0, 0], 0.0)
    rig.publish("flight_config_ack", REG.msg("std_msgs/UInt8").new(data=0))
    t = rig.run(t, t + 0.1, each=lambda _t: rig.node.set_mocap([0, 0, 0], [0, 0, 0], 0.0))
    assert rig.node.state.value == "armed"
    n_cmd, n_info = len(cmds), len(rig.by_topic["uav_info"])
    t = rig.run(t, t + 0.5, each=lambda _t: rig.node.set_mocap([0, 0, 0], [0, 0, 0], 0.0))
    assert len(rig.by_topic["flight_config_cmd"]) == n_cmd  # no more ARM_ON
    assert len(rig.by_topic["uav_info"]) == n_info  # infos only while starting
    assert rig.count("four_axes/command", t - 0.5, t) == 20
    # disarm: ARM_OFF until ack 1
    rig.node.disarm()
    t = rig.run(t, t + 0.1)
    assert rig.by_topic["flight_config_cmd"][-1][1].cmd == 1
    rig.publish("flight_config_ack", REG.msg("std_msgs/UInt8").new(data=1))
    t = rig.run(t, t + 0.1)
    assert rig.node.state.value == "idle"
    n = len(rig.by_topic["four_axes/command"])
    rig.run(t, t + 0.2)
    assert len(rig.by_topic["four_axes/command"]) == n  # no commands while disarmed


def test_force_landing_on_demand_and_spinal_failsafe(rig: Rig) -> None:
    t = arm_and_fly(rig, 0.0, np.zeros(10), 1.0)
    rig.node.force_landing()
    t = rig.run(t, t + 0.1)
    assert rig.by_topic["flight_config_cmd"][-1][1].cmd == 2
    assert rig.node.state.value == "landing"
    rig.node.disarm()
    t = rig.run(t, t + 0.1)
    rig.node.arm()
    t = arm_and_fly(rig, t, np.zeros(10), t + 0.5)
    assert rig.node.state.value == "armed"
    rig.publish("flight_config_ack", REG.msg("std_msgs/UInt8").new(data=2))  # Spinal fail-safe
    rig.run(t, t + 0.1)
    assert rig.node.state.value == "landing"
    assert rig.node.arming.counts["spinal_force_landing"] == 1


def test_integration_on_after_take_off_height(rig: Rig) -> None:
    rig.servo_q = np.zeros(10)
    t = rig.run(0.0, 0.3)
    rig.node.set_target([0.0, 0.0, 1.0], 0.0)
    rig.node.arm()
    z = {"v": 0.0}
    z_at: dict[float, float] = {}

    def each(tt):
        z["v"] += 0.002  # climbing 8 cm/s
        z_at[round(tt, 6)] = z["v"]
        rig.node.set_mocap([0.0, 0.0, z["v"]], [0.0, 0.0, 0.08], 0.0)

    rig.run(t, t + 1.5, each=each)
    cmds = [(tt, m.cmd) for tt, m in rig.by_topic["flight_config_cmd"]]
    on = [tt for tt, c in cmds if c == 160]
    armed_at = next(tt for tt, c in cmds if c == 0)
    assert len(on) == 1 and on[0] > armed_at
    # z at the first armed tick (ack arrives one tick after ARM_ON)
    z_arm = z_at[round(armed_at + DT, 6)]
    assert z_at[round(on[0], 6)] - z_arm >= 0.05 - 1e-9
    assert z_at[round(on[0] - DT, 6)] - z_arm < 0.05


@pytest.mark.parametrize("q", [np.zeros(10), Q_BENT])
def test_gains_equal_scipy_at_present_q(rig: Rig, q: np.ndarray) -> None:
    rig.servo_q = q
    rig.run(0.0, 0.6)
    qq = quantized(q)
    assert np.allclose(rig.node.present_q, qq)
    _, gains = scipy_gains(qq)
    got = gains_of(rig.by_topic["rpy/gain"][-1][1])
    assert np.abs(got - wire_terms(gains)).max() <= 1  # one count: truncation at a boundary


def test_gains_follow_servo_states(rig: Rig) -> None:
    rig.servo_q = np.zeros(10)
    t = rig.run(0.0, 0.5)
    before = gains_of(rig.by_topic["rpy/gain"][-1][1])
    rig.servo_q = Q_BENT
    rig.run(t, t + 0.2)
    after = gains_of(rig.by_topic["rpy/gain"][-1][1])
    _, g_bent = scipy_gains(quantized(Q_BENT))
    assert np.abs(after - wire_terms(g_bent)).max() <= 1
    assert np.abs(after - before).max() > 100  # the model really moved


def test_lqi_failure_keeps_last_good_gains(rig: Rig) -> None:
    """In the straight vertical posture Q̄ loses rank (docs/model.md: ρ = 0), the LQI problem
    is not stabilisable: the last good gains stay on the wire, counted; commands stay finite."""
    from rdm.model import VERTICAL_Q

    t = arm_and_fly(rig, 0.0, np.zeros(10), 0.5)
    good = gains_of(rig.by_topic["rpy/gain"][-1][1])
    n = len(rig.by_topic["rpy/gain"])
    rig.servo_q = np.asarray(VERTICAL_Q, dtype=float)
    rig.run(t, t + 0.5, each=lambda _t: rig.node.set_mocap([0, 0, 1], [0, 0, 0], 0.0))
    o = model_at(quantized(rig.servo_q))
    assert np.linalg.matrix_rank(o["allocation_bar"], tol=1e-9) < 4
    assert rig.node.control.counts["lqi_failed"] >= 15
    assert rig.node.counts["gains_kept"] == rig.node.control.counts["lqi_failed"]
    later = rig.by_topic["rpy/gain"][n + 2 :]
    assert len(later) >= 15 and all(np.array_equal(gains_of(m), good) for _, m in later)
    for _, m in rig.by_topic["four_axes/command"]:
        assert np.all(np.isfinite(m.base_thrust)) and np.all(np.isfinite(m.angles))


def test_p_matrix_equals_numpy_pinv(rig: Rig) -> None:
    rig.servo_q = Q_BENT
    rig.run(0.0, 0.5)
    msg = rig.by_topic["p_matrix_pseudo_inverse_inertia"][-1][1]
    o = model_at(quantized(Q_BENT))
    pinv = np.linalg.pinv(o["allocation_bar"])
    got = np.array([[u.r, u.p, u.y] for u in msg.pseudo_inverse])
    i = o["inertia"]
    inertia = np.array([i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[1, 2], i[0, 2]])
    for value, wire in ((pinv[:, 1:4] * 1000, got), (inertia * 1000, np.array(msg.inertia))):
        # x1000 truncated toward zero (the C++ int16 cast), exactly: only a value within
        # 1e-6 count of an integer may differ by the pseudo-inverse's last bits
        want = np.clip(np.trunc(value), -32768, 32767)
        clear = np.abs(value - np.round(value)) > 1e-6
        np.testing.assert_array_equal(wire[clear], want[clear])
        assert np.abs(wire - want).max() <= 1
    # the payload tells truncation from rounding: some terms have a fraction above one half
    frac = np.abs(pinv[:, 1:4] * 1000) % 1.0
    assert np.count_nonzero((frac > 0.5) & (frac < 1 - 1e-6)) >= 2


def test_to_wire_golden_values() -> None:
    """x1000, truncated toward zero and saturated to int16, written out by hand."""
    golden = [
        (0.0019, (1, False)),
        (-0.0019, (-1, False)),
        (1.9999, (1999, False)),
        (-7.9996, (-7999, False)),
        (0.0009, (0, False)),
        (32.7679, (32767, False)),
        (40.0, (32767, True)),
        (-40.0, (-32768, True)),
    ]
    for value, wire in golden:
        assert to_wire(value) == wire, value


def test_command_matches_eqs_30_32_and_z_pid() -> None:
    """First armed tick with a mocap error: roll/pitch (eqs. 30-32), yaw P-I term, base
    thrust (z P-I-D + hover feed-forward) vs numpy from scipy's gains."""
    rig = make_rig()
    try:
        rig.servo_q = Q_FLY
        t = rig.run(0.0, 0.5)
        p, v, yaw = np.array([0.1, -0.05, 0.98]), np.array([0.02, 0.03, -0.02]), 0.1
        tp, tyaw = np.array([0.3, 0.1, 1.0]), 0.25
        rig.node.set_target(tp, tyaw)
        rig.node.arm()
        armed_at = []

        def each(tt):
            rig.node.set_mocap(p, v, yaw)
            if rig.node.state.value == "armed" and not armed_at:
                armed_at.append(tt)

        rig.run(t, t + 0.3, each=each)
        first = rig.by_topic["four_axes/command"][0][1]
        qq = quantized(Q_FLY)
        o = model_at(qq)
        _, gains = scipy_gains(qq)
        # eq. (30), one step from zero integral (rectangle rule), ė = v_d − v
        ex, ey = tp[0] - p[0], tp[1] - p[1]
        ax = 4.6 * ex + 1.5 * ex * DT + 7.0 * (0 - v[0])
        ay = 7.0 * ey + 0.005 * ey * DT + 10.5 * (0 - v[1])
        roll = 0.0 * (ax * math.sin(tyaw) - ay * math.cos(tyaw)) / G  # k_φd = 0
        pitch = 1.0 * (ax * math.cos(tyaw) + ay * math.sin(tyaw)) / G
        e_yaw = tyaw - yaw
        imax = int(np.argmax(gains[:, 2, 2]))
        yaw_term = gains[imax, 2, 0] * e_yaw + gains[imax, 2, 1] * e_yaw * DT
        hover = np.linalg.lstsq(o["allocation_bar"], [o["mass"] * G, 0, 0, 0], rcond=None)[0]
        ez, ezd = tp[2] - p[2], 0 - v[2]
        base = hover + gains[:, 3, 0] * ez + gains[:, 3, 1] * ez * DT + gains[:, 3, 2] * ezd
        assert first.angles[0] == pytest.approx(roll, abs=1e-6)
        assert first.angles[1] == pytest.approx(pitch, rel=1e-5)
        assert first.angles[2] == pytest.approx(yaw_term, rel=1e-5)
        assert np.all((base > 0) & (base < 20))  # inside the clip: the law itself is compared
        assert np.allclose(first.base_thrust, base, rtol=1e-5, atol=1e-5)
    finally:
        rig.close()


def test_vectoring_targets_match_eqs_33_36_and_point_thrust() -> None:
    """Servo targets of α_i, β_i: eqs. (33)-(36) in numpy with R_i = (C<-L_i)ᵀ, and the model
    at those angles points each unit's thrust along n_va (settles the eq. 36 frame)."""
    rig = make_rig()
    try:
        q = np.array([0.2, 0.35, 0.3, -0.25, 0.2, 0.1, 0.0, 0.0, 0.0, 0.0])
        rig.servo_q = q
        rig.node.set_joint_targets(q)
        p, v, tp, tyaw = np.zeros(3), np.zeros(3), np.array([0.4, -0.3, 0.0]), 0.2
        rig.node.set_target(tp, tyaw)
        rig.node.arm()
        rig.run(0.0, 0.6, each=lambda _t: rig.node.set_mocap(p, v, tyaw))
        qq = quantized(q)
        o = model_at(qq)
        ex, ey = tp[0], tp[1]
        k = len(rig.by_topic["four_axes/command"])  # position steps taken
        ax = 4.6 * ex + 1.5 * ex * DT * k
        ay = 7.0 * ey + 0.005 * ey * DT * k
        a_par = ax * math.cos(tyaw) + ay * math.sin(tyaw)
        a_perp = ax * math.sin(tyaw) - ay * math.cos(tyaw)
        msg = rig.by_topic["servo/target_states"][-1][1]
        by_index = dict(zip(msg.index, msg.angles, strict=True))
        raw = [by_index[i] for i in rig.node.config.servo_map.servo_index]  # joint order
        got = (np.array(raw) - 2048) / (4096 / (2 * np.pi))
        q_cmd = qq.copy()
        for i, (k_th, k_ph) in enumerate(((0.0, 1.0), (0.0, 0.0))):
            r_ci = o["unit_parent_rotations"][i]
            # heading-frame lateral demand -a_perp: the thrust leans toward it (docs/lqi.md)
            n = r_ci.T @ np.array([k_th * a_par, -k_ph * a_perp, G])
            n /= np.linalg.norm(n)
            alpha = math.atan(-n[1] / n[2])
            beta = math.atan(n[0] / (-n[1] * math.sin(alpha) + n[2] * math.cos(alpha)))
            ja, jb = 6 + 2 * i, 7 + 2 * i
            assert got[ja] == pytest.approx(alpha, abs=1e-3)
            assert got[jb] == pytest.approx(beta, abs=1e-3)
            q_cmd[ja], q_cmd[jb] = alpha, beta
        assert abs(got[6]) > 0.05  # the y error really tilts apparatus 1
        # geometry: at the commanded angles the model's rotors point along n_va (CoG axes)
        o2 = model_at(q_cmd)
        for i, rotors in enumerate(((0, 1), (2, 3))):
            want = np.array([0.0, -[1.0, 0.0][i] * a_perp, G])  # toward the demand
            want /= np.linalg.norm(want)
            for r in rotors:
                assert np.allclose(o2["rotor_directions"][r], want, atol=1e-9)
        assert np.allclose(got[:6], qq[:6], atol=2e-3)  # joints follow their targets
    finally:
        rig.close()


def test_default_servo_map_is_the_can_table_order(tmp_path) -> None:
    """Spinal numbers servos by their place in its CAN table: Neurons by slave id, then the
    servos on each (docs/sim.md "Plant bridge": 1 = foot unit alpha1, beta1; 2 = q1-q3;
    3 = arm unit alpha2, beta2; 4 = q4-q6). The node's default map must follow it, not joint
    order."""
    from rdm.link.uart_pipe import open_inproc_uart
    from rdm.nodes.onboard import OnboardNode

    table = ["alpha1", "beta1", "q1", "q2", "q3", "alpha2", "beta2", "q4", "q5", "q6"]
    dev, host = open_inproc_uart(tmp_path, "spinal", ".bin")
    try:
        node = OnboardNode(host, None)
        names = list(node.robot.joint_names)
        assert node.config.servo_map.servo_index == tuple(table.index(j) for j in names)
    finally:
        dev.close()
        host.close()


def test_position_gains_switched_at_run_time() -> None:
    """ControlPipeline.set_position_gains: the next step uses the new x PID (eq. 30 from a
    zero integral, numpy) and the old integral is gone."""
    from rdm.nodes.onboard_control import ControlPipeline, Setpoint, State

    pipe = ControlPipeline(ROBOT, OnboardConfig())
    q = np.zeros(len(ROBOT.joint_names))
    assert pipe.update_model(q) and pipe.synthesize()
    p, v = np.array([0.1, 0.0, 1.0]), np.array([0.05, 0.0, 0.0])
    state = State(p, v, 0.0)
    target = Setpoint(np.array([0.4, 0.0, 1.0]), np.zeros(3), 0.0)
    for _ in range(20):  # wind up Table V's integral
        pipe.step(state, target, q, None, DT)
    assert pipe.position.integral[0] > 0.1
    pipe.set_position_gains({"x_pid": (1.0, 0.1, 2.0)})
    assert np.allclose(pipe.position.integral, 0.0)
    cmd = pipe.step(state, target, q, None, DT)
    ex = 0.4 - 0.1
    ax = 1.0 * ex + 0.1 * ex * DT + 2.0 * (0.0 - v[0])
    assert cmd is not None
    assert cmd.angles[1] == pytest.approx(ax / G, rel=1e-9)
    assert pipe.counts["position_gains_set"] == 1
