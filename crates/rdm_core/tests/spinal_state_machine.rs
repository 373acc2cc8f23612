//! Typed errors and rate scaling of the Spinal state machine, from the Rust API.

use nalgebra::{Matrix3, Vector3};
use rdm_core::control::attitude::{
    AttitudeControlConfig, AttitudeController, CommandError, FlightConfigCmd, SpinalEvent,
};
use rdm_core::pwm::PwmInfo;

fn armed(rate_hz: f64) -> AttitudeController {
    let mut c = AttitudeController::new(AttitudeControlConfig::firmware(rate_hz)).unwrap();
    c.set_uav_info(4, 16).unwrap();
    c.set_pwm_info(PwmInfo::hydrus_example()).unwrap();
    c.flight_config(0, 0.0).unwrap();
    c
}

#[test]
fn wrong_length_is_a_typed_error_and_an_event() {
    let mut c = armed(200.0);
    let err = c.four_axis_command([0.0; 3], &[5.0; 3], 0.0).unwrap_err();
    assert_eq!(
        err,
        CommandError::WrongLength {
            field: "base_thrust",
            expected: 4,
            got: 3
        }
    );
    assert_eq!(c.counters().wrong_length, 1);
    let out = c.step(0.0, &Matrix3::identity(), &Vector3::zeros(), 25.0);
    let events: Vec<_> = out.events.iter().copied().collect();
    assert_eq!(
        events,
        vec![
            SpinalEvent::Ack(FlightConfigCmd::ArmOn),
            SpinalEvent::Rejected(err)
        ]
    );
}

/// One second of force landing lowers the average base thrust by 2.5 N at both rates:
/// 0.0025 N per 1 ms step at 1 kHz, 0.0125 N per 5 ms step at 200 Hz.
#[test]
fn force_landing_ramp_is_rate_independent_in_newton_per_second() {
    for rate in [1000.0, 200.0] {
        let mut c = armed(rate);
        c.four_axis_command([0.0; 3], &[12.0, 13.0, 14.0, 15.0], 0.0)
            .unwrap();
        c.flight_config(2, 0.0).unwrap();
        let steps = rate as usize;
        for k in 0..steps {
            c.step(
                k as f64 / rate,
                &Matrix3::identity(),
                &Vector3::zeros(),
                25.0,
            );
        }
        let average = c.base_thrust().iter().sum::<f64>() / 4.0;
        assert!(
            (average - (13.5 - 2.5)).abs() < 1e-9,
            "{rate} Hz: {average}"
        );
    }
}
