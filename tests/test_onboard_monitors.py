"""Each onboard monitor trips at its threshold and not below it, and a device UART survives
an unplug: the link opens the same path again when the adapter comes back."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest
from onboard_rig import Rig, SpinalCore, VerticalPlant

from rdm.link.serial import open_serial
from rdm.model import Robot
from rdm.nodes.onboard import OnboardNode
from rdm.nodes.onboard_config import OnboardConfig
from rdm.nodes.onboard_flight import FlightLimits
from rdm.nodes.onboard_monitors import MonitorLimits, Monitors, battery_cells

ROBOT = Robot.default()


@pytest.mark.parametrize(("volts", "cells"), [(25.2, 6), (16.8, 4), (12.6, 3), (22.2, 5)])
def test_cell_count_from_the_full_reference_voltage(volts, cells) -> None:
    assert battery_cells([volts - 3.0, volts]) == cells


@pytest.mark.parametrize(
    ("volts", "accepted"),
    # 6 cells x (3.0 .. 4.45) V = 18.0 .. 26.7 V; 0.07 x 25 V (the bad adc scale) is out
    [
        (18.0, True),
        (17.99, False),
        (26.7, True),
        (26.71, False),
        (1.75, False),
        (float("nan"), False),
        (1e-300, False),
    ],
)
def test_battery_plausibility(volts, accepted) -> None:
    m = Monitors(MonitorLimits(), 6)
    m.battery(24.0, 0.0)
    assert m.battery(volts, 1.0) is accepted
    assert m.voltage == (volts if accepted else 24.0)  # a rejected one keeps the last good
    assert m.counts["battery_implausible"] == (0 if accepted else 1)


def test_low_battery_trips_after_its_duration_and_not_above_the_threshold() -> None:
    lim = MonitorLimits()
    low = lim.cell_low * 6
    m = Monitors(lim, 6)
    m.battery(low, 0.0)  # at the threshold: not low
    assert not m.battery_low(5.0)
    m.battery(low - 0.01, 10.0)
    assert not m.battery_low(10.0 + lim.low_battery_s - 0.01)
    assert m.battery_low(10.0 + lim.low_battery_s)
    assert not m.battery_low(12.0)  # one trip per episode
    assert m.counts["battery_low"] == 1


def test_arming_is_refused_on_a_low_or_implausible_battery() -> None:
    lim = MonitorLimits()
    m = Monitors(lim, 6)
    assert m.arm_refusal() is None  # no reading yet: Spinal's own check
    m.battery(lim.cell_arm_min * 6, 0.0)
    assert m.arm_refusal() is None
    m.battery(lim.cell_arm_min * 6 - 0.01, 0.0)
    assert "below" in m.arm_refusal()
    fresh = Monitors(lim, 6)
    fresh.battery(3.0, 0.0)  # 0.5 V/cell
    assert fresh.arm_refusal() == "no plausible battery reading"


def node_rig(config: OnboardConfig | None = None) -> tuple[Rig, SpinalCore, VerticalPlant]:
    rig = Rig(lambda u, f: OnboardNode(u, f, ROBOT, config=config or OnboardConfig()))
    plant = VerticalPlant(float(ROBOT.mass))
    spinal = SpinalCore(rig, plant)
    rig.servo_q = np.zeros(ROBOT.n_q)
    return rig, spinal, plant


def fly(rig: Rig, plant: VerticalPlant, spinal: SpinalCore, t: float, x: float = 0.0) -> float:
    def feed(_t):
        rig.node.set_mocap([x, 0.0, plant.z], [0.0, 0.0, plant.vz], 0.0)

    t = rig.run(t, t + 0.3, each=feed)
    rig.node.set_target([x, 0.0, 1.0], 0.0)
    rig.node.arm()
    return rig.run(t, t + 3.0, each=feed)


@pytest.mark.parametrize(("ticks", "trips"), [(5, 0), (6, 1)])
def test_servo_staleness_trips_past_its_timeout(ticks: int, trips: int) -> None:
    # 0.1 s timeout; the last reading arrives at the first of the ticks, so after 5 ticks
    # it is 0.1 s old (not past the timeout) and after 6 it is 0.125 s old
    rig, spinal, plant = node_rig(OnboardConfig(monitors=MonitorLimits(servo_timeout_s=0.1)))
    try:
        t = fly(rig, plant, spinal, 0.0)
        rig.servo_q = None
        t = rig.run(t, t + ticks * 0.025)
        assert rig.node.monitors.counts["servo_stale"] == trips
        assert (rig.node.flight.mode.value == "land") is bool(trips)
    finally:
        rig.close()


@pytest.mark.parametrize(("x", "trips"), [(1.9, 0), (2.1, 1)])
def test_geofence_lands_outside_and_not_inside(x: float, trips: int) -> None:
    fence = FlightLimits(fence_min=(-2.0, -2.0, -0.5), fence_max=(2.0, 2.0, 3.0))
    rig, spinal, plant = node_rig(OnboardConfig(flight=fence))
    try:
        fly(rig, plant, spinal, 0.0, x=x)
        assert rig.node.monitors.counts["geofence"] == trips
        assert rig.node.counts["geofence_land"] == trips
    finally:
        rig.close()


def test_a_device_link_opens_again_after_an_unplug(tmp_path) -> None:
    """A udev-style name (a symlink) to a pty: closing the pty's master is the unplug (EIO on
    the slave, as a vanished USB adapter gives); a new pty behind the same name comes back."""
    name = tmp_path / "flight_controller"

    def plug() -> int:
        master, slave = os.openpty()
        if name.is_symlink():
            name.unlink()
        name.symlink_to(os.ttyname(slave))
        os.close(slave)
        return master

    master = plug()
    link = open_serial(f"serial:{name}")
    link.reopen_s = 0.05
    try:
        os.write(master, b"abc")
        time.sleep(0.05)
        assert link.read_available() == b"abc"
        os.close(master)  # unplugged
        assert link.read_available() == b""
        assert link.errors == 1 and not link.connected
        assert link.write(b"lost") == 0
        master = plug()
        deadline = time.monotonic() + 2.0
        while not link.connected and time.monotonic() < deadline:
            assert link.read_available() == b""
            time.sleep(0.01)
        assert link.reopens == 1
        os.write(master, b"back")  # pyserial drops what arrived before it opened the port
        got = b""
        while got != b"back" and time.monotonic() < deadline:
            got += link.read_available()
            time.sleep(0.01)
        assert got == b"back"
        assert link.write(b"xyz") == 3
        time.sleep(0.05)
        assert os.read(master, 16) == b"xyz"
    finally:
        link.close()
        os.close(master)


def test_a_pty_link_error_reaches_the_caller() -> None:
    from rdm.link.serial import open_pty_pair

    slave, master = open_pty_pair()
    master.port.close()
    with pytest.raises(OSError):
        slave.read_available()
    slave.port.close()
