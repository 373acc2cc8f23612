"""The onboard node's perch sequence and joint motions against the firmware-exact Spinal core
(tests/onboard_rig.py) with a point mass between a floor and a ceiling as the plant, and a
Leptrino sensor side that reads the push on the ceiling: approach at the configured rate,
contact from the foot sensor, perched at the contact height with perching control, unperch
down a jerk-limited path, land. Joint motions: ruckig paths within their limits (finite
differences). Times are simulated (25 ms ticks)."""

from __future__ import annotations

import numpy as np
import pytest
from onboard_rig import FlightRig, G, VerticalPlant

from rdm.model import Robot
from rdm.nodes.onboard import OnboardNode
from rdm.nodes.onboard_config import OnboardConfig
from rdm.nodes.onboard_flight import FlightLimits

pytestmark = pytest.mark.timeout(300)
ROBOT = Robot.default()
DT = 0.025
RATED = np.array([150.0, 150.0, 300.0, 4.0, 4.0, 4.0])  # CFS034CA301U (paper Sec. VI-B)
CEILING = 1.4  # m: the CoG height at which the foot touches


class CeilingPlant(VerticalPlant):
    """:class:`VerticalPlant` under a ceiling at z = ``ceiling``: there the mass stops and
    the foot sensor reads the net upward push (thrust - m g) as its normal force."""

    def __init__(self, mass: float, ceiling: float | None) -> None:
        super().__init__(mass, 0.0)
        self.ceiling = ceiling
        self.push = 0.0

    def step(self, dt: float, thrust: float) -> None:
        super().step(dt, thrust)
        self.push = 0.0
        if self.ceiling is not None and self.z >= self.ceiling:
            self.z, self.vz = self.ceiling, min(self.vz, 0.0)
            self.push = max(thrust - self.mass * G, 0.0)


class Perch(FlightRig):
    """The rig with a ceiling and a foot sensor that reads the push on it."""

    def __init__(self, ceiling: float | None = CEILING, foot: bool = True, **flight) -> None:
        config = OnboardConfig(flight=FlightLimits(**flight))
        node = lambda u, f: OnboardNode(u, f, ROBOT, config=config)  # noqa: E731
        super().__init__(node, CeilingPlant(float(ROBOT.mass), ceiling), foot=foot)
        self.foot_alive = True

    def feed(self, t: float) -> None:
        if self.foot_alive:
            w = np.array([0.0, 0.0, self.plant.push, 0.0, 0.0, 0.0])
            self.rig.foot_raw = tuple(int(v) for v in np.round(w * 10000 / RATED))
        else:
            self.rig.foot_raw = None
        super().feed(t)

    @property
    def mode(self) -> str:
        return self.node.flight.mode.value

    def hover(self, height: float = 1.0) -> None:
        self.run(0.3)
        assert self.node.takeoff(height) is None
        self.run_until(lambda: self.mode == "hover", 15.0)

    def perched(self) -> None:
        self.hover()
        assert self.node.perch() is None
        self.run_until(lambda: self.mode == "perched", 10.0)


@pytest.fixture
def perch():
    p = Perch()
    yield p
    p.rig.close()


def test_approach_rises_at_the_rate_then_perches_at_the_contact_height(perch) -> None:
    lim = FlightLimits()
    perch.hover()
    t0 = perch.t
    assert perch.node.perch() is None
    assert perch.mode == "approach"
    perch.run_until(lambda: perch.mode == "perched", 10.0)
    # the setpoint rose at approach_speed (finite differences over the approach)
    rising = [(t, sp) for t, _, sp in perch.log if t0 + 0.1 < t < perch.node.flight.perched_at]
    ts, zs = np.array(rising).T
    rates = np.diff(zs) / np.diff(ts)
    assert rates == pytest.approx(lim.approach_speed, rel=1e-6)
    # contact: the foot sensor read more than contact_fz, not before the ceiling
    assert perch.plant.z == pytest.approx(CEILING)
    hold = perch.node.flight.hold_position
    assert hold is not None and hold[2] == pytest.approx(CEILING, abs=0.01)
    perch.run(0.5)
    status = perch.node.status()
    assert status["perching"] is True and status["flight_mode"] == "perched"
    assert perch.node.monitors.counts["contact"] == 1
    assert perch.node.land() == "perched: unperch first"
    assert perch.plant.z == pytest.approx(CEILING)  # held perched, pushing
    assert perch.plant.push > 0.5 and sum(status["command"]["perch_thrust"]) > 0.0


def test_unperch_leaves_down_a_jerk_limited_path_then_lands(perch) -> None:
    lim = FlightLimits()
    perch.perched()
    perch.run(1.0)
    z_perched = perch.node.flight.hold_position[2]
    t0 = perch.t
    assert perch.node.unperch() is None
    assert perch.mode == "unperch"
    perch.run_until(lambda: perch.mode == "hover", 10.0)
    assert perch.node.status()["perching"] is False
    path = np.array([(t, sp) for t, _, sp in perch.log if t >= t0])
    v = np.diff(path[:, 1]) / np.diff(path[:, 0])
    assert np.min(v) >= -lim.max_velocity[2] - 1e-6
    assert perch.node.flight.hold_position[2] == pytest.approx(z_perched - lim.unperch_drop)
    perch.run_until(lambda: perch.plant.z < CEILING - 0.1, 5.0)
    assert perch.node.land() is None
    perch.run_until(lambda: not perch.spinal.core.armed, 20.0)
    assert perch.plant.z < 0.01 and perch.mode == "ground"


def test_no_contact_within_the_rise_limit_returns_to_the_start() -> None:
    p = Perch(ceiling=None, approach_rise_max=0.2, approach_speed=0.1)
    try:
        p.hover()
        z0 = p.node.flight.hold_position[2]
        assert p.node.perch() is None
        p.run_until(lambda: p.mode == "hover", 4.0)
        assert p.node.flight.counts["approach_no_contact"] == 1
        highest = max(sp for _, _, sp in p.log)
        assert highest == pytest.approx(z0 + 0.2, abs=0.1 * DT + 1e-9)
        assert p.node.flight.hold_position[2] == pytest.approx(z0)
        assert p.node.status()["perching"] is False
    finally:
        p.rig.close()


class SpikyPerch(Perch):
    """:class:`Perch` whose foot sensor adds ``spike`` N to its normal force on the feeds in
    ``spike_at`` (counted from the approach's start), as a noisy wrench sensor at times."""

    def __init__(self, spike_at: set[int], spike: float = 5.0, **flight) -> None:
        super().__init__(**flight)
        self.spike_at, self.spike, self.feeds = spike_at, spike, None
        self.pushes: list[tuple[float, float]] = []  # (time, the true push)

    def feed(self, t: float) -> None:
        if self.feeds is not None:
            self.pushes.append((t, self.plant.push))
            self.feeds += 1
            if self.feeds in self.spike_at:
                self.plant.push += self.spike
        super().feed(t)


@pytest.mark.parametrize("hold_s", [0.0, 0.05])
def test_contact_needs_the_force_to_hold_for_contact_hold_s(hold_s: float) -> None:
    """Two readings above ``contact_fz`` one tick each, 0.2 s apart, in the approach: with
    ``contact_hold_s`` 0 the first perches away from the ceiling; with 0.05 s (three 25 ms
    feeds) neither does, and the true contact perches at the ceiling 0.05 s after the first
    true reading above it. Bugs caught: the hold ignored, a count that does not restart after
    a quiet reading (the second spike would then complete it)."""
    p = SpikyPerch({4, 12}, contact_hold_s=hold_s) if hold_s else SpikyPerch({4, 12})
    try:
        p.hover()
        assert p.node.perch() is None
        p.feeds = 0
        p.run_until(lambda: p.mode == "perched", 10.0)
        z = p.node.flight.hold_position[2]
        if hold_s == 0.0:
            assert z < CEILING - 0.01 and p.plant.push == 0.0
            assert p.node.counts["contact_pending"] == 0
        else:
            assert z == pytest.approx(CEILING, abs=0.01)
            fz = FlightLimits().contact_fz
            first = next(t for t, push in p.pushes if push > fz)
            assert p.node.flight.perched_at - first == pytest.approx(hold_s, abs=DT + 1e-9)
            assert p.node.counts["contact_pending"] >= 2 + 2
    finally:
        p.rig.close()


def test_perch_is_refused_when_it_cannot_be_done() -> None:
    p = Perch(foot=False)
    try:
        assert p.node.perch() == "no foot sensor"
    finally:
        p.rig.close()
    p = Perch()
    try:
        assert p.node.perch() == "not flying"
        p.hover()
        assert "approach speed" in p.node.perch(speed=5.0)
        assert "approach speed" in p.node.perch(speed=float("nan"))
        assert p.node.unperch().startswith("not perched")
        assert p.mode == "hover"
    finally:
        p.rig.close()
    p = Perch(perched_gains="stiff")
    try:
        p.hover()
        assert "names no gain profile" in p.node.perch()
    finally:
        p.rig.close()


def test_force_landing_from_the_perch_releases_it_and_lands(perch) -> None:
    perch.perched()
    perch.run(0.5)
    perch.node.force_landing()
    perch.run(0.2)
    assert perch.mode == "land"
    assert perch.node.status()["perching"] is False
    assert perch.node.counts["perch_released_to_land"] == 1
    perch.run_until(lambda: not perch.spinal.core.armed, 20.0)
    assert perch.plant.z < 0.01


def test_foot_sensor_loss_while_perched_holds_the_perch(perch) -> None:
    perch.perched()
    perch.run(0.5)
    perch.foot_alive = False
    perch.run(1.0)
    assert perch.node.monitors.counts["foot_stale"] == 1
    assert perch.mode == "perched" and perch.spinal.core.armed
    assert perch.plant.z == pytest.approx(CEILING)


def test_joint_motion_is_a_path_within_the_joint_limits(perch) -> None:
    lim = FlightLimits()
    perch.run(0.3)
    goal = np.array([0.6, -0.4, 0.2, 0.0, 0.0, 0.0])
    assert perch.node.move_joints(goal.tolist()) is None
    times, qs = perch.node._trajectory
    assert times[0] == pytest.approx(perch.rig.t)  # the last tick
    v = np.diff(qs, axis=0) / np.diff(times)[:, None]
    a = np.diff(v, axis=0) / np.diff(times[1:])[:, None]
    assert np.max(np.abs(v)) <= lim.joint_max_velocity + 1e-6
    assert np.max(np.abs(a)) <= lim.joint_max_acceleration + 0.05
    assert np.max(np.abs(v[:, 0])) > 0.9 * lim.joint_max_velocity  # the longest joint at vmax
    # all joints arrive together, at the goal, vectoring joints untouched
    np.testing.assert_allclose(qs[-1, :6], goal)
    np.testing.assert_allclose(qs[:, 6:], 0.0)
    assert times[-1] - times[0] >= 0.6 / lim.joint_max_velocity
    # bad goals are refused, nothing changes
    assert perch.node.move_joints([0.0, float("inf"), 0, 0, 0, 0]) is not None
    assert perch.node.move_joints([0.0] * 4) is not None
    assert perch.node._trajectory[0] is times
