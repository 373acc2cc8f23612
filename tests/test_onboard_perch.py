"""OnboardNode perching mode and bad input, over pty pairs (rosserial Spinal peer + a Leptrino
sensor-side encoder), simulated time. λ_perch is compared with an independently driven
PerchController fed the same filtered wrench and a numpy Q̄_foot."""

from __future__ import annotations

import numpy as np
import pytest
from onboard_rig import REG, Rig

from rdm.control.perch import PerchController
from rdm.model import Robot
from rdm.nodes.onboard import OnboardNode
from rdm.nodes.onboard_config import OnboardConfig
from rdm.nodes.onboard_monitors import MonitorLimits
from rdm.protocol import leptrino as lp

pytestmark = pytest.mark.timeout(300)

ROBOT = Robot.default()
RATED = np.array([150.0, 150.0, 300.0, 4.0, 4.0, 4.0])  # CFS034CA301U (paper Sec. VI-B)
Q_FLY = np.array([0.1, -0.1, 0.1, 0.2, 0.05, 0.0, 0.0, 0.0, 0.0, 0.0])
DT = 0.025


#: The rig's Spinal reports the servo angles a test sets, never the goals the node sends:
#: to the node's joint-tracking monitor that is a stuck servo. 7 rad is more than any joint
#: can be from its goal, so that monitor stays out of these tests (its own tests:
#: test_onboard_monitor_rules.py, the stuck-servo fault of test_fault_campaign.py).
RIG_MONITORS = MonitorLimits(joint_tracking_rad=7.0)


def make_rig(**cfg) -> Rig:
    cfg.setdefault("monitors", RIG_MONITORS)
    return Rig(lambda uart, f: OnboardNode(uart, f, ROBOT, config=OnboardConfig(**cfg)), foot=True)


def raw_of(w) -> tuple[int, ...]:
    return tuple(int(v) for v in np.round(np.asarray(w) * 10000 / RATED))


def numpy_foot_allocation(q: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Eqs. (8)-(9) about the foot origin from the model's rotor positions/directions (base at
    identity: world = foot frame, whose axes are the CoG frame's)."""
    o = ROBOT.evaluate(q)
    p, u = o["rotor_positions"], o["rotor_directions"]
    c = np.array([r["drag_to_thrust"] for r in ROBOT.rotors])
    sigma = np.array([r["spin"] for r in ROBOT.rotors])
    m = np.cross(p, u) - (c * sigma)[:, None] * u
    return np.vstack([u[:, 2], m.T]), o["allocation_bar"], o["mass"]


def fly(rig: Rig, t0: float, t1: float, mocap=None) -> float:
    def each(_t):
        if mocap is None:
            rig.node.set_mocap([0.0, 0.0, 1.0], [0.0, 0.0, 0.0], 0.0)
        else:
            mocap(_t)

    return rig.run(t0, t1, each=each)


def start(rig: Rig) -> float:
    rig.servo_q = Q_FLY
    rig.node.set_target([0.0, 0.0, 1.0], 0.0)
    rig.node.arm()
    return fly(rig, 0.0, 0.5)


def wrench_at(t: float) -> np.ndarray:
    return np.array([2.0, -1.0, 10.0 * min(1.0, t - 0.5), 0.1, -0.05, 0.2 * np.sin(3 * t)])


def test_perching_thrust_equals_independent_controller() -> None:
    rig = make_rig()
    try:
        rig.foot_raw = raw_of(wrench_at(0.5))
        t = start(rig)
        assert rig.foot_commands[0].command == lp.Command.DATA_START
        assert rig.node.state.value == "armed"
        rig.node.request_perch(True)
        records = []
        for k in range(60):
            tt = t + k * DT
            rig.node.set_mocap([0.0, 0.0, 1.0], [0.0, 0.0, 0.0], 0.0)
            rig.foot_raw = raw_of(wrench_at(tt))
            rig.step(tt)
            cmd = rig.node.last_command
            wire = rig.by_topic["four_axes/command"][-1]
            assert wire[0] == tt
            # the sample the node had at tick tt: the newest one written before it
            sample = [r for ts, r in rig.foot_sent if ts < tt][-1]
            records.append((np.array(wire[1].base_thrust), cmd.flight_thrust, sample, cmd.perch))
        qq = rig.node.present_q
        qfoot, qbar, mass = numpy_foot_allocation(qq)
        ref = PerchController(40.0, 1.0, rotor_thrust_max=[20.0] * 4)
        ref.reset(np.zeros(4))
        peak = 0.0
        for base, flight, sample, perch in records:
            w = np.asarray(sample, dtype=float) * RATED / 10000  # raw 10000 = rated
            r = ref.tick(w, qfoot, qbar, mass)
            assert perch.status == r.status
            assert np.allclose(base - flight, r.thrust, atol=2e-5), (base - flight, r.thrust)
            peak = max(peak, float(np.max(r.thrust)))
        assert peak > 1.0  # perching really adds thrust (foot rotors press the plate)
        assert rig.node.control.counts["perch_solved"] + rig.node.control.counts.get(
            "perch_almost_solved", 0
        ) == len(records)
        # leaving perching ramps λ_perch down by at most δλ = 5 N per tick
        rig.node.request_perch(False)
        last = records[-1][0] - records[-1][1]
        t = t + 60 * DT
        rig.node.set_mocap([0.0, 0.0, 1.0], [0.0, 0.0, 0.0], 0.0)
        rig.step(t)
        assert np.allclose(rig.node.last_command.perch_thrust, np.maximum(last - 5.0, 0), atol=1e-5)
    finally:
        rig.close()


def test_perching_qp_failure_visible_and_command_safe() -> None:
    rig = make_rig()
    try:
        rig.foot_raw = raw_of([0, 0, 5.0, 0, 0, 0])
        t = start(rig)
        rig.node.request_perch(True)
        t = fly(rig, t, t + 0.25)
        # |M_y| = 3.9 N m needs F_z >= 3.9 / H_x = 97.5 N: infeasible with two 20 N rotors
        rig.foot_raw = raw_of([0, 0, 5.0, 0.0, 3.9, 0])
        t = fly(rig, t, t + 0.5)
        status = rig.node.last_command.perch.status
        assert status not in ("solved", "almost_solved")
        assert rig.node.control.counts[f"perch_{status}"] > 0
        assert rig.node.status()["command"]["perch_status"] == status
        for _, msg in rig.by_topic["four_axes/command"]:
            b = np.array(msg.base_thrust)
            assert np.all(np.isfinite(b)) and np.all(np.isfinite(msg.angles))
            assert np.all((b >= 0) & (b <= 20.0))
        # stale sensor (stream stops): safe command, counted
        rig.foot_raw = None
        n = rig.node.control.counts["perch_no_foot_sample"]
        fly(rig, t, t + 0.3)
        assert rig.node.control.counts["perch_no_foot_sample"] > n
        assert np.all(np.isfinite(rig.by_topic["four_axes/command"][-1][1].base_thrust))
    finally:
        rig.close()


def test_bad_input_counted_never_nan_on_wire() -> None:
    rig = make_rig()
    try:
        rig.foot_raw = raw_of([0, 0, 3.0, 0, 0, 0])
        t = start(rig)
        node = rig.node
        # wrong-size / bad inputs from outside
        assert not node.set_joint_targets([0.1] * 4)
        assert not node.set_joint_targets("abcdef")
        assert not node.set_target([0.0, np.nan, 1.0])
        assert not node.set_target([0.0, 0.0, 1.0], yaw="north")
        assert not node.set_mocap([0, 0, 1], [0, 0, 0], yaw=float("inf"))
        assert not node.set_trajectory([(1.0, np.zeros(10)), (0.5, np.zeros(10))])
        assert not node.set_trajectory([(1.0, np.zeros(7))])
        assert node.counts["joint_targets_invalid"] == 2
        assert node.counts["target_invalid"] == 2
        assert node.counts["trajectory_invalid"] == 2
        # servo states: an unknown index and a partial message
        rig.servo_extra = [(42, 100)]
        t = fly(rig, t, t + 0.1)
        assert node.counts["servo_unknown_index"] > 0
        rig.servo_extra = []
        before = node.counts["servo_states_partial"]
        rig.servo_q = None
        st = REG.msg("spinal/ServoState")
        rig.publish(
            "servo/states",
            REG.msg("spinal/ServoStates").new(servos=[st.new(index=1, angle=2048 + 100)]),
        )
        t = fly(rig, t, t + 0.05)
        assert node.counts["servo_states_partial"] == before + 1
        joint = node.config.servo_map.joint_of(1)  # Spinal index 1: beta1 (CAN table order)
        assert node.present_q[joint] == pytest.approx(100 * 2 * np.pi / 4096)
        # corrupted Leptrino bytes between good frames
        good = node.foot.counts["samples"]
        bad_bcc = bytearray(lp.encode_response(lp.ForceData((1, 2, 3, 4, 5, 6))))
        bad_bcc[-1] ^= 0x5A
        rig.foot_garbage = b"\x00\xffgarbage\x10\x02\x05\x10\x07" + bytes(bad_bcc)
        t = fly(rig, t, t + 0.1)
        fc = node.foot.counts
        assert fc["frame_bcc"] >= 1 and fc["frame_escape"] >= 1
        assert node.foot.parser.discarded_bytes >= 9
        assert fc["samples"] > good  # the stream recovers
        # NaN mocap: counted, command held, then FORCE_LANDING after 1 s without mocap
        held_from = len(rig.by_topic["four_axes/command"])
        t = fly(rig, t, t + 1.3, mocap=lambda _t: node.set_mocap([np.nan, 0, 1], [0, 0, 0], 0.0))
        assert node.counts["mocap_invalid"] == 52 + 1
        assert node.counts["command_held"] > 30
        cmds = [m for _, m in rig.by_topic["four_axes/command"][held_from + 9 :]]
        assert all(list(c.base_thrust) == list(cmds[0].base_thrust) for c in cmds)
        assert rig.by_topic["flight_config_cmd"][-1][1].cmd == 2
        assert node.counts["mocap_lost_force_landing"] == 1
        for _, msg in rig.by_topic["four_axes/command"]:
            assert np.all(np.isfinite(msg.base_thrust)) and np.all(np.isfinite(msg.angles))
        for _, msg in rig.by_topic["rpy/gain"]:
            assert len(msg.motors) == 4
    finally:
        rig.close()


def _servo_goals(rig: Rig, k: int = -1) -> tuple[float, np.ndarray]:
    """(time, joint-order angles) of the k-th ``servo/target_states`` the node sent."""
    t, msg = rig.by_topic["servo/target_states"][k]
    by_index = dict(zip(msg.index, msg.angles, strict=True))
    raw = [by_index[i] for i in rig.node.config.servo_map.servo_index]
    return t, (np.array(raw) - 2048) * 2 * np.pi / 4096


def test_trajectory_interpolated_into_servo_targets() -> None:
    rig = make_rig(vectoring=False)
    try:
        rig.servo_q = np.zeros(10)
        q_end = np.array([0.4, -0.2, 0.1, 0.3, 0.0, 0.2, 0.0, 0.1, 0.5, -0.1])
        assert rig.node.set_trajectory([(0.5, np.zeros(10)), (1.5, q_end)])
        rig.run(0.0, 1.0)
        _, msg = rig.by_topic["servo/target_states"][-1]
        assert sorted(msg.index) == list(range(10))  # every servo, once
        t, got = _servo_goals(rig)
        want = q_end * (t - 0.5) / 1.0
        assert np.allclose(got, want, atol=2e-3)
    finally:
        rig.close()


@pytest.mark.parametrize("lead", [0.1, 0.35])
def test_servo_goals_lead_the_trajectory_by_the_configured_time(lead: float) -> None:
    """``servo_lead_s``: the goals on the wire are the path ``lead`` s ahead of the node's
    clock (clamped to the path's last point), decoded from the bytes Spinal receives."""
    rig = make_rig(vectoring=False, servo_lead_s=lead)
    try:
        rig.servo_q = np.zeros(10)
        q_end = np.array([0.4, -0.2, 0.1, 0.3, 0.0, 0.2, 0.0, 0.1, 0.5, -0.1])
        assert rig.node.set_trajectory([(0.5, np.zeros(10)), (1.5, q_end)])
        rig.run(0.0, 1.0)
        t, got = _servo_goals(rig)
        want = q_end * np.clip((t + lead - 0.5) / 1.0, 0.0, 1.0)
        assert np.allclose(got, want, atol=2e-3)
        assert not np.allclose(got, q_end * (t - 0.5), atol=2e-2)  # not the plan at t
        rig.run(1.0, 1.6)  # past the end: the last point, held
        assert np.allclose(_servo_goals(rig)[1], q_end, atol=2e-3)
        assert rig.node.set_joint_targets(np.zeros(10))  # a fixed goal is sent as it is
        rig.run(1.6, 1.7)
        assert np.allclose(_servo_goals(rig)[1], 0.0, atol=2e-3)
    finally:
        rig.close()


@pytest.mark.parametrize("lead", [-0.01, float("nan"), 1.5])
def test_servo_lead_out_of_range_is_refused(lead: float) -> None:
    with pytest.raises(ValueError, match="servo_lead_s"):
        OnboardConfig(servo_lead_s=lead)


def test_perched_node_holds_position_and_altitude_loops() -> None:
    """Perched, a mocap error must neither tilt the attitude targets nor change the altitude
    thrust (eq. 20: λ_flight keeps the weight, λ_perch alone presses); flying, the same error
    does both. Compared with the node's own flying response, so the hold is what is seen."""
    rig = make_rig()
    try:
        rig.foot_raw = raw_of([0.0, 0.0, 10.0, 0.0, 0.0, 0.0])
        t = start(rig)
        off = lambda _t: rig.node.set_mocap([0.3, -0.2, 0.8], [0.1, 0.0, 0.0], 0.0)  # noqa: E731
        t = fly(rig, t, t + 0.2, mocap=off)
        flying = rig.node.last_command
        assert abs(flying.angles[1]) > 0.01  # θ_d from the x error
        rig.node.request_perch(True)
        t = fly(rig, t, t + 0.1, mocap=off)
        first = rig.node.last_command
        t = fly(rig, t, t + 0.5, mocap=off)
        held = rig.node.last_command
        assert held.angles[0] == 0.0 and held.angles[1] == 0.0
        np.testing.assert_allclose(held.flight_thrust, first.flight_thrust, atol=1e-9)
        assert not np.allclose(flying.flight_thrust, held.flight_thrust)  # z loop was live
        assert np.all(rig.node.control.position.integral == 0.0)
    finally:
        rig.close()
