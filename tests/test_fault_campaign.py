"""The fault campaign (``rdm sim mission --fault KIND|all --seeds N``) and its byte faults.

* ``CorruptingLink``: on 200,000 zero bytes each fault count is within 5 sigma of its binomial
  mean, every surviving damaged byte has exactly one bit set (one flip, never two), and the
  output length is the input's minus the lost plus the repeated bytes.
* The campaign's rows against each run folder's own ``summary.json`` (read back with
  ``json.loads``): counts of safe ends, detections, outcomes, the fault-to-touchdown times.
  The UART-noise and battery-sag faults must end safe and be detected in every run.
* The plant-side faults (``rdm.scenarios.mission_faults``): IMU outliers at their rate and
  beyond Spinal's ranges, each one dropped by Spinal's estimator (its ``out_of_range``
  counter equals the injected count) and refused by the node (``imu_implausible``, the same
  count), the flight ending safe; a dead rotor (any of the four) gives no
  thrust, the node's ``rotor_lost`` trips within 0.1 s, names the rotor, stops the turn
  (Table V's LQI gains without its row for ``rotor_loss_arrest_s``, a light rotor's
  ``rotor_loss_light_arrest_s``) and cuts the motors, and the ground truth's tilt stays
  under 30 deg down to the floor. A Neuron reset stops rotor 0's ESC for the reboot: the
  same reaction, the rotor back inside the arrest held on the thrust floor, the robot landed.
"""

from __future__ import annotations

import json
import math
import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import rdm
from rdm.nodes.onboard import OnboardNode
from rdm.plant.ceiling import NoCeilingEffect
from rdm.plant.sensors import ImuReading
from rdm.scenarios import mission
from rdm.scenarios.common import roll_pitch, truth_arrays
from rdm.scenarios.mission_faults import (
    SPIKE_ACC,
    SPIKE_GYRO,
    SPIKE_PROBABILITY,
    DeadRotor,
    SpikingImu,
)
from rdm.sim.byte_faults import CorruptingLink


class _Source:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def read_available(self) -> bytes:
        data, self.data = self.data, b""
        return data


def test_byte_faults_follow_their_probability():
    n, p = 200_000, 0.02
    link = CorruptingLink(_Source(bytes(n)), p, seed=3)
    out = np.frombuffer(link.read_available(), dtype=np.uint8)
    c = link.counts()
    sigma = math.sqrt(n * p * (1 - p))
    for key in ("flipped", "lost"):
        assert abs(c[key] - n * p) < 5 * sigma, (key, c)
    kept = n - c["lost"]
    assert abs(c["repeated"] - kept * p) < 5 * math.sqrt(kept * p * (1 - p))
    assert out.size == n - c["lost"] + c["repeated"]
    damaged = out[out != 0]
    assert damaged.size > 0
    assert all(bin(int(b)).count("1") == 1 for b in damaged)  # one bit flipped per byte
    # about the flipped share survives: flips that were not lost, repeated ones twice
    expected = c["flipped"] * (1 - p) * (1 + p)
    assert abs(damaged.size - expected) < 5 * math.sqrt(expected)
    assert CorruptingLink(_Source(b"abc"), 0.0, seed=1).read_available() == b"abc"
    with pytest.raises(ValueError, match="p"):
        CorruptingLink(_Source(b""), 1.5, seed=1)


def _sim(args: list[str], timeout: float = 600) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(Path(rdm.__file__).resolve().parent.parent))
    cmd = [sys.executable, "-m", "rdm.cli", "sim", *args]
    return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout)


@pytest.mark.parametrize("fault", ["uart-noise-1e-3", "battery-sag"])
def test_campaign_rows_are_the_runs_records(tmp_path, fault):
    campaign = ["--fault", fault, "--seeds", "2", "--workers", "2"]
    out = _sim(["mission", *campaign, "--out", str(tmp_path), "--json"])
    assert out.returncode in (0, 1), out.stderr
    doc = json.loads(out.stdout)
    assert doc == json.loads((tmp_path / "faults-mission.json").read_text())
    (row,) = doc["faults"]
    records = [
        json.loads((tmp_path / f"mission-{fault}-seed{k}" / "summary.json").read_text())["mission"]
        for k in (0, 1)
    ]
    assert row["runs"] == row["completed"] == 2 and not row["failed_runs"]
    assert row["safe"] == sum(r["safe"] for r in records)
    assert row["detected"] == sum(bool(r["fault_detected"]) for r in records)
    assert row["outcomes"] == {
        o: sum(r["outcome"] == o for r in records) for o in {r["outcome"] for r in records}
    }
    times = [r["touchdown_s"] - r["fault_at_s"] for r in records if r["outcome"] == "landed"]
    assert row["fault_to_touchdown_s"]["max"] == pytest.approx(max(times))
    assert row["max_tilt_deg"] == max(r["max_tilt_deg"] for r in records)
    detect = [r["detected_at_s"] - r["fault_at_s"] for r in records if r["detected_at_s"]]
    if detect:  # battery-sag: the node's battery_low monitor
        assert row["fault_to_detection_s"]["max"] == pytest.approx(max(detect))
    # the safety claim: every run ends safe and the node noticed the fault
    assert row["safe"] == 2 and row["detected"] == 2 and out.returncode == 0
    assert all(r["fault"] == fault and r["fault_at_s"] > 0 for r in records)


def test_campaign_refuses_bad_options():
    for args in (
        ["hover", "--fault", "all", "--seeds", "2"],
        ["mission", "--fault", "x", "--seeds", "2"],
    ):
        out = _sim(args, timeout=120)
        assert out.returncode == 2 and "--fault" in out.stderr and "Traceback" not in out.stderr


def test_imu_spikes_are_rare_outliers_beyond_the_sensor_range():
    clean = ImuReading(np.array([0.1, -0.2, 0.3]), np.array([0.0, 0.0, 9.8]), np.ones(3), False)
    imu = SpikingImu(lambda: clean, seed=4)
    n = 40_000
    samples = [imu() for _ in range(n)]
    changed = [r for r in samples if r is not clean]
    assert len(changed) == imu.spikes
    sigma = math.sqrt(n * SPIKE_PROBABILITY * (1 - SPIKE_PROBABILITY))
    assert abs(imu.spikes - n * SPIKE_PROBABILITY) < 5 * sigma
    for r in changed:  # one gyro and one accelerometer axis beyond the range, the rest kept
        g = np.abs(r.gyro) == SPIKE_GYRO
        a = np.abs(r.accel) == SPIKE_ACC
        assert g.sum() == 1 and a.sum() == 1
        assert np.array_equal(r.gyro[~g], clean.gyro[~g])
        assert np.array_equal(r.accel[~a], clean.accel[~a])
        assert np.array_equal(r.mag, clean.mag)
    assert SPIKE_GYRO > 34.91 and SPIKE_ACC > 78.5  # Spinal's estimator ranges
    assert DeadRotor(NoCeilingEffect()).thrust_ratio(0.3) == 0.0


def test_imu_spikes_mission_ends_safe_and_each_spike_is_dropped(tmp_path):
    result = mission.run(
        tmp_path, duration=mission.QUICK_DURATION, seed=0, fault="imu-spikes", quick=True
    )
    record, stack = result.facts["mission"], result.stack
    spikes = stack.plant.imu.spikes
    assert spikes > 10  # the injection ran: about 3 a second after the fault
    # every outlier reached Spinal's estimator and was dropped there, no other sample was
    assert stack.spinal.core.estimator_counters["out_of_range"] == spikes
    # and its accelerometer value, published on ``imu``, was refused by the node: each one,
    # no other reading (the first of each run of refusals logged)
    assert stack.onboard.monitors.counts["imu_implausible"] == spikes
    assert record["monitors"]["imu_implausible"] == spikes
    assert record["fault_at_s"] < record["detected_at_s"] < record["fault_at_s"] + 2.0
    assert record["safe"] and record["fault_detected"] and record["outcome"] == "landed"


def test_dead_esc_is_detected_cut_and_falls_upright(tmp_path):
    result = mission.run(
        tmp_path, duration=mission.QUICK_DURATION, seed=0, fault="dead-esc", quick=True
    )
    record, stack = result.facts["mission"], result.stack
    assert isinstance(stack.plant.ceiling_effects[0], DeadRotor)
    node = stack.onboard
    at = record["fault_at_s"]
    # detected by the node within 0.1 s (without the reaction the robot rolls past 30 deg
    # 0.14 s after the fault and lands upside down), then the motors cut
    assert at < record["detected_at_s"] <= at + 0.1
    assert node.monitors.counts["rotor_lost"] == 1
    assert node.monitors.counts["rotor_lost_cut"] == 1
    # Table V's LQI gains go to Spinal at the detection (the arrest), the cut after it
    arrest = node.config.monitors.rotor_loss_arrest_s
    assert node.counts["rotor_lost_fall"] == 1
    cut_after = node.monitors.first_trip["rotor_lost_cut"] - record["detected_at_s"]
    assert arrest - 1e-6 <= cut_after <= arrest + 1e-6
    # the ground truth, not the record: tilt while airborne and the resting height
    a = truth_arrays(stack)
    floor = a["cog"][np.searchsorted(a["t"], mission.ARM_AT) - 1, 2]
    airborne = a["cog"][:, 2] > floor + 0.05
    tilt = np.degrees(np.abs(roll_pitch(a["quat"][airborne]))).max()
    assert tilt <= mission.MAX_TILT_DEG
    assert abs(a["cog"][-1, 2] - floor) < 0.05
    assert not stack.spinal.core.armed and node.state.value == "idle"
    # Spinal's own tilt fail-safe (57 deg) never had to act
    assert not stack.spinal.counters.failsafes["failsafe_tilt"]
    assert record["fault_detected"] and record["safe"] and record["outcome"] == "landed"


@pytest.mark.parametrize("rotor", [1, 2, 3])
def test_any_dead_rotor_is_detected_named_and_cut_upright(tmp_path, monkeypatch, rotor):
    """A dead rotor 1 (as heavy as rotor 0: the specific force drops) or 2, 3 (3.8 N: the
    attitude alone shows it): the node names it, arrests the turn without it and cuts; the
    ground truth stays under 30 deg down to the floor."""
    monkeypatch.setattr(mission, "DEAD_ROTOR", rotor)
    record, stack = _quick(tmp_path, "dead-esc")
    assert isinstance(stack.plant.ceiling_effects[rotor], DeadRotor)
    effects = stack.plant.ceiling_effects
    assert sum(isinstance(e, DeadRotor) for e in effects) == 1
    node, at = stack.onboard, record["fault_at_s"]
    assert node.monitors.counts["rotor_lost"] == 1 and node.lost_rotor == rotor
    assert node.lost_heavy == (rotor == 1)
    lim = node.config.monitors
    arrest = lim.rotor_loss_arrest_s if rotor == 1 else lim.rotor_loss_light_arrest_s
    cut_after = node.monitors.first_trip["rotor_lost_cut"] - record["detected_at_s"]
    assert at < record["detected_at_s"] <= at + 0.1
    assert arrest - 1e-6 <= cut_after <= arrest + 1e-6
    a = truth_arrays(stack)
    floor = a["cog"][np.searchsorted(a["t"], mission.ARM_AT) - 1, 2]
    airborne = a["cog"][:, 2] > floor + 0.05
    assert np.degrees(np.abs(roll_pitch(a["quat"][airborne]))).max() <= mission.MAX_TILT_DEG
    assert abs(a["cog"][-1, 2] - floor) < 0.05
    assert not stack.spinal.core.armed and node.state.value == "idle"
    assert record["fault_detected"] and record["safe"] and record["outcome"] == "landed"


def test_the_help_names_every_fault() -> None:
    """``rdm sim --help`` (written out so the parser imports no scenario) lists each fault
    of ``mission.FAULTS``."""
    import argparse
    import re

    from rdm.commands.sim import add_arguments
    from rdm.scenarios.mission import FAULTS

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    # (a name wrapped at one of its hyphens is joined again)
    text = " ".join(re.sub(r"-\n\s*", "-", parser.format_help()).split())
    named = set(re.findall(r"[a-z]+(?:-[a-z0-9]+(?:\.[0-9]+)?)+", text))
    assert set(FAULTS) - {"none"} <= named


def _perched_run(tmp_path, fault: str):
    result = mission.run(tmp_path, duration=mission.DEFAULT_DURATION, seed=1, fault=fault)
    return result.facts["mission"], truth_arrays(result.stack), result.stack


def test_stuck_servo_is_held_perched_where_it_stuck(tmp_path):
    record, a, stack = _perched_run(tmp_path, "stuck-servo")
    j = list(stack.plant.joint_names).index(mission.STUCK_JOINT)
    t, q = a["t"], a["q"][:, j]
    at = record["fault_at_s"]
    after = t > at + 0.05
    # the ground truth: the shaft stays where it was while the goal moved on (stiff servo:
    # within a few mrad under the arm's load); the other moved joint (q2) did move
    assert np.ptp(q[after]) < 0.01
    q2 = a["q"][:, list(stack.plant.joint_names).index("q2")]
    assert abs(q2[-1] - q2[np.searchsorted(t, at)]) > 0.05
    node = stack.onboard
    trip = [e for e in node.monitors.events if e["monitor"] == "joint_tracking"]
    assert len(trip) == 1 and at < trip[0]["t"] < at + 2.0
    # held where they are: the goals sent equal the present angles again, to the one
    # encoder count (2 pi / 4096) a loaded joint's reading may flicker by after the hold
    # (a goal left moving is off by the > 0.05 rad q2 moved above)
    count = 2.0 * np.pi / 4096
    np.testing.assert_allclose(node.joint_targets[:6], node.present_q[:6], atol=1.01 * count)
    assert node.counts["joint_tracking_hold"] == 1
    assert record["outcome"] == "perched" and record["safe"] and record["fault_detected"]
    assert a["contact"][t > at].all()


def test_infeasible_qp_is_held_perched_and_the_problem_has_no_solution(tmp_path):
    from scipy.optimize import linprog

    record, a, stack = _perched_run(tmp_path, "infeasible-qp")
    node = stack.onboard
    perch = node.control.perch
    assert perch.params()["mu_x"] == perch.params()["mu_y"] == mission.INFEASIBLE_MU
    # an independent solver on the last tick's QP rows: no point satisfies them
    prob = perch.problem_data()
    z = prob.zero_cone
    A = prob.A.toarray()
    lp = linprog(
        np.zeros(A.shape[1]),
        A_ub=A[z:],
        b_ub=prob.b[z:],
        A_eq=A[:z] if z else None,
        b_eq=prob.b[:z] if z else None,
        bounds=(None, None),
        method="highs",
    )
    assert lp.status == 2, lp.message  # infeasible
    assert perch.counters()["infeasible"] > 0
    assert node.last_command.perch.status == "infeasible"
    trip = [e for e in node.monitors.events if e["monitor"] == "perch_qp_failed"]
    at = record["fault_at_s"]
    limit = node.config.monitors.perch_qp_fail_s
    assert len(trip) == 1 and at + limit - 0.05 < trip[0]["t"] < at + limit + 0.1
    assert node.counts["perch_qp_failed_hold"] == 1
    assert record["outcome"] == "perched" and record["safe"] and record["fault_detected"]
    assert a["contact"][a["t"] > at].all()


def _candump(path: Path) -> tuple[np.ndarray, list[int]]:
    """Stamps and ids of a ``candump -L`` file, parsed here (not by the package)."""
    stamps, ids = [], []
    for line in path.read_text().splitlines():
        stamp, _, frame = line.split()[:3]
        stamps.append(float(stamp.strip("()")))
        ids.append(int(frame.split("#")[0], 16))
    return np.array(stamps), ids


def _quick(tmp_path, fault: str):
    result = mission.run(tmp_path, duration=mission.QUICK_DURATION, seed=0, fault=fault, quick=True)
    return result.facts["mission"], result.stack


def test_can_bus_off_silences_the_bus_for_the_disturbance_and_the_recovery_bits(tmp_path):
    record, stack = _quick(tmp_path, "can-bus-off")
    stamps, _ = _candump(stack.folder.candump)
    at = record["fault_at_s"]
    flying = stamps > mission.ARM_AT + 0.5  # the CAN master's enumeration is over
    stamps = stamps[flying]
    gaps = np.diff(stamps)
    k = int(np.argmax(gaps))  # the longest silence from then on is the bus-off
    silence = mission.BUS_OFF_S + 128 * 11 / 1e6
    assert stamps[k] <= at + 1e-3 < stamps[k + 1]
    # the bus carries nothing from the fault until 1.408 ms after the disturbance (the next
    # 1 kHz tick after it), then Spinal's and the Neurons' frames flow as before
    assert silence <= stamps[k + 1] - at < silence + 1.5e-3
    assert np.sort(gaps)[-2] < 0.01
    counters = stack.spinal.master.wire.wire.fault_counters()
    # 21.4 ms of Spinal's schedule lost: 10 PWM broadcasts, 10 angle + current pairs, replies
    assert counters["bus_off"] == 1 and counters["bus_off_lost"] >= 30
    assert record["fault_detected"] and record["safe"] and record["outcome"] == "landed"


def test_a_bus_off_past_the_watchdog_reaches_the_node_as_spinals_log(tmp_path, monkeypatch):
    """150 ms of bus-off: Spinal's "CAN disconnected!!" logerror (no frame for 100 ms) reaches
    the node, which trips ``can_disconnected`` and lands; the Neurons' own 100 ms watchdog
    stops every motor at once for the rest of the gap (no moment from it), and from the
    mission's quiet hover the robot falls, recovers and lands safe. The fall drops the
    specific force (the lost-rotor thrust condition) but turns the robot too slowly for the
    rate condition: no ``rotor_lost``, no cut (docs/flying.md "A lost rotor")."""
    monkeypatch.setattr(mission, "BUS_OFF_S", 0.15)
    record, stack = _quick(tmp_path, "can-bus-off")
    at = record["fault_at_s"]
    trips = [e for e in stack.onboard.monitors.events if e["monitor"] == "can_disconnected"]
    assert len(trips) == 1
    # 100 ms without a frame, then Spinal's next ms, the UART and the node's 25 ms tick
    assert 0.1 < trips[0]["t"] - at < 0.1 + 0.035
    assert stack.onboard.counts["can_disconnected_land"] == 1
    assert "rotor_lost" not in stack.onboard.monitors.counts
    assert record["safe"] and record["outcome"] == "landed"


def _pwm_values(data: bytes) -> list[int]:
    """The six 10-bit values of a Neuron PWM frame, unpacked here from the fact sheet's layout
    (sec. 2.4: LSB first, 3 values per 4 bytes), not by the package."""
    bits = int.from_bytes(data[:4], "little") | int.from_bytes(data[4:8], "little") << 32
    return [(bits >> (10 * i + 2 * (i // 3))) & 0x3FF for i in range(6)]


def test_pwm_unpacking_matches_the_fact_sheet_layout():
    # d0 = v0[7:0], d1 = v1[5:0]<<2 | v0[9:8], d2 = v2[3:0]<<4 | v1[9:6], d3 = v2[9:4]
    v = [788, 658, 199, 461, 1, 1000]
    frame = bytearray()
    for a, b, c in (v[:3], v[3:]):
        frame += bytes([a & 0xFF, (b & 0x3F) << 2 | a >> 8, (c & 0xF) << 4 | b >> 6, c >> 4])
    assert _pwm_values(bytes(frame)) == v


def test_a_50_ms_bus_off_leaves_the_escs_on_one_held_pulse_and_the_quiet_hover_survives(
    tmp_path, monkeypatch
):
    """50 ms of bus-off, seed 1: the Neurons hold the last PWM frame's pulse (below their
    100 ms watchdog, fact sheet sec. 2.6), so the truth's rotor thrusts settle on it, none
    stopped, ranked as the held pulses. The hover it interrupts is quiet (the mission's LQI
    roll weights, ``lqi.ROLL_DAMPED_Q``): the PWM broadcast of the 3 s before the fault,
    read from the candump, moves by less than 20 us (std) per rotor (Table V's weights: a
    12 Hz swing of 49-87 us), so the held pulse is near the hover's and the run lands."""
    monkeypatch.setattr(mission, "BUS_OFF_S", 0.05)
    result = mission.run(
        tmp_path, duration=mission.QUICK_DURATION, seed=1, fault="can-bus-off", quick=True
    )
    record, stack = result.facts["mission"], result.stack
    at = record["fault_at_s"]
    frames = []
    for line in stack.folder.candump.read_text().splitlines():
        stamp, _, frame = line.split()[:3]
        can_id, data = frame.split("#")
        if int(can_id, 16) == 0x00F:  # MOTOR device, msg 0, broadcast: slaves 1-6
            frames.append((float(stamp.strip("()")), _pwm_values(bytes.fromhex(data))[:4]))
    stamps = np.array([f[0] for f in frames])
    k = int(np.searchsorted(stamps, at + 1e-3, side="right")) - 1  # the last before the gap
    held, after = np.array(frames[k][1]), np.array(frames[k + 1][1])
    assert stamps[k + 1] - at >= mission.BUS_OFF_S + 128 * 11 / 1e6
    before = np.array([f[1] for f in frames if at - 3.0 <= f[0] < at])
    assert len(before) > 1400  # every 2 ms
    assert before.std(axis=0).max() < 20.0
    assert np.abs(held - before.mean(axis=0)).max() < 60.0
    a = truth_arrays(stack)
    t = a["t"]
    # MuJoCo's rotor thrusts over the 0.5 s before the fault: each below 0.3 N (std)
    hover = a["thrust"][(t > at - 0.5) & (t < at)]
    assert len(hover) >= 49 and hover.std(axis=0).max() < 0.3
    late = a["thrust"][np.searchsorted(t, at + 0.04) : np.searchsorted(t, at + 0.05) + 1]
    assert len(late) == 2  # 10 ms truth samples inside the gap, the rotors settled on it
    assert np.abs(late[1] - late[0]).max() < 0.1
    assert late[1].min() > 0.5  # no motor stopped (the watchdog is 100 ms)
    assert list(np.argsort(late[1])) == list(np.argsort(held))
    assert np.abs(after - held).max() < 100
    assert record["safe"] and record["outcome"] == "landed"


def test_can_loss_drops_its_share_of_the_pwm_broadcasts(tmp_path):
    record, stack = _quick(tmp_path, "can-loss-1e-1")
    stamps, ids = _candump(stack.folder.candump)
    at = record["fault_at_s"]
    pwm = np.array([i == 0x00F for i in ids])
    window = 4.0  # s after the fault: Spinal broadcasts PWM every 2 ms
    before = ((stamps >= at - window - 0.5) & (stamps < at - 0.5) & pwm).sum()
    after = ((stamps >= at + 0.01) & (stamps < at + 0.01 + window) & pwm).sum()
    assert before == pytest.approx(window * 500, abs=2)  # none lost before the fault
    expected = before * (1 - mission.CAN_LOSS["can-loss-1e-1"])
    sigma = math.sqrt(before * 0.1 * 0.9)
    assert abs(after - expected) < 5 * sigma, (before, after)
    counters = stack.spinal.master.wire.wire.fault_counters()
    assert counters["error_frames"] == counters["lost"] >= before - after
    assert record["fault_detected"] and record["safe"] and record["outcome"] == "landed"


def test_neuron_reset_is_detected_the_board_comes_back_and_the_robot_lands(tmp_path, monkeypatch):
    # every rpy/gain payload the node puts on the Spinal UART, with the node's time
    gains: list[tuple[float, bytes]] = []
    publish = OnboardNode._publish_payload

    def spy(node, topic, payload):
        if topic == "rpy/gain":
            gains.append((node._now, bytes(payload)))
        return publish(node, topic, payload)

    monkeypatch.setattr(OnboardNode, "_publish_payload", spy)
    record, stack = _quick(tmp_path, "neuron-reset")
    at = record["fault_at_s"]
    k = mission.RESET_BOARD
    board = stack.neurons[k].state()
    slave = board["slave_id"]
    # the candump, parsed here: the board's servo-state replies (DLC 8 on SERVO ids from its
    # slave id) stop for its reboot time, then come back
    replies = []
    for line in stack.folder.candump.read_text().splitlines():
        stamp, _, frame = line.split()[:3]
        can_id, data = frame.split("#")
        ident = int(can_id, 16)
        if ident >> 8 == 2 and ident & 0xF == slave and len(data) == 16:
            replies.append(float(stamp.strip("()")))
    replies = np.array(replies)
    gaps = np.diff(replies[replies > mission.ARM_AT + 0.5])
    # 100 ms of reboot, plus up to 8 ms on each side: the board is asked every 8 ms (four
    # Neurons, one servo-angle frame on every second ms)
    assert 0.1 <= gaps.max() <= 0.116
    silent_from = replies[replies > mission.ARM_AT + 0.5][int(np.argmax(gaps))]
    assert at - 0.009 < silent_from <= at
    # back at power-on and turned on again by Spinal's torque bits (the goal-sync handshake)
    assert board["reboots"] == 1 and not board["rebooting"] and board["connected"]
    assert all(s["torque_enable"] for s in board["servos"])
    reporting = sum(1 for s in board["servos"] if s["config"]["send_data_flag"])
    assert stack.spinal.master.goal_resyncs >= reporting > 0
    # the ESC stopped meanwhile: rotor 0's true thrust near zero 40-90 ms after the reset
    # (the rotor's 10 ms lag)
    a = truth_arrays(stack)
    window = (a["t"] > at + 0.04) & (a["t"] < at + 0.09)
    assert a["thrust"][window, 0].max() < 0.5
    # rotor 0 without thrust rolls the robot: the node's lost-rotor detection names it and
    # cuts (docs/flying.md "A lost rotor")
    node = stack.onboard
    assert node.monitors.counts["rotor_lost"] == 1
    assert node.monitors.counts["rotor_lost_cut"] == 1
    detected = node.monitors.first_trip["rotor_lost"]
    cut = node.monitors.first_trip["rotor_lost_cut"]
    assert node.lost_rotor == 0 and at < detected <= at + 0.05

    # rotor 0 comes back inside the arrest: the rpy/gain rows sent from the detection to the
    # cut (decoded here from the wire layout: uint32 count, then roll_p, roll_i, roll_d,
    # pitch_p, pitch_i, pitch_d, yaw_d as int16 per motor) have rotor 0's roll and pitch
    # terms zero and the other rotors' not; before the fault every row is whole
    def rows(payload: bytes) -> np.ndarray:
        (count,) = struct.unpack_from("<I", payload)
        return np.frombuffer(payload, "<i2", count * 7, 4).reshape(count, 7)

    # the detection's tick: its last payload (a synthesis may have sent whole rows before the
    # trip in the same tick), then every one up to the cut
    at_trip = [rows(p) for t, p in gains if t == detected]
    arrest = at_trip[-1:] + [rows(p) for t, p in gains if detected < t < cut]
    assert at_trip
    for r in arrest:
        assert not r[0, :6].any() and r[1:, :6].any(axis=1).all()
    before = [rows(p) for t, p in gains if t < at]
    assert before and before[-1][:, :6].any(axis=1).all()
    # the ground truth: tilt in the air under 30 deg, disarmed on the floor
    floor = a["cog"][np.searchsorted(a["t"], mission.ARM_AT) - 1, 2]
    airborne = a["cog"][:, 2] > floor + 0.05
    assert np.degrees(np.abs(roll_pitch(a["quat"][airborne]))).max() <= mission.MAX_TILT_DEG
    assert abs(a["cog"][-1, 2] - floor) < 0.05
    assert record["fault_detected"] and record["safe"] and record["outcome"] == "landed"


def test_no_goal_resync_without_a_fault(tmp_path):
    record, stack = _quick(tmp_path, "none")
    assert stack.spinal.master.goal_resyncs == 0 and record["safe"]
