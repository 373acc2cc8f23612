"""The onboard node flies safely against the firmware-exact Spinal core (AttitudeController
behind a rosserial ClientSession on a pty pair, tests/onboard_rig.py) with a point mass on a
floor as the plant: force landing lands and disarms, a stuck pipeline goes silent within
``command_hold_s``, Spinal's silence is noticed within 100 ms, commanded tilt saturates,
take-off / go-to / land run on jerk-limited paths. Times are simulated (25 ms ticks)."""

from __future__ import annotations

import numpy as np
import pytest
from onboard_rig import FlightRig, VerticalPlant

from rdm.control.attitude import AttitudeController
from rdm.model import Robot
from rdm.nodes.onboard import OnboardNode
from rdm.nodes.onboard_config import OnboardConfig
from rdm.nodes.onboard_flight import FlightLimits
from rdm.protocol.rosserial.client import ClientSession
from rdm.protocol.rosserial.constants import LogLevel

pytestmark = pytest.mark.timeout(300)
ROBOT = Robot.default()
DT = 0.025
#: motor_info's force_landing_thrust (the Hydrus example the node sends)
FORCE_LANDING_THRUST = 6.5


class Flight(FlightRig):
    """The rig with the default onboard configuration and a point mass on the floor."""

    def __init__(self, config: OnboardConfig | None = None, z0: float = 0.0) -> None:
        cfg = config or OnboardConfig()
        node = lambda u, f: OnboardNode(u, f, ROBOT, config=cfg)  # noqa: E731
        super().__init__(node, VerticalPlant(float(ROBOT.mass), z0))

    def commands_between(self, t0: float, t1: float) -> list[float]:
        return [t for t, _ in self.rig.by_topic["four_axes/command"] if t0 <= t < t1]

    def hover_at(self, z: float) -> None:
        """Armed on the floor, then the script's setpoint to z (the scenarios' way)."""
        self.run(0.3)
        self.node.set_target([0.0, 0.0, z], 0.0)
        assert self.node.arm() is None
        self.run_until(lambda: self.spinal.core.armed, 2.0)
        self.run_until(lambda: abs(self.plant.z - z) < 0.05 and abs(self.plant.vz) < 0.05, 15)
        self.run(1.0)


@pytest.fixture
def flight():
    f = Flight()
    yield f
    f.close()


def test_force_landing_descends_at_the_landing_rate_and_disarms_on_touchdown(flight) -> None:
    flight.hover_at(1.0)
    base_before = float(np.mean(flight.spinal.core.base_thrust))
    flight.node.force_landing()
    t0 = flight.t
    flight.run_until(lambda: flight.spinal.core.force_landing, 1.0)
    # controlled descent under position control: commands keep coming, the z goes down
    took = flight.run_until(lambda: not flight.spinal.core.armed, 10.0)
    flight.run(2 * DT)  # Spinal's ack 1 reaches the node
    assert flight.node.state.value == "idle"
    assert flight.plant.z < 0.01
    # the descent between 0.8 m and 0.3 m runs at about 0.3 m/s (JSK land_descend_vel)
    zs = [(t, z) for t, z, _ in flight.log if t >= t0]
    t_hi = next(t for t, z in zs if z < 0.8)
    t_lo = next(t for t, z in zs if z < 0.3)
    rate = 0.5 / (t_lo - t_hi)
    assert 0.22 < rate < 0.4, rate
    # it lands in about height / rate (plus the touchdown checks), not Spinal's drop
    assert 2.5 < took < 6.0, took
    assert flight.node.monitors.counts["touchdown"] == 1
    # main kept the ~9 N hover command: Spinal's base thrust never left it
    assert base_before > FORCE_LANDING_THRUST + 1.5


def last_command_time(t_loss: float, config: OnboardConfig) -> float:
    """When the last ``four_axes/command`` goes out after mocap stops at ``t_loss``: the last
    sample reaches the node before the tick before ``t_loss`` and is stamped with the tick
    before that (``set_mocap`` between ticks); commands stay fresh while the sample is at most
    ``mocap_timeout_s`` old, then the last one is held ``command_hold_s``."""
    stamp = t_loss - 2 * DT
    last_fresh = stamp + DT * int(config.mocap_timeout_s / DT + 1e-9)
    return last_fresh + DT * int(config.flight.command_hold_s / DT + 1e-9)


def test_mocap_loss_stops_commands_within_the_hold_and_spinal_lands_itself(flight) -> None:
    flight.hover_at(1.0)
    flight.mocap = False
    t_loss = flight.t
    flight.run(3.0)
    sent = flight.commands_between(t_loss, flight.t)
    assert max(sent) == pytest.approx(last_command_time(t_loss, OnboardConfig()), abs=1e-6)
    core = flight.spinal.core
    assert core.force_landing and core.counters["failsafes"] >= 1
    # Spinal's own ramp: the average base thrust fell to force_landing_thrust
    assert float(np.mean(core.base_thrust)) == pytest.approx(FORCE_LANDING_THRUST, abs=0.01)
    # on the floor and still: touchdown from the IMU, then ARM_OFF
    flight.run_until(lambda: not core.armed, 5.0)
    assert flight.plant.z == 0.0
    assert flight.node.flight.counts["touchdown_imu"] == 1


def test_a_stuck_pipeline_goes_silent_after_the_hold(flight, monkeypatch) -> None:
    flight.hover_at(1.0)

    def broken(*_a, **_k):
        raise ValueError("control error")

    monkeypatch.setattr(flight.node.control, "step", broken)
    t_stuck = flight.t
    flight.run(1.0)
    sent = flight.commands_between(t_stuck, flight.t)
    assert sent and max(sent) <= t_stuck + 0.1 + 1e-6
    assert flight.node.counts["command_withheld"] > 0
    assert flight.spinal.core.force_landing  # Spinal's 500 ms timeout acted


@pytest.mark.parametrize("hold", [0.05, 0.2])
def test_the_hold_bound_is_the_configured_one(hold) -> None:
    f = Flight(OnboardConfig(flight=FlightLimits(command_hold_s=hold)))
    try:
        f.hover_at(1.0)
        f.mocap = False
        t_loss = f.t
        f.run(1.0)
        sent = f.commands_between(t_loss, f.t)
        assert max(sent) == pytest.approx(last_command_time(t_loss, f.node.config), abs=1e-6)
    finally:
        f.close()


def test_spinal_silence_is_noticed_within_100_ms_and_lands_in_flight(flight) -> None:
    flight.hover_at(1.0)
    flight.rig.silent = True
    t0 = flight.t
    flight.run(0.075)  # 3 ticks: 75 ms of silence, below the 100 ms threshold
    assert flight.node.monitors.counts["spinal_silent"] == 0
    flight.run(0.1)
    assert flight.node.monitors.counts["spinal_silent"] == 1
    trip = flight.node.monitors.events[-1]
    assert trip["monitor"] == "spinal_silent" and trip["t"] - t0 <= 0.1 + DT + 1e-9
    assert flight.node.flight.mode.value == "land"
    # Spinal still hears the node (only its transmit side is gone): it lands under control
    flight.run_until(lambda: flight.plant.z < 0.05, 6.0)


def test_spinal_silence_while_perched_holds() -> None:
    f = Flight()
    try:
        f.hover_at(1.0)
        f.node.request_perch(True)
        f.run(0.1)
        f.rig.silent = True
        f.run(0.3)
        assert f.node.monitors.counts["spinal_silent"] == 1
        assert f.node.counts["spinal_silent_hold"] == 1
        assert f.node.flight.mode.value == "manual"
    finally:
        f.close()


@pytest.mark.parametrize("perched", [False, True])
def test_spinals_can_disconnected_log_lands_in_flight_and_holds_perched(perched) -> None:
    """Spinal's only report of its Neuron bus, a ``logerror`` "CAN disconnected!!"
    (jsk-wire-protocols.md sec. 2.6): counted ``can_disconnected``, logged, in flight land,
    perched hold. The same text at warn level, and another error line, change nothing."""
    f = Flight()
    try:
        f.hover_at(1.0)
        if perched:
            f.node.request_perch(True)
            f.run(0.1)
        f.rig.spinal.log(LogLevel.WARN, "CAN disconnected!!")
        f.rig.spinal.log(LogLevel.ERROR, "CAN: 4 Neurons [1, 2, 3, 4], uav_model 16")
        f.run(0.1)
        assert f.node.monitors.counts["can_disconnected"] == 0
        assert f.node.flight.mode.value != "land"
        f.rig.spinal.log(LogLevel.ERROR, "CAN disconnected!!")
        f.run(0.05)
        assert f.node.monitors.counts["can_disconnected"] == 1
        event = f.node.monitors.events[-1]
        assert event["monitor"] == "can_disconnected" and "CAN disconnected!!" in event["reason"]
        if perched:
            assert f.node.counts["can_disconnected_hold"] == 1
            assert f.node.flight.mode.value == "manual" and f.node.control.perching
        else:
            assert f.node.counts["can_disconnected_land"] == 1
            assert f.node.flight.mode.value == "land"
            f.run_until(lambda: not f.spinal.core.armed, 20.0)
            assert f.plant.z < 0.01
    finally:
        f.close()


def test_commanded_tilt_saturates_below_spinal_failsafe(flight) -> None:
    flight.hover_at(1.0)
    flight.node.set_target([2.1, 0.0, 1.0], 0.0)  # a 2.1 m step: > 1 rad of tilt unbounded
    flight.run(0.5)
    cmds = [m for t, m in flight.rig.by_topic["four_axes/command"] if t > flight.t - 0.5]
    tilt = max(max(abs(m.angles[0]), abs(m.angles[1])) for m in cmds)
    limit = FlightLimits().max_tilt_cmd
    assert tilt == pytest.approx(limit, abs=1e-6)  # float32 on the wire
    assert flight.node.counts["tilt_limited"] > 0
    assert flight.node.monitors.counts["tilt_limit"] == 1
    assert flight.spinal.core.counters["failsafes"] == 0


def test_takeoff_goto_land_on_jerk_limited_paths(flight) -> None:
    lim = FlightLimits()
    flight.run(0.3)
    assert flight.node.takeoff(1.0) is None
    flight.run_until(lambda: flight.node.flight.mode.value == "hover", 15.0)
    assert abs(flight.plant.z - 1.0) < lim.takeoff_z_tol
    t_climb = [(t, sp) for t, _, sp in flight.log]
    # the setpoint obeys the z limits: finite differences of the path (velocity, acceleration)
    ts = np.array([t for t, _ in t_climb])
    zs = np.array([sp for _, sp in t_climb])
    v = np.diff(zs) / np.diff(ts)
    a = np.diff(v) / np.diff(ts[1:])
    assert np.max(np.abs(v)) <= lim.max_velocity[2] + 1e-6
    assert np.max(np.abs(a)) <= lim.max_acceleration[2] + 0.05
    assert np.max(v) > 0.9 * lim.max_velocity[2]  # it does climb at the limit
    # goto: refused outside the fence, accepted inside
    assert "geofence" in flight.node.goto([50.0, 0.0, 1.0])
    assert flight.node.goto([0.0, 0.0, 1.5]) is None
    flight.run_until(lambda: abs(flight.plant.z - 1.5) < 0.05, 10.0)
    assert flight.node.land() is None
    flight.run_until(lambda: not flight.spinal.core.armed, 15.0)
    assert flight.plant.z < 0.01 and flight.node.flight.mode.value == "ground"


def test_halt_stops_the_motors_at_once(flight) -> None:
    flight.hover_at(0.5)
    flight.node.halt()
    flight.run(0.1)
    assert not flight.spinal.core.armed


def test_ground_loss_lands_in_flight(flight) -> None:
    flight.hover_at(1.0)
    flight.node.on_ground_lost()
    assert flight.node.flight.mode.value == "land"
    flight.run_until(lambda: not flight.spinal.core.armed, 10.0)


def test_takeoff_is_refused_on_a_low_battery_and_nothing_arms(flight) -> None:
    flight.rig.battery_v = 21.5  # 3.58 V per cell: below the 3.6 V/cell arming floor
    flight.run(0.3)
    reason = flight.node.takeoff(1.0)
    assert reason is not None and "battery" in reason
    flight.run(1.0)
    assert not flight.spinal.core.armed and flight.node.flight.mode.value == "ground"
    assert not any(m.cmd == 0 for _, m in flight.rig.by_topic["flight_config_cmd"])
    flight.rig.battery_v = 21.7  # 3.62 V per cell: above the floor, below the hover's reserve
    flight.run(0.3)
    reason = flight.node.takeoff(1.0)
    assert reason is not None and "reserve" in reason
    # the reserve: the hover's largest rotor thrust is 93 % of 20 N x (V / 25.2)^2 there
    hover = float(np.max(flight.node.control.terms.hover_thrust))
    assert f"{25.2 * np.sqrt(hover / (0.93 * 20.0)):.2f} V reserve" in reason
    flight.rig.battery_v = 22.3  # above the reserve (22.15 V): allowed
    flight.run(0.3)
    assert flight.node.takeoff(1.0) is None
    flight.run_until(lambda: flight.spinal.core.armed, 2.0)


def test_land_during_a_goto_brakes_from_where_the_path_is_then_descends(flight) -> None:
    """A land asked mid-path: the setpoint neither jumps (to the goal, or back to the hover
    point before the go-to) nor stops dead (a step of deceleration): it brakes within the
    path's acceleration limit (finite differences of the setpoint), then descends."""
    lim = FlightLimits()
    flight.run(0.3)
    assert flight.node.takeoff(1.0) is None
    flight.run_until(lambda: flight.node.flight.mode.value == "hover", 15.0)
    assert flight.node.goto([0.0, 0.0, 1.8]) is None
    flight.run(1.5)  # mid-path, climbing at the velocity limit
    t_land = flight.log[-1][0]
    assert flight.node.land() is None
    flight.run(3.0)
    ts, zs = np.array([(t, sp) for t, _, sp in flight.log if t >= t_land - 3 * DT]).T
    v = np.diff(zs) / np.diff(ts)
    a = np.diff(v) / np.diff(ts[1:])
    assert v[0] > 0.9 * lim.max_velocity[2]  # it was moving
    assert 1.1 < zs[0] < 1.7
    stopped = int(np.argmax(v <= 1e-9))  # the first step with no more climb
    assert stopped > 0 and ts[stopped] - t_land < 1.0  # the stop is short at these limits
    assert np.max(np.abs(a[: stopped - 1])) <= lim.max_acceleration[2] + 0.05
    assert np.max(np.abs(v)) <= lim.max_velocity[2] + 1e-6  # no jump: to the goal or back
    assert v[-1] == pytest.approx(-lim.land_descend_rate)  # then the descent
    flight.run_until(lambda: not flight.spinal.core.armed, 20.0)
    assert flight.plant.z < 0.01


def test_a_spinal_reset_in_flight_is_noticed_and_never_rearms_by_itself(flight) -> None:
    """Spinal reboots in hover (silent 1.5 s while it boots, then a fresh rosserial client and
    a disarmed attitude core): the node notices within 100 ms, lands (the motors stopped: the
    robot falls), ends idle on the ground and sends no ARM_ON of its own; after the new
    handshake an operator's take-off flies again."""
    flight.hover_at(1.0)
    t_reset = flight.t
    flight.rig.silent = True
    flight.spinal.core = AttitudeController(200.0)
    flight.rig.spinal = ClientSession.from_layout()
    flight.run(0.15)
    assert flight.node.monitors.counts["spinal_silent"] == 1
    assert flight.node.flight.mode.value == "land"
    flight.run(1.35)
    flight.rig.silent = False
    flight.run_until(lambda: flight.rig.spinal.configured, 10.0)
    flight.run(2.0)
    assert flight.plant.z == 0.0 and not flight.spinal.core.armed
    assert (flight.node.state.value, flight.node.flight.mode.value) == ("idle", "ground")
    arm_on = [t for t, m in flight.rig.by_topic["flight_config_cmd"] if m.cmd == 0 and t > t_reset]
    assert arm_on == []
    assert flight.node.takeoff(1.0) is None
    flight.run_until(lambda: flight.node.flight.mode.value == "hover", 20.0)
    assert abs(flight.plant.z - 1.0) < 0.05


@pytest.mark.parametrize(
    ("rotvec_deg", "allowed"),
    [
        ((8.0, 0.0, 0.0), True),
        ((0.0, -12.0, 0.0), False),
        ((12.0, 0.0, 0.0), False),
        # roll and pitch 7.5 deg each: each inside 10 deg, the body z axis 10.6 deg off vertical
        ((7.5, 7.5, 0.0), False),
        ((6.0, 6.0, 90.0), True),
    ],
)
def test_takeoff_is_refused_from_a_tilted_rest(flight, rotvec_deg, allowed) -> None:
    """A robot resting tilted beyond ``FlightLimits.takeoff_max_tilt`` (10 deg) does not arm:
    the tilt is the angle of the body z axis from vertical (scipy's rotation as the oracle),
    refused in a message that names the limit, counted and logged."""
    from scipy.spatial.transform import Rotation

    rot = Rotation.from_euler("xyz", rotvec_deg, degrees=True)
    tilt = np.degrees(np.arccos(rot.apply([0.0, 0.0, 1.0])[2]))
    limit = np.degrees(FlightLimits().takeoff_max_tilt)
    assert (tilt <= limit) == allowed  # the cases straddle the limit as intended
    flight.rig.imu_quaternion = list(rot.as_quat())  # x, y, z, w
    flight.run(0.3)
    reason = flight.node.takeoff(1.0)
    flight.run(1.0)
    if allowed:
        assert reason is None
        assert flight.spinal.core.armed
    else:
        assert reason is not None and "takeoff_max_tilt" in reason
        assert f"{tilt:.1f} deg" in reason
        assert not flight.spinal.core.armed and flight.node.flight.mode.value == "ground"
        assert flight.node.monitors.counts["takeoff_refused_tilt"] == 1
        assert not any(m.cmd == 0 for _, m in flight.rig.by_topic["flight_config_cmd"])


def test_takeoff_is_refused_without_a_fresh_attitude(flight) -> None:
    """No ``imu`` from Spinal (silent since boot; on a second rig, silent for longer than
    ``takeoff_imu_max_age`` after a good start): no take-off, each refusal counted."""
    flight.rig.silent = True
    flight.run(0.3)
    reason = flight.node.takeoff(1.0)
    assert reason is not None and "no imu" in reason
    flight.run(0.5)
    assert not flight.spinal.core.armed
    assert flight.node.monitors.counts["takeoff_refused_tilt"] == 1
    stale = Flight()
    try:
        stale.run(0.3)
        assert stale.node.imu_euler is not None
        stale.rig.silent = True
        stale.run(0.6)  # the newest attitude is now more than 0.5 s old
        reason = stale.node.takeoff(1.0)
        assert reason is not None and "s old" in reason
        stale.run(0.5)
        assert not stale.spinal.core.armed
        assert stale.node.monitors.counts["takeoff_refused_tilt"] == 1
    finally:
        stale.close()
