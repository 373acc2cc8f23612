"""The onboard monitors' rules one by one (``rdm.nodes.onboard_monitors``): every trip counted
(twice is two), logged with its name and reason and kept as an event; a freshness monitor
trips once per episode and again after it recovered; the battery window's closed edges, the
low-battery delay's closed edge and the voltages its messages name (cells x per-cell
threshold); the cell count from ``motor_info``; every limit rule refused at its edge. Written
against the rules stated in the module and in docs/flying.md, to catch the one-line slips a
mutation campaign plants (``= 1`` for ``+= 1``, ``<`` for ``<=``, ``/`` for ``*``)."""

from __future__ import annotations

import logging

import pytest

from rdm.nodes.onboard_monitors import MonitorLimits, Monitors, battery_cells


def test_each_trip_is_counted_logged_and_kept(caplog) -> None:
    m = Monitors(MonitorLimits(), cells=6)
    with caplog.at_level(logging.WARNING, logger="rdm.onboard"):
        m.trip("geofence", "x outside", 1.23456)
        m.trip("geofence", "y outside", 2.0)
        m.trip("tilt_limit", "0.6 rad", 2.5)
    assert m.counts == {"geofence": 2, "tilt_limit": 1}
    assert list(m.events) == [
        {"t": 1.2346, "monitor": "geofence", "reason": "x outside"},
        {"t": 2.0, "monitor": "geofence", "reason": "y outside"},
        {"t": 2.5, "monitor": "tilt_limit", "reason": "0.6 rad"},
    ]
    assert [r.getMessage() for r in caplog.records] == [
        "t=1.235 geofence: x outside",
        "t=2.000 geofence: y outside",
        "t=2.500 tilt_limit: 0.6 rad",
    ]
    status = m.status()
    assert status["counts"] == {"geofence": 2, "tilt_limit": 1}
    assert status["events"] == list(m.events) and status["battery_cells"] == 6


def test_the_status_keeps_the_latest_32_events_and_counts_every_trip() -> None:
    m = Monitors(MonitorLimits(), cells=6)
    for k in range(40):
        if k % 2:
            m.note("takeoff", f"note {k}", float(k))
        else:
            m.trip("geofence", f"trip {k}", float(k))
    assert m.counts == {"geofence": 20, "takeoff": 20}
    kept = m.status()["events"]
    assert [e["t"] for e in kept] == [float(k) for k in range(8, 40)]
    assert kept[0]["reason"] == "trip 8" and kept[-1]["reason"] == "note 39"


def test_a_freshness_monitor_trips_once_per_episode_and_again_after_recovery() -> None:
    m = Monitors(MonitorLimits(), cells=6)
    assert m.stale("spinal_silent", True, 1.0, "no imu for 0.11 s")
    assert not m.stale("spinal_silent", True, 1.1, "no imu for 0.21 s")
    assert m.active("spinal_silent") and m.status()["active"] == ["spinal_silent"]
    assert not m.stale("spinal_silent", False, 1.2, "")
    assert not m.active("spinal_silent")
    assert m.stale("spinal_silent", True, 2.0, "no imu for 0.12 s")
    assert m.counts["spinal_silent"] == 2
    assert [e["reason"] for e in m.events] == ["no imu for 0.11 s", "no imu for 0.12 s"]
    # another monitor's recovery does not end this episode
    assert not m.stale("servo_stale", False, 2.1, "")
    assert not m.stale("spinal_silent", True, 2.2, "still")
    assert m.counts["spinal_silent"] == 2


def test_the_battery_window_is_closed_at_both_ends() -> None:
    limits = MonitorLimits()
    m = Monitors(limits, cells=4)
    lo, hi = (4 * c for c in limits.cell_plausible)
    assert m.battery(lo, 0.0) and m.battery(hi, 0.1)
    assert m.voltage == hi
    assert not m.battery(hi + 1e-9, 0.2) and not m.battery(lo - 1e-9, 0.3)
    assert not m.battery(float("nan"), 0.4)
    assert m.voltage == hi and m.counts["battery_implausible"] == 3
    assert m.events[0]["reason"] == f"{hi + 1e-9!r} V outside 12.00..17.80 V (4 cells)"


def test_low_battery_trips_exactly_after_its_delay_and_names_the_pack_threshold() -> None:
    limits = MonitorLimits(low_battery_s=1.0)
    m = Monitors(limits, cells=6)
    assert m.battery(20.9, 10.0)  # below 6 x 3.5 = 21.0 V
    assert not m.battery_low(10.999)
    assert m.battery_low(11.0)  # exactly low_battery_s later
    assert m.events[-1]["reason"] == "20.9 V below 21.00 V"
    assert m.battery(21.0, 11.1) and not m.battery_low(11.1)  # at the threshold: not low
    assert m.battery(20.5, 12.0) and not m.battery_low(12.5)  # the delay starts again


def test_arming_is_refused_below_the_pack_minimum_and_without_a_plausible_reading() -> None:
    m = Monitors(MonitorLimits(), cells=6)
    assert m.arm_refusal() is None  # nothing heard yet: the node's handshake gates arming
    assert not m.battery(5.0, 0.0)
    assert m.arm_refusal() == "no plausible battery reading"
    assert m.battery(21.5, 0.1)
    assert m.arm_refusal() == "battery 21.50 V below 21.60 V"
    assert m.battery(21.6, 0.2) and m.arm_refusal() is None


@pytest.mark.parametrize(
    ("voltages", "cells"),
    [
        ([25.2, 12.0], 6),
        ([16.8], 4),
        ([4.2], 1),
        ([0.5], 1),
        ([], 1),
        ([float("nan"), -3, 0, 8.4], 2),
    ],
)
def test_cell_count_from_the_highest_reference_voltage(voltages, cells) -> None:
    """round(V / 4.2) of the highest finite positive voltage, at least 1; none: 1 cell, so a
    real pack's reading is implausible and arming is refused (the safe side)."""
    assert battery_cells(voltages) == cells


@pytest.mark.parametrize(
    "kwargs",
    [
        {"imu_timeout_s": 0.0},
        {"servo_timeout_s": float("inf")},
        {"low_battery_s": float("nan")},
        {"cell_plausible": (0.0, 4.45)},
        {"cell_plausible": (3.5, 4.45)},  # not below cell_low
        {"cell_low": 3.6},  # not below cell_arm_min
        {"cell_arm_min": 4.46},  # above the plausible top
        {"cell_plausible": (3.0, float("inf")), "cell_arm_min": 3.6},
        {"battery_cells": 0},
        {"battery_cells": 25},
        {"battery_cells": 6.0},
        {"ground_loss_perched": "LAND"},
    ],
)
def test_limits_are_refused_at_their_edges_naming_the_field(kwargs) -> None:
    with pytest.raises(ValueError, match="MonitorLimits"):
        MonitorLimits(**kwargs)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"battery_cells": 1},
        {"battery_cells": 24},
        {"cell_arm_min": 4.45},  # equal to the plausible top: allowed
        {"ground_loss_perched": "land"},
        {"imu_timeout_s": 1e-3},
    ],
)
def test_limits_at_the_allowed_edges_are_taken(kwargs) -> None:
    MonitorLimits(**kwargs)
