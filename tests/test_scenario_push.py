"""The push scenario (Figs. 11-12): an external force at the end effector, in flight and
perched, through every wire. Outcomes from MuJoCo's ground truth and its end-effector force
sensor; one default run shared by the module."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.spatial.transform import Rotation

from rdm.scenarios import push
from rdm.scenarios.common import truth_arrays

#: the default plan (2.5 s quiet, x, y, z pushes of 2.5 s, 1.5 s apart): the perched scales
#: hold for 2.5 s push-pulls (a 1.5 s one outruns the foot-wrench filter), and the flying
#: robot needs the 1.5 s gaps (with 0.5 s ones the y push meets the x push's swing)
PLAN = push.DEFAULT_PLAN


#: the perching controller's own ZMP of each perched tick of the shared run (the scenario's
#: observer): t, zmp x, y (foot frame), margin x, y (eq. 42) [m]
PROBE: list[tuple[float, float, float, float, float]] = []


def _probe_perch_zmp(stack, now: float) -> None:
    c = stack.onboard.last_command
    p = getattr(c, "perch", None) if c is not None else None
    if p is not None:
        PROBE.append((now, *p.zmp, *p.zmp_margin))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    PROBE.clear()
    res = push.run(
        tmp_path_factory.mktemp("push"), plan=PLAN, log=False, plots=False,
        observer=_probe_perch_zmp,
    )  # fmt: skip
    return res, truth_arrays(res.stack)


def _window(a, w):
    return (a["t"] >= w[0]) & (a["t"] <= w[1])


def test_both_stages_ran_and_nothing_failed(run):
    res, a = run
    script = res.script
    assert script.t_flight_stage is not None and script.t_perched_stage is not None
    assert script.phase == "done"
    assert not res.stack.spinal.counters.failsafes
    # airborne through the flight stage: the foot well above the floor and below the ceiling
    fl = _window(a, push.stage_windows(PLAN, script.t_flight_stage + PLAN.move_s)["pushes"])
    assert a["foot"][fl, 2].min() > 0.4 and a["foot"][fl, 2].max() < 1.5
    assert not a["contact"][fl].any()


def test_push_makes_the_flying_robot_drift(run):
    res, a = run
    w = push.stage_windows(PLAN, res.script.t_flight_stage + PLAN.move_s)
    pushed, quiet = _window(a, w["pushes"]), _window(a, w["quiet"])
    foot = a["foot"]
    std_pushed = np.std(foot[pushed], axis=0)
    std_quiet = np.std(foot[quiet], axis=0)
    # the unobserved push moves the root: several times the hover scatter, centimetres
    assert np.linalg.norm(std_pushed) > 3 * np.linalg.norm(std_quiet)
    excursion = np.linalg.norm(foot[pushed] - foot[quiet].mean(axis=0), axis=1).max()
    assert excursion > 0.01


def test_perched_robot_holds_the_push(run):
    res, a = run
    w = push.stage_windows(PLAN, res.script.t_perched_stage)
    pushed = _window(a, w["pushes"])
    assert a["contact"][pushed].all(), "the foot left the ceiling under the push"
    slip = a["slip"][pushed]
    assert np.max(np.linalg.norm(slip - slip[0], axis=1)) < 1e-3
    # the perched root barely moves, far less than the flying one
    fl = push.stage_windows(PLAN, res.script.t_flight_stage + PLAN.move_s)
    std_perched = np.linalg.norm(np.std(a["foot"][pushed], axis=0))
    std_flight = np.linalg.norm(np.std(a["foot"][_window(a, fl["pushes"])], axis=0))
    assert std_perched < 0.1 * std_flight
    # Table IX: the perched foot scatters less than the paper's on every axis (the plate
    # does not rock under pushes its QP can hold)
    assert np.all(np.std(a["foot"][pushed], axis=0) < np.asarray(push.PAPER_FOOT_STD_PERCHED))


def test_perched_controller_zmp_agrees_with_the_contact_centre_of_pressure(run):
    """Under the perched pushes the perching controller's own ZMP (eqs. 42-44) keeps its
    eq. (42) margin and agrees with MuJoCo's contact-force centre of pressure: over the
    pushes to 3 mm, over every 0.5 s to 2 cm; the contact CoP averaged over 0.5 s stays 2 mm
    off every plate edge (a plate rocking on an edge holds it there)."""
    res, a = run
    lo, hi = push.stage_windows(PLAN, res.script.t_perched_stage)["pushes"]
    probe = np.array(PROBE)
    probe = probe[(probe[:, 0] >= lo) & (probe[:, 0] <= hi)]
    pushed = _window(a, (lo, hi))
    t, cop = a["t"][pushed], a["zmp"][pushed]
    assert len(probe) > 500 and pushed.sum() > 500
    assert np.all(probe[:, 3:5] >= -1e-9), probe[:, 3:5].min(axis=0)  # eq. (42)
    np.testing.assert_allclose(probe[:, 1:3].mean(axis=0), cop.mean(axis=0), atol=3e-3)
    half = np.asarray(push.PLATE_HALF)
    for start in np.arange(t[0], t[-1] - 0.5, 0.5):
        ours = probe[(probe[:, 0] >= start) & (probe[:, 0] < start + 0.5), 1:3]
        truth = cop[(t >= start) & (t < start + 0.5)]
        np.testing.assert_allclose(ours.mean(axis=0), truth.mean(axis=0), atol=0.02)
        assert np.all(half - np.abs(truth.mean(axis=0)) > 2e-3), (start, truth.mean(axis=0))


#: Table VIII against the end-effector sensor, as fractions of the paper's average / peak:
#: (stage, axis, band of mean |F| / paper average, band of peak |F| / paper peak). Flight x
#: is the paper's push and meets Table VIII within 10 %; the other axes are the fractions of
#: it the simulated robot holds (FLIGHT_SCALE, PERCHED_SCALE; docs/scenarios.md), below the
#: paper: their bands are the present values' (seed 0) +-15 %.
TABLE_VIII_BANDS = (
    ("flight", 0, (0.9, 1.1), (0.9, 1.1)),
    ("flight", 1, (0.255, 0.345), (0.35, 0.48)),
    ("flight", 2, (0.34, 0.46), (0.39, 0.53)),
    ("perched", 0, (0.021, 0.029), (0.026, 0.036)),
    ("perched", 1, (0.17, 0.23), (0.18, 0.25)),
    ("perched", 2, (0.068, 0.092), (0.072, 0.098)),
)


def test_end_effector_forces_against_table_viii(run):
    res, _ = run
    avg = {"flight": push.PAPER_FLIGHT_FORCE_AVG, "perched": push.PAPER_PERCHED_FORCE_AVG}
    peak = {"flight": push.PAPER_FLIGHT_FORCE_PEAK, "perched": push.PAPER_PERCHED_FORCE_PEAK}
    for stage, k, (m_lo, m_hi), (p_lo, p_hi) in TABLE_VIII_BANDS:
        r = res.analysis[stage]
        mean_ratio = r["force_mean_abs"][k] / avg[stage][k]
        peak_ratio = r["force_peak"][k] / peak[stage][k]
        assert m_lo <= mean_ratio <= m_hi, (stage, k, mean_ratio)
        assert p_lo <= peak_ratio <= p_hi, (stage, k, peak_ratio)


def test_perched_pushes_stay_within_the_perching_qps_static_ceiling():
    """The default perched pushes peak within the perching QP's static ceiling (scipy's
    linprog over eqs. 39-44 with the foot rotors' spare thrust) in the push posture."""
    from rdm.model import Robot
    from rdm.scenarios.push_ceiling import ceiling

    peak = np.asarray(PLAN.perched_force) * push.PROFILE_PEAK / push.PROFILE_MEAN_ABS
    lim = ceiling(Robot.default(), np.asarray(push.PERCHED_POSTURE))
    assert np.all(peak <= 0.82 * lim), (peak, lim)
    beyond = np.asarray(push.PERCHED_SCALE_BEYOND_CEILING) * push.PAPER_PERCHED_FORCE_AVG
    assert np.any(beyond * push.PROFILE_PEAK / push.PROFILE_MEAN_ABS > lim)


def test_perched_pushes_in_the_push_posture_and_the_qp_presses_harder(run):
    """Perched, the arm is in PERCHED_POSTURE (the end effector ~0.2 m below the plate,
    MuJoCo's body positions, not the onboard model) and the perching QP raises the foot's
    normal force under the push (MuJoCo's contact force, the paper's mechanism)."""
    res, a = run
    w = push.stage_windows(PLAN, res.script.t_perched_stage)
    pushed, quiet = _window(a, w["pushes"]), _window(a, w["quiet"])
    q_err = np.abs(a["q"][pushed, :6] - np.array(push.PERCHED_POSTURE))
    assert q_err.max() < 0.1, q_err.max(axis=0)
    depth = a["foot"][pushed, 2] - a["ee"][pushed, 2]
    assert depth.min() > 0.1 and depth.max() < 0.3  # the hanging posture's is ~1.0 m
    fz_quiet = a["force"][quiet, 2].mean()
    fz_pushed = a["force"][pushed, 2]
    assert fz_quiet == pytest.approx(push.PERCH_PARAMS["epsilon_z"], rel=0.2)
    # seed 0: 1.72 x (2.1 x without Spinal's integration held during the fold, whose pitch
    # integral the QP's ZMP rows also had to press against); a QP that does not press: ~1.1 x
    assert fz_pushed.max() > 1.5 * fz_quiet
    # the applied perched forces are the per-axis scales of Table VIII's averages
    for k in range(3):
        assert PLAN.perched_force[k] == pytest.approx(
            push.PERCHED_SCALE[k] * push.PAPER_PERCHED_FORCE_AVG[k]
        )


def test_flying_robot_holds_the_papers_x_push(run):
    """In flight the x push is Table VIII's average (scale 1.0): the robot tilts against it
    (attitude from MuJoCo's quaternion via scipy) but stays far from Spinal's 1 rad tilt
    fail-safe, and comes back near its hover point after the pushes."""
    res, a = run
    assert PLAN.flight_force[0] == pytest.approx(push.PAPER_FLIGHT_FORCE_AVG[0])
    w = push.stage_windows(PLAN, res.script.t_flight_stage + PLAN.move_s)
    x_lo, x_hi = w["axes"][0]
    in_x = _window(a, (x_lo, x_hi + PLAN.gap_s))
    quat = a["quat"][in_x]  # w, x, y, z
    tilt = Rotation.from_quat(quat[:, [1, 2, 3, 0]]).as_euler("ZYX")[:, 1:]
    assert 0.03 < np.max(np.abs(tilt[:, 0])) < 0.5  # pitch: leans against the push, < 0.5 rad
    assert np.max(np.abs(tilt[:, 1])) < 0.1  # roll stays small under an x push
    quiet = _window(a, w["quiet"])
    end = a["t"] >= res.script.t_flight_stage + PLAN.flight_stage_s() - 0.5
    end &= a["t"] <= res.script.t_flight_stage + PLAN.flight_stage_s()
    back = np.linalg.norm(a["foot"][end].mean(0) - a["foot"][quiet].mean(0))
    assert back < 0.1, f"the root did not come back after the pushes: {back:.3f} m"


def test_end_effector_sensor_sees_the_applied_force(run):
    """MuJoCo's end-effector force sensor reads the pushes at the planned size: the mean |F|
    of the profile (integrated here with scipy) times the amplitude the plan implies."""
    res, _ = run
    mean_abs_shape, _ = quad(lambda s: abs(np.sin(2 * np.pi * s) * np.sin(np.pi * s) ** 2), 0, 1)
    assert abs(mean_abs_shape - push.PROFILE_MEAN_ABS) < 1e-3
    for stage, means in (("flight", PLAN.flight_force), ("perched", PLAN.perched_force)):
        r = res.analysis[stage]
        for ax in range(3):
            assert r["force_mean_abs"][ax] == pytest.approx(means[ax], rel=0.15), (stage, ax)
        # the sensor's force follows the applied one (sign convention: one sign for all axes)
        log = r["log"]
        for k in range(3):
            on = np.abs(log["applied"][:, k]) > 0.2 * means[k]
            corr = np.corrcoef(log["applied"][on, k], log["force"][on, k])[0, 1]
            assert abs(corr) > 0.9, (stage, k, corr)
