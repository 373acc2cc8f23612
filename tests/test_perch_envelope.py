"""Perching envelope (rdm.scenarios.perch_envelope) against independent oracles: a brute-force
grid over the two foot rotors' perching thrust for the push bound, the closed form of a pull
along the plate normal, and the plate-offset rule for the perch itself."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rdm.descriptions import build_description
from rdm.scenarios import perch_envelope as pe
from rdm.scenarios.perching import leveled

GRAVITY = 9.80665


def _by_name(name: str) -> pe.Candidate:
    return next(c for c in pe.CANDIDATES if c.name == name)


def _grid_bound(cand: pe.Candidate, gain: np.ndarray, eps: float = 1.0, n: int = 161):
    """Largest push/pull amplitude per end-effector axis, by enumerating lambda_perch of the
    two foot rotors on a grid: eqs. (39)-(42) written from the rotor positions, axes, spins
    and drag ratios (eq. 9), hover thrust from numpy's least squares."""
    robot = pe.candidate_robot(cand.foot_unit_position)
    o = robot.evaluate(leveled(np.asarray(cand.q6), robot.n_q))
    pos = np.asarray(o["rotor_positions"])
    ax = np.asarray(o["rotor_directions"])
    rot = robot.rotors
    hover = np.linalg.lstsq(o["allocation_bar"], [o["mass"] * GRAVITY, 0, 0, 0], rcond=None)[0]
    cols = []  # foot wrench [F(3), M(3)] per unit thrust of rotors 1, 2
    for i in (0, 1):
        m = np.cross(pos[i], ax[i]) - rot[i]["drag_to_thrust"] * rot[i]["spin"] * ax[i]
        cols.append(np.r_[ax[i], m])
    cols = np.array(cols).T  # 6 x 2
    top = [rot[i]["thrust_max"] * gain[i] - hover[i] for i in (0, 1)]
    l1, l2 = np.meshgrid(np.linspace(0, top[0], n), np.linspace(0, top[1], n))
    base = cols[:, :1] * l1.ravel() + cols[:, 1:] * l2.ravel()  # 6 x n^2
    ee = np.asarray(o["frames"]["end_effector"])
    out = []
    for k in range(3):
        e = ee[:3, k]
        w = np.r_[e, np.cross(ee[:3, 3], e)]
        best = []
        for sign in (1.0, -1.0):
            fz0, fzw = base[2], sign * w[2]
            rows = [(-fzw, fz0 - eps)]  # F_z >= eps
            for idx, lim in ((0, 0.9), (1, 0.9), (5, 0.5), (4, 0.04), (3, 0.07)):
                for s in (1.0, -1.0):  # s X <= lim F_z
                    rows.append((s * sign * w[idx] - lim * fzw, lim * fz0 - s * base[idx]))
            amax = np.full(base.shape[1], 1e3)
            ok = np.ones(base.shape[1], dtype=bool)
            for alpha, beta in rows:
                ok &= beta >= -1e-9
                pos_a = alpha > 1e-12
                amax = np.where(pos_a, np.minimum(amax, beta / np.where(pos_a, alpha, 1)), amax)
            best.append(float(np.max(np.where(ok, amax, -np.inf))))
        out.append(min(best))
    return np.array(out)


def test_push_bound_matches_grid_enumeration() -> None:
    cand = _by_name("foot at plate, hanging")
    r = pe.envelope(cand)
    grid = _grid_bound(cand, np.asarray(r["ceiling_gain"]))
    lp = np.asarray(r["push_bound_perch"])
    assert np.all(lp >= grid - 1e-6)
    np.testing.assert_allclose(lp, grid, rtol=0.03, atol=0.02)
    assert np.all(lp < np.asarray(pe.PAPER_PERCHED_FORCE_AVG) * 0.2)  # far from Table VIII


def test_pull_along_the_normal_is_the_spare_foot_thrust() -> None:
    """Arm straight below the plate: the end effector's x axis is the normal, so a pull is
    held by the foot rotors' spare thrust alone: 2 (gain t_max - hover) - eps_z."""
    r = pe.envelope(_by_name("straight hanging"))
    assert abs(r["end_effector"][0]) < 1e-9 and abs(r["end_effector"][1]) < 1e-9
    g = r["ceiling_gain"]
    closed = sum(20.0 * g[i] - r["hover_thrust"][i] for i in (0, 1)) - 1.0
    assert math.isclose(r["push_bound_perch"][0], closed, rel_tol=1e-4)
    assert r["binding_perch"][0] == "thrust_max"


def test_foot_rotors_off_the_plate_axis_cannot_perch_with_table_vii() -> None:
    """Pressing with rotors x_r from the plate centre puts the ZMP at x_r: beyond H_x = 0.04 m
    the perch with F_z only (U_mask diag[1,0,0,0]) does not hold."""
    for name in ("root along ceiling", "foot at plate, root along ceiling", "hanging"):
        cand = _by_name(name)
        robot = pe.candidate_robot(cand.foot_unit_position)
        o = robot.evaluate(leveled(np.asarray(cand.q6), robot.n_q))
        x_r = abs(float(np.asarray(o["rotor_positions"])[0, 0]))
        assert pe.envelope(cand)["holds"] == (x_r < 0.04), name


def test_ceiling_gain_and_commanded_foot_thrust() -> None:
    """The gain is the plant's model at the rotor's distance (finite difference: it falls with
    distance); eps_z = 8 N in the hanging posture asks the foot rotors for ~1.36x flight, the
    ratio the perching simulation measures; a foot unit 6 cm below the ceiling stays at the
    flight level with Table VII's 1 N."""
    hang8 = pe.envelope(_by_name("hanging"), epsilon_z=8.0)
    assert 1.3 < hang8["foot_commanded_after_contact_over_flight"][0] < 1.42
    near = pe.envelope(_by_name("foot at plate, hanging"))
    d = near["foot_distance_to_ceiling"][0]
    assert math.isclose(d, 0.06, abs_tol=1e-6)
    from rdm.plant.ceiling import ParametricCeilingEffect

    ce = ParametricCeilingEffect(radius=0.0635)
    assert (ce.thrust_ratio(d + 1e-3) - ce.thrust_ratio(d - 1e-3)) / 2e-3 < 0
    assert near["ceiling_gain"][0] > 1.05
    assert 0.9 < near["foot_commanded_after_contact_over_flight"][0] < 1.1


def test_command_line_rejects_unknown_argument(capsys) -> None:
    assert pe.main(["--bogus"]) == 2
    assert "--bogus" in capsys.readouterr().err


def test_foot_unit_position_out_of_range_is_named() -> None:
    with pytest.raises(ValueError, match="foot_unit_position must lie in"):
        build_description("rdm", 1.0, 1.5)
    assert build_description("rdm", 1.0, 0.1).name == "rdm_foot10"
