"""The wall-perching scenario end to end through every wire: the foot's side face pressed on
a vertical plate by the tilted foot rotors, the perching QP on the wall's plane, the wall's
friction carrying the weight share the rotors shed; outcomes from
MuJoCo's ground truth, the contact's centre of pressure computed here without the plane's
tangent convention (r = n x M_c / (n . F))."""

from __future__ import annotations

import numpy as np
import pytest

from rdm.scenarios import wall_perching as wp
from rdm.scenarios.common import roll_pitch, truth_arrays

#: per perched control tick: t, the QP's status, F_n it decided, λ_perch (4), the
#: controller's filtered wrench (plane coordinates, 6)
PROBE: list[tuple] = []


def _probe(stack, now: float) -> None:
    c = stack.onboard.last_command
    p = getattr(c, "perch", None) if c is not None else None
    perch = stack.onboard.control.perch
    if p is not None and stack.onboard.control.perching:
        PROBE.append(
            (
                now,
                p.status,
                float(p.foot_wrench[0]),
                np.asarray(p.thrust, float).copy(),
                np.asarray(perch.filtered_foot_wrench(), float).copy(),
            )
        )


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    PROBE.clear()
    res = wp.run(tmp_path_factory.mktemp("wall"), observer=_probe)
    return res, truth_arrays(res.stack)


def _window(res, a) -> np.ndarray:
    t = a["t"]
    return (t >= res.facts["t_perch"] + wp.SETTLE_S) & (t <= res.facts["t_release"])


def test_touches_perches_and_leaves(run):
    res, a = run
    assert res.facts["t_contact"] is not None, "never touched the wall"
    assert res.facts["t_perch"] is not None and res.facts["t_release"] is not None
    assert res.facts["final_phase"] == "hover"
    held = _window(res, a)
    assert held.sum() > 400  # ~5 s of 100 Hz truth
    assert a["contact"][held].all(), "the foot left the wall"
    slip = a["slip"][held]
    assert np.max(np.linalg.norm(slip - slip[0], axis=1)) < 1e-3
    # the truth's slip is (x, y): down the wall (z) is read from the foot origin
    down = a["foot"][held, 2]
    assert np.max(np.abs(down - down[0])) < 1e-3
    # left: no contact in the last second, the foot face well off the wall, at hover height
    last = a["t"] >= a["t"][-1] - 1.0
    assert not a["contact"][last].any()
    model = res.stack.plant.model
    face_x = model.geom(wp.WALL_GEOM).pos[0] + model.geom(wp.WALL_GEOM).size[0]
    assert a["foot"][-1, 0] + wp.FACE_CENTER[0] - face_x > 0.15
    # while perched, the foot's side face is on the wall's face (within the contact's softness)
    assert np.all(np.abs(a["foot"][held, 0] + wp.FACE_CENTER[0] - face_x) < 2e-3)
    assert abs(a["cog"][-1, 2] - wp.CLIMB_Z) < 0.1


def test_contact_wrench_inside_the_side_face_limits(run):
    res, a = run
    held = _window(res, a)
    f, m = a["force"][held], a["torque"][held]  # the foot's wrench on the wall, foot axes
    n = np.array(wp.FACE_NORMAL)  # outward normal of the wall (towards the robot)
    c = np.array(wp.FACE_CENTER)
    fn = -(f @ n)  # presses along -n
    assert np.all(fn > 10.0)  # the tilted foot rotors press ~16 N, ~12.5 N with the share
    tangential = np.linalg.norm(f - np.outer(f @ n, n), axis=1)
    assert np.all(tangential < wp.MU[0] * fn)  # friction cone
    m_c = m - np.cross(c, f)
    cop = np.cross(n, m_c) / (f @ n)[:, None]  # in the face's plane, relative to its centre
    assert np.all(np.abs(cop @ n) < 1e-12)
    assert np.all(np.abs(cop[:, 2]) < wp.FACE_HALF[0])  # up-down on the 6 cm face
    assert np.all(np.abs(cop[:, 1]) < wp.FACE_HALF[1])  # across the 15 cm face


def _full_share(res, a) -> np.ndarray:
    return _window(res, a) & (a["t"] <= res.facts["t_release"] - wp.SHARE_RAMP_S)


def test_friction_carries_the_handed_share_of_the_weight(run):
    """Friction (the foot pushing the wall down, -F_z) carries the share the feed-forward
    sheds, and the rotors' total thrust drops by at least that much against the flight
    before the switch (measured in the truth's thrusts, not the controller's command)."""
    res, a = run
    full = _full_share(res, a)
    assert full.sum() > 300
    weight = float(res.stack.plant.model.body_subtreemass[1]) * 9.80665
    carried = -a["force"][full, 2]  # the foot's force on the wall, down
    share = carried / weight
    assert np.all(share > 0.6 * wp.WEIGHT_SHARE) and np.all(share < 1.2 * wp.WEIGHT_SHARE)
    before = (a["t"] >= res.facts["t_perch"] - 0.5) & (a["t"] < res.facts["t_perch"])
    saved = a["thrust"][before].sum(axis=1).mean() - a["thrust"][full].sum(axis=1).mean()
    assert saved > carried.mean()
    # without the share (perching off, still pressed by the tilted rotors) friction carries
    # about nothing: the share, not the press, hands it the weight
    back = (a["t"] > res.facts["t_release"] + 0.2) & (a["t"] <= res.facts["t_release"] + 0.8)
    assert a["contact"][back].all()
    assert np.all(np.abs(a["force"][back, 2]) < 0.03 * weight)


def test_wall_push_posture_is_level_with_the_foot_rotors_tilted(run):
    res, a = run
    held = _window(res, a)
    beta1 = a["q"][held, 7]
    assert np.all(np.abs(beta1 - wp.WALL_BETA1) < np.radians(2.0))
    assert np.degrees(np.abs(roll_pitch(a["quat"][held])).max()) < 2.0
    assert a["thrust"][held].max() <= 20.0 + 1e-9  # the rotors' limit (Table IV)


def test_perching_qp_ran_on_the_wall_plane(run):
    res, a = run
    ticks = [p for p in PROBE if p[0] >= res.facts["t_perch"] + wp.SETTLE_S]
    assert len(ticks) > 150
    assert all(p[1] == "solved" for p in ticks)
    assert all(p[2] >= wp.PERCH_PARAMS["epsilon_z"] - 1e-6 for p in ticks)  # eq. (39)
    lam = np.array([p[3] for p in ticks])
    # the posture's hover thrust already presses ~16 N: through eq. (38)'s feedback on the
    # measured wrench eqs. (39)-(44) hold without λ_perch, which stays 0 (docs/scenarios.md);
    # only Table VII's perch rotors could get it
    assert np.all(lam >= 0.0) and np.all(lam[:, 2:] == 0.0)
    assert np.all(lam <= 20.0 - 16.0)  # eq. (47): the rotor limit above the hover thrust
    # the controller's filtered wrench is in the wall's plane: its F_n is the truth's -F_x
    # (were the foot-axes wrench passed untransformed, it would read F_z ~ 0 here)
    t_last, *_, filt = ticks[-1]
    k = np.searchsorted(a["t"], t_last)
    fn_truth = -a["force"][max(k - 100, 0) : k, 0].mean()
    assert abs(filt[2] - fn_truth) < 1.5
    assert res.metrics and all(m.passed is not False for m in res.metrics)
