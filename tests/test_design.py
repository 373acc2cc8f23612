"""Design evaluation (Sec. II-A, Tables II-III) on the 3-D grid at a coarse resolution:
the voxel integral against an analytic volume, the perching-authority force against an
independent scipy LP, the yaw joints against the planar arm's geometry, the orderings the
paper reports, and ``rdm design --json``. Run with -s to see ours beside the paper's."""

import json

import numpy as np
import pytest
from scipy.optimize import linprog

from rdm.cli import main
from rdm.descriptions import build_description
from rdm.model import Robot
from rdm.planner import PlannerSetup, evaluate_design, make_core
from rdm.planner.design import PAPER_TABLE3, format_table, table_json
from rdm.planner.perch_force import feasible_force
from rdm.planner.plan import run_core
from rdm.planner.reach import grid_image_voxels, voxel_volume

#: Coarse grids for the tests (the documented figures use the defaults, docs/planner.md).
RESOLUTION = 0.15
JOINT_STEP = 0.3
G = 9.80665


def _setup(layout: str, fraction: float = 1.0) -> PlannerSetup:
    d = build_description(layout, arm_unit_position=fraction)
    return PlannerSetup.for_robot((d.urdf, d.toml), "perched")


def _run(setup: PlannerSetup, name: str, yaw: bool = True):
    return evaluate_design(
        setup, name, RESOLUTION, progress=False, joint_step=JOINT_STEP, yaw=yaw, executor=None
    )


@pytest.fixture(scope="module")
def results():
    setups = {
        "root": _setup("rdm", 0.0),
        "middle": _setup("rdm", 0.5),
        "end": _setup("rdm", 1.0),
        "rcm": _setup("rcm"),
    }
    return {n: _run(s, n) for n, s in setups.items()}


# --- the voxel integral of eq. (4) -------------------------------------------------------


@pytest.mark.parametrize("res", [0.1, 0.05])
def test_voxel_volume_of_a_two_link_arm_is_its_spherical_shell(res):
    """A 2-link arm (lengths 0.6, 0.4; yaw a full turn, shoulder pitch +-90 deg, elbow
    0..180 deg) reaches exactly the shell 0.2 <= |p| <= 1.0: volume 4/3 pi (R^3 - r^3).
    The joint grid is coarse (tip steps of ~0.1 m), so the segments between neighbours
    must fill it; the boundary voxels only partly inside bound the error (one voxel layer
    over both spheres' area; about half of it is found: the voxel integral is biased high
    by ~0.5 area x resolution, docs/planner.md)."""
    l1, l2 = 0.6, 0.4
    yaw = np.linspace(-np.pi, np.pi, 64)
    pitch = np.linspace(-np.pi / 2, np.pi / 2, 33)
    elbow = np.linspace(0.0, np.pi, 33)
    t, p, e = np.meshgrid(yaw, pitch, elbow, indexing="ij")

    def u(th, ph):
        return np.stack([np.cos(ph) * np.cos(th), np.cos(ph) * np.sin(th), np.sin(ph)], -1)

    ee = l1 * u(t, p) + l2 * u(t, p + e)
    keys = grid_image_voxels(np.ones(t.shape, dtype=bool), ee, res)
    exact = 4.0 / 3.0 * np.pi * ((l1 + l2) ** 3 - (l1 - l2) ** 3)
    layer = res * 4.0 * np.pi * ((l1 + l2) ** 2 + (l1 - l2) ** 2)
    got = voxel_volume(keys, res)
    print(f"\nres {res}: voxels {got:.3f} m^3, shell {exact:.3f} m^3, layer bound {layer:.3f}")
    assert exact - 0.02 * exact <= got <= exact + layer


def test_voxel_volume_counts_only_feasible_points():
    """Half the grid infeasible (pitch < 0 removed): the lower half-shell disappears."""
    l1, l2 = 0.6, 0.4
    t, p = np.meshgrid(np.linspace(-np.pi, np.pi, 64), np.linspace(-np.pi / 2, 0.0, 17))
    ee = np.stack([np.cos(p) * np.cos(t), np.cos(p) * np.sin(t), np.sin(p)], -1) * (l1 + l2)
    keys = grid_image_voxels(p > -0.5, ee, 0.1)
    assert np.all(keys[:, 2] * 0.1 >= -(l1 + l2) * np.sin(0.5) - 0.1 - 1e-9)


# --- the feasible force with the perching controller's authority -------------------------


def _scipy_force(robot: Robot, q: np.ndarray, perch: tuple[int, ...]) -> np.ndarray:
    """eq. (3) re-derived for the check: hover thrust from the model binding's residual
    wrench (F_z and the moment about the CoG zero), the rotors ``perch`` add
    lambda_perch >= 0 with each total in 1..20 N (the others' hover share must be),
    Table VII's epsilon_z 1 N, mu 0.9, mu_z 0.5, H 0.04 / 0.07 m; scipy's HiGHS LP per
    axis and sign."""
    ws = robot.evaluate(q)
    foot = np.array(ws["frames"]["foot"])[:3, 3]
    cog = np.array(ws["cog"])

    def res(thr, ee=(0.0,) * 6, grav=(0.0, 0.0, 0.0)):
        tau, r = robot.static_torques(q, thrusts=list(thr), end_effector_wrench=list(ee),
                                      gravity=grav)  # fmt: skip
        return np.array(tau), np.array(r)

    cols = [res(np.eye(4)[k])[1] for k in range(4)]
    r_g = res(np.zeros(4), grav=(0.0, 0.0, -G))[1]

    def about_cog(r):
        return np.r_[r[2], r[3:] - np.cross(cog, r[:3])]

    a = np.column_stack([about_cog(c) for c in cols])
    hover = np.linalg.solve(a, -about_cog(r_g))
    rest = [k for k in range(4) if k not in perch]
    if np.any(hover[rest] < 1.0) or np.any(hover[rest] > 20.0):  # outside the rotor range
        return np.zeros(3)

    def foot_w(r):
        return -np.r_[r[:3], r[3:] - np.cross(foot, r[:3])]

    tau0, r0 = res(hover, grav=(0.0, 0.0, -G))
    w0 = foot_w(r0)
    tcols = [res(np.eye(4)[k]) for k in perch]
    stall = np.array(robot.stall_torques)
    out = np.zeros(3)
    for j in range(3):
        for sign in (1.0, -1.0):
            ee = np.zeros(6)
            ee[j] = sign
            tf, rf = res(np.zeros(4), ee=ee)
            T = np.column_stack([tf] + [c[0] for c in tcols])
            W = np.column_stack([foot_w(rf)] + [foot_w(c[1]) for c in tcols])
            A, b = [T, -T], [stall - tau0, stall + tau0]
            n_row, n0 = -W[2], -w0[2]
            A.append(-n_row[None])
            b.append([n0 - 1.0])
            for c, lim in ((0, 0.9), (1, 0.9), (5, 0.5), (3, 0.07), (4, 0.04)):
                A += [(W[c] - lim * n_row)[None], (-W[c] - lim * n_row)[None]]
                b += [[lim * n0 - w0[c]], [lim * n0 + w0[c]]]
            bounds = [(0.0, 200.0)] + [(max(0.0, 1.0 - hover[k]), 20.0 - hover[k]) for k in perch]
            r = linprog(np.r_[-1.0, np.zeros(len(perch))], A_ub=np.vstack(A),
                        b_ub=np.concatenate(b), bounds=bounds, method="highs")  # fmt: skip
            if r.status == 0:
                out[j] = max(out[j], r.x[0])
    return out


@pytest.mark.parametrize(
    ("robot_name", "q5"),
    [
        ("rdm", (1.2, 0.8, 0.0, -0.9, 0.0)),
        ("rdm", (1.5, -0.4, -0.7, -1.2, -0.2)),
        ("rdm", (1.5, 1.2, 1.5, 1.4, 0.5)),
        ("rdm", (1.0, 0.6, 0.5, -0.6, -0.4)),  # a foot rotor's hover share below zero
        ("rcm", (0.4, 0.9, -0.1, -0.7, -0.6)),
        ("rcm", (1.2, 0.8, 0.0, -0.9, 0.0)),  # cannot stay perched
    ],
)
def test_feasible_force_matches_an_independent_lp(robot_name, q5):
    setup = PlannerSetup.for_robot(robot_name)
    robot = Robot.from_strs(setup.urdf, setup.toml)
    core = make_core(setup)
    zeta = core.zeta.copy()
    zeta[6:11] = q5
    core.set_zeta(zeta)  # levelled vectoring units
    q = core.zeta[6:]
    ours = feasible_force(robot, q)
    # the root unit perches: the RDM's foot rotors, all four of the RCM's (all on the root)
    ref = _scipy_force(robot, q, (0, 1) if robot_name == "rdm" else (0, 1, 2, 3))
    print(f"\n{robot_name} {q5}: ours {None if ours is None else ours[0]}, scipy {ref}")
    if ours is None:
        assert np.all(ref == 0.0)
        return
    np.testing.assert_allclose(ours[0], ref, atol=1e-3 * (1.0 + ref.max()))
    assert ours[1] == max(ours[0])


def test_perching_authority_is_below_every_rotor_acting():
    """Only the foot rotors add thrust: never more than the planner's all-rotor LP."""
    setup = PlannerSetup.for_robot("rdm")
    core = make_core(setup)
    ours = feasible_force(Robot.from_strs(setup.urdf, setup.toml), core.zeta[6:])
    assert ours is not None and 0.0 < ours[1] < core.feasible_force()[1]


# --- the planner core's all-rotor LP (rdm_core planner/force.rs) ----------------------


def _all_rotor_force_scipy(robot, zeta, thrust0, perch=5.0, eps_n=0.5):
    """eq. (3) re-derived: for each axis and sign, max f with F_ee = ±f e_j held by thrust
    changes dλ within the stall torques (eq. 61 from the model binding), the thrust range
    with eq. (64)'s extra perching share, and the foot perched (normal force >= eps_n,
    friction, yaw friction, ZMP in the plate). scipy's HiGHS LP."""
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


def test_planner_all_rotor_force_matches_an_independent_lp():
    """The planner core's own eq. (3) LP (Rust, every rotor acting; not the design sweep's)
    against a scipy re-derivation built from the model binding's torques and wrenches, at
    the start and two reached poses."""
    setup = PlannerSetup.for_robot("rdm", "perched")
    robot = Robot.from_strs(setup.urdf, setup.toml)
    for target in (None, (0.2, -0.3, -0.7), (-0.2, 0.0, -0.7)):
        core = make_core(setup)
        lay = core.layout
        if target is not None:
            assert run_core(core, target, "perched").reached
        t0 = core.values[lay["thrust"][0] : lay["thrust"][0] + 4]
        per_axis, feasible = core.feasible_force()
        ref = _all_rotor_force_scipy(robot, core.zeta.copy(), t0)
        np.testing.assert_allclose(per_axis, ref, atol=1e-3 * (1 + ref.max()))
        assert feasible == max(per_axis) > 0.0


# --- the sweep ----------------------------------------------------------------------------


def test_yaw_joints_reach_off_the_arm_plane():
    """Yaw joints fixed at 0: every joint axis is perpendicular to the x-z plane, so the end
    effector stays at y = 0 and only the two voxel rows beside it are reached. Active: the
    reachable set extends to |y| >= 0.4 m and its volume grows."""
    setup = PlannerSetup.for_robot("rdm")
    planar = _run(setup, "planar", yaw=False)
    full = _run(setup, "full", yaw=True)
    assert len(planar.points) > 0
    assert np.all(np.abs(planar.points[:, 1]) <= RESOLUTION / 2 + 1e-9)
    assert np.any(np.abs(full.points[:, 1]) >= 0.4)
    assert full.amr > 2.0 * planar.amr


def test_amr_is_voxel_count_times_cell_volume(results):
    r = results["end"]
    assert r.amr == pytest.approx(len(r.points) * RESOLUTION**3)
    assert np.all(r.force > 0.0)
    amf = (r.force / 33.5).sum() * RESOLUTION**3 / 1.2**3
    assert r.amf == pytest.approx(amf)
    assert r.amr <= r.amr_admitted <= r.amr_kinematic


def test_table2_root_holds_nothing_middle_and_end_do(results):
    """The root variant's arm rotors sit on the q2 axis and cannot carry the arm: no admitted
    configuration (the paper's AMF 0.0). Middle and end reach about the same volume; with
    the perching controller's authority the middle variant's AMF is not below the end's
    (the paper's ordering does not hold here, docs/planner.md)."""
    table = {k: results[k] for k in ("root", "middle", "end")}
    print("\n" + format_table(2, table))
    assert table["root"].admitted == 0 and table["root"].amf == 0.0
    assert table["middle"].amf > 0.0 and table["end"].amf > 0.0
    assert table["middle"].amr == pytest.approx(table["end"].amr, rel=0.2)


def test_table3_rdm_beats_rcm(results):
    table = {"rcm": results["rcm"], "rdm": results["end"]}
    print("\n" + format_table(3, table))
    assert table["rdm"].amr > table["rcm"].amr > 0.0
    assert table["rdm"].amf > table["rcm"].amf > 0.0
    j = json.loads(json.dumps(table_json(3, table)))
    assert j["robots"]["rdm"]["paper"]["amr_m3"] == PAPER_TABLE3["rdm"][0]


def test_cli_json_is_valid_and_carries_the_paper(capsys):
    code = main(["design", "--table", "3", "--json", "--resolution", "0.2",
                 "--joint-step", "0.4", "--workers", "1"])  # fmt: skip
    out = capsys.readouterr().out
    assert code == 0
    doc = json.loads(out)
    for name, paper in (("rcm", (1.01, 7.5e-2)), ("rdm", (2.86, 3.2e-1))):
        row = doc["robots"][name]
        assert row["paper"] == {"amr_m3": paper[0], "amf": paper[1]}
        assert row["ours"]["amr_m3"] > 0.0
    assert doc["rdm_over_rcm"]["paper"]["amr"] == pytest.approx(2.86 / 1.01)


def test_cli_refuses_a_grid_too_fine(capsys):
    assert main(["design", "--joint-step", "0.001"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--joint-step" in err and len(err.splitlines()) == 1
