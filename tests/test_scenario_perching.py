"""The perching scenario (Fig. 10) end to end through every wire: physical outcomes from
MuJoCo's ground truth, the perching QP's status in the MCAP log."""

from __future__ import annotations

import json

import numpy as np
import pytest
from mcap.reader import make_reader

from rdm.scenarios import perching
from rdm.scenarios.common import roll_pitch, truth_arrays

#: one arm motion while perched (the default has three) keeps the run short
SHORT_MOTION = ((3.0, (1.5708, -0.9, 0.3, 0.5, 0.0, 0.0)),)


#: the perching controller's own ZMP of each perched tick of the shared run, sampled by the
#: scenario's observer: t, zmp x, y (foot frame), margin x, y (eq. 42) [m]
PROBE: list[tuple[float, float, float, float, float]] = []


def _probe_perch_zmp(stack, now: float) -> None:
    c = stack.onboard.last_command
    p = getattr(c, "perch", None) if c is not None else None
    if p is not None:
        PROBE.append((now, *p.zmp, *p.zmp_margin))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    base = tmp_path_factory.mktemp("perching")
    PROBE.clear()
    res = perching.run(base, duration=23.0, motion=SHORT_MOTION, observer=_probe_perch_zmp)
    return res, truth_arrays(res.stack)


def test_perches_and_holds_without_slip(run):
    res, a = run
    t_perch = res.facts["t_perch"]
    assert t_perch is not None, "never touched the ceiling"
    assert res.facts["final_phase"] == "hold"
    held = a["t"] >= t_perch + 0.5
    assert held.sum() > 500
    assert a["contact"][held].all(), "the foot left the ceiling"
    slip = a["slip"][held]
    assert np.max(np.linalg.norm(slip - slip[0], axis=1)) < 1e-3  # < 1 mm
    # the foot really is at the ceiling (1.6 m), plate level
    assert abs(a["foot"][held, 2].mean() - 1.6) < 0.01


def test_fold_holds_spinal_integration_and_perches_with_a_small_integral(run):
    """The hanging configuration stops Spinal's roll/pitch integration while the fold turns
    the root link (161, then 160) and perches with a small pitch integral (without the hold
    the fold leaves about 0.5 rad s, docs/scenarios.md). Bugs caught: the scenario flown
    without the hold; a hold never resumed."""
    res, _ = run
    node, core = res.stack.onboard, res.stack.spinal.core
    assert node.counts["rp_integration_held"] >= 1
    assert node.counts["rp_integration_resumed"] == node.counts["rp_integration_held"]
    assert core.integrating
    assert abs(core.error_integral[1]) < 0.1


def test_contact_wrench_inside_friction_and_zmp_limits(run):
    res, a = run
    held = a["t"] >= res.facts["t_perch"] + perching.SETTLE_S
    f, m, zmp = a["force"][held], a["torque"][held], a["zmp"][held]
    fz = f[:, 2]
    assert np.all(fz > 1.0)  # eq. (39)
    assert np.all(np.hypot(f[:, 0], f[:, 1]) < perching.MU[0] * fz)  # eq. (40)
    assert np.all(np.abs(m[:, 2]) < perching.MU[2] * fz)  # eq. (41)
    # off the edge most of the time (a centre of pressure of contact forces is always on the
    # plate; a tipping plate holds it on an edge)
    inner = (np.abs(zmp[:, 0]) < 0.049) & (np.abs(zmp[:, 1]) < 0.074)
    assert inner.mean() > 0.9


def test_controller_zmp_agrees_with_the_contact_centre_of_pressure(run):
    """The perching controller's own ZMP (eqs. 42-44 from the foot wrench it commands) keeps
    its eq. (42) margin and agrees with MuJoCo's contact-force centre of pressure: over the
    settled perch to 5 mm, over every 0.5 s to 2 cm; the contact CoP, averaged over 0.5 s
    (the contact solver's chatter), stays 1 cm off every plate edge (a tipping plate holds it
    on an edge). A sign error in the controller's ZMP moves its mean by about 1 cm."""
    res, a = run
    t0 = res.facts["t_perch"] + perching.SETTLE_S
    probe = np.array(PROBE)
    probe = probe[probe[:, 0] >= t0]
    held = a["t"] >= t0
    t, cop = a["t"][held], a["zmp"][held]
    assert len(probe) > 200 and held.sum() > 400
    assert np.all(probe[:, 3:5] >= -1e-9), probe[:, 3:5].min(axis=0)  # eq. (42)
    np.testing.assert_allclose(probe[:, 1:3].mean(axis=0), cop.mean(axis=0), atol=5e-3)
    half = np.asarray(perching.PLATE_HALF)
    for start in np.arange(t[0], t[-1] - 0.5, 0.5):
        ours = probe[(probe[:, 0] >= start) & (probe[:, 0] < start + 0.5), 1:3]
        truth = cop[(t >= start) & (t < start + 0.5)]
        np.testing.assert_allclose(ours.mean(axis=0), truth.mean(axis=0), atol=0.02)
        assert np.all(half - np.abs(truth.mean(axis=0)) > 0.01), (start, truth.mean(axis=0))


def test_arm_moves_while_perched_and_nothing_fails(run):
    res, a = run
    goal = np.array(SHORT_MOTION[-1][1])
    assert np.max(np.abs(a["q"][-1, :6] - goal)) < 0.03
    assert not res.stack.spinal.counters.failsafes
    assert np.all(a["thrust"] <= 20.0 * 1.5)  # rotor limit x the ceiling-effect ceiling
    counts = res.facts["perch_status_counts"]
    assert counts.get("solved", 0) > 0 and set(counts) <= {"solved", "almost_solved"}


def test_mcap_carries_the_perching_qp_status(run):
    res, _ = run
    statuses = []
    with open(res.folder / "signals.mcap", "rb") as fh:
        for _schema, channel, message in make_reader(fh).iter_messages():
            if channel.topic == "/onboard/status":
                statuses.append(json.loads(message.data)["perch_status"])
    assert "solved" in statuses
    assert statuses[0] is None  # flight before perching
    summary = json.loads((res.folder / "summary.json").read_text())
    assert summary["metrics"]


def test_infeasible_perching_qp_is_logged_and_the_command_stays_safe(tmp_path):
    """A normal-force floor the rotors cannot reach (epsilon_z = 25 N: the foot rotors have
    ~18 N of spare thrust over hover, eq. 47) makes every perching QP infeasible, with or
    without eq. (48): the status is in the MCAP and the counters, the safe command keeps
    every rotor inside [0, thrust_max], Spinal sees no bad command."""

    onboard = perching.onboard_config(perch_params={"epsilon_z": 25.0})
    res = perching.run(tmp_path, duration=17.0, motion=SHORT_MOTION, onboard=onboard)
    assert res.facts["t_perch"] is not None
    counts = res.facts["perch_status_counts"]
    assert counts.get("infeasible", 0) > 20, counts
    assert res.stack.onboard.control.counts["perch_infeasible"] > 20  # counted by the node
    logged = []
    with open(res.folder / "signals.mcap", "rb") as fh:
        for _schema, channel, message in make_reader(fh).iter_messages():
            if channel.topic == "/onboard/status":
                rec = json.loads(message.data)
                if rec["perch_status"] is not None:
                    logged.append(rec)
    assert any(r["perch_status"] == "infeasible" for r in logged)
    for r in logged:
        assert all(0.0 <= b <= 20.0 for b in r["base_thrust"])
    assert not res.stack.spinal.counters.rejected


def _settled_tilt_and_edge(res, a) -> tuple[float, float]:
    """Over the settled perch (from SETTLE_S after the switch): the largest truth roll/pitch
    of the foot [deg] and the fraction of samples with the ZMP within 1 mm of a y edge."""
    held = a["t"] >= res.facts["t_perch"] + perching.SETTLE_S
    tilt = np.degrees(np.abs(roll_pitch(a["quat"][held])).max(axis=1))
    on_edge = np.abs(a["zmp"][held, 1]) > perching.PLATE_HALF[1] - 1e-3
    return float(tilt.max()), float(on_edge.mean())


@pytest.mark.parametrize("calibrated", [True, False])
def test_seed_1_plate_lies_flat_with_the_calibrated_imu(tmp_path, calibrated):
    """Seed 1's accelerometer bias reads as 0.8 deg of roll. With Spinal's flash holding the
    calibration (the default) the settled plate lies flat; without it the attitude loop
    rocks the plate on its y edges for seconds after the contact (the counter-check)."""
    res = perching.run(
        tmp_path, duration=19.0, seed=1, motion=(), log=False, imu_acc_calibrated=calibrated
    )
    assert res.facts["t_perch"] is not None
    tilt, edge = _settled_tilt_and_edge(res, truth_arrays(res.stack))
    if calibrated:
        assert tilt < 0.1 and edge < 0.02, (tilt, edge)
    else:
        assert tilt > 0.3 and edge > 0.2, (tilt, edge)


def test_setpoint_ramp_distance_is_numpys_norm() -> None:
    """``SetpointRamp.step``'s distance (``sqrt(d.dot(d))``) against ``np.linalg.norm`` on
    random vectors, and ``arrived`` against ``np.all(position == goal)``."""
    from rdm.scenarios.common import SetpointRamp

    rng = np.random.default_rng(3)
    for _ in range(500):
        start, goal = rng.normal(size=3) * rng.choice([1e-6, 1.0, 1e3]), rng.normal(size=3)
        speed, dt = float(rng.uniform(0.01, 2.0)), 0.01
        ramp = SetpointRamp(start, speed)
        ramp.set_goal(goal)
        delta = goal - start
        dist = float(np.linalg.norm(delta))
        ramp.step(dt)
        reach = speed * dt
        want = goal if dist <= reach else start + delta / dist * reach
        assert ramp.position.tobytes() == np.asarray(want, dtype=float).tobytes()
        assert ramp.arrived == bool(np.all(ramp.position == ramp.goal))
    ramp = SetpointRamp(np.array([0.0, -0.0, 1.0]), 1.0)
    ramp.set_goal(np.array([-0.0, 0.0, 1.0]))
    assert ramp.arrived  # -0.0 == 0.0, as numpy compares
    ramp.set_goal(np.array([np.nan, 0.0, 1.0]))
    assert not ramp.arrived
