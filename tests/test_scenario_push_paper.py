"""``push-paper-forces``: the perched-wrench claim at Table VIII's forces (one run, seed 0).

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
    PAPER_FLIGHT_FORCE_AVG,
    PAPER_FOOT_STD_PERCHED,
    PAPER_PERCHED_FORCE_AVG,
    profile,
)


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


def test_asymmetric_profile_keeps_the_mean_and_bounds_the_pull():
    """The window's mean |F| is the plan's mean whatever the half weights (scipy quad), and
    the +x half peaks at half_peaks' pull."""
    plan = pp.PAPER_PLAN
    w0, _ = plan.window(0)
    mean = (
        quad(lambda s: abs(plan.stage_force(s, "perched")[0]), w0, w0 + plan.push_s, limit=200)[0]
        / plan.push_s
    )
    # PROFILE_MEAN_ABS is a 20001-point grid mean: 5e-5 relative
    assert mean == pytest.approx(plan.perched_force[0], rel=1e-4)
    grid = np.linspace(w0, w0 + plan.push_s, 20001)
    fx = np.array([plan.stage_force(s, "perched")[0] for s in grid])
    pull, push_ = pp.half_peaks(plan.perched_force[0], plan.perched_half_weights[0])
    assert fx.max() == pytest.approx(pull, rel=1e-4)
    assert -fx.min() == pytest.approx(push_, rel=1e-4)
    # the pull stays under the static bound of the perch rotors
    assert pull < pp.static_bound()["push_bound_perch"][0]
    # symmetric weights: the push scenario's profile
    sym = pp.PaperPushPlan(perched_half_weights=((1.0, 1.0),) * 3)
    s = np.linspace(0, sym.stage_s(), 2001)
    a = np.array([sym.stage_force(v, "perched") for v in s])
    b = np.array([sym.force(v, sym.perched_force) for v in s])
    np.testing.assert_allclose(a, b, atol=1e-12)
    assert profile(0.25) > 0  # the first half is +axis


def test_perched_force_reaches_table_viii_in_x(run):
    res, probe = run
    assert res.facts["final_phase"] == "done"
    perched = _windows(res, "perched")
    flight = _windows(res, "flight")
    fx_perched = _mean_abs(probe, perched[0], 0)
    fx_flight = _mean_abs(probe, flight[0], 0)
    assert fx_perched >= 0.9 * PAPER_PERCHED_FORCE_AVG[0]
    # flight at Table VIII's flight force in x (the sampled mean of the smooth profile)
    assert fx_flight == pytest.approx(PAPER_FLIGHT_FORCE_AVG[0], rel=0.01)
    assert fx_perched / fx_flight > 1.0
    rows = {m.name: m for m in res.metrics}
    # the metric rows (the end-effector sensor) agree with what MuJoCo was given
    for k, ax in enumerate("xyz"):
        for stage, w in (("perched", perched), ("flight", flight)):
            row = rows[f"{stage}: mean |F_ee,{ax}| (EE sensor, {ax} push)"]
            assert row.ours == pytest.approx(_mean_abs(probe, w[k], k), rel=0.02, abs=1e-3)
    assert rows["perched / flight mean |F_ee,x|"].passed is True
    assert rows["perched: foot contact kept while pushed"].ours == 1.0
    # the onboard node's perching QP solved every tick of the pushes (its own status counts)
    assert rows["perched: perching-QP ticks not solved while pushed"].ours == 0


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
