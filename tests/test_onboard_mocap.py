"""The CoG state from a marker pose (rdm.nodes.onboard_mocap) against MuJoCo: the plant's own
CoG (``data.subtree_com``) for random joint angles, base poses and marker offsets; the velocity
filter against its first-order formula; the node's freshness check on the capture stamp."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rdm.model import Robot
from rdm.nodes.onboard import OnboardNode
from rdm.nodes.onboard_config import OnboardConfig
from rdm.nodes.onboard_mocap import CogEstimator, MocapConfig
from rdm.plant import Plant

ROBOT = Robot.default()


def marker_pose(base_p, base_q_wxyz, offset_p, offset_q_xyzw):
    w, x, y, z = base_q_wxyz
    r_base = Rotation.from_quat([x, y, z, w])
    r_marker = r_base * Rotation.from_quat(offset_q_xyzw)
    return np.asarray(base_p) + r_base.apply(offset_p), r_marker.as_quat()


@pytest.mark.parametrize("seed", range(4))
def test_cog_from_the_marker_pose_matches_mujoco(seed) -> None:
    rng = np.random.default_rng(seed)
    plant = Plant("rdm", seed=seed)
    q = rng.uniform(-0.8, 0.8, ROBOT.n_q)
    base_q = Rotation.from_rotvec(rng.normal(0, 0.4, 3)).as_quat()  # x, y, z, w
    base_wxyz = [base_q[3], *base_q[:3]]
    plant.reset(q, base_position=rng.uniform(-1, 1, 3), base_quaternion=base_wxyz)
    gt = plant.ground_truth()
    offset_p = tuple(rng.uniform(-0.1, 0.1, 3))
    offset_q = tuple(Rotation.from_rotvec(rng.normal(0, 1.0, 3)).as_quat())
    est = CogEstimator(ROBOT, MocapConfig(marker_position=offset_p, marker_quaternion=offset_q))
    p, quat = marker_pose(gt.base_position, gt.base_quaternion, offset_p, offset_q)
    cog, vel, yaw = est.update(0.0, p, quat, np.asarray(gt.joint_positions))
    assert np.allclose(cog, gt.cog_position, atol=1e-9)
    assert np.array_equal(vel, np.zeros(3))  # the first sample has no velocity
    assert yaw == pytest.approx(Rotation.from_quat(base_q).as_euler("ZYX")[0], abs=1e-12)


def test_the_velocity_filter_reaches_the_steady_state_kalman_gain() -> None:
    """Constant-velocity Kalman filter per axis: after many samples at a fixed rate its gain is
    the one of the discrete algebraic Riccati equation (scipy's solver), and a noise-free ramp
    is tracked exactly."""
    from scipy.linalg import solve_discrete_are

    cfg = MocapConfig()
    est = CogEstimator(ROBOT, cfg)
    q = np.zeros(ROBOT.n_q)
    ident = np.array([0.0, 0.0, 0.0, 1.0])
    v_true = np.array([0.3, -0.2, 0.1])
    dt = 1 / 100
    n = 400
    for k in range(n):
        pos, vel, _ = est.update(k * dt, v_true * k * dt, ident, q)
    c = est.cog_in_root(q)  # the marker is the root link's origin here
    assert np.allclose(vel, v_true, atol=1e-9) and np.allclose(pos, v_true * (n - 1) * dt + c)
    # the gain: one sample off the ramp by delta moves the estimate by K delta
    f = np.array([[1.0, dt], [0.0, 1.0]])
    h = np.array([[1.0, 0.0]])
    qn = cfg.acceleration_sigma**2 * np.array([[dt**4 / 4, dt**3 / 2], [dt**3 / 2, dt**2]])
    r = np.array([[cfg.position_noise_m**2]])
    prior = solve_discrete_are(f.T, h.T, qn, r)
    gain = (prior @ h.T / (h @ prior @ h.T + r)).ravel()
    delta = 0.001
    pos, vel, _ = est.update(n * dt, v_true * n * dt + delta, ident, q)
    assert (pos - c - v_true * n * dt) / delta == pytest.approx([gain[0]] * 3, rel=1e-6)
    assert (vel - v_true) / delta == pytest.approx([gain[1]] * 3, rel=1e-6)
    # a gap longer than max_gap_s restarts the filter at zero velocity
    _, vel, _ = est.update(n * dt + 0.5, v_true * (n + 1) * dt, ident, q)
    assert np.array_equal(vel, np.zeros(3)) and est.counts["velocity_restarted"] == 1


class Silent:
    """A UART end that reads nothing and takes every write."""

    def read_available(self) -> bytes:
        return b""

    def write(self, data: bytes) -> int:
        return len(data)


def test_the_node_takes_stamped_poses_and_checks_their_age() -> None:
    node = OnboardNode(Silent(), None, ROBOT, config=OnboardConfig())
    node.tick(1.0)
    ident = [0.0, 0.0, 0.0, 1.0]
    assert node.set_mocap_pose([0, 0, 1], ident, stamp=0.95)
    assert node._mocap_usable(1.0)
    timeout = node.config.mocap_timeout_s
    assert node._mocap_usable(0.95 + timeout) and not node._mocap_usable(0.95 + timeout + 0.001)
    for bad in ([0, 0, 2], [float("nan"), 0, 0, 1], [0, 0, 0, 0]):
        assert not node.set_mocap_pose([0, 0, 1], bad)
    assert not node.set_mocap_pose([0, 0, 1], ident, stamp=1.2)  # from the future
    assert node.counts["mocap_invalid"] == 4


def test_a_late_pose_is_predicted_to_the_control_time() -> None:
    """A marker moving at a constant 1 m/s, each pose arriving 50 ms after it was taken: the
    CoG state the control uses at the node's time is where the CoG is then (the filter's
    velocity over the age), not where it was 50 ms ago (a 5 cm lag)."""

    node = OnboardNode(Silent(), None, ROBOT, config=OnboardConfig())
    cog0 = np.asarray(ROBOT.evaluate(node.present_q)["cog"], dtype=float)
    ident = [0.0, 0.0, 0.0, 1.0]
    latency, speed = 0.05, np.array([1.0, 0.0, 0.0])
    for k in range(200):  # 100 Hz for 2 s
        now = 1.0 + 0.01 * k
        node.tick(now)
        taken = now - latency
        assert node.set_mocap_pose(speed * taken + [0.0, 0.0, 1.0], ident, stamp=taken)
    p, v, _ = node._mocap_at(now)
    truth = speed * now + [0.0, 0.0, 1.0] + cog0
    np.testing.assert_allclose(v, speed, atol=1e-3)
    np.testing.assert_allclose(p, truth, atol=2e-3)
    # a state given as of now (set_mocap) is taken as it is
    node.set_mocap([1.0, 2.0, 3.0], [1.0, 0.0, 0.0], 0.0)
    node.tick(now + 0.02)
    np.testing.assert_allclose(node._mocap_at(now + 0.02)[0], [1.0, 2.0, 3.0])


def test_the_simulated_marker_pose_is_the_root_link_pose_times_the_offset() -> None:
    """rdm.scenarios.mocap_node without noise or latency: the pose handed to the node is the
    plant's root link pose composed with the marker offset (scipy's rotations as the oracle)."""
    from rdm.scenarios.mocap_node import MocapNode, MocapSensor

    rng = np.random.default_rng(7)
    plant = Plant("rdm", seed=7)
    base_q = Rotation.from_rotvec(rng.normal(0, 0.5, 3)).as_quat()
    plant.reset(np.zeros(ROBOT.n_q), (0.2, -0.1, 1.0), [base_q[3], *base_q[:3]])
    offset_p = (0.05, -0.02, 0.03)
    offset_q = tuple(Rotation.from_rotvec([0.3, -0.2, 1.1]).as_quat())
    cfg = OnboardConfig(mocap=MocapConfig(marker_position=offset_p, marker_quaternion=offset_q))

    class Recorder:
        config = cfg

        def __init__(self) -> None:
            self.poses: list = []

        def set_mocap_pose(self, p, q, stamp):
            self.poses.append((p, q, stamp))

    rec = Recorder()
    sensor = MocapSensor(position_noise_m=0.0, rotation_noise_rad=0.0, latency_s=0.0)
    node = MocapNode(plant, rec, 0.01, sensor)
    node.tick(0.0)
    ((p, q, stamp),) = rec.poses
    expect_p, expect_q = marker_pose((0.2, -0.1, 1.0), [base_q[3], *base_q[:3]], offset_p, offset_q)
    assert np.allclose(p, expect_p, atol=1e-12) and stamp == 0.0
    assert abs(abs(np.dot(q, expect_q)) - 1.0) < 1e-12
