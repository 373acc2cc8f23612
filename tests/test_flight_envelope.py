"""The flight envelope of the paper's controller (docs/scenarios.md), checked against an
independent computation from MuJoCo: the rotor wrenches from the actuators' gear vectors at
the rotor sites, the CoG and composite inertia from the bodies, the levelling vectoring
angles solved on MuJoCo's kinematics, and the LQI gains from scipy's Riccati solver with the
paper's Table V weights. Nothing here comes from ``rdm.model``."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import scipy.linalg
from lqi_reference import hover_state_model
from scipy.optimize import least_squares

from rdm.model import Robot
from rdm.plant import Plant
from rdm.plant.mjcf import rotor_actuator
from rdm.scenarios import flight_envelope as fe
from rdm.scenarios import tracking
from rdm.scenarios.perching import PERCH_POSTURE, POSITION_GAINS

OFFSET = np.array(tracking.MOTION[0][1])  # q2..q5 = (-0.3, 0.2, 0.4, 0.3)
HANGING = np.array(PERCH_POSTURE)
#: Table V (the paper): W1 diag in the state order [z, ż, φ, φ̇, θ, θ̇, ψ, ψ̇, ∫z, ∫φ, ∫θ, ∫ψ],
#: W2 = identity; x PID (4.6, 1.5, 7.0)
TABLE_V_W1 = [20, 30, 90, 12.8, 600, 80, 100, 50, 20, 0.15, 1, 0.5]
TABLE_V_X = (4.6, 1.5, 7.0)


class MujocoRobot:
    """Hover quantities of the robot computed with MuJoCo alone."""

    def __init__(self) -> None:
        self.robot = Robot.default()  # names and rotor limits only
        self.plant = Plant("rdm", ceiling_height=None, floor_height=None)
        self.m = self.plant.model
        self.d = mujoco.MjData(self.m)
        self.g = -float(self.m.opt.gravity[2])
        self.names = list(self.robot.joint_names)
        m = self.m
        self.root = next(
            b for b in range(1, m.nbody) if m.body_parentid[b] == 0 and m.body_jntnum[b]
        )
        self.acts = [self.m.actuator(rotor_actuator(r["name"])).id for r in self.robot.rotors]
        self.lo = np.array([r["thrust_min"] for r in self.robot.rotors])
        self.hi = np.array([r["thrust_max"] for r in self.robot.rotors])

    def forward(self, q: np.ndarray) -> None:
        mujoco.mj_resetData(self.m, self.d)
        for n, v in zip(self.names, q, strict=True):
            self.d.qpos[self.m.jnt_qposadr[self.m.joint(n).id]] = v
        mujoco.mj_forward(self.m, self.d)

    def rotor_wrenches(self) -> tuple[np.ndarray, np.ndarray]:
        """(6, N) unit-thrust wrenches about the CoG in the foot body's axes, and the mass."""
        sub = [b for b in range(1, self.m.nbody) if self.m.body_rootid[b] == self.root]
        mass = sum(self.m.body_mass[b] for b in sub)
        cog = sum(self.m.body_mass[b] * self.d.xipos[b] for b in sub) / mass
        rf = self.d.xmat[self.root].reshape(3, 3)
        cols = []
        for a in self.acts:
            site = self.m.actuator_trnid[a, 0]
            rs = self.d.site_xmat[site].reshape(3, 3)
            gear = self.m.actuator_gear[a]
            force = rs @ gear[:3]
            torque = rs @ gear[3:] + np.cross(self.d.site_xpos[site] - cog, force)
            cols.append(np.r_[rf.T @ force, rf.T @ torque])
        return np.array(cols).T, mass

    def inertia(self) -> np.ndarray:
        """Composite inertia about the CoG, foot body's axes."""
        sub = [b for b in range(1, self.m.nbody) if self.m.body_rootid[b] == self.root]
        mass = sum(self.m.body_mass[b] for b in sub)
        cog = sum(self.m.body_mass[b] * self.d.xipos[b] for b in sub) / mass
        i = np.zeros((3, 3))
        for b in sub:
            r = self.d.ximat[b].reshape(3, 3)
            dd = self.d.xipos[b] - cog
            i += r @ np.diag(self.m.body_inertia[b]) @ r.T
            i += self.m.body_mass[b] * (dd @ dd * np.eye(3) - np.outer(dd, dd))
        rf = self.d.xmat[self.root].reshape(3, 3)
        return rf.T @ i @ rf

    def levelled(self, joints: np.ndarray) -> np.ndarray:
        """Joints plus the vectoring angles that make every rotor axis the foot's z axis."""
        q = np.r_[joints, np.zeros(len(self.names) - len(joints))]
        idx = [self.names.index(n) for n in ("alpha1", "beta1", "alpha2", "beta2")]

        def tilt(x):
            q[idx] = x
            self.forward(q)
            w, _ = self.rotor_wrenches()
            # thrust axes = foot z; the tiny pull toward 0 fixes the angle that is free when an
            # axis lies on the unit's x axis (hanging posture), as the robot keeps it at 0
            return np.r_[(w[:3] - [[0.0], [0.0], [1.0]]).ravel(), 1e-7 * x]

        sol = least_squares(tilt, np.zeros(4), xtol=1e-14, ftol=1e-14, gtol=1e-14)
        q[idx] = sol.x
        self.forward(q)
        return q.copy()

    def hover(self, joints: np.ndarray) -> np.ndarray:
        self.levelled(joints)
        w, mass = self.rotor_wrenches()
        return np.linalg.solve(w[2:6], [mass * self.g, 0, 0, 0])

    def margin(self, joints: np.ndarray) -> float:
        t = self.hover(joints)
        return float(np.min(np.minimum(t - self.lo, self.hi - t)))


@pytest.fixture(scope="module")
def mj():
    return MujocoRobot()


def test_levelled_units_point_their_thrust_up(mj):
    q = fe.levelled_configuration(mj.robot, 2.0 * OFFSET)
    mj.forward(q)
    w, _ = mj.rotor_wrenches()
    assert np.allclose(w[:3], np.array([[0.0], [0.0], [1.0]]), atol=1e-9)


@pytest.mark.parametrize(
    "joints",
    [OFFSET, 2.0 * OFFSET, np.array([0.5, -0.5, 0.2, 0.8, 0.6, 0.0]), HANGING + OFFSET],
    ids=["tracking_1x", "tracking_2x", "fig9", "hanging_1x"],
)
def test_hover_thrusts_match_mujoco(mj, joints):
    ours = fe.hover_thrusts(mj.robot, joints, gravity=mj.g)
    assert np.allclose(ours, mj.hover(joints), atol=1e-6)


def test_tracking_motion_limit_is_the_static_thrust_limit(mj):
    """The straight-posture motion leaves the rotors' [1, 20] N range between 1.0x and 1.5x:
    at 2x the levelled hover needs rotor 3 below zero and rotor 1 above 20 N."""
    t2 = mj.hover(2.0 * OFFSET)
    assert t2[2] < 0.0 and t2[0] > 20.0
    assert mj.margin(1.0 * OFFSET) > 0.0
    assert mj.margin(1.5 * OFFSET) < 0.0
    grid = np.linspace(0.0, 1.0, 21)
    lo, hi = 1.0, 1.5  # MuJoCo bisection of the largest feasible scale
    while hi - lo > 1e-3:
        mid = 0.5 * (lo + hi)
        ok = all(mj.margin(s * mid * OFFSET) >= 0.0 for s in grid)
        lo, hi = (mid, hi) if ok else (lo, mid)
    ours = fe.largest_scale(mj.robot, np.zeros(6), OFFSET)
    assert abs(ours - lo) < 0.01
    assert 1.05 < ours < 1.2


def _scipy_loop(mj, joints, pid, axis):
    """Independent linearised hover: scipy LQR on MuJoCo's inertia and allocation, position
    PID on the roll (y) or pitch (x) target."""
    mj.levelled(joints)
    w, mass = mj.rotor_wrenches()
    qbar = w[2:6]
    a, b = hover_state_model(mass, mj.inertia(), qbar)
    p = scipy.linalg.solve_continuous_are(a, b, np.diag(TABLE_V_W1), np.eye(4))
    k = -b.T @ p
    st, sign = (2, -1.0) if axis == "y" else (4, 1.0)
    kp, ki, kd = pid
    g = fe.GRAVITY
    f = np.zeros((15, 15))
    f[:12, :12] = a + b @ k
    tgt = np.zeros(15)
    tgt[12], tgt[13], tgt[14] = -sign * kp / g, -sign * kd / g, -sign * ki / g
    f[:12] -= np.outer(b @ k[:, st], tgt)
    f[8 + st // 2] += tgt
    f[12, 13], f[13, st], f[14, 12] = 1.0, sign * g, 1.0
    return np.linalg.eigvals(f), mj.levelled(joints)


H1 = HANGING + OFFSET  # the hanging posture after the tracking motion's first segment


@pytest.mark.parametrize(
    ("gains", "axis", "joints", "expected"),
    [
        (POSITION_GAINS["y_pid"], "y", HANGING, "unstable"),
        (POSITION_GAINS["y_pid"], "y", H1, "unstable"),
        (TABLE_V_X, "x", HANGING, "unstable"),
        (TABLE_V_X, "x", H1, "marginal"),
        (tracking.HANGING_FLIGHT_GAINS["y_pid"], "y", HANGING, "stable"),
        (tracking.HANGING_FLIGHT_GAINS["y_pid"], "y", H1, "stable"),
        (tracking.HANGING_FLIGHT_GAINS["x_pid"], "x", HANGING, "stable"),
        (tracking.HANGING_FLIGHT_GAINS["x_pid"], "x", H1, "stable"),
    ],
    ids=[
        "perching_y-hanging",
        "perching_y-hanging_1x",
        "table_v_x-hanging",
        "table_v_x-hanging_1x",
        "flight_stage_y-hanging",
        "flight_stage_y-hanging_1x",
        "flight_stage_x-hanging",
        "flight_stage_x-hanging_1x",
    ],
)
def test_hanging_posture_horizontal_loops(mj, gains, axis, joints, expected):
    """In the hanging posture the perching configuration's y gains (through roll) and Table
    V's x gains (through pitch) give a growing (or barely damped) oscillation; the tracking
    scenario's hanging flight-stage gains are damped (>= 0.25) along its 1.0x motion."""
    ev, q = _scipy_loop(mj, joints, gains, axis)
    ours = fe.horizontal_loop_poles(mj.robot, q, gains, axis, gravity=fe.GRAVITY)
    assert np.allclose(np.sort_complex(ours), np.sort_complex(ev), rtol=1e-5, atol=1e-6)
    osc = ev[np.abs(ev.imag) > 0.05]
    damping = min(-e.real / abs(e) for e in osc)
    if expected == "unstable":
        assert ev.real.max() > 0.1  # e-folds in < 10 s
    elif expected == "marginal":
        assert ev.real.max() < 0.0 and damping < 0.05
    else:
        assert ev.real.max() < 0.0 and damping > 0.25


def test_straight_posture_keeps_the_gains_that_fly(mj):
    """At q = 0 both the perching y gains and Table V x are stable (the tracking default run)."""
    for pid, axis in ((POSITION_GAINS["y_pid"], "y"), (TABLE_V_X, "x")):
        ev, _ = _scipy_loop(mj, np.zeros(6), pid, axis)
        assert ev.real.max() < 0.0


def test_hanging_flight_stage_flies_the_tracking_motion(tmp_path):
    """The tracking scenario's flight stage in the hanging posture (its planned path): before
    the hanging gain set the robot fell (Spinal's commanded-tilt fail-safe ~10 s after the
    fold, with or without the motion)."""
    res = tracking.run(tmp_path, flight_posture="hanging", duration=26.0, log=False, plots=False)
    assert not res.stack.spinal.counters.failsafes
    assert "flight" in res.facts
    e = res.errors["flight"]
    assert e.pos_max.max() < 1.0 and e.att_max.max() < 0.2
    cog_z = np.array([g.cog_position[2] for g in res.stack.truth if g.time > 13.0])
    assert cog_z.min() > 0.5


def test_table_v_x_loop_is_the_lightly_damped_pair_of_a_slow_pitch_loop():
    """Table V's x PID at q = 0: the least-damped pair equals that of the reduced model
    ``s^3 (s + 13.6)(s + 2.8) + 38.7 (7 s^2 + 4.6 s + 1.5)`` (the pitch loop as the
    identified 38.7 / ((s + 13.6)(s + 2.8)), x = g theta / s^2, the PID over g), roots by
    numpy; a stiffer pitch (inertia / 100) raises the damping only to ~0.24, the ceiling set
    by Table V's sqrt(600 / 80) rad/s pitch pole; Table V's weights read in the paper's
    eq. (26) order (angles, rates, integrals) make the loop diverge."""
    robot = Robot.default()
    q = fe.levelled_configuration(robot, np.zeros(6))
    zeta, wn = fe.least_damped_pair(fe.horizontal_loop_poles(robot, q, TABLE_V_X, "x"))
    poly = np.polyadd(
        np.polymul([1, 0, 0, 0], np.polymul([1, 13.6], [1, 2.8])), 38.7 * np.array([7, 4.6, 1.5])
    )
    ref = np.roots(poly)
    ref_pair = ref[np.abs(ref.imag) > 1.0][0]
    assert wn == pytest.approx(abs(ref_pair), rel=0.03)
    assert zeta == pytest.approx(-ref_pair.real / abs(ref_pair), rel=0.1)
    assert zeta < 0.1
    stiff, _ = fe.least_damped_pair(
        fe.horizontal_loop_poles(robot, q, TABLE_V_X, "x", inertia_scale=0.01)
    )
    assert 0.2 < stiff < 0.3
    w = TABLE_V_W1
    paper_order = [w[0], w[4], w[1], w[5], w[2], w[6], w[3], w[7], *w[8:]]
    ev = fe.horizontal_loop_poles(robot, q, TABLE_V_X, "x", q_weights=paper_order)
    assert ev.real.max() > 0.05
