"""Position control (eqs. 30-36) against an independent numpy implementation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rdm.control import position as pc

G = 9.80665
TABLE_V = dict(
    kp=np.array([4.6, 7.0]),
    ki=np.array([1.5, 0.005]),
    kd=np.array([7.0, 10.5]),
    k_roll=0.0,
    k_pitch=1.0,
    k_theta=np.array([0.0, 0.0]),
    k_phi=np.array([1.0, 0.0]),
)


class NumpyPosition:
    """Eqs. (30)-(36) re-derived, with the documented integral clamp |k_I int e| <= limit and
    the tilt bound (1.0 rad): |acc| <= g tan(bound), |roll|, |pitch| <= bound, each
    apparatus's lean (its local x, y) <= g tan(bound)."""

    MAX_TILT = 1.0

    def __init__(self, kp, ki, kd, k_roll, k_pitch, k_theta, k_phi, limit=(1.0, 1.0)):
        self.kp, self.ki, self.kd = kp, ki, kd
        self.k_roll, self.k_pitch, self.k_theta, self.k_phi = k_roll, k_pitch, k_theta, k_phi
        self.limit = np.asarray(limit)
        self.integral = np.zeros(2)

    def step(self, p, v, pd, vd, yaw, rots, dt):
        e = pd - p
        self.integral = self.integral + e * dt
        bound = self.limit / np.abs(self.ki)
        self.integral = np.clip(self.integral, -bound, bound)
        acc = self.kp * e + self.ki * self.integral + self.kd * (vd - v)
        a_max = G * np.tan(self.MAX_TILT)
        if np.linalg.norm(acc) > a_max:
            acc = acc * a_max / np.linalg.norm(acc)
        s, c = np.sin(yaw), np.cos(yaw)
        roll = np.clip(self.k_roll * (acc[0] * s - acc[1] * c) / G, -self.MAX_TILT, self.MAX_TILT)
        pitch = np.clip(self.k_pitch * (acc[0] * c + acc[1] * s) / G, -self.MAX_TILT, self.MAX_TILT)
        alphas, betas, ns = [], [], []
        for i, rot in enumerate(rots):
            lean = np.array(
                [
                    self.k_theta[i] * (acc[0] * c + acc[1] * s),
                    # heading-frame lateral acceleration (the thrust leans toward it; the
                    # printed eq. 36 has the opposite sign here, see docs/lqi.md)
                    self.k_phi[i] * (-acc[0] * s + acc[1] * c),
                ]
            )
            if np.linalg.norm(lean) > a_max:
                lean = lean * a_max / np.linalg.norm(lean)
            n_va = rot @ np.array([lean[0], lean[1], G])
            n = n_va / np.linalg.norm(n_va)
            alpha = np.arctan(-n[1] / n[2])
            beta = np.arctan(n[0] / (-n[1] * np.sin(alpha) + n[2] * np.cos(alpha)))
            alphas.append(alpha)
            betas.append(beta)
            ns.append(n)
        return acc, roll, pitch, alphas, betas, np.array(ns)


def rx(a):
    return Rotation.from_euler("x", a).as_matrix()


def ry(b):
    return Rotation.from_euler("y", b).as_matrix()


@pytest.mark.parametrize("gains", ["table_v", "random"])
def test_position_steps_match_numpy(gains):
    rng = np.random.default_rng(0 if gains == "table_v" else 1)
    if gains == "table_v":
        g = TABLE_V
        ctrl = pc.PositionController()
    else:
        g = dict(
            kp=rng.uniform(1, 8, 2),
            ki=rng.uniform(0.1, 2, 2),
            kd=rng.uniform(1, 10, 2),
            k_roll=rng.uniform(0, 1),
            k_pitch=rng.uniform(0, 1),
            k_theta=rng.uniform(0, 1, 2),
            k_phi=rng.uniform(0, 1, 2),
        )
        ctrl = pc.PositionController(
            x_pid=(g["kp"][0], g["ki"][0], g["kd"][0]),
            y_pid=(g["kp"][1], g["ki"][1], g["kd"][1]),
            k_roll=g["k_roll"],
            k_pitch=g["k_pitch"],
            k_pitch_vectoring=list(g["k_theta"]),
            k_roll_vectoring=list(g["k_phi"]),
        )
    ref = NumpyPosition(**g)
    clamped = saturated = 0
    for _ in range(400):
        p, v, pd, vd = (rng.normal(scale=s, size=2) for s in (1.0, 0.5, 1.0, 0.2))
        yaw = rng.uniform(-np.pi, np.pi)
        rots = (
            Rotation.random(2, random_state=rng).as_matrix()
            if rng.random() < 0.5
            else (
                np.stack(
                    [rx(rng.uniform(-0.5, 0.5)) @ ry(rng.uniform(-0.5, 0.5)) for _ in range(2)]
                )
            )
        )
        pd = pd + 2.0  # persistent error so the integral clamp engages
        out = ctrl.step(p, v, pd, vd, yaw, rots, 0.025)
        acc, roll, pitch, alphas, betas, ns = ref.step(p, v, pd, vd, yaw, rots, 0.025)
        np.testing.assert_allclose(out.acceleration, acc, rtol=1e-12, atol=1e-12)
        assert out.roll == pytest.approx(roll, abs=1e-12)
        assert out.pitch == pytest.approx(pitch, abs=1e-12)
        np.testing.assert_allclose(out.alpha, alphas, atol=1e-12)
        np.testing.assert_allclose(out.beta, betas, atol=1e-12)
        np.testing.assert_allclose(out.direction, ns, atol=1e-12)
        np.testing.assert_allclose(ctrl.integral, ref.integral, atol=1e-12)
        clamped += out.integral_clamped
        saturated += out.saturated
    assert clamped > 0, "anti-windup clamp never exercised"
    assert 0 < saturated < 400, "tilt bound never (or always) exercised"


def test_angles_turn_apparatus_z_onto_direction():
    rng = np.random.default_rng(2)
    for _ in range(500):
        n = rng.normal(size=3)
        n[2] = abs(n[2]) + 0.05
        n /= np.linalg.norm(n)
        alpha, beta = pc.vectoring_angles(n)
        turned = rx(alpha) @ ry(beta) @ np.array([0.0, 0.0, 1.0])
        # atan (not atan2) gives cos(beta) > 0 only when the denominator is positive.
        sign = np.sign(-n[1] * np.sin(alpha) + n[2] * np.cos(alpha))
        np.testing.assert_allclose(turned * sign, n, atol=1e-12)


def test_controller_directions_are_realised_by_its_angles():
    rng = np.random.default_rng(3)
    ctrl = pc.PositionController()
    for _ in range(100):
        rots = np.stack([rx(rng.uniform(-0.4, 0.4)) @ ry(rng.uniform(-0.4, 0.4)) for _ in range(2)])
        out = ctrl.step(
            rng.normal(size=2),
            rng.normal(size=2),
            np.zeros(2),
            np.zeros(2),
            rng.uniform(-3, 3),
            rots,
            0.025,
        )
        for i in range(2):
            turned = rx(out.alpha[i]) @ ry(out.beta[i]) @ np.array([0.0, 0.0, 1.0])
            np.testing.assert_allclose(turned, out.direction[i], atol=1e-12)


def test_bad_inputs_raise_named_errors():
    ctrl = pc.PositionController()
    good = dict(
        position=np.zeros(2),
        velocity=np.zeros(2),
        target_position=np.ones(2),
        target_velocity=np.zeros(2),
        target_yaw=0.0,
        link_rotations=np.stack([np.eye(3)] * 2),
        dt=0.025,
    )
    for name, bad in [
        ("position", np.array([np.nan, 0.0])),
        ("velocity", np.array([0.0, np.inf])),
        ("target_yaw", float("nan")),
        ("dt", 0.0),
        ("link_rotations", np.stack([np.eye(3) * 2] * 2)),
    ]:
        before = ctrl.integral.copy()
        with pytest.raises(pc.PositionControlError, match=name):
            ctrl.step(**{**good, name: bad})
        np.testing.assert_array_equal(ctrl.integral, before)
    with pytest.raises(pc.PositionControlError, match="gains"):
        pc.PositionController(x_pid=(float("nan"), 0.0, 0.0))
    ctrl.step(**good)


@pytest.mark.parametrize("yaw", [0.0, 0.7, -2.0])
def test_vectoring_thrust_leans_toward_the_lateral_demand(yaw):
    """Physical sign of eqs. (33)-(36): with level links (R = I), a demand toward +y' (the
    heading frame's y) must tilt the thrust R_x(alpha) R_y(beta) e_z toward +y', else the
    vectoring loop feeds back positively."""
    ctrl = pc.PositionController(x_pid=(1.0, 0.0, 0.0), y_pid=(1.0, 0.0, 0.0))
    lateral_world = np.array([-np.sin(yaw), np.cos(yaw)])  # heading-frame +y in the world
    target = 0.5 * lateral_world  # robot at the origin, target along +y'
    out = ctrl.step(
        np.zeros(2), np.zeros(2), target, np.zeros(2), yaw, np.stack([np.eye(3)] * 2), 0.025
    )
    thrust = rx(out.alpha[0]) @ ry(out.beta[0]) @ np.array([0.0, 0.0, 1.0])
    assert thrust[1] > 0.02, f"thrust y {thrust[1]} does not lean toward the demand"
    # k_phi = 0 on the arm apparatus (Table V): its thrust stays vertical
    arm = rx(out.alpha[1]) @ ry(out.beta[1]) @ np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(arm, [0.0, 0.0, 1.0], atol=1e-12)


def _wound(x_pid, y_pid, error=(0.3, -0.2), ticks=40, limit=(1.0, 1.0)):
    """A controller whose integral was built by ``ticks`` steps at a constant error."""
    ctrl = pc.PositionController(x_pid=x_pid, y_pid=y_pid, integral_limit=limit)
    rots = np.stack([np.eye(3)] * 2)
    for _ in range(ticks):
        ctrl.step(np.zeros(2), np.zeros(2), np.array(error), np.zeros(2), 0.0, rots, 0.025)
    return ctrl


@pytest.mark.parametrize(
    ("new_x", "new_y", "new_limit"),
    [
        ((1.5, 1.0, 2.0), (0.3, 0.05, 0.8), (1.0, 1.0)),  # the fold gains' kind of switch
        ((1.0, 0.1, 2.0), (7.0, 0.005, 10.5), (0.05, 1.0)),  # new x limit bounds the action
        ((1.0, 0.0, 2.0), (3.0, 0.5, 4.0), (1.0, 1.0)),  # no integral on the new x
    ],
)
def test_bumpless_switch_carries_the_integral_action(new_x, new_y, new_limit):
    """After ``take_integral_action`` the new controller's first output has the old
    integral action k_I ∫e (bounded by the new limit) plus its own P and D terms, computed
    here with numpy from the old controller's integral."""
    old = _wound((4.6, 1.5, 7.0), (7.0, 0.005, 10.5))
    old_action = np.array([1.5, 0.005]) * old.integral
    assert np.all(np.abs(old_action) > 1e-3)  # something to carry
    new = pc.PositionController(x_pid=new_x, y_pid=new_y, integral_limit=new_limit)
    new.take_integral_action(old)
    ki = np.array([new_x[1], new_y[1]])
    want = np.where(ki == 0, 0.0, np.clip(old_action, -np.array(new_limit), new_limit))
    np.testing.assert_allclose(ki * new.integral, want, rtol=1e-12, atol=1e-15)
    # the next step (zero velocities: no D term): numpy PI from the carried integral
    e, dt = np.array([0.01, -0.02]), 0.025
    rots = np.stack([np.eye(3)] * 2)
    out = new.step(np.zeros(2), np.zeros(2), e, np.zeros(2), 0.0, rots, dt)
    kp = np.array([new_x[0], new_y[0]])
    action = np.clip(ki * new.integral, -np.array(new_limit), new_limit)  # after this step
    np.testing.assert_allclose(out.acceleration[:2], kp * e + action, rtol=1e-12)
    carried_then_stepped = np.clip(want + ki * e * dt, -np.array(new_limit), new_limit)
    np.testing.assert_allclose(action, carried_then_stepped, rtol=1e-12, atol=1e-15)
    # the old controller is untouched
    np.testing.assert_allclose(np.array([1.5, 0.005]) * old.integral, old_action)


def _tilt_from_link_z(n: np.ndarray, rot: np.ndarray) -> float:
    """Angle between a unit direction and its link's z axis (rot's third column)."""
    return float(np.arccos(np.clip(np.dot(n, rot[:, 2]), -1.0, 1.0)))


@pytest.mark.parametrize(
    ("position", "velocity"),
    [
        ([1e300, 0.0], [0.0, 0.0]),
        ([-1e300, 2e299], [1e300, -1e300]),
        ([1e308, -1e308], [-1e308, 1e308]),  # the PID sum overflows to inf - inf
    ],
)
def test_absurd_errors_command_at_most_the_tilt_bound(position, velocity):
    """1e300 m of error asks for the bound (1.0 rad), not 4.7e299 rad, and says so."""
    ctrl = pc.PositionController()
    rots = np.stack([rx(0.3) @ ry(-0.2), ry(0.4)])
    out = ctrl.step(np.array(position), np.array(velocity), np.zeros(2), np.zeros(2), 0.4, rots,
                    0.025)  # fmt: skip
    limit = pc.MAX_TILT_RAD
    assert limit == 1.0
    assert abs(out.roll) <= limit and abs(out.pitch) <= limit
    assert np.all(np.isfinite(out.acceleration))
    assert np.hypot(*out.acceleration) <= G * np.tan(limit) * (1 + 1e-12)
    for i in range(2):
        assert np.all(np.isfinite(out.direction[i]))
        assert _tilt_from_link_z(out.direction[i], rots[i]) <= limit + 1e-12
    assert np.all(np.isfinite(out.alpha)) and np.all(np.isfinite(out.beta))
    assert out.saturated and "acceleration" in out.saturation
    # A later, ordinary step is not cut (the integral stayed within its clamp).
    ctrl.reset()
    calm = ctrl.step(np.array([0.1, 0.0]), np.zeros(2), np.zeros(2), np.zeros(2), 0.0, rots, 0.025)
    assert not calm.saturated and calm.saturation == ()


def test_the_tilt_bound_cuts_pitch_at_the_bound_it_is_given():
    """With k_theta_d = 1 the pitch target is a/g (eq. 32): a 5 m/s^2 demand is 0.51 rad, cut
    to a 0.3 rad bound; the acceleration itself is cut to g tan(0.3)."""
    ctrl = pc.PositionController(x_pid=(5.0, 0.0, 0.0), max_tilt=0.3)
    out = ctrl.step(np.array([-1.0, 0.0]), np.zeros(2), np.zeros(2), np.zeros(2), 0.0,
                    np.stack([np.eye(3)] * 2), 0.025)  # fmt: skip
    assert out.pitch == pytest.approx(0.3, abs=1e-12)
    np.testing.assert_allclose(out.acceleration, [G * np.tan(0.3), 0.0], atol=1e-12)
    # a/g = tan(0.3) > 0.3: eq. (32)'s linear pitch target is cut too
    assert out.saturation == ("acceleration", "attitude")
    free = pc.PositionController(x_pid=(5.0, 0.0, 0.0)).step(
        np.array([-1.0, 0.0]), np.zeros(2), np.zeros(2), np.zeros(2), 0.0,
        np.stack([np.eye(3)] * 2), 0.025,
    )  # fmt: skip
    assert free.pitch == pytest.approx(5.0 / G, abs=1e-12) and not free.saturated


@pytest.mark.parametrize("bad", [0.0, -0.2, np.pi / 2, float("nan"), float("inf")])
def test_a_tilt_bound_outside_the_open_quarter_turn_is_refused(bad):
    with pytest.raises(pc.PositionControlError, match="gains"):
        pc.PositionController(max_tilt=bad)


def test_nan_errors_are_refused_not_saturated():
    ctrl = pc.PositionController()
    with pytest.raises(pc.PositionControlError, match="position"):
        ctrl.step(np.array([np.nan, 1e300]), np.zeros(2), np.zeros(2), np.zeros(2), 0.0,
                  np.stack([np.eye(3)] * 2), 0.025)  # fmt: skip
