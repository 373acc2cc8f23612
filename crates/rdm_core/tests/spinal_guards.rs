//! The actuator-path guards of the Spinal core from the Rust API: the CAN PWM packer clamps,
//! the firmware configuration selects every firmware-exact option, the voltage window.

use nalgebra::{Matrix3, Vector3};
use rdm_core::control::attitude::{
    AntiWindup, AttitudeControlConfig, AttitudeController, SpinalConfig, SpinalEvent,
};
use rdm_core::estimate::EstimatorConfig;
use rdm_core::firmware::spinal_frame::pwm;
use rdm_core::pwm::{PwmInfo, VoltageGuard};

/// Slot values above 1000 are clamped, not masked to 10 bits. The expected payload is
/// cantools' encoding of `MotorPwmSlaves1To6` (firmware_protocol/neuron/
/// neuron_spinal_to_neuron.dbc) with Pwm1..6 = 1000, 1000, 0, 1000, 999, 288. Masking would
/// have packed 3360 as 288 (3360 & 0x3FF) and 1001 as 1001.
#[test]
fn pwm_frame_clamps_slot_values_to_1000() {
    let frame = pwm(0, &[3360, 1000, 0, 1001, 999, 288]);
    assert_eq!(frame.id, 15);
    assert_eq!(frame.len, 8);
    assert_eq!(frame.data, [232, 163, 15, 0, 232, 159, 15, 18]);
    let saturated = pwm(1, &[u16::MAX; 6]);
    let in_range = pwm(1, &[1000; 6]);
    assert_eq!(saturated.data, in_range.data);
}

#[test]
fn firmware_configs_select_every_firmware_exact_option() {
    let control = AttitudeControlConfig::firmware(1000.0);
    assert_eq!(control.anti_windup, AntiWindup::Off);
    assert_eq!(control.voltage_guard, VoltageGuard::Off);
    assert!(!control.saturate_commands);
    assert!(!control.bound_alpha);
    assert!(EstimatorConfig::firmware(1000.0).guards.is_none());
    let spinal = SpinalConfig::firmware(200.0);
    assert!(spinal.estimator.guards.is_none());
    assert_eq!(spinal.control.voltage_guard, VoltageGuard::Off);
    // The defaults are the guarded ones.
    let default = SpinalConfig::default();
    assert!(default.estimator.guards.is_some());
    assert!(default.control.saturate_commands);
    assert!(default.control.bound_alpha);
    assert_ne!(default.control.voltage_guard, VoltageGuard::Off);
}

fn armed(config: AttitudeControlConfig) -> AttitudeController {
    let mut c = AttitudeController::new(config).unwrap();
    c.set_uav_info(4, 16).unwrap();
    c.set_pwm_info(PwmInfo::hydrus_example()).unwrap();
    c.flight_config(0, 0.0).unwrap();
    c
}

/// 25.2 V reference = 6 cells (round(25.2 / 4.2)); window 6 x [3.0, 4.45] = [18.0, 26.7] V.
/// A voltage of 1e-300 is rejected and the reference's own voltage (factor 1) is used; with
/// the guard off the factor is infinite, yet the duty stays within [min_pwm, max_pwm].
#[test]
fn voltage_guard_rejects_and_duty_never_exceeds_max() {
    let mut c = armed(AttitudeControlConfig::default());
    let out = c.step(0.0, &Matrix3::identity(), &Vector3::zeros(), 1e-300);
    let pwm = c.pwm().unwrap();
    assert_eq!(pwm.voltage_window(), Some((18.0, 6.0 * 4.45)));
    assert_eq!(pwm.voltage_factor(), 1.0);
    assert_eq!(c.counters().rejected_voltages, 1);
    assert!(out
        .events
        .iter()
        .any(|e| *e == SpinalEvent::VoltageRejected));
    assert!(out.duty[..out.outputs]
        .iter()
        .all(|d| (0.59 - 0.01..=0.9375).contains(d)));

    let mut exact = armed(AttitudeControlConfig::firmware(200.0));
    let out = exact.step(0.0, &Matrix3::identity(), &Vector3::zeros(), 1e-300);
    assert!(exact.pwm().unwrap().voltage_factor().is_infinite());
    assert_eq!(out.duty[..4], [0.59; 4]); // min_duty = convert(min_thrust) = inf -> min_pwm
    let out = exact.step(0.6, &Matrix3::identity(), &Vector3::zeros(), 1.75);
    assert_eq!(out.duty[..4], [0.9375; 4]); // min_duty capped at max_pwm
    assert_eq!(out.pwm_report[..4], [1875; 4]);
}

/// Roll -0.9 rad, roll P gains (30, 15, -15, -30), 5 N base thrust, 20 N limit: roll terms
/// (27, 13.5, -13.5, -27) N; the firmware's alpha = (20 - 32) / 5 = -2.4 gives thrusts
/// rp - 7 N = (20, 6.5, -20.5, -34); the bound alpha = -1 gives the roll terms alone.
/// Two bounded steps in a row count twice and report one `AlphaBounded` event; a level step
/// ends the run.
#[test]
fn alpha_is_bounded_to_minus_one_by_default() {
    use rdm_core::control::gains::GainSet;
    let roll_p = [30.0, 15.0, -15.0, -30.0];
    let rot = nalgebra::Rotation3::from_euler_angles(-0.9, 0.0, 0.0).into_inner();
    for (config, alpha, expected, bounded) in [
        (
            AttitudeControlConfig::default(),
            -1.0,
            [27.0, 13.5, -13.5, -27.0],
            1,
        ),
        (
            AttitudeControlConfig::firmware(200.0),
            -2.4,
            [20.0, 6.5, -20.5, -34.0],
            0,
        ),
    ] {
        let mut c = armed(config);
        let mut gains = GainSet::default();
        for (g, p) in gains.iter_mut().zip(roll_p) {
            g.roll.p = p;
        }
        c.set_gains(&gains).unwrap();
        c.four_axis_command([0.0; 3], &[5.0; 4], 0.0).unwrap();
        let alpha_events = |out: &rdm_core::control::attitude::AttitudeOutput| {
            out.events
                .iter()
                .filter(|e| **e == SpinalEvent::AlphaBounded)
                .count() as u64
        };
        // Two bounded steps in a row: counted twice, reported once (the first of the run).
        let mut events = 0;
        for t in [0.0, 0.005] {
            let out = c.step(t, &rot, &Vector3::zeros(), 25.2);
            assert!((out.alpha - alpha).abs() < 1e-12, "alpha {}", out.alpha);
            for (got, want) in out.thrust[..4].iter().zip(expected) {
                assert!((got - want).abs() < 1e-12, "thrust {got} != {want}");
            }
            events += alpha_events(&out);
        }
        assert_eq!(c.counters().bounded_alphas, 2 * bounded);
        assert_eq!(events, bounded);
        // A level step (roll terms 0, alpha 0) ends the run; the next bounded step starts one.
        let out = c.step(0.01, &Matrix3::identity(), &Vector3::zeros(), 25.2);
        assert_eq!((out.alpha, alpha_events(&out)), (0.0, 0));
        let out = c.step(0.015, &rot, &Vector3::zeros(), 25.2);
        assert_eq!(alpha_events(&out), bounded);
        assert_eq!(c.counters().bounded_alphas, 3 * bounded);
    }
}
