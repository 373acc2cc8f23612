"""The battery reserve (``battery_reserve``) and the slow sags of the mission.

* the reserve voltage against the plant's own duty -> thrust map (``rdm.plant.esc``) solved
  for full duty with scipy: ours is at or above it (``motor_info``'s 20 N is below the
  plant's 20.4 N at 0.9375 duty), within 1.5 %;
* a plain discharge (0.02 V/s on Spinal's filter model) trips ``battery_reserve`` as the pack
  crosses the reserve, once (latched), logged, before ``battery_low`` and without
  ``battery_sag``;
* arming is refused below the reserve (the model's hover thrust known);
* a fraction above 1 (or not finite, or 0) is refused naming the field;
* the mission's slow sags (0.5, 0.3 V/s: ``battery_sag``'s 5 s window; the 0.3 V/s fault
  run at 0.15 V/s: ``battery_reserve``) are detected by a battery monitor, land (touchdown by
  the landing) with the duty below its maximum all along (thrust authority left) and the
  truth tilt under 30 deg. A ``battery_low`` at 21 V alone (3.5 V/cell, below the hover's 21.4 V)
  lands only after the duty has saturated and the robot sank.
"""

from __future__ import annotations

import logging

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.spatial.transform import Rotation

from rdm.nodes.onboard_monitors import MonitorLimits, Monitors
from rdm.plant.esc import EscParams
from rdm.scenarios import mission
from rdm.scenarios.common import truth_arrays

#: motor_info's row of the mission's robot (25.2 V, 20 N at full duty)
ROW = (25.2, 20.0)
MAX_PWM = 0.9375
#: the default reserve fraction (``[monitors] reserve_thrust_fraction``)
F = 0.93


@pytest.mark.parametrize("hover", [10.0, 14.4, 16.0])
def test_the_reserve_voltage_against_the_plant_duty_map(hover) -> None:
    m = Monitors(MonitorLimits(reserve_thrust_fraction=F), cells=6, max_thrust_at=ROW)
    ours = m.reserve_voltage(hover)
    esc = EscParams()
    plant = brentq(lambda v: esc.steady_thrust(MAX_PWM, v) - hover / F, 5.0, 25.0)
    assert plant <= ours <= plant * 1.015


def test_no_reserve_without_motor_info_or_hover() -> None:
    assert Monitors(MonitorLimits(), cells=6).reserve_voltage(14.4) is None
    m = Monitors(MonitorLimits(reserve_thrust_fraction=F), cells=6, max_thrust_at=ROW)
    assert m.reserve_voltage(float("nan")) is None and not m.battery_reserve(0.0, float("nan"))


def spinal(raw_at, until_s: float) -> list[tuple[float, float]]:
    """Spinal's readings (s, V) every 100 ms: its 0.99/0.01 filter every 20 ms of the pack."""
    y, out = raw_at(0.0), []
    for ms in range(0, int(until_s * 1000) + 1, 20):
        y = 0.99 * y + 0.01 * raw_at(ms / 1000.0)
        if ms % 100 == 0:
            out.append((ms / 1000.0, y))
    return out


def test_a_discharge_trips_the_reserve_once_before_battery_low(caplog) -> None:
    m = Monitors(MonitorLimits(reserve_thrust_fraction=F), cells=6, max_thrust_at=ROW)
    floor = m.reserve_voltage(14.4)
    assert floor == pytest.approx(25.2 * np.sqrt(14.4 / (20.0 * F)))
    pack = lambda t: 25.2 - 0.02 * t  # noqa: E731
    crossed = (25.2 - floor) / 0.02
    trips, low, sag = [], [], []
    with caplog.at_level(logging.WARNING, logger="rdm.onboard"):
        for t, y in spinal(pack, 230.0):
            assert m.battery(y, t)
            hover = 14.4 + 0.2 * np.sin(t)  # the hover thrust moving with the posture
            floor_now = m.reserve_voltage(hover)
            if m.battery_reserve(t, hover):
                trips.append((t, floor_now))
            if m.battery_low(t):
                low.append(t)
            if m.battery_sag(t):
                sag.append(t)
    assert len(trips) == 1 and m.counts["battery_reserve"] == 1 and not sag
    t_trip, floor_trip = trips[0]
    assert abs(t_trip - (25.2 - floor_trip) / 0.02) <= 1.0
    assert abs(t_trip - crossed) <= 15.0  # the hover's +-0.2 N moves the floor by 0.16 V
    assert low and low[0] > t_trip + 40.0
    assert "battery_reserve" in caplog.text and "of the thrust at full duty" in caplog.text


def test_arming_is_refused_below_the_reserve() -> None:
    m = Monitors(MonitorLimits(reserve_thrust_fraction=F), cells=6, max_thrust_at=ROW)
    floor = 25.2 * np.sqrt(14.4 / (20.0 * F))  # 22.17 V: above cell_arm_min's 21.6 V
    assert m.battery(floor - 0.05, 0.0)
    assert "reserve" in m.arm_refusal(14.4) and m.arm_refusal() is None
    assert m.battery(floor + 0.05, 0.1) and m.arm_refusal(14.4) is None


@pytest.mark.parametrize("bad", [1.1, 0.0, float("nan")])
def test_the_reserve_fraction_is_refused_naming_the_field(bad) -> None:
    assert MonitorLimits().reserve_thrust_fraction == F
    with pytest.raises(ValueError, match="reserve_thrust_fraction"):
        MonitorLimits(reserve_thrust_fraction=bad)


@pytest.mark.parametrize(
    ("fault", "rate", "duration"),
    [
        ("battery-sag-0.5", 0.5, mission.QUICK_DURATION),
        ("battery-sag-0.3", 0.3, mission.QUICK_DURATION),
        ("battery-sag-0.3", 0.15, 40.0),  # below battery_sag's 0.24 V/s: battery_reserve's
    ],
)
def test_a_slow_sag_lands_with_thrust_left(tmp_path, monkeypatch, fault, rate, duration) -> None:
    monkeypatch.setitem(mission.SAG_RATES, fault, rate)
    result = mission.run(tmp_path, duration=duration, seed=0, fault=fault, quick=True)
    record = result.facts["mission"]
    assert record["fault_detected"] is True
    # before the pack reaches the hover's limit (the heavy rotors' 14.4 N at full duty)
    hover_limit = 25.2 * np.sqrt(14.4 / 20.0)
    assert record["detected_at_s"] - record["fault_at_s"] < (25.2 - hover_limit) / rate - 2.0
    assert record["outcome"] == "landed" and record["safe"]
    counts = result.stack.onboard.counts
    assert counts["battery_sag_land"] + counts["battery_reserve_land"] == 1
    assert record["max_duty"] < MAX_PWM - 0.002  # never saturated: authority left
    a = truth_arrays(result.stack)
    xyzw = a["quat"][:, [1, 2, 3, 0]]  # the truth's quaternions are w, x, y, z
    z_axis = Rotation.from_quat(xyzw).apply([0.0, 0.0, 1.0])
    tilt = np.degrees(np.arccos(np.clip(z_axis[:, 2], -1.0, 1.0)))
    assert tilt.max() < 30.0
