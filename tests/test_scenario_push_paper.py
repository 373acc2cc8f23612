"""``push-paper-forces``: the perched-wrench claim within Table VIII's peaks (one run, seed 0).

The forces are recomputed from what MuJoCo was given (``xfrc_applied`` on the end-effector
body, turned into the end-effector frame) and the foot scatter from MuJoCo's free-joint
position, both read by an observer on every script tick, not from the scenario's own logs.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad

from rdm.scenarios import SCENARIOS
from rdm.scenarios import push_paper as pp
from rdm.scenarios.push_plan import (
    PAPER_FLIGHT_FORCE_PEAK,
    PAPER_FOOT_STD_PERCHED,
    PAPER_PERCHED_FORCE_PEAK,
    profile,
)

# Independent of the profile code: the unit profile 2 sin^3(pi s) cos(pi s) has mean |.| 1/pi
# (4/pi times the integral of sin^3 cos over [0, pi/2]) and peak 3 sqrt(3)/8 (at s = 1/3).
MEAN_OVER_PEAK = (1.0 / np.pi) / (3.0 * np.sqrt(3.0) / 8.0)


class _Probe:
    """MuJoCo's own record each tick: time, applied end-effector force (EE frame), root position."""

    def __init__(self) -> None:
        self.t: list[float] = []
        self.force: list[np.ndarray] = []
        self.root: list[np.ndarray] = []

    def __call__(self, stack, now: float) -> None:
        plant = stack.plant
        d, bid = plant.data, plant.model.body(pp.push.EE_BODY).id
        rot = np.array(d.xmat[bid]).reshape(3, 3)
        self.t.append(float(d.time))
        self.force.append(rot.T @ np.array(d.xfrc_applied[bid, :3]))
        self.root.append(np.array(d.qpos[0:3]))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    probe = _Probe()
    res = pp.run(tmp_path_factory.mktemp("push_paper"), plots=False, observer=probe)
    return res, probe


def _windows(res, stage: str) -> dict[int, tuple[float, float]]:
    """Per-axis push windows from the plan's timing (quiet, push, gap), absolute times."""
    plan = pp.PAPER_PLAN
    f = res.facts
    # the flight stage's pushes start after its move_s settle
    t0 = f["t_flight_stage"] + plan.move_s if stage == "flight" else f["t_perched_stage"]
    out = {}
    for k in range(3):
        start = t0 + plan.quiet_s + k * (plan.push_s + plan.gap_s)
        out[k] = (start, start + plan.push_s)
    return out


def _mean_abs(probe: _Probe, w: tuple[float, float], k: int) -> float:
    t = np.array(probe.t)
    f = np.array(probe.force)
    m = (t >= w[0]) & (t <= w[1])
    return float(np.mean(np.abs(f[m, k])))


def test_registered():
    assert SCENARIOS["push-paper-forces"].run is pp.run


def test_profile_peaks_are_capped_at_table_viii():
    """Every half's peak (fine grid) is at most Table VIII's peak for its axis; x's halves peak
    at the pull cap (15 N) and at Table VIII's 41.8 N, and the window's mean |F| (scipy quad)
    is what the two caps give, about 55 % of Table VIII's 25.1 N."""
    plan = pp.PAPER_PLAN
    for stage, paper in (
        ("flight", PAPER_FLIGHT_FORCE_PEAK),
        ("perched", PAPER_PERCHED_FORCE_PEAK),
    ):
        t = np.linspace(0.0, plan.stage_s(), 100001)
        f = np.array([plan.stage_force(v, stage) for v in t])
        assert np.all(np.abs(f).max(axis=0) <= np.asarray(paper) * (1 + 1e-9)), stage
    w0, _ = plan.window(0)
    grid = np.linspace(w0, w0 + plan.push_s, 20001)
    fx = np.array([plan.stage_force(s, "perched")[0] for s in grid])
    assert fx.max() == pytest.approx(pp.X_PULL_PEAK, rel=1e-6)
    assert -fx.min() == pytest.approx(PAPER_PERCHED_FORCE_PEAK[0], rel=1e-6)
    assert pp.static_bound()["push_bound_perch"][0] > pp.X_PULL_PEAK
    mean = (
        quad(lambda s: abs(plan.stage_force(s, "perched")[0]), w0, w0 + plan.push_s, limit=200)[0]
        / plan.push_s
    )
    expected = 0.5 * (15.0 + 41.8) * MEAN_OVER_PEAK
    # PROFILE_MEAN_ABS is a 20001-point grid mean: 5e-5 relative
    assert mean == pytest.approx(expected, rel=1e-4)
    assert mean == pytest.approx(plan.perched_force[0], rel=1e-4)
    assert 0.5 < mean / 25.1 < 0.6
    assert pp.half_peaks(plan.perched_force[0], plan.perched_half_weights[0]) == pytest.approx(
        (15.0, 41.8), rel=1e-9
    )
    # flight: x and z capped at Table VIII's flight peaks, y at 0.2 of the average
    assert plan.flight_force == pytest.approx(
        (7.48 * MEAN_OVER_PEAK, 0.2 * 1.76, 6.07 * MEAN_OVER_PEAK), rel=1e-4
    )
    # symmetric weights: the push scenario's profile
    sym = pp.PaperPushPlan(perched_half_weights=((1.0, 1.0),) * 3)
    s = np.linspace(0, sym.stage_s(), 2001)
    a = np.array([sym.stage_force(v, "perched") for v in s])
    b = np.array([sym.force(v, sym.perched_force) for v in s])
    np.testing.assert_allclose(a, b, atol=1e-12)
    assert profile(0.25) > 0  # the first half is +axis


def test_applied_forces_within_table_viii_peaks(run):
    """From MuJoCo's applied record: every push and pull peak at most Table VIII's, x's pull
    at 15 N and push near 41.8 N, the x mean what the caps give, perched/flight in x > 1."""
    res, probe = run
    assert res.facts["final_phase"] == "done"
    t, f = np.array(probe.t), np.array(probe.force)
    perched, flight = _windows(res, "perched"), _windows(res, "flight")
    for w, paper in ((perched, PAPER_PERCHED_FORCE_PEAK), (flight, PAPER_FLIGHT_FORCE_PEAK)):
        for k in range(3):
            m = (t >= w[k][0]) & (t <= w[k][1])
            assert np.abs(f[m, k]).max() <= paper[k] + 1e-9
    m = (t >= perched[0][0]) & (t <= perched[0][1])
    assert 14.9 < f[m, 0].max() <= 15.0 + 1e-9  # the pull, off the ceiling
    assert 41.5 < -f[m, 0].min() <= 41.8 + 1e-9  # the push, into the ceiling
    fx_perched = _mean_abs(probe, perched[0], 0)
    fx_flight = _mean_abs(probe, flight[0], 0)
    assert fx_perched == pytest.approx(0.5 * (15.0 + 41.8) * MEAN_OVER_PEAK, rel=0.01)
    assert fx_flight == pytest.approx(7.48 * MEAN_OVER_PEAK, rel=0.01)
    assert fx_perched / fx_flight > 1.0
    rows = {m.name: m for m in res.metrics}
    # the metric rows (the end-effector sensor) agree with what MuJoCo was given
    for k, ax in enumerate("xyz"):
        for stage, w in (("perched", perched), ("flight", flight)):
            row = rows[f"{stage}: mean |F_ee,{ax}| (EE sensor, {ax} push)"]
            assert row.ours == pytest.approx(_mean_abs(probe, w[k], k), rel=0.02, abs=1e-3)
            peak = rows[f"{stage}: peak |F_ee,{ax}| applied, push and pull (at most Table VIII's)"]
            mk = (t >= w[k][0]) & (t <= w[k][1])
            assert peak.ours == pytest.approx(np.abs(f[mk, k]).max(), rel=1e-9)
            assert peak.passed is True
    assert rows["perched / flight mean |F_ee,x|"].passed is True
    assert rows["perched: mean |F_ee,x| / Table VIII's 25.1 N"].ours == pytest.approx(
        fx_perched / 25.1, rel=0.02
    )
    assert rows["perched: foot contact kept while pushed"].ours == 1.0
    # the onboard node's perching QP solved every tick of the pushes (its own status counts)
    assert rows["perched: perching-QP ticks not solved while pushed"].ours == 0
    # no row with a limit that cannot be met: every verdict row passes
    assert all(m.passed is not False for m in res.metrics), [
        m.name for m in res.metrics if m.passed is False
    ]


def test_perched_foot_scatter_within_table_ix(run):
    res, probe = run
    t = np.array(probe.t)
    root = np.array(probe.root)
    w = _windows(res, "perched")
    m = (t >= w[0][0]) & (t <= w[2][1])
    std = np.std(root[m], axis=0)
    assert np.all(std <= np.array(PAPER_FOOT_STD_PERCHED))
    rows = {m.name: m for m in res.metrics}
    for ax in "xyz":
        assert rows[f"perched: foot position std {ax} (pushes)"].passed is True
    # in flight the same pushes move the root by centimetres (the perched-wrench claim)
    wf = _windows(res, "flight")
    mf = (t >= wf[0][0]) & (t <= wf[2][1])
    assert np.std(root[mf], axis=0)[0] > 10 * std[0]


def test_bound_rows_name_the_binding_constraint(run):
    res, _ = run
    names = [m.name for m in res.metrics if m.name.startswith("perched: static bound")]
    assert len(names) == 3
    assert "thrust_max" in names[0]
    assert all("zmp" in n for n in names[1:])
    # the y and z ratios are info rows that state the static bound and what binds it
    ratios = [m for m in res.metrics if m.name.startswith("perched / flight mean")]
    assert [m.rule for m in ratios] == ["min", "info", "info"]
    assert all("static bound" in m.name and "zmp" in m.name for m in ratios[1:])
