"""The onboard node refuses what Spinal could not have measured, and holds only what the arm can
reach:

* ``imu`` plausibility (``Monitors.imu_plausible``) on hand-made readings: each range at its
  limit and just past it, the gyro change and the attitude rotation against their limits x the
  time since the last plausible reading (the angle between two attitudes from scipy's
  ``Rotation``, not from our quaternion code), a sign-flipped quaternion (the same attitude)
  taken, the comparison always against the last plausible reading, one log line per run of
  refusals, every refusal counted;
* the node's two ``imu`` paths (payload and decoded message) refuse a reading alike and keep the
  last plausible one; sustained implausible readings trip the stale-IMU monitor
  (``spinal_silent``) and land, against the firmware-exact Spinal core;
* the joint hold: a present angle outside a joint limit (inside the wire's int16 range) is held
  at the limit of the shipped URDF (read with ElementTree), on the first full reading and on a
  ``joint_tracking`` trip; ``set_joint_targets`` refuses targets outside the limits.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from fed_byte_link import FedByteLink
from onboard_rig import REG
from scipy.spatial.transform import Rotation
from urdf_limits import urdf_limits

from rdm.nodes.onboard import OnboardNode
from rdm.nodes.onboard_config import OnboardConfig
from rdm.nodes.onboard_monitors import MonitorLimits, Monitors
from rdm.nodes.onboard_operator import JOINT_LIMIT_SLACK
from rdm.protocol.rosserial.events import MessageReceived

IMU = REG.msg("spinal/Imu")
LEVEL = [0.0, 0.0, 0.0, 1.0]
G = [0.0, 0.0, 9.8]
ZERO = [0.0, 0.0, 0.0]


def fresh() -> Monitors:
    return Monitors(MonitorLimits(), cells=6)


# ------------------------------------------------------------------ ranges and the quaternion


@pytest.mark.parametrize(
    ("acc", "gyro", "quat", "ok"),
    [
        ([86.3, -86.3, 0.0], ZERO, LEVEL, True),  # +-8 g full scale and 10 %
        ([86.31, 0.0, 9.8], ZERO, LEVEL, False),
        ([0.0, -500.0, 9.8], ZERO, LEVEL, False),  # the imu-spikes fault's outlier
        ([0.0, float("nan"), 9.8], ZERO, LEVEL, False),
        (G, [38.4, -38.4, 0.0], LEVEL, True),  # +-2000 deg/s and 10 %
        (G, [0.0, 0.0, -38.41], LEVEL, False),
        (G, None, LEVEL, True),  # a gyro that is not finite is not used, nor judged
        (G, ZERO, [0.0, 0.0, 0.0, 1.001], True),
        (G, ZERO, [0.0, 0.0, 0.0, 1.0011], False),
        (G, ZERO, [0.0, 0.0, 0.6, 0.6], False),  # norm 0.85
    ],
)
def test_a_first_reading_is_judged_by_the_ranges_and_the_norm(acc, gyro, quat, ok) -> None:
    m = fresh()
    assert m.imu_plausible(0.0, acc, gyro, quat) is ok
    assert m.counts["imu_implausible"] == (0 if ok else 1)


# ------------------------------------------------------------------ jumps against the time


@pytest.mark.parametrize(
    ("dt", "jump", "ok"),
    [
        (0.0, 9.99, True),  # two readings in one tick: Spinal's 5 ms interval at least
        (0.0, 10.01, False),  # 2000 rad/s^2 x 5 ms = 10 rad/s
        (0.003, 10.01, False),
        (0.02, 39.9 - 2.0, True),  # 2000 x 20 ms = 40, within the range from -2
        (0.02, 36.0, True),
    ],
)
def test_the_gyro_change_is_bounded_by_the_time_since_the_last_plausible(dt, jump, ok) -> None:
    m = fresh()
    assert m.imu_plausible(1.0, G, [-2.0, 0.0, 0.0], LEVEL)
    assert m.imu_plausible(1.0 + dt, G, [-2.0 + jump, 0.0, 0.0], LEVEL) is ok


@pytest.mark.parametrize(
    ("dt", "angle", "ok"),
    [
        (0.0, 0.30, True),  # 61 rad/s x 5 ms = 0.305 rad
        (0.0, 0.31, False),
        (0.01, 0.60, True),  # x 10 ms = 0.61 rad
        (0.01, 0.62, False),
    ],
)
def test_the_attitude_turn_is_bounded_by_the_time_since_the_last_plausible(dt, angle, ok) -> None:
    start = Rotation.from_euler("xyz", [0.3, -0.2, 1.0])
    turn = Rotation.from_rotvec(angle * np.array([1.0, 2.0, -2.0]) / 3.0)
    q0, q1 = start.as_quat(), (turn * start).as_quat()  # x, y, z, w
    assert (turn * start * start.inv()).magnitude() == pytest.approx(angle)
    m = fresh()
    assert m.imu_plausible(2.0, G, ZERO, list(q0))
    assert m.imu_plausible(2.0 + dt, G, ZERO, list(q1)) is ok


def test_a_sign_flipped_quaternion_is_the_same_attitude() -> None:
    q = Rotation.from_euler("xyz", [0.1, 0.2, 2.5]).as_quat()
    m = fresh()
    assert m.imu_plausible(0.0, G, ZERO, list(q))
    assert m.imu_plausible(0.005, G, ZERO, list(-q))


def test_refusals_compare_with_the_last_plausible_reading_and_log_once_per_run(
    caplog,
) -> None:
    m = fresh()
    caplog.set_level(logging.WARNING, logger="rdm.onboard")
    assert m.imu_plausible(0.0, G, ZERO, LEVEL)
    # three spikes in a row: each one against the reading at t = 0, not the spike before
    assert not m.imu_plausible(0.005, G, [30.0, 0.0, 0.0], LEVEL)
    assert not m.imu_plausible(0.010, G, [30.0, 0.0, 0.0], LEVEL)  # 20 allowed in 10 ms
    assert not m.imu_plausible(0.015, [0.0, 0.0, 200.0], ZERO, LEVEL)
    assert m.imu_refusing
    assert m.imu_plausible(0.020, G, [1.0, 0.0, 0.0], LEVEL)  # back next to it: taken
    assert not m.imu_refusing
    assert not m.imu_plausible(0.025, G, [30.0, 0.0, 0.0], LEVEL)
    assert m.counts["imu_implausible"] == 4
    events = [e for e in m.events if e["monitor"] == "imu_implausible"]
    assert [e["t"] for e in events] == [0.005, 0.025]  # the first of each run
    assert len(caplog.records) == 2 and "gyro jumped 30 rad/s" in caplog.records[0].getMessage()


def test_a_refused_reading_leaves_the_reference_where_it_was() -> None:
    """Far from a refused spike, the growing allowance takes the sensor back: 30 rad/s off
    the last plausible reading after 15 ms (2000 x 15 ms = 30)."""
    m = fresh()
    assert m.imu_plausible(0.0, G, [30.0, 0.0, 0.0], LEVEL)
    assert not m.imu_plausible(0.005, G, ZERO, LEVEL)
    assert not m.imu_plausible(0.0149, G, ZERO, LEVEL)
    assert m.imu_plausible(0.0151, G, ZERO, LEVEL)


# ------------------------------------------------------------------ in the node


def _payload(acc, gyro, quat) -> bytes:
    return IMU.encode(IMU.new(acc=acc, gyro=gyro, quaternion=quat))


@pytest.mark.parametrize("path", ["payload", "decoded"])
def test_the_node_keeps_the_last_plausible_reading(path) -> None:
    node = OnboardNode(FedByteLink())

    def feed(t, acc, gyro, quat):
        node._now = t
        p = _payload(acc, gyro, quat)
        if path == "payload":
            node._on_imu_payload(p)
        else:
            node._on_event(MessageReceived("imu", "spinal/Imu", 101, IMU.decode(p)))

    q = list(Rotation.from_euler("xyz", [0.0, 0.0, 1.0]).as_quat())
    feed(1.0, G, [0.1, 0.0, 0.0], q)
    assert node._imu_at == 1.0 and node.imu_euler[2] == pytest.approx(1.0, abs=1e-6)
    feed(1.005, [0.0, 500.0, 9.8], [0.1, 0.0, 0.0], q)  # the accelerometer outlier
    feed(1.010, G, [0.1, 0.0, 0.0], LEVEL)  # the attitude turned 1 rad in 10 ms (0.61)
    assert node._imu_at == 1.0
    assert node.imu_euler[2] == pytest.approx(1.0, abs=1e-6)
    assert node._imu_acc == pytest.approx(G)
    assert node.monitors.counts["imu_implausible"] == 2
    feed(1.015, G, [0.2, 0.0, 0.0], q)
    assert node._imu_at == 1.015 and node.imu_gyro[0] == pytest.approx(0.2)


def test_sustained_implausible_imu_trips_the_stale_imu_monitor_and_lands() -> None:
    from test_onboard_flight_safety import Flight

    f = Flight()
    try:
        f.hover_at(1.0)
        assert f.node.monitors.counts["spinal_silent"] == 0
        # a quaternion 2 % off unit length on every reading from now (the rig's plant
        # writes the accelerometer)
        f.rig.imu_quaternion = [0.0, 0.0, 0.0, 1.02]
        t0 = f.t
        f.run(0.075)  # 75 ms: refused, counted, not yet stale
        # the rig's Spinal publishes after the node's tick: two readings taken in three ticks
        assert f.node.monitors.counts["imu_implausible"] == 2
        assert f.node.monitors.counts["spinal_silent"] == 0
        f.run(0.1)
        assert f.node.monitors.counts["spinal_silent"] == 1
        trip = next(e for e in f.node.monitors.events if e["monitor"] == "spinal_silent")
        assert 0.1 < trip["t"] - t0 <= 0.1 + 0.025 + 1e-9
        assert trip["reason"].startswith("no plausible imu for")
        assert f.node.flight.mode.value == "land"
        assert f.node.counts["spinal_silent_land"] == 1
        # one log line and one event for the whole run of refusals
        events = [e for e in f.node.monitors.events if e["monitor"] == "imu_implausible"]
        assert len(events) == 1
    finally:
        f.close()


# ------------------------------------------------------------------ the joint hold


def _reading(node: OnboardNode, q: np.ndarray):
    """A ``spinal/ServoStates`` of the joint angles ``q`` through the node's servo map."""
    smap = node.config.servo_map
    unit, states = REG.msg("spinal/ServoState"), REG.msg("spinal/ServoStates")
    servos = [
        unit.new(index=smap.servo_index[j], angle=smap.to_raw(j, float(q[j])))
        for j in range(node.robot.n_q)
    ]
    return states.new(servos=servos)


def test_the_first_full_reading_is_held_inside_the_joint_limits() -> None:
    node = OnboardNode(FedByteLink())
    limits = urdf_limits()
    names = list(node.robot.joint_names)
    q = np.zeros(node.robot.n_q)
    q[names.index("q1")] = 2.0  # beyond q1's limit, well inside the int16 wire range
    q[names.index("q4")] = -1.9
    node._on_servo_states(_reading(node, q))
    assert node.present_q[names.index("q1")] == pytest.approx(2.0, abs=2e-3)  # as read
    held = node.joint_targets
    assert held is not None
    assert held[names.index("q1")] == limits["q1"][1]
    assert held[names.index("q4")] == limits["q4"][0]
    for j, name in enumerate(names):
        lo, hi = limits[name]
        assert lo <= held[j] <= hi
    assert node.counts["joint_hold_clamped"] == 1


def test_a_joint_tracking_trip_holds_inside_the_joint_limits() -> None:
    node = OnboardNode(FedByteLink())
    limits = urdf_limits()
    names = list(node.robot.joint_names)
    lim = node.config.monitors
    q = np.zeros(node.robot.n_q)
    node._on_servo_states(_reading(node, q))
    q[names.index("q2")] = 1.8  # read beyond q2's limit, far from its goal (0)
    node.present_q[:] = q
    node._seen[:] = True
    node.last_servo_goals = [0.0] * node.robot.n_q
    node._monitor_joints(10.0)
    node._monitor_joints(10.0 + lim.joint_tracking_s)
    assert node.monitors.counts["joint_tracking"] == 1 and node.counts["joints_held"] == 1
    assert node.joint_targets[names.index("q2")] == limits["q2"][1]
    assert node.counts["joint_hold_clamped"] == 1


def test_set_joint_targets_refuses_targets_outside_the_joint_limits() -> None:
    node = OnboardNode(FedByteLink(), config=OnboardConfig())
    lo, hi = urdf_limits()["q3"]
    q = np.zeros(6)
    q[2] = hi
    assert node.set_joint_targets(q)
    q[2] = math.nextafter(hi + JOINT_LIMIT_SLACK, math.inf)
    assert not node.set_joint_targets(q)
    q[2] = lo - 0.01
    assert not node.set_joint_targets(q)
    assert node.counts["joint_targets_invalid"] == 2
    assert node.joint_targets[2] == hi  # the accepted one kept
