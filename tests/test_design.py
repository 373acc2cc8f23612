"""Design evaluation (Sec. II-A, Tables II-III) at a coarse resolution: the orderings the
paper reports must hold; our values are printed beside the paper's (run with -s)."""

import numpy as np
import pytest

from rdm.descriptions import build_description
from rdm.model import Robot
from rdm.planner import PlannerSetup, evaluate_design, feasible_starts, make_core
from rdm.planner.design import PAPER_TABLE2, PAPER_TABLE3, format_table
from rdm.planner.plan import run_core

#: Coarse grid for the test (the documented figures use finer ones, docs/planner.md).
RESOLUTION = 0.25


def _setup(layout: str, fraction: float = 1.0) -> PlannerSetup:
    d = build_description(layout, arm_unit_position=fraction)
    return PlannerSetup.for_robot((d.urdf, d.toml), "perched")


@pytest.fixture(scope="module")
def results():
    setups = {
        "root": _setup("rdm", 0.0),
        "middle": _setup("rdm", 0.5),
        "end": _setup("rdm", 1.0),
        "rcm": _setup("rcm"),
    }
    return {n: evaluate_design(s, n, RESOLUTION, progress=False) for n, s in setups.items()}


def test_table2_amf_ordering_root_middle_end(results):
    table = {k: results[k] for k in ("root", "middle", "end")}
    print("\n" + format_table(2, table))
    ours = [table[k].amf for k in ("root", "middle", "end")]
    print(
        f"middle/end AMF: ours {ours[1] / ours[2]:.2f}, "
        f"paper {PAPER_TABLE2['middle'] / PAPER_TABLE2['end']:.2f}"
    )
    assert ours[0] == 0.0  # the root variant holds no configuration (paper: AMF 0.0)
    assert 0.0 < ours[1] < ours[2]


def test_table3_rdm_beats_rcm(results):
    table = {"rcm": results["rcm"], "rdm": results["end"]}
    print("\n" + format_table(3, table))
    rcm, rdm = table["rcm"], table["rdm"]
    print(
        f"paper ratios: AMR {PAPER_TABLE3['rdm'][0] / PAPER_TABLE3['rcm'][0]:.1f}x, "
        f"AMF {PAPER_TABLE3['rdm'][1] / PAPER_TABLE3['rcm'][1]:.1f}x"
    )
    assert rdm.amr > rcm.amr > 0.0
    assert rdm.amf > rcm.amf > 0.0


def test_root_variant_has_no_feasible_start():
    """Table II 'Root': the arm rotors sit on the q2 axis and cannot carry the arm; no
    planar configuration keeps every thrust and torque inside its limits."""
    assert feasible_starts(_setup("rdm", 0.0)) == []


def test_amr_counts_only_reached_cells(results):
    r = results["end"]
    assert r.amr == pytest.approx(r.reached.sum() * RESOLUTION**2)
    assert np.all(r.force[~r.reached] == 0.0)
    assert np.all(r.force[r.reached] > 0.0)


def _feasible_force_scipy(robot, zeta, thrust0, perch=5.0, eps_n=0.5):
    """eq. (3) re-derived: for each axis and sign, max f with F_ee = ±f e_j held by thrust
    changes dλ within the stall torques (eq. 61 from the model binding), the thrust range
    with eq. (64)'s extra perching share, and the foot perched (normal force >= eps_n,
    friction, yaw friction, ZMP in the plate). scipy's HiGHS LP."""
    from scipy.optimize import linprog

    q, base = zeta[6:], list(zeta[:6])
    ws = robot.evaluate(q, base_pose=base)
    foot = np.array(ws["frames"]["foot"])[:3, 3]
    base_p = np.array(zeta[:3])
    lever = foot - base_p

    def loads(thrusts, ee=None, gravity=(0.0, 0.0, 0.0)):
        tau, res = robot.static_torques(
            q, thrusts=list(thrusts), base_pose=base, end_effector_wrench=ee, gravity=gravity
        )
        f, m = np.array(res[:3]), np.array(res[3:])
        return np.array(tau), -np.concatenate([f, m - np.cross(lever, f)])

    tau0, w0 = loads(thrust0, gravity=(0.0, 0.0, -9.80665))
    cols = [loads(np.eye(4)[k]) for k in range(4)]
    pos = np.array(ws["rotor_positions"])
    spin = np.array([r["spin"] for r in robot.rotors])
    c = np.array([r["drag_to_thrust"] for r in robot.rotors])
    z = np.array([0.0, 0.0, 1.0])
    q_foot = np.array(
        [np.concatenate([[1.0], np.cross(p - foot, z) - ci * s * z])
         for p, s, ci in zip(pos, spin, c, strict=True)]
    ).T  # fmt: skip
    q_foot_inv = np.linalg.inv(q_foot)
    stall = np.array(robot.stall_torques)
    tmin = np.array([r["thrust_min"] for r in robot.rotors])
    tmax = np.array([r["thrust_max"] for r in robot.rotors])
    mu, mu_z = robot.friction
    hx, hy = 0.5 * robot.plate_size[0], 0.5 * robot.plate_size[1]
    best = np.zeros(3)
    for j in range(3):
        for sign in (1.0, -1.0):
            ee = np.zeros(6)
            ee[j] = sign
            tau_f, w_f = loads(np.zeros(4), ee=list(ee))
            T = np.column_stack([tau_f] + [cl[0] for cl in cols])  # torque per x
            W = np.column_stack([w_f] + [cl[1] for cl in cols])  # foot wrench per x
            A, b = [T, -T], [stall - tau0, stall + tau0]
            up = np.hstack([np.zeros((4, 1)), np.eye(4)])
            if j < 2:
                up[:, 0] = q_foot_inv[:, 0] / mu
            A += [up, -np.hstack([np.zeros((4, 1)), np.eye(4)])]
            b += [tmax - thrust0, thrust0 - tmin]
            n_row, n0 = -W[2], -w0[2]
            A.append(-n_row[None])
            b.append([n0 - eps_n])
            for comp, lim in ((0, mu), (1, mu), (5, mu_z), (3, hy), (4, hx)):
                A += [(W[comp] - lim * n_row)[None], (-W[comp] - lim * n_row)[None]]
                b += [[lim * n0 - w0[comp]], [lim * n0 + w0[comp]]]
            r = linprog(
                np.r_[-1.0, np.zeros(4)], A_ub=np.vstack(A), b_ub=np.concatenate(b),
                bounds=[(0.0, 200.0)] + [(None, None)] * 4, method="highs",
            )  # fmt: skip
            if r.status == 0:
                best[j] = max(best[j], r.x[0])
    return best


def test_feasible_force_matches_an_independent_lp():
    """The planner's eq. (3) LP (Rust, on the dense QP) against a scipy re-derivation built
    from the model binding's torques and wrenches, at the start and two reached poses."""
    setup = PlannerSetup.for_robot("rdm", "perched")
    robot = Robot.from_strs(setup.urdf, setup.toml)
    for target in (None, (0.2, -0.3, -0.7), (-0.2, 0.0, -0.7)):
        core = make_core(setup)
        lay = core.layout
        if target is not None:
            assert run_core(core, target, "perched").reached
        t0 = core.values[lay["thrust"][0] : lay["thrust"][0] + 4]
        per_axis, feasible = core.feasible_force()
        ref = _feasible_force_scipy(robot, core.zeta.copy(), t0)
        np.testing.assert_allclose(per_axis, ref, atol=1e-3 * (1 + ref.max()))
        assert feasible == max(per_axis) > 0.0
