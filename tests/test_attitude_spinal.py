"""Spinal attitude controller and flight state machine against an independent numpy
re-derivation of jsk-wire-protocols.md sec. 3.4-3.7 (attitude_control.cpp update() and
pwmConversion()), including the saturation cases, anti-windup and the fail-safes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rdm.control.attitude import (
    ARM_OFF,
    ARM_ON,
    FORCE_LANDING,
    INTEGRATION_CONTROL_ON,
    UAV_HYDRUS,
    AttitudeController,
    CommandRejectedError,
    SpinalStep,
    clamp_gain,
    gains_from_wire_terms,
    gains_to_wire_terms,
)

P2, P1, P0 = 0.07983707, -6.627443098, 12.3593793002
VREF, MAX_THRUST, MIN_PWM, MAX_PWM, MIN_THRUST, FL_THRUST = 25.2, 20.0, 0.59, 0.9375, 1.0, 6.5
RATE = 200.0
DT = 1.0 / RATE


def ref_duty_raw(f: float, v_factor: float) -> float:
    """Invert f = 0.1 p2 x^2 + 0.1 p1 x + p0 with numpy.roots (larger root), x in %."""
    f = max(v_factor * f, 0.0)
    roots = np.roots([0.1 * P2, 0.1 * P1, P0 - f])
    return float(np.max(roots.real)) / 100.0


def euler_zyx(r: np.ndarray) -> np.ndarray:
    return np.array(
        [
            np.arctan2(r[2, 1], r[2, 2]),
            -np.arcsin(np.clip(r[2, 0], -1, 1)),
            np.arctan2(r[1, 0], r[0, 0]),
        ]
    )


class ReferenceController:
    """numpy model of the firmware controller (rotor divider 1, one SQRT curve)."""

    def __init__(self, gains, pinv, inertia6, voltage):
        self.kp = np.array([[g[0][0], g[1][0]] for g in gains])
        self.ki = np.array([[g[0][1], g[1][1]] for g in gains])
        self.kd = np.array([[g[0][2], g[1][2], g[2][2]] for g in gains])
        self.pinv = np.asarray(pinv)
        xx, yy, zz, xy, yz, xz = inertia6
        self.inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        self.vf = (VREF / voltage) ** 2
        self.min_duty = ref_duty_raw(MIN_THRUST, self.vf)
        self.ei = np.zeros(2)
        self.target = np.zeros(2)
        self.base = np.zeros(4)
        self.extra_yaw = np.zeros(4)
        positive = np.where(self.kd[:, 2] > 0)[0]
        self.imax = int(positive[np.argmax(self.kd[positive, 2])]) if len(positive) else None

    def command(self, angles, base):
        self.target = np.array(angles[:2])
        self.base = np.array(base, float)
        if self.imax is not None:
            self.extra_yaw = angles[2] * self.kd[:, 2] / self.kd[self.imax, 2]

    def step(self, rot, gyro):
        e = euler_zyx(rot)
        err = self.target - e[:2]
        self.ei = self.ei + err * DT
        w = np.asarray(gyro)
        gm = np.cross(w, self.inertia @ w)
        rp = (self.kp * err).sum(1) + (self.ki * self.ei).sum(1) - (self.kd[:, :2] * w[:2]).sum(1)
        rp += self.pinv @ gm
        yaw = self.extra_yaw - self.kd[:, 2] * w[2]
        limit = MAX_THRUST / self.vf
        alpha, beta = 0.0, 0.0
        s2 = self.base + rp
        imax = int(np.argmax(s2)) if s2.max() > 0 else 0
        residual = limit - max(s2.max(), 0.0)
        if residual < 0 and self.base[imax] > 0:
            alpha = residual / self.base[imax]
            beta = -1.0
        elif self.imax is not None and self.base[0] != 0:
            s1 = self.base + rp + yaw
            hi = int(np.argmax(s1)) if s1.max() > 0 else 0
            lo = int(np.argmin(s1)) if s1.min() < 10000 else 0
            r_max = limit - max(s1.max(), 0.0)
            r_min = min(s1.min(), 10000.0) - MIN_THRUST
            residual, idx = (r_min, lo) if r_min < r_max else (r_max, hi)
            if residual < 0:
                beta = residual / abs(yaw[idx])
            beta = float(np.clip(beta, -1.0, 0.0))
        else:
            beta = -1.0
        thrust = rp + (1 + alpha) * self.base + (1 + beta) * yaw
        duty = np.clip([ref_duty_raw(f, self.vf) for f in thrust], self.min_duty, MAX_PWM)
        return thrust, duty, alpha, beta


def _gains(rng):
    g = np.zeros((4, 4, 3))
    g[:, 0, :] = rng.uniform([2, 0.5, 0.5], [6, 2.0, 1.5], (4, 3)) * rng.choice([-1, 1], (4, 1))
    g[:, 1, :] = rng.uniform([2, 0.5, 0.5], [6, 2.0, 1.5], (4, 3)) * rng.choice([-1, 1], (4, 1))
    g[:, 2, 2] = np.array([0.4, -0.4, 0.6, -0.3])
    return g


def _armed(gains, pinv, inertia6, *, anti_windup=False, **kw):
    c = AttitudeController(RATE, anti_windup=anti_windup, **kw)
    c.set_uav_info(4, UAV_HYDRUS)
    c.set_pwm_info_hydrus_example()
    c.set_gains(gains)
    c.set_pinv_inertia(pinv, inertia6)
    c.flight_config(ARM_ON, 0.0)
    c.flight_config(INTEGRATION_CONTROL_ON, 0.0)
    return c


@pytest.mark.parametrize("case", ["nominal", "z_saturation", "yaw_saturation", "low_side"])
def test_step_matches_numpy_rederivation(case: str) -> None:
    rng = np.random.default_rng(
        {"nominal": 1, "z_saturation": 2, "yaw_saturation": 3, "low_side": 4}[case]
    )
    gains = _gains(rng)
    pinv = rng.uniform(-0.5, 0.5, (4, 3))
    inertia6 = [0.12, 0.15, 0.2, 0.01, -0.005, 0.003]
    voltage = 24.0
    ctrl = _armed(gains, pinv, inertia6)
    ref = ReferenceController(gains, pinv, inertia6, voltage)
    base = {"nominal": 6.0, "z_saturation": 19.5, "yaw_saturation": 9.0, "low_side": 1.3}[case]
    yaw_cmd = {"nominal": 0.3, "z_saturation": 0.5, "yaw_saturation": 8.0, "low_side": -2.0}[case]
    seen_alpha, seen_beta = [], []
    for k in range(400):
        now = k * DT
        if k % 5 == 0:
            angles = [0.1 * np.sin(0.05 * k), -0.08 * np.cos(0.03 * k), yaw_cmd]
            thrusts = base + 0.5 * np.sin(0.1 * k + np.arange(4))
            ctrl.four_axis_command(angles, thrusts, now)
            ref.command(angles, thrusts)
        rot = Rotation.from_euler(
            "ZYX", [0.3 * np.sin(0.01 * k), 0.2 * np.sin(0.02 * k), 0.25 * np.cos(0.015 * k)]
        ).as_matrix()
        gyro = rng.normal(0.0, 0.6, 3)
        out = ctrl.step(now, rot, gyro, voltage)
        thrust, duty, alpha, beta = ref.step(rot, gyro)
        assert out.status == "armed"
        np.testing.assert_allclose(out.thrust, thrust, rtol=0, atol=1e-10)
        np.testing.assert_allclose(out.duty, duty, rtol=0, atol=1e-10)
        assert out.alpha == pytest.approx(alpha, abs=1e-12)
        assert out.beta == pytest.approx(beta, abs=1e-12)
        np.testing.assert_array_equal(
            out.pwm_report, np.trunc(np.asarray(duty) * 2000).astype(np.uint16)
        )
        seen_alpha.append(alpha)
        seen_beta.append(beta)
    seen_alpha, seen_beta = np.array(seen_alpha), np.array(seen_beta)
    if case == "z_saturation":
        assert (seen_alpha < 0).mean() > 0.5
    elif case in ("yaw_saturation", "low_side"):
        assert ((seen_beta < 0) & (seen_beta > -1)).any()
    else:
        assert (seen_alpha == 0).all()


def _saturating_run(anti_windup: bool, steps: int = 600):
    gains = np.zeros((4, 4, 3))
    gains[:, 0, :] = [[8.0, 3.0, 1.0], [8.0, 3.0, 1.0], [-8.0, -3.0, -1.0], [-8.0, -3.0, -1.0]]
    ctrl = _armed(
        gains, np.zeros((4, 3)), [0.1] * 3 + [0.0] * 3, anti_windup=anti_windup, integral_limit=0.4
    )
    rot = Rotation.from_euler("x", -0.6).as_matrix()  # 0.6 rad roll error held
    integral = []
    for k in range(steps):
        now = k * DT
        if k % 5 == 0:
            ctrl.four_axis_command([0.0, 0.0, 0.0], np.full(4, 18.0), now)
        out = ctrl.step(now, rot, [0.0, 0.0, 0.0], 25.2)
        integral.append(out.error_integral[0])
    return np.array(integral), out


def test_anti_windup_bounds_the_integral_under_saturation() -> None:
    off, out_off = _saturating_run(anti_windup=False)
    on, out_on = _saturating_run(anti_windup=True)
    assert out_off.alpha < 0 and out_on.alpha < 0  # really saturated
    # Firmware behaviour: e_i grows by e*dt every step without bound.
    assert off[-1] == pytest.approx(0.6 * DT * len(off), rel=1e-9)
    # Anti-windup: no growth once saturated, and never beyond the clamp.
    assert np.abs(on).max() <= 0.4 + 1e-12
    assert on[-1] < 0.05 * off[-1]


def test_anti_windup_clamp_without_saturation() -> None:
    gains = np.zeros((4, 4, 3))
    gains[:, 0, 1] = 0.001  # tiny I gain: no saturation, only the clamp acts
    ctrl = _armed(
        gains, np.zeros((4, 3)), [0.1] * 3 + [0.0] * 3, anti_windup=True, integral_limit=0.05
    )
    rot = Rotation.from_euler("x", -0.2).as_matrix()
    for k in range(400):
        if k % 5 == 0:
            ctrl.four_axis_command([0.0, 0.0, 0.0], np.full(4, 6.0), k * DT)
        out = ctrl.step(k * DT, rot, [0.0, 0.0, 0.0], 25.2)
    assert out.error_integral[0] == pytest.approx(0.05)


def _ready(**kw) -> AttitudeController:
    g = np.zeros((4, 4, 3))
    g[:, 0, 0] = 2.0
    c = AttitudeController(RATE, **kw)
    c.set_uav_info(4, UAV_HYDRUS)
    c.set_pwm_info_hydrus_example()
    c.set_gains(g)
    return c


def _events(out):
    return list(out.events)


def test_arming_preconditions_and_acks() -> None:
    c = AttitudeController(RATE)
    with pytest.raises(CommandRejectedError, match="ARM_ON"):
        c.flight_config(ARM_ON, 0.0)  # no uav_info, no motor_info
    c.set_uav_info(4, UAV_HYDRUS)
    with pytest.raises(CommandRejectedError, match="ARM_ON"):
        c.flight_config(ARM_ON, 0.0)  # no motor_info: max_duty == min_duty
    assert _events(c.step(0.0, np.eye(3), [0, 0, 0], 25.0)) == []  # no ack
    c.set_pwm_info_hydrus_example()
    c.flight_config(ARM_ON, 0.01)
    out = c.step(0.01, np.eye(3), [0, 0, 0], 25.0)
    assert out.status == "armed" and ("ack", ARM_ON) in _events(out)
    # With base thrust 0 the motors run at min_duty = convert(min_thrust).
    min_duty = ref_duty_raw(MIN_THRUST, (VREF / 25.0) ** 2)
    np.testing.assert_allclose(out.duty, min_duty, atol=1e-12)
    c.flight_config(ARM_OFF, 0.02)
    out = c.step(0.02, np.eye(3), [0, 0, 0], 25.0)
    assert out.status == "disarmed" and ("ack", ARM_OFF) in _events(out)
    np.testing.assert_array_equal(out.duty, 0.5)
    assert np.all(c.thrust_gains == 0.0)  # reset() cleared the gains
    # A different motor count later blocks arming (firmware setMotorNumber).
    c.set_uav_info(3, UAV_HYDRUS)
    assert c.motor_number == 0
    with pytest.raises(CommandRejectedError):
        c.flight_config(ARM_ON, 0.03)


def test_command_timeout_starts_force_landing_after_500_ms() -> None:
    c = _ready()
    c.flight_config(ARM_ON, 0.0)
    c.step(0.0, np.eye(3), [0, 0, 0], 25.0)
    # No timeout before the first command.
    assert c.step(10.0, np.eye(3), [0, 0, 0], 25.0).status == "armed"
    c.four_axis_command([0, 0, 0], np.full(4, 8.0), 10.0)
    assert c.step(10.5, np.eye(3), [0, 0, 0], 25.0).status == "armed"  # exactly 500 ms
    out = c.step(10.505, np.eye(3), [0, 0, 0], 25.0)
    assert out.status == "force_landing"
    assert _events(out) == [("failsafe_timeout", None), ("ack", FORCE_LANDING)]
    assert c.counters["failsafes"] == 1
    # Once only.
    assert _events(c.step(10.51, np.eye(3), [0, 0, 0], 25.0)) == []


def test_force_landing_ramp_rate_and_command_filter() -> None:
    c = _ready()
    c.flight_config(ARM_ON, 0.0)
    c.flight_config(INTEGRATION_CONTROL_ON, 0.0)
    base = np.array([9.0, 10.0, 11.0, 12.0])
    c.four_axis_command([0, 0, 0], base, 0.0)
    c.flight_config(FORCE_LANDING, 0.0)
    out = c.step(0.0, np.eye(3), [0, 0, 0], 25.0)
    assert ("ack", FORCE_LANDING) in _events(out)
    # Independent ramp: base_i -= base_i/avg * 2.5 N/s * dt while avg > 6.5 N.
    expected = base.copy()
    expected -= expected / expected.mean() * 2.5 * DT
    np.testing.assert_allclose(c.base_thrust, expected, rtol=0, atol=1e-12)
    avg = [c.base_thrust.mean()]
    for k in range(1, 400):
        c.step(k * DT, np.eye(3), [0, 0, 0], 25.0)
        avg.append(c.base_thrust.mean())
    avg = np.array(avg)
    rate = -np.diff(avg[:100]) / DT
    np.testing.assert_allclose(rate, 2.5, rtol=1e-9)  # 2.5 N/s on the average
    assert avg[-1] <= FL_THRUST and avg[-1] > FL_THRUST - 2.5 * DT - 1e-12  # stops there
    # Commands below force_landing_thrust are ignored, above are taken.
    with pytest.raises(CommandRejectedError, match="force_landing"):
        c.four_axis_command([0, 0, 0], np.full(4, 5.0), 2.0)
    c.four_axis_command([0.2, 0, 0], np.full(4, 7.0), 2.0)
    np.testing.assert_allclose(c.base_thrust, 7.0)
    c.step(2.0, np.eye(3), [0, 0, 0], 25.0)
    np.testing.assert_array_equal(c.target_angles, [0.0, 0.0])  # targets zeroed


def test_tilt_failsafes() -> None:
    c = _ready()
    c.flight_config(ARM_ON, 0.0)
    c.flight_config(INTEGRATION_CONTROL_ON, 0.0)
    c.four_axis_command([0.3, 0, 0], np.full(4, 8.0), 0.0)
    for k in range(20):
        c.step(k * DT, np.eye(3), [0, 0, 0], 25.0)
    assert c.error_integral[0] > 0
    tilted = Rotation.from_euler("ZYX", [0.0, 0.0, 1.05]).as_matrix()
    out = c.step(0.1, tilted, [0, 0, 0], 25.0)
    assert out.status == "force_landing"
    assert _events(out) == [("failsafe_tilt", None), ("ack", FORCE_LANDING)]
    # zeroed, then (as in the firmware) this step's error -1.05 rad is integrated once
    np.testing.assert_allclose(out.error_integral, [-1.05 * DT, 0.0], atol=1e-12)
    # commanded tilt
    c2 = _ready()
    c2.flight_config(ARM_ON, 0.0)
    c2.four_axis_command([0.0, -1.01, 0.0], np.full(4, 8.0), 0.0)
    out = c2.step(0.0, np.eye(3), [0, 0, 0], 25.0)
    assert _events(out) == [
        ("ack", ARM_ON),
        ("failsafe_command_tilt", None),
        ("ack", FORCE_LANDING),
    ]
    # 0.99 rad pitch estimated is fine
    c3 = _ready()
    c3.flight_config(ARM_ON, 0.0)
    assert (
        c3.step(0.0, Rotation.from_euler("y", 0.99).as_matrix(), [0, 0, 0], 25.0).status == "armed"
    )


def test_wrong_length_and_non_finite_commands_are_rejected_and_counted() -> None:
    c = _ready()
    with pytest.raises(CommandRejectedError, match="not armed"):
        c.four_axis_command([0, 0, 0], np.full(4, 5.0), 0.0)
    c.flight_config(ARM_ON, 0.0)
    with pytest.raises(CommandRejectedError, match="base_thrust: length 3"):
        c.four_axis_command([0, 0, 0], np.full(3, 5.0), 0.0)
    with pytest.raises(CommandRejectedError, match="pseudo_inverse: length 2"):
        c.set_pinv_inertia(np.zeros((2, 3)), [0.1] * 6)
    with pytest.raises(CommandRejectedError, match=r"rpy/gain\.motors: length 3"):
        c.set_gains_wire(np.zeros((3, 7), dtype=np.int64))
    with pytest.raises(CommandRejectedError, match="not finite"):
        c.four_axis_command([np.nan, 0, 0], np.full(4, 5.0), 0.0)
    with pytest.raises(CommandRejectedError, match="unknown value 7"):
        c.flight_config(7, 0.0)
    assert c.counters["wrong_length"] == 3
    assert c.counters["non_finite"] == 1
    out = c.step(0.0, np.eye(3), [0, 0, 0], 25.0)
    assert sum(1 for e in out.events if e[0] == "rejected") == 3
    # The failsafe timer was not started by the rejected commands.
    assert c.step(5.0, np.eye(3), [0, 0, 0], 25.0).status == "armed"


def test_non_finite_step_inputs_hold_outputs() -> None:
    c = _ready()
    c.flight_config(ARM_ON, 0.0)
    c.four_axis_command([0, 0, 0], np.full(4, 8.0), 0.0)
    good = c.step(0.0, np.eye(3), [0.1, 0, 0], 25.0)
    for rot, gyro, now in [
        (np.full((3, 3), np.nan), [0, 0, 0], 0.005),
        (np.eye(3), [np.inf, 0, 0], 0.005),
        (np.eye(3), [0, 0, 0], np.nan),
    ]:
        out = c.step(now, rot, gyro, 25.0)
        assert out.status == "invalid_input"
        np.testing.assert_array_equal(out.duty, good.duty)
        assert np.all(np.isfinite(out.thrust))
    # NaN voltage: ignored and counted by the converter, step still finite.
    c.four_axis_command([0, 0, 0], np.full(4, 8.0), 0.55)
    out = c.step(0.6, np.eye(3), [0, 0, 0], np.nan)
    assert out.status == "armed" and np.all(np.isfinite(out.duty))
    assert c.counters["invalid_steps"] == 3


def test_yaw_spreading_and_torque_gain_mapping() -> None:
    c = AttitudeController(RATE)
    c.set_uav_info(4, UAV_HYDRUS)
    c.set_pwm_info_hydrus_example()
    tinv = np.array(
        [[100, -200, 300], [-100, 200, -150], [250, 50, 100], [-250, -50, -300]], dtype=np.int16
    )
    c.set_torque_allocation_inv_wire(tinv)
    one = np.array([[4000, 1000, 800, 3000, 900, 700, 2000]], dtype=np.int64)
    c.set_gains_wire(one)
    p, i, d = c.thrust_gains
    t = tinv * 0.001
    np.testing.assert_allclose(p.reshape(4, 3)[:, :2], t[:, :2] * [4.0, 3.0], atol=1e-12)
    np.testing.assert_allclose(i.reshape(4, 3)[:, :2], t[:, :2] * [1.0, 0.9], atol=1e-12)
    np.testing.assert_allclose(d.reshape(4, 3), t * [0.8, 0.7, 2.0], atol=1e-12)
    yaw_d = t[:, 2] * 2.0
    assert c.max_yaw_index == int(np.argmax(yaw_d))
    c.flight_config(ARM_ON, 0.0)
    c.four_axis_command([0, 0, 1.5], np.full(4, 6.0), 0.0)
    out = c.step(0.0, np.eye(3), [0, 0, 0], 25.2)
    # thrust = base + (1+beta) * 1.5 * kd_yaw_i / kd_yaw_max with no attitude error
    expected = 6.0 + (1 + out.beta) * 1.5 * yaw_d / yaw_d.max()
    np.testing.assert_allclose(out.thrust, expected, atol=1e-12)


def test_gain_wire_conversion_and_clamp_gain() -> None:
    rng = np.random.default_rng(5)
    g = rng.uniform(-40, 40, (4, 4, 3))
    wire = gains_to_wire_terms(g)
    flat = np.column_stack(
        [g[:, 0, 0], g[:, 0, 1], g[:, 0, 2], g[:, 1, 0], g[:, 1, 1], g[:, 1, 2], g[:, 2, 2]]
    )
    expected = np.clip(np.trunc(flat * 1000.0), -32768, 32767).astype(np.int16)
    np.testing.assert_array_equal(wire, expected)
    back = gains_from_wire_terms(wire.astype(np.int64))
    np.testing.assert_allclose(back[:, 0, 0], expected[:, 0] * 0.001)
    np.testing.assert_allclose(back[:, 2, 2], expected[:, 6] * 0.001)
    assert np.all(back[:, 3, :] == 0) and np.all(back[:, 2, :2] == 0)
    clamped, scaled = clamp_gain(g)
    assert scaled
    ref = g.copy()
    for axis, term in [(0, 0), (0, 2), (1, 0), (1, 2), (2, 2)]:
        m = np.abs(ref[:, axis, term]).max()
        if m > 32.767:
            ref[:, axis, term] *= 32.767 / m
    np.testing.assert_allclose(clamped, ref, rtol=1e-15)
    with pytest.raises(Exception, match=r"roll\.p"):
        bad = g.copy()
        bad[1, 0, 0] = np.nan
        gains_to_wire_terms(bad)


def test_spinal_step_runs_estimator_and_controller() -> None:
    s = SpinalStep(RATE, gyro_calib_duration_s=0.1)
    s.set_uav_info(4, UAV_HYDRUS)
    s.set_pwm_info_hydrus_example()
    g = np.zeros((4, 4, 3))
    g[:, 0, 0] = [3, 3, -3, -3]
    s.set_gains(g)
    s.flight_config(ARM_ON, 0.0)
    mag = [30.0, 0.0, -40.0]
    for k in range(100):
        out = s.step(k * DT, [0, 0, 0], [0, 0, 9.8], mag, 25.2)
        if k % 5 == 0:
            s.four_axis_command([0.1, 0, 0], np.full(4, 6.0), k * DT)
    assert out.estimate_status == "ok" and out.status == "armed"
    # level attitude, roll target 0.1: rp_i = kp_i * 0.1 on top of the 6 N base
    np.testing.assert_allclose(out.thrust, 6.0 + 0.1 * np.array([3, 3, -3, -3]), atol=1e-9)
    bad = s.step(0.5, [np.nan, 0, 0], [0, 0, 9.8], mag, 25.2)
    assert bad.estimate_status == "invalid_input"
    assert np.all(np.isfinite(bad.duty))
