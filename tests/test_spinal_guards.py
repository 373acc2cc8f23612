"""Guards on the Spinal actuator path (docs/spinal.md "Guards on the actuator path"):
battery-voltage window, duty cap, command thrust saturation, non-finite thrust, CAN value
clamp. Expected duties come from numpy.roots on the Hydrus SQRT curve of
jsk-wire-protocols.md sec. 3.6, not from the converter."""

from __future__ import annotations

import numpy as np
import pytest

from rdm.control.attitude import (
    ARM_ON,
    UAV_DRAGON,
    UAV_HYDRUS,
    AttitudeController,
)
from rdm.protocol import neuron as nr
from rdm.pwm import POLYNOMIAL_MODE, PwmConverter, duty_to_can, hydrus_converter

P2, P1, P0 = 0.07983707, -6.627443098, 12.3593793002
VREF, MAX_THRUST, MIN_PWM, MAX_PWM, MIN_THRUST = 25.2, 20.0, 0.59, 0.9375, 1.0
RATE = 200.0
EYE = np.eye(3)
STILL = [0.0, 0.0, 0.0]


def curve_duty(f: float, v_factor: float = 1.0) -> float:
    """Larger root of 0.1 p2 x^2 + 0.1 p1 x + (p0 - v_factor f) = 0, x in %, as a duty."""
    roots = np.roots([0.1 * P2, 0.1 * P1, P0 - max(v_factor * f, 0.0)])
    return float(np.max(roots.real)) / 100.0


def armed(**kw) -> AttitudeController:
    c = AttitudeController(RATE, **kw)
    c.set_uav_info(4, UAV_HYDRUS)
    c.set_pwm_info_hydrus_example()
    c.flight_config(ARM_ON, 0.0)
    return c


def kinds(out) -> list[str]:
    return [kind for kind, _value in out.events]


# ------------------------------------------------------------------------ battery voltage
def test_implausible_voltage_is_rejected_counted_and_replaced_by_the_last_good_one() -> None:
    c = armed()
    # 1e-300 V: the firmware's factor (25.2/1e-300)^2 is inf and so is min_duty = convert(1 N)
    # (the unguarded core gave duty inf, pwm_report 65535).
    out = c.step(0.0, EYE, STILL, 1e-300)
    np.testing.assert_allclose(out.duty, curve_duty(MIN_THRUST), atol=1e-12)  # factor 1
    assert c.voltage_window == (pytest.approx(18.0), pytest.approx(26.7))  # 6S x 3.0..4.45 V
    assert c.last_good_voltage == VREF  # nothing good yet: the reference's own voltage
    assert c.counters["rejected_voltages"] == 1 and "voltage_rejected" in kinds(out)
    # A good reading is taken (500 ms later) ...
    out = c.step(0.6, EYE, STILL, 24.0)
    vf = (VREF / 24.0) ** 2
    np.testing.assert_allclose(out.duty, curve_duty(MIN_THRUST, vf), atol=1e-12)
    # ... and stays in use when the next one (the 0.07 ADC scale: 1.75 V) is implausible.
    c.four_axis_command([0.0, 0.0, 0.0], np.full(4, 9.0), 1.2)
    out = c.step(1.2, EYE, STILL, 1.75)
    assert c.last_good_voltage == 24.0 and c.counters["rejected_voltages"] == 2
    assert "voltage_rejected" in kinds(out)  # the first of a new run of rejections
    np.testing.assert_allclose(out.duty, curve_duty(9.0, vf), atol=1e-12)
    assert c.pwm_state[2] == pytest.approx(vf, rel=1e-15)


@pytest.mark.parametrize(
    ("voltage", "accepted"),
    [(17.99, False), (18.0, True), (26.7, True), (26.71, False), (-25.0, False), (np.inf, False)],
)
def test_voltage_window_edges(voltage: float, accepted: bool) -> None:
    conv = hydrus_converter()
    conv.force_voltage(25.0)
    used = conv.force_voltage(voltage)
    expected = voltage if accepted else 25.0
    assert conv.voltage_factor == pytest.approx((VREF / expected) ** 2, rel=1e-15)
    assert conv.rejected_voltages == (0 if accepted else 1)
    assert used is accepted


def test_cell_count_from_the_reference_curves_or_configured() -> None:
    coeffs = [50.0, 12.0, -1.5, 0.2, -0.01]
    dragon = np.array([[v, 26.0, *coeffs] for v in (25.2, 24.2, 23.2, 22.2)])
    conv = PwmConverter(0.55, 0.92, 2.0, 13.0, POLYNOMIAL_MODE, dragon)
    assert conv.voltage_window == pytest.approx((18.0, 26.7))  # round(25.2 / 4.2) = 6 cells
    four = PwmConverter(
        0.55,
        0.92,
        2.0,
        13.0,
        POLYNOMIAL_MODE,
        dragon,
        battery_cells=4,
        cell_voltage_range=(3.2, 4.2),
    )
    assert four.voltage_window == pytest.approx((12.8, 16.8))
    off = PwmConverter(0.55, 0.92, 2.0, 13.0, POLYNOMIAL_MODE, dragon, voltage_guard=False)
    assert off.voltage_window is None
    assert off.force_voltage(1.75)  # firmware-exact: any positive voltage


def test_firmware_exact_keeps_the_firmware_voltage_but_never_exceeds_max_duty() -> None:
    c = armed(firmware_exact=True)
    out = c.step(0.0, EYE, STILL, 1.75)
    assert c.pwm_state[2] == pytest.approx((VREF / 1.75) ** 2)  # the firmware's factor
    # min_duty = convert(1 N) at factor 207 is above 1 (the firmware's clamp would let it
    # through); capped at max_pwm.
    assert curve_duty(MIN_THRUST, (VREF / 1.75) ** 2) > 1.0
    np.testing.assert_array_equal(out.duty, MAX_PWM)
    np.testing.assert_array_equal(out.pwm_report, 1875)
    out = c.step(0.6, EYE, STILL, 1e-300)  # infinite factor: min_duty falls back to min_pwm
    np.testing.assert_array_equal(out.duty, MIN_PWM)
    np.testing.assert_array_equal(out.pwm_report, 1180)
    assert c.counters["rejected_voltages"] == 0


# ------------------------------------------------------------------------ thrust commands
def test_huge_base_thrust_saturates_to_the_curve_maximum() -> None:
    """3.4e38 (a float32 the wire carries). Unsaturated, alpha = (20 - 3.4e38)/3.4e38 rounds
    to -1 exactly (20 is far below half an ulp of 3.4e38), so (1 + alpha) base = 0: the
    firmware's saturation turns the largest command into min_duty."""
    huge = float(np.float32(3.4e38))
    c = armed()
    c.four_axis_command([0.0, 0.0, 0.0], np.full(4, huge), 0.0)
    out = c.step(0.0, EYE, STILL, VREF)
    np.testing.assert_allclose(out.thrust, MAX_THRUST)
    np.testing.assert_allclose(out.duty, min(curve_duty(MAX_THRUST), MAX_PWM), atol=1e-12)
    np.testing.assert_array_equal(c.base_thrust, MAX_THRUST)
    assert c.counters["saturated_commands"] == 1 and "command_saturated" in kinds(out)
    # At 24 V the limit is 20 / (25.2/24)^2 N: alpha scales the saturated command to it.
    out = c.step(0.6, EYE, STILL, 24.0)
    np.testing.assert_allclose(out.thrust, MAX_THRUST / (VREF / 24.0) ** 2, rtol=1e-12)

    exact = armed(firmware_exact=True)
    exact.four_axis_command([0.0, 0.0, 0.0], np.full(4, huge), 0.0)
    out = exact.step(0.0, EYE, STILL, VREF)
    assert out.alpha == -1.0 and np.all(out.thrust == 0.0)


def test_negative_thrust_and_yaw_term_saturate() -> None:
    c = armed()
    c.four_axis_command([0.0, 0.0, -1e30], np.array([-5.0, 3.0, 8.0, 25.0]), 0.0)
    np.testing.assert_array_equal(c.base_thrust, [0.0, 3.0, 8.0, 20.0])
    c.four_axis_command([0.0, 0.0, 0.0], np.array([1.0, 3.0, 8.0, 9.0]), 0.01)
    assert c.counters["saturated_commands"] == 1
    exact = armed(firmware_exact=True)
    exact.four_axis_command([0.0, 0.0, 0.0], np.array([-5.0, 3.0, 8.0, 25.0]), 0.0)
    np.testing.assert_array_equal(exact.base_thrust, [-5.0, 3.0, 8.0, 25.0])


def test_dragon_command_maximum_includes_the_rotor_divider() -> None:
    c = AttitudeController(RATE)
    c.set_uav_info(4, UAV_DRAGON)
    c.set_pwm_info_hydrus_example()
    c.flight_config(ARM_ON, 0.0)
    c.four_axis_command([0.0, 0.0, 0.0], np.full(4, 1e9), 0.0)
    np.testing.assert_array_equal(c.base_thrust, 2.0 * MAX_THRUST)


def test_non_finite_thrust_gives_min_duty_never_max() -> None:
    """A finite but huge rate makes the gyro-moment term w x (I w) infinite: with inertia
    xy 0.05 and w = (1e200, 0, 0), (I w) = (1e199, 5e198, 0) and the z component of the
    cross product is 1e200 * 5e198 = inf. Armed on the ground (base thrust 0, so alpha stays
    0), rotors 0 and 2 get +inf thrust, which the firmware's clamp turns into max_pwm."""
    c = armed()
    pinv = np.array([[0, 0, 1.0], [0, 0, -1.0], [0, 0, 1.0], [0, 0, 0.0]])
    c.set_pinv_inertia(pinv, [0.1, 0.2, 0.3, 0.05, 0, 0])
    out = c.step(0.0, EYE, [1e200, 0.0, 0.0], VREF)
    np.testing.assert_allclose(out.duty, curve_duty(MIN_THRUST), atol=1e-12)  # min_duty
    np.testing.assert_array_equal(out.thrust, 0.0)
    assert c.counters["non_finite_outputs"] == 1 and "non_finite_output" in kinds(out)
    c.four_axis_command([0.0, 0.0, 0.0], np.full(4, 8.0), 0.0)
    out = c.step(0.005, EYE, STILL, VREF)  # a sane rate: back to the commanded thrust
    np.testing.assert_allclose(out.thrust, 8.0)
    assert "non_finite_output" not in kinds(out)


# ------------------------------------------------------------------------ CAN encodings
def test_can_value_is_clamped_to_0_1000() -> None:
    duty = np.array([0.4, 0.5, 0.59, MAX_PWM, 1.0, 1.68, 3.0])
    # (uint16)(duty*2000 - 1000) for 0.5..1.0; 1.68 would be 2360 (and 3360 for 2.18).
    np.testing.assert_array_equal(duty_to_can(duty), [0, 0, 180, 875, 1000, 1000, 1000])


def test_python_pwm_encoder_refuses_out_of_range_values() -> None:
    with pytest.raises(nr.NeuronFrameError, match="values"):
        nr.PwmFrame(0, (3360, 0, 0, 0, 0, 0))
    with pytest.raises(nr.NeuronFrameError, match="duty"):
        nr.duty_to_pwm_value(1.68)


# ------------------------------------------------------------------------ in the mirror
def test_bad_adc_scale_never_drives_a_duty_above_max_on_the_can_bus() -> None:
    """The lockstep defect: set_adc_scale 0.07 from the PC makes the battery reading
    0.07 x 25.2 = 1.76 V; the unguarded core drove every duty to 1.0 (CAN value 1000, a
    2000 us pulse). The mirror takes the scale as the firmware does (firmware_adc_scale); the
    core's voltage guard rejects the low-passed reading once it leaves 18.0..26.7 V and keeps
    every CAN value at or below max_pwm's (0.9375 x 2000 - 1000 = 875)."""
    from test_spinal_mirror import Rig, arm, four_axis, msg

    rig = Rig()
    try:
        rig.mirror.firmware_adc_scale = True
        rig.handshake()
        rig.wait_can_running()
        arm(rig)
        t_scale = rig.t
        rig.publish("set_adc_scale", msg("std_msgs/Float32", data=0.07))
        # 6 s of hover commands at 20 Hz: the 0.99/0.01 battery filter (every 20 ms) takes
        # the reading below 4.95 V after about 4 s, where the firmware's min_duty =
        # convert(1 N x (25.2/V)^2) passes duty 1.0.
        for _ in range(120):
            rig.publish("four_axes/command", four_axis([0.0, 0.0, 0.0], [9.0] * 4))
            rig.run_for(50)
        values = [v for _t, frame in rig.pwm_frames(since=t_scale) for v in frame[:4]]
        assert values and max(values) <= 875
        assert rig.mirror.battery_voltage < 18.0  # the reading did leave the window
        assert rig.mirror.core.counters["rejected_voltages"] >= 1
        texts = [e.text for _t, e in rig.logs(since=t_scale)]
        assert any("implausible battery voltage" in text for text in texts)
    finally:
        rig.close()


# ------------------------------------------------------------------------ alpha bound
ROLL_P = np.array([30.0, 15.0, -15.0, -30.0])
BASE = 5.0


def _roll_saturated(**kw) -> tuple[AttitudeController, object]:
    """Roll -0.9 rad with per-rotor roll P gains (30, 15, -15, -30) and 5 N base thrust:
    rotor 0's roll term alone (27 N) exceeds the 20 N thrust limit, so alpha < -1."""
    c = armed(**kw)
    gains = np.zeros((4, 4, 3))
    gains[:, 0, 0] = ROLL_P
    c.set_gains(gains)
    c.four_axis_command([0.0, 0.0, 0.0], np.full(4, BASE), 0.0)
    return c, c.step(0.0, *_roll_saturated_inputs())


def _roll_saturated_inputs() -> tuple[np.ndarray, list[float], float]:
    """Rotation (roll -0.9 rad), rate and voltage of a step of :func:`_roll_saturated`."""
    roll = -0.9
    rot = np.array(
        [[1.0, 0.0, 0.0], [0.0, np.cos(roll), -np.sin(roll)], [0.0, np.sin(roll), np.cos(roll)]]
    )
    return rot, STILL, VREF


def _expected(bound: bool) -> tuple[float, np.ndarray, np.ndarray]:
    """The allocation of docs/spinal.md "Attitude allocation" in numpy: alpha, thrust, duty."""
    rp = ROLL_P * 0.9  # error = 0 - (-0.9)
    alpha = (MAX_THRUST - np.max(BASE + rp)) / BASE  # rotor divider 1 (HYDRUS)
    if bound:
        alpha = max(alpha, -1.0)
    thrust = rp + (1.0 + alpha) * BASE  # beta = -1 removes the yaw term
    lo = curve_duty(MIN_THRUST)
    duty = np.array([min(max(curve_duty(f), lo), MAX_PWM) for f in thrust])
    return alpha, thrust, duty


def test_alpha_below_minus_one_is_bounded_keeping_each_base_thrust_sign() -> None:
    c, out = _roll_saturated()
    alpha, thrust, duty = _expected(bound=True)
    assert alpha == -1.0 and out.alpha == -1.0
    np.testing.assert_allclose(out.thrust, thrust, atol=1e-12)  # the roll terms alone
    np.testing.assert_allclose(out.duty, duty, atol=1e-12)
    assert c.counters["bounded_alphas"] == 1
    # Rotor 1 keeps its 13.5 N roll term; the firmware's alpha = -2.4 takes 7 N off it.
    assert out.thrust[1] == pytest.approx(13.5, abs=1e-12)
    # The first bounded step of a run is an event; the next one is only counted.
    assert kinds(out).count("alpha_bounded") == 1
    out = c.step(0.005, *_roll_saturated_inputs())
    assert out.alpha == -1.0 and "alpha_bounded" not in kinds(out)
    assert c.counters["bounded_alphas"] == 2


def test_firmware_exact_alpha_reverses_every_base_thrust() -> None:
    for kw in ({"firmware_exact": True}, {"bound_alpha": False}):
        c, out = _roll_saturated(**kw)
        alpha, thrust, duty = _expected(bound=False)
        assert alpha == pytest.approx(-2.4) and out.alpha == pytest.approx(alpha, abs=1e-12)
        np.testing.assert_allclose(out.thrust, thrust, atol=1e-12)  # rp - 7 N on every rotor
        np.testing.assert_allclose(out.duty, duty, atol=1e-12)
        assert c.counters["bounded_alphas"] == 0 and "alpha_bounded" not in kinds(out)


def test_bounded_alpha_is_logged_once_per_run_by_the_mirror() -> None:
    """The mirror logs the first bounded step of a run as a rosout warning, read here by the
    PC-side rosserial server. Roll P gains (30, 15, -15, -30) on the wire (x 1000), level
    IMU, target roll 0.9 rad (below the 1.0 rad command tilt limit) and 5 N base: rotor 0's
    roll term (27 N) alone exceeds the 20 N limit. Rotor 1 keeps its 13.5 N roll term (the
    CAN value read back through the inverse of the thrust curve); the firmware's alpha would
    leave it 6.5 N."""
    from test_spinal_mirror import Rig, arm, can_value_to_thrust, four_axis, msg

    from rdm.protocol.rosserial import constants as C

    rig = Rig()
    try:
        rig.mirror.set_battery_voltage(24.0)
        rig.handshake()
        rig.wait_can_running()
        arm(rig)
        terms = [msg("spinal/RollPitchYawTerm", roll_p=int(p * 1000)) for p in ROLL_P]
        rig.publish("rpy/gain", msg("spinal/RollPitchYawTerms", motors=terms))
        t_cmd = rig.t
        for _ in range(6):  # 300 ms of commands at 20 Hz: about 60 bounded steps
            rig.publish("four_axes/command", four_axis([0.9, 0.0, 0.0], [BASE] * 4))
            rig.run_for(50)
        assert rig.mirror.core.counters["bounded_alphas"] >= 50
        lines = [(e.level, e.text) for _t, e in rig.logs(since=t_cmd) if "alpha" in e.text]
        text = "guard: saturation factor alpha below -1, bounded to -1"
        assert lines == [(C.LogLevel.WARN, text)]
        frames = rig.pwm_frames(since=rig.t - 20)
        assert can_value_to_thrust(frames[-1][1][1], 24.0) == pytest.approx(13.5, abs=0.1)
    finally:
        rig.close()
